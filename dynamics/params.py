"""Vehicle and terrain parameters: validated, immutable values loaded from YAML.

A parameter file maps names to numbers, each either plain (``mass: 31.0``) or with its
source note (``mass: {value: 31.0, unit: kg, source: "..."}``). Units are SI. The package
ships the Pioneer 3-AT of the paper as ``p3at`` and the terrains of
``PARAMETERS.md``; :func:`load_vehicle` and :func:`load_terrain` take either a shipped
name or a path to a user's file. Every problem is reported as a :class:`ParameterError`
naming the file, the key, what was expected and what was found.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml

G = 9.81  # m/s^2, gravitational acceleration


class ParameterError(ValueError):
    """A parameter file or value is wrong; the message names file, key, expected, found."""


@dataclass(frozen=True)
class Vehicle:
    """A skid-steered vehicle with one lumped drive per side, expressed at the wheel.

    Geometry follows the paper's Fig. 1: ``width`` is B, the contact patches of a side span
    y in [-L/2, -C/2] and [C/2, L/2] with ``patch_outer`` = L and ``patch_inner`` = C, and
    are ``patch_width`` = b wide. The drive is a current-controlled DC motor per side
    (eqs. 26, 27) under a modified PID (Fig. 4).

    The ``*_scale``, ``viscous``, ``no_load_current``, ``delay``, ``lag`` and ``sag`` fields
    are model extensions found by ``sbmpc diagnose``; their defaults leave the paper's
    model unchanged.
    """

    name: str = "p3at"
    mass: float = 31.0                 # kg
    inertia: float = 0.67              # kg m^2, yaw
    wheel_radius: float = 0.11         # m
    width: float = 0.40                # m, B
    patch_outer: float = 0.31          # m, L
    patch_inner: float = 0.24          # m, C
    patch_width: float = 0.05          # m, b
    v_max: float = 12.0                # V, largest motor voltage (eq. 27)
    torque_constant: float = 1.3825    # N m/A = V s/rad, at the wheel
    armature_resistance: float = 0.706  # ohm
    current_limit: float = 3.62        # A, continuous
    controller_rate: float = 1000.0    # Hz
    kp: float = 2.0                    # A s/rad
    ki: float = 20.0                   # A/rad
    kd: float = 0.09                   # A s^2/rad, on the reference
    ref_accel: float = 1.0             # m/s^2, rate limit of the wheel-speed reference (0: none)
    regen: bool = False                # allow negative battery power
    # --- model extensions (defaults: the paper's model) ---
    radius_scale_left: float = 1.0     # effective / nominal rolling radius, left side
    radius_scale_right: float = 1.0    # effective / nominal rolling radius, right side
    viscous: float = 0.0               # N m s/rad, extra resistance torque per wheel speed
    no_load_current: float = 0.0       # A, what each side's motors draw turning freely (their own friction)
    delay: float = 0.0                 # s, commands reach the drive late
    lag: float = 0.0                   # s, first-order lag of delivered current
    sag: float = 0.0                   # V/J, fall of available voltage per energy drawn
    shear_lag: float = 0.0             # s, lag with which turning friction builds up
    torque_scale_left: float = 1.0     # the left motors' constant / torque_constant (a weak motor: < 1)
    torque_scale_right: float = 1.0    # the right motors' constant / torque_constant
    # --- the robot's driver (not the model) ---
    command_separation: float = 0.0    # m: the track its driver turns cmd_vel into wheel speeds with (0: width)
    description: str = ""
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, hash=False)

    # Derived quantities -------------------------------------------------------------
    @property
    def command_track(self) -> float:
        """The track [m] with which the robot's driver turns a ``cmd_vel`` twist into wheel
        speeds and back (w = (v -+ omega B / 2) / r): ``command_separation`` where set (a
        ROS diff_drive_controller's ``wheel_separation`` times its
        ``wheel_separation_multiplier``: 0.555 m x 1.875 on a Husky), else ``width``."""
        return self.command_separation if self.command_separation > 0.0 else self.width

    @property
    def ref_wheel_accel(self) -> float:
        """Rate limit of the wheel-speed reference in rad/s^2 (0 = none)."""
        return self.ref_accel / self.wheel_radius

    @property
    def no_load_speed(self) -> float:
        """Wheel speed at zero torque and full voltage, rad/s (eq. 26: V_max / k)."""
        return self.v_max / self.torque_constant

    @property
    def stall_torque(self) -> float:
        """Torque at zero speed and full voltage, N m (eq. 26: k V_max / R_a)."""
        return self.torque_constant * self.v_max / self.armature_resistance

    @property
    def continuous_torque(self) -> float:
        """Torque at the continuous current limit, N m (k I_max)."""
        return self.torque_constant * self.current_limit

    @property
    def max_power(self) -> float:
        """Largest mechanical power of one side, W (V_max^2 / (4 R_a))."""
        return self.v_max ** 2 / (4.0 * self.armature_resistance)

    def replace(self, **changes: Any) -> "Vehicle":
        """A copy with some fields changed, validated."""
        return _replaced(self, changes)


def _replaced(obj, changes: dict):
    """``dataclasses.replace`` of a Vehicle or Terrain, validated; an unknown field is a
    ParameterError naming it (was a bare TypeError)."""
    names = [f.name for f in dataclasses.fields(obj)]
    for key in changes:
        if key not in names:
            raise ParameterError(f"<replace>: unknown {type(obj).__name__.lower()} parameter '{key}'"
                                 f"{did_you_mean(key, names)}: expected one of {', '.join(names)}")
    return _validated(dataclasses.replace(obj, **changes), "<replace>")


@dataclass(frozen=True)
class Terrain:
    """Terrain parameters of the model: alpha (eq. 1), mu_roll, mu_sa, mu_op, K (eq. 7)."""

    name: str = "vinyl"
    alpha: float = 1.5            # kinematic ICR factor, >= 1
    mu_roll: float = 0.0371       # rolling resistance coefficient
    mu_sa: float = 0.4437         # friction when the side's motor drives
    mu_op: float = 0.3093         # friction when the side's motor brakes
    shear_modulus: float = 0.00054  # m, K
    sources: Mapping[str, str] = field(default_factory=dict, compare=False, hash=False)

    def replace(self, **changes: Any) -> "Terrain":
        """A copy with some fields changed, validated."""
        return _replaced(self, changes)


# Bounds: (low, high, low inclusive). Values outside are rejected with a clear message.
_BOUNDS: dict[str, tuple[float, float, bool]] = {
    "mass": (0.0, 1e5, False), "inertia": (0.0, 1e6, False), "wheel_radius": (0.0, 5.0, False),
    "width": (0.0, 10.0, False), "patch_outer": (0.0, 10.0, False),
    "patch_inner": (0.0, 10.0, True), "patch_width": (0.0, 2.0, False),
    "v_max": (0.0, 1e4, False), "torque_constant": (0.0, 1e4, False),
    "armature_resistance": (0.0, 1e4, False), "current_limit": (0.0, 1e5, False),
    "controller_rate": (1.0, 1e6, True), "kp": (0.0, 1e6, True), "ki": (0.0, 1e6, True),
    "kd": (0.0, 1e6, True), "ref_accel": (0.0, 1e3, True),
    "radius_scale_left": (0.0, 2.0, False), "radius_scale_right": (0.0, 2.0, False),
    "torque_scale_left": (0.0, 2.0, False), "torque_scale_right": (0.0, 2.0, False),
    "viscous": (-1e3, 1e3, True), "no_load_current": (0.0, 1e3, True), "delay": (0.0, 10.0, True), "lag": (0.0, 10.0, True),
    "sag": (0.0, 1e3, True), "shear_lag": (0.0, 10.0, True),
    "command_separation": (0.0, 100.0, True),
    "alpha": (1.0, 20.0, True), "mu_roll": (0.0, 2.0, True), "mu_sa": (0.0, 5.0, True),
    "mu_op": (0.0, 5.0, True), "shear_modulus": (0.0, 1.0, False),
}


def checked_number(name: str, value: Any, want: str, lo: float = -math.inf, hi: float = math.inf,
                   lo_open: bool = False) -> float:
    """``value`` as a float when it is a finite number (not a bool) in [lo, hi] ((lo, hi]
    with ``lo_open``); else a ParameterError '``name``: expected ``want``, found ...'. The
    one check of the numeric arguments of the model's functions."""
    import numpy as np
    ok = (not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
          and math.isfinite(value) and (lo < value if lo_open else lo <= value) and value <= hi)
    if not ok:
        raise ParameterError(f"{name}: expected {want}, found {value!r:.40}")
    return float(value)


