"""Calibration protocols: the manoeuvres to record before ``sbmpc calibrate``
(``sbmpc protocol``).

A protocol is a sequence of parts, each a command held for a few seconds and a pause,
in the spirit of DRIVE (Baril et al., Norlab: commands spread over the robot's whole
input space, steps of a few seconds): straight driving at speeds spread up to the top
speed, forward and back; the top speed itself (a command the drive cannot reach, which
holds the wheels at V_max / k); pivots; and turns whose speeds and curvatures are spread
over what the drive holds (a Halton sequence), each turn driven both ways. Every part
that leaves the start drives back along its own track (the same command reversed), so
the robot stays near where it began, and the hold times are sized so that the part stays
inside the free area (``area``: W along the robot's heading at the start, H across it,
the robot at its centre).

Which parameter each part excites is :mod:`sbmpc.calibration`'s rule (``PARAMS``):
accelerations with efforts or currents give the mass; straight driving the rolling
resistance; turns of both directions mu_sa and mu_op; the top speed, or efforts and
currents, the torque constant; accelerations the current limit and reference rate.
:func:`check` simulates the protocol with the closed-loop model (``dynamics.synth``)
and measures it by calibrate's own ``excitation``, in the training and the held-out
part, and confirms the simulated path stays inside the area.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dynamics.params import Terrain, Vehicle

RATE = 20.0          # Hz: the commands' rate in the file (a robot's driver takes cmd_vel at 10-50 Hz)
PAUSE_S = 1.5        # s at rest between parts (the drive settles; calibrate sees a fresh acceleration)
HOLD_S = 4.0         # s a command is held where the area allows
TURN_HOLD_S = 3.0    # s a turn is held where the area allows (eight legs per turn: see design)
MIN_HOLD_S = 2.0     # s: a shorter hold reaches no steady state (the reference ramp and the PID settle)
SAFETY_M = 0.25      # m kept from the area's edge beyond the footprint's half diagonal
SPEEDS = (0.25, 0.5, 0.75)   # straight parts, as shares of the top speed
TOP_OVER = 1.15      # the top-speed part commands this share more than the drive delivers
PIVOT = (0.35, 0.6)  # pivots: wheel speed as a share of the top wheel speed
TURN_V = (0.15, 0.85)  # turns: speed range, shares of the top speed
TURN_WHEEL = 0.9     # turns: the outer wheel at most this share of the top wheel speed
HELD_MARGIN = 1.3    # pivots and turns the drive holds with this much more resistance than the file's: a
#                      vehicle off its file by 10-20 % then does not stall in them (a stall makes the
#                      calibration's fit a cliff: its replay stalls on one side of the truth, not the other)
MAX_S = 3600.0

IDENTIFIES = {
    "pause": (),
    "straight": ("mass", "ref_accel", "mu_roll", "torque_constant"),
    "top_speed": ("torque_constant", "current_limit", "mass", "mu_roll"),
    "pivot": ("mu_sa", "mu_op", "current_limit"),
    "turn": ("mu_sa", "mu_op", "mass"),
}


class ProtocolError(ValueError):
    """The area or duration cannot hold a protocol for this vehicle; the message says
    what was expected and what was found."""


@dataclass(frozen=True)
class Part:
    """One command held: ``v`` [m/s] and ``omega`` [rad/s] as a cmd_vel twist (the robot's
    driver turns them into wheel speeds with the vehicle's ``command_track``), for
    ``seconds``; ``kind`` one of IDENTIFIES; ``label`` what a reader sees."""

    kind: str
    v: float
    omega: float
    seconds: float
    label: str = ""

    @property
    def identifies(self) -> tuple:
        return IDENTIFIES[self.kind]

    def wheels(self, vehicle: Vehicle) -> tuple:
        """Commanded wheel speeds (left, right) [rad/s]."""
        half = 0.5 * self.omega * vehicle.command_track
        return (self.v - half) / vehicle.wheel_radius, (self.v + half) / vehicle.wheel_radius


@dataclass(frozen=True)
class Protocol:
    """The parts in order, the vehicle and terrain they were sized for, the free area
    (W, H) [m] and what sizing left out (``notes``)."""

    vehicle: Vehicle
    terrain: Terrain
    area: tuple
    parts: tuple
    notes: tuple = field(default=())

    @property
    def seconds(self) -> float:
        return float(sum(p.seconds for p in self.parts))

    def commands(self, dt: float = 1.0 / RATE) -> dict:
        """The commands every ``dt`` [s]: t, wl_cmd, wr_cmd [rad/s], v_cmd [m/s],
        omega_cmd [rad/s] and segment (the part's index), each an array."""
        n = [int(round(p.seconds / dt)) for p in self.parts]
        wheels = [p.wheels(self.vehicle) for p in self.parts]
        rep = lambda xs: np.repeat(np.asarray(xs, float), n)
        return {"t": np.arange(sum(n)) * dt, "wl_cmd": rep([w[0] for w in wheels]),
                "wr_cmd": rep([w[1] for w in wheels]), "v_cmd": rep([p.v for p in self.parts]),
                "omega_cmd": rep([p.omega for p in self.parts]), "segment": rep(range(len(self.parts)))}


def reach(vehicle: Vehicle, area: tuple) -> tuple:
    """(a, b) [m]: how far the robot's centre may go from the start along and across its
    heading: half the area less the footprint's half diagonal and SAFETY_M."""
    W, H = area
    foot = 0.5 * math.hypot(vehicle.patch_outer + 2 * vehicle.wheel_radius, vehicle.width + vehicle.patch_width)
    return 0.5 * W - foot - SAFETY_M, 0.5 * H - foot - SAFETY_M


def arc_extent(v: float, yaw_rate: float, seconds: float) -> tuple:
    """(x_lo, x_hi, y_lo, y_hi) [m]: the box around an arc from the origin heading +x at
    speed v [m/s] and yaw rate [rad/s] for ``seconds``."""
    s = np.linspace(0.0, seconds, 257)
    if abs(yaw_rate) < 1e-9:
        x, y = v * s, 0.0 * s
    else:
        rho = v / yaw_rate
        th = yaw_rate * s
        x, y = rho * np.sin(th), rho * (1.0 - np.cos(th))
    return float(x.min()), float(x.max()), float(y.min()), float(y.max())


def _fits(ext: tuple, a: float, b: float) -> bool:
    return ext[0] >= -a and ext[1] <= a and ext[2] >= -b and ext[3] <= b


def _longest_hold(v: float, yaw_rate: float, a: float, b: float, most: float = HOLD_S) -> float:
    """The longest hold <= ``most`` [s] whose arc fits |x| <= a, |y| <= b (0 if none does)."""
    if _fits(arc_extent(v, yaw_rate, most), a, b):
        return most
    lo, hi = 0.0, most
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _fits(arc_extent(v, yaw_rate, mid), a, b) else (lo, mid)
    return lo


def _pause(seconds: float = PAUSE_S) -> Part:
    return Part("pause", 0.0, 0.0, seconds, "pause")


def deceleration(vehicle: Vehicle, terrain: Terrain) -> float:
    """The rate [m/s^2] at which the drive brings the vehicle to rest on level ground: its
    reference rate, or what the current limit gives on both sides (eqs. 24, 25: 2 k I_max
    / r over the mass, rolling resistance helping), whichever is lower."""
    from dynamics.params import G
    drive = 2 * vehicle.torque_constant * vehicle.current_limit / (vehicle.wheel_radius * vehicle.mass)
    return max(min(vehicle.ref_accel if vehicle.ref_accel > 0 else math.inf, drive + G * terrain.mu_roll), 1e-3)


def _at_rest(part: Part, vehicle: Vehicle, decel: float) -> Part:
    """The pause after ``part``: PAUSE_S once the fastest wheel has come to rest (a pause
    shorter than the braking starts the next part moving, and the legs no longer retrace)."""
    fastest = max(abs(w) for w in part.wheels(vehicle)) * vehicle.wheel_radius
    return _pause(PAUSE_S + round(fastest / decel * RATE) / RATE)


def _ticks(seconds: float) -> float:
    """``seconds`` down to whole command periods (1 / RATE): a part then starts on a row of
    the commands file, and a log at any multiple of RATE holds its switch."""
    return max(1, math.floor(seconds * RATE + 1e-9)) / RATE


def _there_and_back(kind: str, v: float, omega: float, seconds: float, label: str, vehicle: Vehicle,
                    decel: float) -> list:
    """The command for ``seconds``, a pause, the reverse command back along the track, a pause."""
    seconds = _ticks(seconds)
    go, back = Part(kind, v, omega, seconds, label), Part(kind, -v, -omega, seconds, label + ", back")
    return [go, _at_rest(go, vehicle, decel), back, _at_rest(back, vehicle, decel)]


def _past_and_back(kind: str, v: float, omega: float, seconds: float, label: str, vehicle: Vehicle,
                   decel: float) -> list:
    """There and back, then the same starting the other way: four legs of ``seconds``,
    each from rest, so that what a leg falls short of by its ramps (a drive that cannot
    follow its reference rate) cancels."""
    seconds = _ticks(seconds)
    legs = [Part(kind, v, omega, seconds, label), Part(kind, -v, -omega, seconds, label + ", back"),
            Part(kind, -v, -omega, seconds, label + ", the other way"),
            Part(kind, v, omega, seconds, label + ", back")]
    return [p for leg in legs for p in (leg, _at_rest(leg, vehicle, decel))]


def design(vehicle: Vehicle, terrain: Terrain, area: tuple, seconds: float = 240.0, scale: float = 1.0) -> Protocol:
    """A protocol for ``vehicle`` on ``terrain`` in a free area (W, H) [m] lasting about
    ``seconds`` (the turns fill what the fixed parts leave; at least those are kept), its
    parts sized to ``scale`` times the reach (:func:`reach`).
    Raises :class:`ProtocolError` where the area holds no straight part of MIN_HOLD_S at
    the slowest speed."""
    from scipy.stats import qmc

    from dynamics.limits import holds_turn, top_speed
    W, H = (float(x) for x in area)
    if not (math.isfinite(W) and math.isfinite(H) and W > 0 and H > 0):
        raise ProtocolError(f"area: expected a width and height in metres, found {W:g} x {H:g}")
    if not (math.isfinite(seconds) and 0 < seconds <= MAX_S):
        raise ProtocolError(f"duration: expected seconds in (0, {MAX_S:g}], found {seconds:g}")
    a, b = (scale * x for x in reach(vehicle, (W, H)))
    r, S = vehicle.wheel_radius, vehicle.command_track
    v_top = top_speed(vehicle, terrain)
    decel = deceleration(vehicle, terrain)
    w_top = v_top / r
    yaw_of = lambda omega: omega * S / (terrain.alpha * vehicle.width)     # eq. 1 with the terrain's alpha
    need = SPEEDS[0] * v_top * MIN_HOLD_S
    if a < need or b < 0.0:
        foot = 2 * (0.5 * W - a)
        raise ProtocolError(f"area: expected at least {need + 0.5 * foot:.1f} m along the heading and "
                            f"{0.5 * foot:.1f} m across for the {vehicle.name} ({SPEEDS[0]:.0%} of its "
                            f"{v_top:.2f} m/s top speed for {MIN_HOLD_S:g} s each way from the centre, its "
                            f"footprint and {SAFETY_M} m to spare), found {W:g} x {H:g} m")
    notes = [] if scale == 1.0 else [f"parts sized to {scale:.0%} of the free area's reach: the simulated drive "
                                     "drifts further than their geometry"]
    straights, tops, pivots, turns = [], [], [], []
    # straight: forward to +d, back through the start to -d, forward to the start
    for share in SPEEDS:
        v = share * v_top
        t = min(HOLD_S, a / v)
        if t < MIN_HOLD_S:
            notes.append(f"straight at {v:.2f} m/s left out: {a:.1f} m from the start is {a / v:.1f} s at that "
                         f"speed (needs {MIN_HOLD_S:g} s)")
            continue
        straights.append(_past_and_back("straight", v, 0.0, t, f"straight {v:.2f} m/s", vehicle, decel))
    # the over-command keeps the wheels at the top speed while its reference ramps down
    t = (a - (TOP_OVER - 1.0) * v_top ** 2 / max(vehicle.ref_accel, 1e-6)) / v_top
    if t >= MIN_HOLD_S:
        v = TOP_OVER * v_top
        for sign in (1.0, -1.0):        # forward first, then reverse first
            tops.append(_past_and_back("top_speed", sign * v, 0.0, min(HOLD_S, t),
                                       f"top speed{'' if sign > 0 else ' in reverse'} (commanded {v:.2f}, "
                                       f"delivers {v_top:.2f} m/s)", vehicle, decel))
    else:
        notes.append(f"top-speed part left out: {a:.1f} m from the start is {t:.1f} s at {v_top:.2f} m/s "
                     f"(needs {MIN_HOLD_S:g} s); the torque constant then needs efforts or currents logged")
    for share in PIVOT:
        w = share * w_top
        while w > 0.1 * w_top and not holds_turn(vehicle, terrain, -w, w, HELD_MARGIN):
            w *= 0.8
        omega = 2 * w * r / S
        first = 1.0 if len(pivots) % 2 == 0 else -1.0      # left then right, then right then left
        pivots.append(_there_and_back("pivot", 0.0, first * omega, HOLD_S,
                                      f"pivot {'left' if first > 0 else 'right'} {math.degrees(omega):.0f} deg/s",
                                      vehicle, decel))
    fixed = sum(p.seconds for blk in straights + tops + pivots for p in blk) + PAUSE_S
    left = seconds - fixed
    for u, q in qmc.Halton(d=2, scramble=False).random(401)[1:]:     # (its first point is the origin)
        if left <= 0:
            break
        v = (TURN_V[0] + (TURN_V[1] - TURN_V[0]) * u) * v_top
        t = 0.0
        while v >= 0.1 * v_top:        # a turn too wide for the area is driven slower
            omega = (0.15 + 0.85 * q) * 2 * (TURN_WHEEL * v_top - v) / S
            t = _longest_hold(v, yaw_of(omega), a, b, TURN_HOLD_S)
            if t >= MIN_HOLD_S:
                break
            v *= 0.8
        if t < MIN_HOLD_S:
            continue
        # a turn the drive does not hold with the margin is made wider; where none is
        # held (a vehicle whose file turns only at the drive's limit), the first is kept
        held = False
        for k in range(7):
            wider = omega * 0.7 ** k
            if holds_turn(vehicle, terrain, *Part("turn", v, wider, t).wheels(vehicle), HELD_MARGIN):
                t_wider = _longest_hold(v, yaw_of(wider), a, b, TURN_HOLD_S)
                if t_wider >= MIN_HOLD_S:
                    omega, t, held = wider, t_wider, True
                break
        label = (f"{v:.2f} m/s, commanded radius {v / omega:.2f} m"
                 f"{'' if held else ' (beyond the drive as modelled: it saturates)'}")
        # left and right, each there and back, then the same starting in reverse: the
        # right turn mirrors the left's drift across the heading, the reverse start along
        # it (a drive's rate-limited ramps do not retrace an arc exactly)
        block = []
        for first in (1.0, -1.0):
            for sign, side in ((1.0, "left"), (-1.0, "right")):
                block += _there_and_back("turn", first * v, first * sign * omega, t,
                                         f"turn {side} {label}{'' if first > 0 else ', in reverse'}", vehicle,
                                         decel)
        turns.append(block)
        left -= sum(p.seconds for p in block)
    if not turns:
        notes.append("no turn fits the area or the duration: mu_sa and mu_op rest on the pivots alone")
    # each kind spread evenly over the drive, so that the training part (the first 70 %)
    # and the held-out part both have some of each
    kinds = {"straight": straights, "turn": turns, "pivot": pivots, "top_speed": tops}
    spread = sorted(((i + 0.5) / len(blocks), rank, i, blocks[i]) for rank, blocks in enumerate(kinds.values())
                    for i in range(len(blocks)))
    parts = [_pause()] + [p for *_, block in spread for p in block]
    return Protocol(vehicle, terrain, (W, H), tuple(parts), tuple(notes))


@dataclass(frozen=True)
class Check:
    """A protocol simulated with the closed-loop model: the run (dynamics.runs.Run), what
    calibrate's ``excitation`` finds in its training and held-out parts and which
    parameters it would fit (``chosen``), and the path's box [m] and end distance from the
    start against the reach (a, b)."""

    run: object
    training: dict
    heldout: dict
    chosen: dict
    box: tuple
    end_m: float
    reach: tuple

    @property
    def inside(self) -> bool:
        a, b = self.reach
        return _fits(self.box, a, b)


def simulated(protocol: Protocol, vehicle: Vehicle | None = None, terrain: Terrain | None = None,
              seed: int | None = None):
    """The run (dynamics.runs.Run) of the protocol's commands driven by ``vehicle`` on
    ``terrain`` (default the protocol's) with the closed-loop model, logged at 100 Hz,
    with sensor noise from ``seed`` (none when None)."""
    from dynamics.runs import Run
    from dynamics.simulate import Model
    from dynamics.synth import measured
    v, t = vehicle or protocol.vehicle, terrain or protocol.terrain
    model = Model(v, t)
    c = protocol.commands(model.step_s)
    cols = measured(model, c["wl_cmd"], c["wr_cmd"], seed)
    idx = np.minimum(np.searchsorted(c["t"], cols["t"] - 1e-9), len(c["t"]) - 1)
    cols["part"] = c["segment"][idx]
    meta = {"vehicle": v.name, "terrain": t.name, "slope_deg": "0",
            "note": f"sbmpc protocol simulated, area {protocol.area[0]:g} x {protocol.area[1]:g} m"}
    return Run(cols, meta, "protocol")


def check(protocol: Protocol) -> Check:
    """:func:`simulated` (noise-free) and measured as calibrate measures (module doc)."""
    from dynamics.discrepancy import TRAIN_FRACTION
    from sbmpc.calibration import chosen, excitation
    run = simulated(protocol)
    t = run.t
    cut = int(np.searchsorted(t, t[0] + TRAIN_FRACTION * (t[-1] - t[0])))
    train, held = run.slice(0, cut), run.slice(cut, len(t))
    x, y = run["x"], run["y"]
    box = (float(x.min()), float(x.max()), float(y.min()), float(y.max()))
    return Check(run, excitation([train]), excitation([held]), chosen(excitation([train])), box,
                 float(math.hypot(x[-1] - x[0], y[-1] - y[0])), reach(protocol.vehicle, protocol.area))


def sized(vehicle: Vehicle, terrain: Terrain, area: tuple, seconds: float = 240.0, rounds: int = 8) -> tuple:
    """(Protocol, Check): :func:`design`, shrunk by 15 % a round while the simulated path
    leaves the area (the rate-limited ramps and the turns' slip drift it from the
    geometry), at most ``rounds`` times; the last one's check says whether it fits."""
    scale = 1.0
    for _ in range(rounds):
        p = design(vehicle, terrain, area, seconds, scale)
        c = check(p)
        if c.inside:
            break
        scale *= 0.85
    return p, c


SCHEMA = "sbmpc.protocol/1"
COLUMNS = ("t", "wl_cmd", "wr_cmd", "v_cmd", "omega_cmd", "segment")


def write_csv(path, protocol: Protocol) -> None:
    """The commands CSV (docs/formats.md): ``# key: value`` lines (schema, vehicle,
    terrain, area, a line per part), then t [s], wl_cmd, wr_cmd [rad/s], v_cmd [m/s],
    omega_cmd [rad/s], segment (the part) every 1 / RATE s."""
    c = protocol.commands()
    with open(path, "w", newline="") as f:
        f.write(f"# schema: {SCHEMA}\n# vehicle: {protocol.vehicle.name}\n# terrain: {protocol.terrain.name}\n"
                f"# area_m: {protocol.area[0]:g} x {protocol.area[1]:g}\n# rate_hz: {RATE:g}\n")
        for i, p in enumerate(protocol.parts):
            if p.kind != "pause":
                f.write(f"# part {i}: {p.label}; {p.seconds:.2f} s; identifies {', '.join(p.identifies)}\n")
        f.write(",".join(COLUMNS) + "\n")
        for row in zip(*(c[k] for k in COLUMNS)):
            f.write(",".join(f"{int(x)}" if k == "segment" else f"{x:.6g}" for k, x in zip(COLUMNS, row)) + "\n")


def read_commands(path) -> tuple:
    """(t [s], wl_cmd, wr_cmd [rad/s], meta) from a commands CSV (a protocol's, or any CSV
    with t, wl_cmd and wr_cmd columns after optional ``#`` lines). A ProtocolError
    names the file and line of anything else."""
    from pathlib import Path
    path = Path(path)
    if not path.is_file():
        raise ProtocolError(f"{path}: expected a commands CSV file, found {'a folder' if path.is_dir() else 'no such file'}")
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"{path}: expected a commands CSV (text), found {type(exc).__name__}") from None
    meta, k = {}, 0
    while k < len(lines) and lines[k].startswith("#"):
        key, _, value = lines[k][1:].partition(":")
        meta[key.strip()] = value.strip()
        k += 1
    if k >= len(lines):
        raise ProtocolError(f"{path}: expected a header line with t, wl_cmd, wr_cmd, found none")
    header = [h.strip() for h in lines[k].split(",")]
    missing = [c for c in ("t", "wl_cmd", "wr_cmd") if c not in header]
    if missing:
        raise ProtocolError(f"{path} line {k + 1}: expected the columns t, wl_cmd, wr_cmd, found no {missing[0]!r}")
    cols = [header.index(c) for c in ("t", "wl_cmd", "wr_cmd")]
    rows = []
    for i in range(k + 1, len(lines)):
        if not lines[i].strip():
            continue
        cells = lines[i].split(",")
        try:
            row = [float(cells[j]) for j in cols]
        except (ValueError, IndexError):
            raise ProtocolError(f"{path} line {i + 1}: expected numbers in t, wl_cmd, wr_cmd, found "
                                f"{lines[i][:60]!r}") from None
        if not all(math.isfinite(x) for x in row) or (rows and row[0] <= rows[-1][0]):
            raise ProtocolError(f"{path} line {i + 1}: expected finite numbers and t increasing, found "
                                f"{lines[i][:60]!r}")
        if abs(row[1]) > 1e3 or abs(row[2]) > 1e3:
            raise ProtocolError(f"{path} line {i + 1}: expected wheel speeds of at most 1000 rad/s, found "
                                f"{lines[i][:60]!r}")
        rows.append(row)
    if len(rows) < 2:
        raise ProtocolError(f"{path}: expected at least two rows of commands, found {len(rows)}")
    a = np.asarray(rows)
    if a[-1, 0] - a[0, 0] > MAX_S:
        raise ProtocolError(f"{path}: expected at most {MAX_S:g} s of commands, found {a[-1, 0] - a[0, 0]:.0f} s")
    return a[:, 0] - a[0, 0], a[:, 1], a[:, 2], meta


def held(t: np.ndarray, cmd: np.ndarray, dt: float, end: float | None = None) -> np.ndarray:
    """Commands sampled at ``t`` held every model step ``dt`` until ``end`` [s] (default:
    one sample spacing after the last): what a driver does between messages."""
    end = t[-1] + float(np.median(np.diff(t))) if end is None else end
    steps = np.arange(int(round(end / dt))) * dt
    return cmd[np.clip(np.searchsorted(t, steps + 1e-9, side="right") - 1, 0, len(t) - 1)]


def write_bag(out, protocol: Protocol, topic: str = "/cmd_vel") -> dict:
    """The protocol as a ROS 2 bag folder (MCAP) for ``ros2 bag play``: ``topic``
    geometry_msgs/Twist every 1 / RATE s, and each part's label on /sbmpc/protocol
    (std_msgs/String) when it starts. Returns {topic: messages}."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    c = protocol.commands()
    V3 = T["geometry_msgs/msg/Vector3"]
    counts = {}
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection(topic, "geometry_msgs/msg/Twist", typestore=ts)
        for t, v, om in zip(c["t"], c["v_cmd"], c["omega_cmd"]):
            msg = T["geometry_msgs/msg/Twist"](linear=V3(x=float(v), y=0.0, z=0.0),
                                               angular=V3(x=0.0, y=0.0, z=float(om)))
            w.write(conn, int(round(t * 1e9)), ts.serialize_cdr(msg, "geometry_msgs/msg/Twist"))
        counts[topic] = len(c["t"])
        conn = w.add_connection("/sbmpc/protocol", "std_msgs/msg/String", typestore=ts)
        start = 0.0
        for i, p in enumerate(protocol.parts):
            text = f"part {i}: {p.label}; {p.seconds:.2f} s; identifies {', '.join(p.identifies) or 'nothing'}"
            w.write(conn, int(round(start * 1e9)), ts.serialize_cdr(T["std_msgs/msg/String"](data=text),
                                                                      "std_msgs/msg/String"))
            start += round(p.seconds * RATE) / RATE
        counts["/sbmpc/protocol"] = len(protocol.parts)
    return counts
