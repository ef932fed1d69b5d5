"""The simulated truth of a run: what can differ from the plan (``sbmpc run``, the
closed-loop robustness of ``sbmpc sweep``).

A plan is made with the scenario's vehicle on the scenario's map. The vehicle that drives
it (:class:`Truth`) may differ in three ways, each drawn per run from a seed:

* **the vehicle and the ground** (``vary``: relative standard deviations of any numeric
  vehicle or terrain parameter: mass, inertia, mu_sa, mu_op, mu_roll, v_max (the battery
  voltage), radius_scale_left/right (a wheel's radius), ...), drawn from normal
  distributions around the planning model's (:func:`sbmpc.planning.margin.drawn_world`);
* **the map** (``faults.map``): smooth elevation error (``noise_sd_m`` at a correlation
  length ``corr_m``: white noise smoothed by a Gaussian of sd corr_m / sqrt(2), whose
  correlation falls to exp(-1/2) at corr_m, scaled to the sd), a ``bias_m``, a
  ``tilt_deg`` (a plane through the map's centre, in a drawn direction), a ``patch`` of
  a terrain class the map does not know (``{terrain: grass, radius_m: 3}``, placed on the
  straight line from start to goal unless ``x``/``y`` are given), a ``bump``
  (``{height_m: 0.1, radius_m: 0.5}``, a Gaussian hill not on the map, placed likewise);
* **the execution** (``faults``): ``delay_s`` (commands reach the drive late),
  ``odometry`` (``noise_m``/``noise_deg``: white noise on each measured pose; ``drift``:
  a position error growing by that fraction of the distance driven, in a drawn
  direction; ``drift_deg_per_m``: heading error per metre driven), ``dropped`` (the
  probability that a period's command is lost: the drive holds the previous one).

What was drawn is kept (:attr:`Truth.spec`, JSON) in the run's file, so that
:func:`from_spec` builds the same truth again (``sbmpc run --replay``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np

from dynamics import kernels as K
from dynamics.params import Terrain, Vehicle

from .errors import InputError
from .planning import world as WO
from .planning.margin import drawn_world

MAP_KEYS = ("noise_sd_m", "corr_m", "bias_m", "tilt_deg", "tilt_dir_deg", "patch", "bump")
ODOMETRY_KEYS = ("noise_m", "noise_deg", "drift", "drift_deg_per_m")
FAULT_KEYS = ("delay_s", "odometry", "dropped", "map")
PLACED_KEYS = {"patch": ("terrain", "radius_m", "x", "y"), "bump": ("height_m", "radius_m", "x", "y")}
# (least, largest) of each number of faults: what a run may meet and the model executes
RANGES = {"delay_s": (0.0, 2.0), "dropped": (0.0, 0.9), "noise_sd_m": (0.0, 5.0), "corr_m": (0.0, 1e3),
          "bias_m": (-1e3, 1e3), "tilt_deg": (0.0, 30.0), "tilt_dir_deg": (-360.0, 360.0), "noise_m": (0.0, 10.0),
          "noise_deg": (0.0, 90.0), "drift": (0.0, 0.5), "drift_deg_per_m": (0.0, 10.0), "radius_m": (0.01, 1e3),
          "height_m": (-10.0, 10.0), "x": (-1e9, 1e9), "y": (-1e9, 1e9)}
PLACE_ALONG = (0.25, 0.75)   # a patch or bump without x, y: drawn this far along start -> goal


@dataclass(frozen=True, eq=False)
class Truth:
    """The vehicle a run's plans are executed by: ``world`` its vehicle (with its command
    delay), terrains and map; ``odometry`` the error of its measured pose
    ({noise_m, noise_deg, drift, drift_deg_per_m}); ``dropped`` the probability a period's
    command is lost; ``seed`` of its noise; ``spec`` what was drawn (JSON, for a replay);
    ``name`` for messages."""

    world: WO.World
    odometry: dict = field(default_factory=dict)
    dropped: float = 0.0
    seed: int = 0
    spec: dict = field(default_factory=dict)
    name: str = ""

    def odometer(self) -> "Odometer":
        return Odometer(self.world, self.odometry, np.random.default_rng([self.seed, 2]))

    def dropper(self) -> "Dropper":
        return Dropper(self.dropped, np.random.default_rng([self.seed, 3]))


# ---- building a truth -----------------------------------------------------------------
def nominal(world: WO.World, vehicle: Vehicle | None = None, grip: float | None = None) -> Truth:
    """The truth of ``sbmpc run --truth/--truth-mass/--truth-grip``: ``vehicle`` (default:
    the world's), the terrains' mu_sa and mu_op times ``grip``, the map as planned, an
    exact odometry."""
    tw = world if vehicle is None else replace(world, vehicle=vehicle)
    if grip is not None and grip != 1.0:
        tw = replace(tw, terrains=WO.gripped(tw.terrains, grip))
    name = tw.vehicle.name + (f", grip x{grip:g}" if grip not in (None, 1.0) else "")
    return Truth(tw, spec=_spec(world, tw, {}, {}, 0), name=name)


def draw(world: WO.World, vary: dict | None = None, faults: dict | None = None, seed: int = 0) -> Truth:
    """A truth drawn around ``world`` (module doc): ``vary`` relative standard deviations
    of vehicle and terrain parameters, ``faults`` the map's and the execution's; ``seed``
    seeds every draw (the same seed, the same truth). An InputError names a bad key."""
    vary, faults = dict(vary or {}), dict(faults or {})
    bad = problems(vary, faults)
    if bad:
        raise InputError("; ".join(bad))
    rng = np.random.default_rng([int(seed), 1])
    drawn = drawn_world(world, vary, rng) if vary else world
    m = dict(faults.get("map") or {})
    if m:
        m.setdefault("corr_m", 2.0)
        if m.get("tilt_deg"):
            m.setdefault("tilt_dir_deg", float(rng.uniform(-180.0, 180.0)))
        for key in ("patch", "bump"):
            if m.get(key):
                m[key] = _placed(world, dict(m[key]), rng)
        m["seed"] = int(rng.integers(2 ** 31))
    spec = _spec(world, drawn, m, faults, int(seed))
    return from_spec(world, spec)


def from_spec(world: WO.World, spec: dict) -> Truth:
    """The truth a spec (:attr:`Truth.spec`) describes, around the planning ``world``."""
    try:
        vd = dict(spec.get("vehicle", {}))
        vd["delay"] = vd.get("delay", world.vehicle.delay) + float(spec.get("delay_s", 0.0) or 0.0)
        v = world.vehicle.replace(**vd)
        ts = tuple(t.replace(**d) for t, d in zip(world.terrains, spec.get("terrains", [{}] * len(world.terrains))))
    except Exception as exc:
        raise InputError(f"truth: {str(exc).replace('<replace>: ', '')}") from None
    tw = replace(world, vehicle=v, terrains=ts)
    m = spec.get("map") or {}
    if m:
        tw = _true_map(tw, m)
    odo = {k: float(v) for k, v in (spec.get("odometry") or {}).items()}
    return Truth(tw, odo, float(spec.get("dropped", 0.0) or 0.0), int(spec.get("seed", 0)), spec,
                 spec.get("name") or v.name)


def _spec(world: WO.World, drawn: WO.World, m: dict, faults: dict, seed: int) -> dict:
    """The JSON of a truth: the drawn vehicle's and terrains' numbers that differ from the
    planning world's, the map's faults as placed, the execution's."""
    def diff(a, b):
        return {f.name: getattr(b, f.name) for f in fields(a)
                if isinstance(getattr(a, f.name), float) and getattr(a, f.name) != getattr(b, f.name)}
    vd = diff(world.vehicle, drawn.vehicle)
    td = [diff(a, b) for a, b in zip(world.terrains, drawn.terrains)]
    parts = [f"{k} {100 * (getattr(drawn.vehicle, k) / getattr(world.vehicle, k) - 1):+.0f}%"
             for k in sorted(vd) if getattr(world.vehicle, k)]
    parts += [f"terrain {k} drawn" for k in sorted({k for d in td for k in d})]
    parts += [label for key, label in (("map", "map error"), ("delay_s", f"{faults.get('delay_s', 0):g} s delay"),
                                       ("odometry", "odometry error"), ("dropped", "dropped commands"))
              if (m if key == "map" else faults.get(key))]
    name = drawn.vehicle.name + (f" ({', '.join(parts)})" if parts else "")
    return {"seed": seed, "name": name, "vehicle": vd, "terrains": td, "map": m,
            "delay_s": float(faults.get("delay_s", 0.0) or 0.0), "odometry": dict(faults.get("odometry") or {}),
            "dropped": float(faults.get("dropped", 0.0) or 0.0)}


def _placed(world: WO.World, spec: dict, rng) -> dict:
    """A patch or bump with its centre: given, or drawn along the start -> goal line."""
    s, g = world.scenario.start, world.scenario.goal
    f = float(rng.uniform(*PLACE_ALONG))
    spec.setdefault("x", s["x"] + f * (g["x"] - s["x"]))
    spec.setdefault("y", s["y"] + f * (g["y"] - s["y"]))
    return spec


def _true_map(tw: WO.World, m: dict) -> WO.World:
    """``tw`` with its map changed by the map faults ``m`` (module doc)."""
    from dynamics.params import load_terrain
    from scipy.ndimage import gaussian_filter
    e = tw.emap
    H = e.heights.copy()
    Xg, Yg = WO.centres(e)
    xs, ys = Xg[0], Yg[:, 0]
    rng = np.random.default_rng(int(m.get("seed", 0)))
    sd = float(m.get("noise_sd_m", 0.0) or 0.0)
    if sd > 0.0:
        n = rng.standard_normal(H.shape)
        sigma = float(m.get("corr_m", 2.0)) / math.sqrt(2.0) / e.resolution
        if sigma > 0.0:
            n = gaussian_filter(n, sigma, mode="reflect")
        n -= n.mean()
        H += sd * n / max(n.std(), 1e-12)
    H += float(m.get("bias_m", 0.0) or 0.0)
    if m.get("tilt_deg"):
        d = math.radians(float(m.get("tilt_dir_deg", 0.0)))
        H += math.tan(math.radians(float(m["tilt_deg"]))) * (
            (Xg - xs.mean()) * math.cos(d) + (Yg - ys.mean()) * math.sin(d))
    b = m.get("bump")
    if b:
        H += float(b.get("height_m", 0.1)) * np.exp(
            -0.5 * ((Xg - b["x"]) ** 2 + (Yg - b["y"]) ** 2) / float(b.get("radius_m", 0.5)) ** 2)
    layer, names, terrains = e.terrain_layer, e.terrain_names, tw.terrains
    p = m.get("patch")
    if p:
        try:
            t = load_terrain(p.get("terrain", "grass"), tw.scenario.base)
        except Exception as exc:
            raise InputError(f"faults.map.patch.terrain: {exc}") from None
        layer = np.zeros(H.shape, np.int64) if layer is None else layer.copy()
        layer[(Xg - p["x"]) ** 2 + (Yg - p["y"]) ** 2 <= float(p.get("radius_m", 2.0)) ** 2] = len(terrains)
        names = tuple(names) + (t.name,) if names else tuple(x.name for x in terrains) + (t.name,)
        terrains = tuple(terrains) + (t,)
    emap = replace(e, heights=H, terrain_layer=layer, terrain_names=names)
    return replace(tw, emap=emap, terrains=terrains)


# ---- validation -------------------------------------------------------------------------
def problems(vary: dict, faults: dict, where: str = "") -> list:
    """Every problem of a ``vary`` (relative sds of vehicle/terrain parameters) and a
    ``faults`` mapping, one line each, ``where`` their place in the file."""
    from dynamics.params import did_you_mean
    from .scenario import shown
    out = []
    veh, ter = numeric_fields()
    names = sorted(set(veh) | set(ter))
    if not isinstance(vary, dict):
        out.append(f"{where}vary: expected a mapping of parameter: relative standard deviation, found {shown(vary)}")
        vary = {}
    for name, s in vary.items():
        if name not in names:
            out.append(f"{where}vary.{name}: expected a numeric vehicle or terrain parameter, found an unknown "
                       f"one{did_you_mean(name, names)}")
        elif isinstance(s, bool) or not isinstance(s, (int, float)) or not 0.0 <= s <= 1.0:
            out.append(f"{where}vary.{name}: expected a relative standard deviation in [0, 1], found {shown(s)}")
    if not isinstance(faults, dict):
        return out + [f"{where}faults: expected a mapping with keys among {', '.join(FAULT_KEYS)}, found {shown(faults)}"]

    def number(path, key, val):
        lo, hi = RANGES[key]
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not lo <= val <= hi:
            out.append(f"{where}{path}: expected a number in [{lo:g}, {hi:g}], found {shown(val)}")

    def mapping(path, d, keys):
        if not isinstance(d, dict):
            out.append(f"{where}{path}: expected a mapping with keys among {', '.join(keys)}, found {shown(d)}")
            return {}
        for k in d:
            if k not in keys:
                out.append(f"{where}{path}.{k}: expected one of the keys {', '.join(keys)}, found an unknown key"
                           f"{did_you_mean(k, keys)}")
        return {k: v for k, v in d.items() if k in keys}

    for k, val in mapping("faults", faults, FAULT_KEYS).items():
        if k in ("delay_s", "dropped"):
            number(f"faults.{k}", k, val)
        elif k == "odometry":
            for kk, vv in mapping("faults.odometry", val, ODOMETRY_KEYS).items():
                number(f"faults.odometry.{kk}", kk, vv)
        elif k == "map":
            for kk, vv in mapping("faults.map", val, MAP_KEYS).items():
                if kk in PLACED_KEYS:
                    for k3, v3 in mapping(f"faults.map.{kk}", vv, PLACED_KEYS[kk]).items():
                        if k3 == "terrain":
                            if not isinstance(v3, str) or not v3:
                                out.append(f"{where}faults.map.{kk}.terrain: expected a terrain name or file, "
                                           f"found {shown(v3)}")
                        else:
                            number(f"faults.map.{kk}.{k3}", k3, v3)
                else:
                    number(f"faults.map.{kk}", kk, vv)
    return out


def numeric_fields() -> tuple:
    """(vehicle, terrain) numeric parameter names: what ``vary`` may draw (and a sweep's
    variants change)."""
    def numeric(cls):
        return sorted(f.name for f in fields(cls) if isinstance(f.default, (int, float)) and not isinstance(f.default, bool))
    return numeric(Vehicle), numeric(Terrain)


# ---- what a run measures and commands ---------------------------------------------------
class Odometer:
    """The measured pose of a run's true vehicle: its state with the pose error of its
    odometry ({noise_m, noise_deg, drift, drift_deg_per_m}); exact when these are 0.
    :meth:`advance` after each period the truth drove, :meth:`observe` any time."""

    def __init__(self, world: WO.World, odo: dict, rng):
        self.world = world
        self.noise_m = float(odo.get("noise_m", 0.0))
        self.noise_yaw = math.radians(float(odo.get("noise_deg", 0.0)))
        self.drift = float(odo.get("drift", 0.0))
        self.drift_yaw = math.radians(float(odo.get("drift_deg_per_m", 0.0)))
        self.exact = not (self.noise_m or self.noise_yaw or self.drift or self.drift_yaw)
        self.rng = rng
        self.heading = float(rng.uniform(-math.pi, math.pi))       # of the position drift
        self.turn = float(rng.choice((-1.0, 1.0)))                  # of the heading drift
        self.err = np.zeros(3)         # (dx, dy, dyaw) now
        self.last = None               # the truth's (x, y) at the last advance
        self.distance = 0.0

    def advance(self, Xt: np.ndarray) -> None:
        """A period driven: the drift grows with the distance, fresh noise is drawn."""
        if self.exact:
            return
        xy = (float(Xt[K.S_X]), float(Xt[K.S_Y]))
        if self.last is not None:
            self.distance += math.hypot(xy[0] - self.last[0], xy[1] - self.last[1])
        self.last = xy
        d = self.drift * self.distance
        n = self.rng.standard_normal(3)
        self.err = np.array([d * math.cos(self.heading) + self.noise_m * n[0],
                             d * math.sin(self.heading) + self.noise_m * n[1],
                             self.turn * self.drift_yaw * self.distance + self.noise_yaw * n[2]])

    def observe(self, Xt: np.ndarray) -> np.ndarray:
        """The measured state: a copy of the true state Xt with the pose error (z the true
        ground's where the error moved it)."""
        X = Xt.copy()
        if self.exact:
            return X
        X[K.S_X] += self.err[0]
        X[K.S_Y] += self.err[1]
        X[K.S_YAW] += self.err[2]
        if self.world.emap.contains(X[K.S_X], X[K.S_Y]):
            X[K.S_Z] = self.world.emap.height(X[K.S_X], X[K.S_Y])
        return X


class Dropper:
    """Which periods' commands are lost (probability ``p`` each): the drive holds the last
    command it received."""

    def __init__(self, p: float, rng):
        self.p, self.rng = float(p), rng
        self.last = None
        self.count = 0

    def applied(self, Xt: np.ndarray, control: tuple) -> tuple:
        """The control (wl, wr, duration_s) the drive gets for a period commanded ``control``."""
        if self.last is None:
            self.last = (float(Xt[K.S_REFL]), float(Xt[K.S_REFR]))
        if self.p > 0.0 and self.rng.random() < self.p:
            self.count += 1
            return (self.last[0], self.last[1], control[2])
        self.last = (float(control[0]), float(control[1]))
        return control


__all__ = ["Truth", "Odometer", "Dropper", "nominal", "draw", "from_spec", "problems", "numeric_fields"]