def _check_number(src: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not -1e300 < value < 1e300:
        raise ParameterError(f"{src}: key '{key}': expected a number, found {value!r:.60}")
    value = float(value)
    lo, hi, lo_incl = _BOUNDS[key]
    ok = (value >= lo if lo_incl else value > lo) and value <= hi and math.isfinite(value)
    if not ok:
        lo_txt = f">= {lo:g}" if lo_incl else f"> {lo:g}"
        raise ParameterError(f"{src}: key '{key}': expected a number {lo_txt} and <= {hi:g}, found {value!r}")
    return value


def _validated(obj, src: str):
    for f in dataclasses.fields(obj):
        if f.name in _BOUNDS:
            _check_number(src, f.name, getattr(obj, f.name))
    if isinstance(obj, Vehicle) and not obj.patch_inner < obj.patch_outer:
        raise ParameterError(
            f"{src}: key 'patch_inner': expected C < L = {obj.patch_outer:g}, found {obj.patch_inner:g}")
    return obj


# keys a parameter file may leave out without naming a ``base``: what the paper's model
# does without them (no extension, no regeneration, equal wheels) or only labels
OPTIONAL = {"name", "description", "sources", "regen", "radius_scale_left", "radius_scale_right", "viscous",
            "no_load_current",
            "delay", "lag", "sag", "shear_lag", "command_separation", "torque_scale_left", "torque_scale_right"}


def _from_mapping(cls, data: Any, src: str, complete: bool = False, kind: str = "", base_dir: Path | None = None,
                  depth: int = 0):
    """A Vehicle or Terrain from a mapping. ``base: NAME_OR_PATH`` takes every value not
    given from that vehicle or terrain; without it, a file (``complete``) must give every
    parameter but the OPTIONAL ones: a partial file silently taking the rest from the
    P3-AT was a trap."""
    if not isinstance(data, dict):
        raise ParameterError(f"{src}: expected a mapping of parameter names to values, found {yaml_kind(data)}")
    data = dict(data)
    parent = None
    if "base" in data:
        b = data.pop("base")
        if not isinstance(b, str) or not b:
            raise ParameterError(f"{src}: key 'base': expected a shipped name or a path to a YAML file, found {b!r:.60}")
        if depth > 8:
            raise ParameterError(f"{src}: key 'base': expected a chain of at most 8 bases, found more (a loop?)")
        try:
            parent = _load(cls, kind or ("vehicles" if cls is Vehicle else "terrains"), b,
                           base_dir if base_dir is not None else Path(src).parent, depth + 1)
        except ParameterError as exc:
            if depth > 0:
                raise
            raise ParameterError(f"{src}: key 'base': {exc}") from None
    known = {f.name: f for f in dataclasses.fields(cls)}
    values: dict[str, Any] = {}
    sources: dict[str, str] = {}
    for key, raw in data.items():
        if key not in known or key == "sources":
            allowed = [k for k in known if k != "sources"]
            raise ParameterError(f"{src}: unknown key '{key}'{did_you_mean(key, allowed)}: expected one of base, "
                                 f"{', '.join(allowed)}")
        if isinstance(raw, dict):
            if "value" not in raw:
                raise ParameterError(f"{src}: key '{key}': expected a number or a mapping with 'value', found {raw!r}")
            if "source" in raw:
                sources[key] = str(raw["source"])
            raw = raw["value"]
        if key in ("name", "description"):
            values[key] = str(raw)
        elif key == "regen":
            if not isinstance(raw, bool):
                raise ParameterError(f"{src}: key 'regen': expected true or false, found {raw!r}")
            values[key] = raw
        else:
            values[key] = _check_number(src, key, raw)
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in OPTIONAL and f.name not in data]
    if parent is None and complete and missing:
        raise ParameterError(f"{src}: expected every parameter or a 'base' (e.g. 'base: "
                             f"{'p3at' if cls is Vehicle else 'vinyl'}') to take the others from, found no "
                             f"{', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''}")
    if parent is not None:
        merged = {f.name: getattr(parent, f.name) for f in dataclasses.fields(cls) if f.name != "sources"}
        merged.update(values)
        inherited = {k: f"{v} (from base {parent.name})" for k, v in parent.sources.items() if k not in values}
        own = {k: sources.get(k, f"set in {src}") for k in values if k not in ("name", "description")}
        return _validated(cls(**merged, sources={**inherited, **own}), src)
    return _validated(cls(**values, sources=sources), src)


