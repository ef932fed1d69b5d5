"""Scenario files: validation with every problem at once, key paths, exit code 2."""
from pathlib import Path

import pytest
import yaml

from sbmpc import scenario as SC
from sbmpc.commands.cli import main
from sbmpc.errors import InputError

SCEN_DIR = Path(__file__).resolve().parents[1] / "scenarios"
SHIPPED = sorted(SCEN_DIR.glob("*.yaml"))

GOOD = {
    "name": "t", "map": {"generate": {"size": [10, 10], "resolution": 0.25, "features": []}},
    "terrain": "vinyl", "vehicle": "p3at", "start": {"x": 2, "y": 2, "yaw_deg": 0, "v": 0},
    "goal": {"x": 8, "y": 8, "radius": 0.5}, "cost": "time",
}


def write(tmp_path, data, name="s.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return p


def test_shipped_scenarios_are_valid_and_say_what_they_show():
    assert len(SHIPPED) >= 7
    for path in SHIPPED:
        scn = SC.load(path)
        first = path.read_text().splitlines()[0]
        assert first.startswith("#"), f"{path.name} starts with a comment saying what it shows"
        assert scn.description


def test_defaults_fill_the_planner_settings(tmp_path):
    scn = SC.load(write(tmp_path, GOOD))
    assert scn.planner == SC.PlannerSettings()
    assert scn.goal["radius"] == 0.5 and scn.start["v"] == 0.0


def test_every_problem_is_reported_at_once_with_its_key_path(tmp_path):
    bad = dict(GOOD, start={"x": "east", "y": 2, "speed": 1}, goal={"x": 8, "y": 8, "radius": -1},
               cost="fast", planner={"branching": 0, "period_s": 1.0, "dt": 2.0, "colour": "red"}, extra=1)
    with pytest.raises(InputError) as e:
        SC.load(write(tmp_path, bad))
    msg = str(e.value)
    for key in ("start.x", "start.speed", "goal.radius", "cost", "planner.branching", "planner.dt",
                "planner.colour", "extra"):
        assert key in msg, key
    assert "problems" in msg and "s.yaml" in msg
    assert "'fast'" in msg          # what was found


def test_terrain_regions_validate_their_shapes(tmp_path):
    bad = dict(GOOD, terrain={"default": "vinyl", "regions": [{"terrain": "grass", "rect": [5, 5, 1, 1]},
                                                              {"terrain": "grass", "circle": [1, 1, 1], "rect": [0, 0, 1, 1]}]})
    with pytest.raises(InputError) as e:
        SC.load(write(tmp_path, bad))
    assert "terrain.regions[0].rect" in str(e.value) and "terrain.regions[1]" in str(e.value)


def test_yaml_syntax_error_names_the_line(tmp_path):
    p = write(tmp_path, "name: t\nmap: {generate: [\nstart: 1\n")
    with pytest.raises(InputError) as e:
        SC.load(p)
    assert "line" in str(e.value)


@pytest.mark.parametrize("change, words", [
    ({"terrain": "lava"}, "terrain"),
    ({"vehicle": "tank"}, "vehicle"),
    ({"start": {"x": 50, "y": 2}}, "start: expected (x, y)"),
    ({"start": {"x": 7.8, "y": 8.3}}, "start: expected a start outside the goal disc (centre (8, 8), radius 0.5 m), "
                                      "found (7.8, 8.3) inside it: nothing to plan"),
    ({"goal": {"x": 8, "y": 8, "radius": 20000}}, "goal.radius: expected a radius in [0.01, 10000] m, found 20000"),
    ({"map": {"file": "nothing.npy", "resolution": 0.2}}, "map.file"),
])
def test_cli_bad_scenarios_exit_2_with_one_message(tmp_path, capsys, change, words):
    p = write(tmp_path, dict(GOOD, **change))
    before = p.read_bytes()
    assert main(["plan", str(p)]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and str(p) in err
    assert p.read_bytes() == before           # input files are never modified


def test_a_missing_key_is_said_to_be_missing(tmp_path):
    """Not "found null": the file lacks the key (a key written with no value is null)."""
    doc = {k: v for k, v in GOOD.items() if k != "goal"}
    with pytest.raises(InputError) as e:
        SC.load(write(tmp_path, dict(doc, start={"y": 2.0})))
    assert "goal: expected a mapping {x:, y:, radius:}, found nothing (the key is missing)" in str(e.value)
    assert "start.x: expected a number, found nothing (the key is missing)" in str(e.value)
    with pytest.raises(InputError) as e:
        SC.load(write(tmp_path, dict(GOOD, goal=None)))
    assert "goal: expected a mapping {x:, y:, radius:}, found null" in str(e.value)
    with pytest.raises(InputError) as e:
        SC.load(write(tmp_path, {k: v for k, v in GOOD.items() if k != "map"}))
    assert "map: expected a mapping with 'file' or 'generate', found nothing (the key is missing)" in str(e.value)


def test_cli_missing_scenario_exits_2(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "none.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_terrain_layer_rasterises_regions():
    import numpy as np
    regions = [SC.Region("b", "rect", (0, 0, 1, 1)), SC.Region("c", "circle", (3, 3, 1)),
               SC.Region("b", "polygon", ((2, 0), (4, 0), (4, 1)))]
    x = y = np.arange(0, 5, 0.5)
    L = SC.terrain_layer(regions, 0, ["a", "b", "c"], x, y)
    assert L[0, 0] == 1 and L[6, 6] == 2 and L[9, 0] == 0
    assert L[1, 7] == 1         # (3.5, 0.5) is inside the triangle


def test_every_problem_of_a_scenario_at_once_with_did_you_mean(tmp_path, capsys):
    """Unknown keys, a missing map file, a misspelt vehicle and terrain: one run lists
    all four, each misspelling with the name it probably meant."""
    s = tmp_path / "multi.yaml"
    s.write_text("name: multi\nmap: {file: nosuch.png, resolution: 0.25}\nterrain: grasss\nvehicle: p3att\n"
                 "start: {x: 1, y: 1}\ngoal: {x: 5, y: 5, radius: 0.5}\nplaner: {branching: 8}\n")
    assert main(["plan", str(s)]) == 2
    err = capsys.readouterr().err
    assert "4 problems" in err and "Traceback" not in err
    for part in ("did you mean 'planner'?", "map.file: expected an existing file", "did you mean 'p3at'?",
                 "did you mean 'grass'?"):
        assert part in err, part


def test_a_terrain_class_raster_sets_the_terrain_of_every_cell(tmp_path):
    """terrain.raster: integer classes on the map's grid (.npy rows from the south, PNG
    rows from the north), each listed class a terrain, the others the default, regions
    on top; a raster of the wrong shape is refused with both shapes."""
    import numpy as np
    from PIL import Image
    from sbmpc.planning import world as WO
    C = np.zeros((49, 81), np.int64)
    C[:, 41:] = 1                                   # the eastern half
    C[:10, :] = 7                                   # a class not listed: the default
    np.save(tmp_path / "classes.npy", C)
    Image.fromarray(np.flipud(C).astype(np.uint8)).save(tmp_path / "classes.png")
    base = (SCEN_DIR / "flat.yaml").read_text().replace("terrain: vinyl", "terrain: {default: vinyl, raster: "
                                                        "{file: FILE, classes: {1: grass}}, regions: "
                                                        "[{terrain: asphalt, circle: [2, 10, 1]}]}")
    layers = []
    for f in ("classes.npy", "classes.png"):
        (tmp_path / "s.yaml").write_text(base.replace("FILE", f))
        w = WO.resolve(SC.load(tmp_path / "s.yaml"))
        assert [t.name for t in w.terrains] == ["vinyl", "grass", "asphalt"]
        L = w.emap.terrain_layer
        assert L[20, 60] == 1 and L[20, 20] == 0 and L[5, 60] == 0
        assert L[40, 8] == 2                          # the region (2, 10) m, on top
        assert w.terrain_at(15.0, 5.0).name == "grass" and w.terrain_at(5.0, 5.0).name == "vinyl"
        layers.append(L)
    assert np.array_equal(*layers)
    np.save(tmp_path / "small.npy", C[:10, :10])
    (tmp_path / "s.yaml").write_text(base.replace("FILE", "small.npy"))
    with pytest.raises(InputError, match="49 x 81 cells, found shape"):
        WO.resolve(SC.load(tmp_path / "s.yaml"))


@pytest.mark.parametrize("text, found", [("", "found an empty file"), ("[1, 2]\n", "found a list"),
                                         ("just words\n", "found a single string")])
def test_a_file_that_is_not_a_mapping_says_what_it_holds(tmp_path, capsys, text, found):
    """An empty scenario file said 'found NoneType' (a Python type name)."""
    f = tmp_path / "s.yaml"
    f.write_text(text)
    assert main(["plan", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(found), err

