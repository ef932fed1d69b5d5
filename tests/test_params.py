import re

import pytest

from dynamics.params import (ParameterError, load_terrain, load_vehicle, shipped_terrains,
                             vehicle_to_yaml)


def test_shipped_p3at_values_and_sources():
    v = load_vehicle("p3at")
    assert (v.mass, v.wheel_radius, v.width, v.patch_outer, v.patch_inner, v.patch_width) == (31.0, 0.11, 0.40, 0.31, 0.24, 0.05)
    assert "2nd-hand" in v.sources["mass"] and "calibrated" in v.sources["inertia"]
    # PARAMETERS.md consequences of the drive constants
    assert v.no_load_speed == pytest.approx(8.68, abs=0.01)
    assert v.stall_torque == pytest.approx(23.5, abs=0.05)
    assert v.max_power == pytest.approx(51.0, abs=0.1)
    assert v.continuous_torque == pytest.approx(5.0, abs=0.01)


def test_shipped_terrains_table():
    assert set(shipped_terrains()) >= {"vinyl", "vinyl_lemniscate", "concrete", "asphalt", "packed_dirt", "grass"}
    t = load_terrain("vinyl_lemniscate")
    assert (t.alpha, t.mu_sa, t.mu_op, t.shear_modulus) == (1.5, 0.6488, 0.4601, 0.0009)
    assert "Section V-C" in t.sources["mu_sa"]


def test_values_are_immutable(p3at):
    with pytest.raises(AttributeError):    # a frozen dataclass
        p3at.mass = 3.0


def test_user_file_and_roundtrip(tmp_path, p3at):
    path = tmp_path / "heavy.yaml"
    path.write_text(vehicle_to_yaml(p3at.replace(mass=40.0, name="heavy")))
    v = load_vehicle(str(path))
    assert v == p3at.replace(mass=40.0, name="heavy")
    assert v.sources["mass"] == p3at.sources["mass"]


@pytest.mark.parametrize("text, words", [
    ("mass: -3\n", ["key 'mass'", "> 0", "-3"]),
    ("mass: heavy\n", ["key 'mass'", "expected a number", "'heavy'"]),
    ("masss: 3\n", ["unknown key 'masss'", "expected one of"]),
    ("mass: [1, 2\n", ["malformed YAML", "line"]),
    ("base: p3at\npatch_inner: 0.5\n", ["patch_inner", "C < L"]),
    ("mass: 40\n", ["expected every parameter or a 'base'", "found no inertia"]),
    ("base: nosuchbot\nmass: 40\n", ["nosuchbot", "expected a shipped name"]),
    ("- 1\n", ["expected a mapping"]),
    # under 1 Hz the replay step is over 1 s: simulate ended in exit 3, run drove 2 s steps
    ("base: p3at\ncontroller_rate: 0.5\n", ["key 'controller_rate'", ">= 1", "0.5"]),
])
def test_bad_files_name_file_key_expected_found(tmp_path, text, words):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ParameterError) as err:
        load_vehicle(str(path))
    msg = str(err.value)
    assert str(path) in msg
    for w in words:
        assert w in msg
    assert path.read_text() == text  # never modified


def test_missing_file_and_unknown_name(tmp_path):
    with pytest.raises(ParameterError, match="file not found"):
        load_terrain(str(tmp_path / "nope.yaml"))
    with pytest.raises(ParameterError, match="shipped name"):
        load_terrain("lava")
    with pytest.raises(ParameterError, match="alpha"):
        load_terrain({"base": "vinyl", "alpha": 0.5})
    assert load_terrain({"base": "grass", "alpha": 1.0}).mu_roll == load_terrain("grass").mu_roll
    # a mapping is read as a file is: a partial one without 'base' is refused (it took the rest from vinyl)
    with pytest.raises(ParameterError, match=r"<terrain mapping>: expected every parameter or a 'base'"):
        load_terrain({"alpha": 1.0})
    with pytest.raises(ParameterError, match=r"<vehicle mapping>: expected every parameter or a 'base'"):
        load_vehicle({"mass": 3.0})
    full = {f: getattr(load_vehicle("p3at"), f) for f in ("name", "mass")}
    assert load_vehicle({"base": "p3at", **full, "mass": 40.0}).mass == 40.0


def test_yaml_keys_appear_once_but_merge_and_value_keys_still_load():
    """A repeated key is refused (PyYAML kept the last silently); a merged key may be
    overridden, and YAML 1.1's plain '=' key is a string as before."""
    import yaml
    from dynamics.params import NoAliasLoader
    assert yaml.load("=: 1\nb: {=: 2}\n", Loader=NoAliasLoader) == {"=": 1, "b": {"=": 2}}
    assert yaml.load("<<: {a: 1, c: 3}\na: 2\n", Loader=NoAliasLoader) == {"a": 2, "c": 3}
    for text, says in [("a: 1\nb: 2\na: 3\n", "the key 'a' appears twice in one mapping (first on line 1)"),
                       ("m: {k: 1, k: 2}\n", "the key 'k' appears twice"),
                       ("1: x\n1.0: y\n", "first as '1' on line 1")]:
        with pytest.raises(yaml.YAMLError, match=re.escape(says)):
            yaml.load(text, Loader=NoAliasLoader)


def test_models_manoeuvres_and_replace_name_what_is_wrong():
    """Wrong arguments in Python are one ParameterError naming the argument (were deep
    TypeErrors or a ZeroDivisionError): a Model of something other than a Vehicle and a
    Terrain or with a step outside (0, 1] s, a circle of radius 0, a negative duration,
    a replaced field that does not exist (with the likely one)."""
    import numpy as np
    from dynamics import Model
    from dynamics.manoeuvres import circle, straight
    p3at, vinyl = load_vehicle("p3at"), load_terrain("vinyl")
    for kw, says in [(dict(vehicle="p3at"), "Model.vehicle: expected a Vehicle"),
                     (dict(terrain={"alpha": 1.0}), "Model.terrain: expected a Terrain"),
                     (dict(dt=0.0), r"Model.dt: expected an integration step in \(0, 1\] s, found 0.0"),
                     (dict(dt=float("nan")), "Model.dt"), (dict(dt="1ms"), "Model.dt")]:
        with pytest.raises(ParameterError, match=says):
            Model(**{"vehicle": p3at, "terrain": vinyl, **kw})
    m = Model(p3at, vinyl, np.float64(0.002))
    assert m.step_s == 0.002
    with pytest.raises(ParameterError, match="radius: expected a non-zero radius"):
        circle(m, 0.5, 0.0, 1.0)
    with pytest.raises(ParameterError, match=r"duration: expected a number of seconds in \[0, 1e6\], found -1"):
        straight(m, 0.5, -1.0)
    cl, cr = circle(m, 0.5, float("inf"), 1.0)
    assert len(cl) == 500 and np.allclose(cl, cr)                     # an infinite radius drives straight
    with pytest.raises(ParameterError, match=r"unknown vehicle parameter 'mas' \(did you mean 'mass'\?\)"):
        p3at.replace(mas=30.0)
    with pytest.raises(ParameterError, match="unknown terrain parameter 'foo'"):
        vinyl.replace(foo=1)


@pytest.mark.parametrize("text, found", [("", "found an empty file"), ("- 1\n", "found a list")])
def test_a_vehicle_file_that_is_not_a_mapping_says_what_it_holds(tmp_path, text, found):
    f = tmp_path / "v.yaml"
    f.write_text(text)
    with pytest.raises(ParameterError, match=f"expected a mapping of parameter names to values, {found}$"):
        load_vehicle(f)