def did_you_mean(word, choices) -> str:
    """' (did you mean X?)' for the closest of ``choices`` to ``word``, or ''."""
    import difflib
    close = difflib.get_close_matches(str(word), sorted(str(c) for c in choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


MAX_YAML_BYTES = 4_000_000   # parameter and scenario files larger than this are refused


class NoAliasLoader(yaml.SafeLoader):
    """PyYAML's safe loader without aliases (``*name``): a few lines of nested aliases
    expand to gigabytes ("billion laughs"); no parameter or scenario file needs them."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            raise yaml.composer.ComposerError(None, None, "an alias (*name): aliases are not accepted",
                                              self.peek_event().start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        """A mapping whose keys are all different: YAML forbids a repeated key, and
        PyYAML would keep the last one silently (a second ``planner:`` section dropping
        the first)."""
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                    continue                   # (merged keys may be overridden; others: the constructor judges)
                # a plain '=' is YAML 1.1's value key, a string once the mapping is built
                key = "=" if key_node.tag == "tag:yaml.org,2002:value" else self.construct_object(key_node)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:              # an unhashable key: the constructor says so
                    continue
                if first is not key_node:
                    also = f"as {first.value!r} " if first.value != key_node.value else ""
                    raise yaml.constructor.ConstructorError(
                        None, None, f"the key {key_node.value!r} appears twice in one mapping (first {also}on line "
                        f"{first.start_mark.line + 1}); a YAML key may appear once", key_node.start_mark)
        return super().construct_mapping(node, deep)


def yaml_kind(data) -> str:
    """What a YAML document holds, in words, for a message that expected a mapping: 'an
    empty file', 'a list', 'a single string' (else the Python type's name)."""
    if data is None:
        return "an empty file"
    kinds = {list: "a list", str: "a single string", bool: "a single true/false", int: "a single number",
             float: "a single number"}
    return kinds.get(type(data), type(data).__name__)


def read_yaml_text(path: Path) -> Any:
    """Parse a YAML file with :class:`NoAliasLoader`. Raises ValueError with the reason
    (too large, not UTF-8 text, malformed YAML with its line) and OSError."""
    size = path.stat().st_size
    if size > MAX_YAML_BYTES:
        raise ValueError(f"expected a YAML file of at most {MAX_YAML_BYTES // 1_000_000} MB, found {size / 1e6:.1f} MB")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError("expected a UTF-8 text (YAML) file, found binary data") from None
    try:
        data = yaml.load(text, Loader=NoAliasLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}: " if mark is not None else ""
        raise ValueError(f"{where}malformed YAML: {getattr(exc, 'problem', exc)}") from None
    except RecursionError:
        raise ValueError(f"expected YAML nested at most {MAX_YAML_DEPTH} levels deep, found nesting too deep to "
                         "parse") from None
    depth = yaml_depth(data)
    if depth > MAX_YAML_DEPTH:
        raise ValueError(f"expected YAML nested at most {MAX_YAML_DEPTH} levels deep, found more")
    return data


MAX_YAML_DEPTH = 64     # levels of nested lists and mappings a parameter, scenario or sweep file may hold


def yaml_depth(data) -> int:
    """How deeply lists and mappings nest in parsed YAML (a scalar: 0), without recursion;
    counted up to MAX_YAML_DEPTH + 1."""
    best = 0
    stack = [(data, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, dict):
            kids = list(node.values())
        elif isinstance(node, list):
            kids = node
        else:
            continue
        best = max(best, d)
        if d <= MAX_YAML_DEPTH:
            stack.extend((k, d + 1) for k in kids)
    return best


def _read_yaml(path: Path) -> Any:
    if path.is_dir():
        raise ParameterError(f"{path}: expected a YAML file, found a folder")
    try:
        return read_yaml_text(path)
    except FileNotFoundError:
        raise ParameterError(f"{path}: file not found") from None
    except OSError as exc:
        raise ParameterError(f"{path}: cannot read: {exc.strerror}") from None
    except ValueError as exc:
        raise ParameterError(f"{path}: {exc}") from None


def _shipped(kind: str) -> dict[str, Path]:
    folder = resources.files("dynamics") / "data" / kind
    return {Path(p.name).stem: Path(str(p)) for p in folder.iterdir() if p.name.endswith(".yaml")}


def shipped_vehicles() -> list[str]:
    """Names of the vehicles shipped with the package."""
    return sorted(_shipped("vehicles"))


def shipped_terrains() -> list[str]:
    """Names of the terrains shipped with the package."""
    return sorted(_shipped("terrains"))


def _load(cls, kind: str, spec: "str | Path | dict | Vehicle | Terrain", base: Path | None, depth: int = 0):
    if isinstance(spec, cls):
        return spec
    if isinstance(spec, dict):
        # as a file: every parameter or a 'base' (a partial mapping took the rest from the P3-AT or vinyl)
        return _from_mapping(cls, spec, f"<{kind[:-1]} mapping>", True, kind, base, depth)
    spec_s = str(spec)
    shipped = _shipped(kind)
    if not spec_s:
        raise ParameterError(f"expected a shipped {kind[:-1]} name ({', '.join(sorted(shipped))}) or a path to a "
                             "YAML file, found an empty string")
    if spec_s in shipped:
        return _from_mapping(cls, _read_yaml(shipped[spec_s]), str(shipped[spec_s]), True, kind, depth=depth)
    path = Path(spec_s)
    if base is not None and not path.is_absolute():
        path = base / path
    try:
        is_file = path.suffix in (".yaml", ".yml") or path.exists()
    except OSError:                # a name too long for a path
        is_file = False
    if is_file:
        return _from_mapping(cls, _read_yaml(path), str(path), True, kind, path.parent, depth)
    raise ParameterError(
        f"{kind[:-1]} '{spec_s:.60}': expected a shipped name ({', '.join(sorted(shipped))}) or a path to a YAML file, "
        f"found neither{did_you_mean(spec_s, shipped)}")


def load_vehicle(spec: "str | Path | dict | Vehicle" = "p3at", base: Path | None = None) -> Vehicle:
    """A vehicle by shipped name (``p3at``), path to a YAML file, or mapping (as a file:
    every parameter, or ``base`` and the ones that differ)."""
    return _load(Vehicle, "vehicles", spec, base)


def load_terrain(spec: "str | Path | dict | Terrain" = "vinyl", base: Path | None = None) -> Terrain:
    """A terrain by shipped name (``vinyl``, ``asphalt``, ...), path to a YAML file, or mapping
    (as a file: every parameter, or ``base`` and the ones that differ)."""
    return _load(Terrain, "terrains", spec, base)


def vehicle_to_yaml(vehicle: Vehicle, note: str = "") -> str:
    """YAML text of a vehicle that :func:`load_vehicle` reads back to an equal value."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(vehicle):
        if f.name == "sources":
            continue
        value = getattr(vehicle, f.name)
        src = vehicle.sources.get(f.name)
        out[f.name] = {"value": value, "source": src} if src else value
    head = f"# {note}\n" if note else ""
    return head + yaml.safe_dump(out, sort_keys=False)
