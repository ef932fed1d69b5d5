"""The JSON Schemas shipped in the package (sbmpc schema NAME) describe what the
commands really read and write: every shipped scenario validates, broken ones do not,
and real plan, compare, run and diagnosis outputs validate."""
import json
from pathlib import Path

import pytest

jsonschema = pytest.importorskip("jsonschema")

from dynamics.params import read_yaml_text
from sbmpc import schemas
from sbmpc.commands.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCEN = ROOT / "scenarios"


def valid(name, doc):
    jsonschema.Draft202012Validator(schemas.get(name)).validate(doc)


@pytest.mark.parametrize("name", list(schemas.SCHEMAS))
def test_schemas_are_valid_json_schemas_and_print(name, capsys):
    jsonschema.Draft202012Validator.check_schema(schemas.get(name))
    assert main(["schema", name]) == 0
    assert json.loads(capsys.readouterr().out)["$id"].startswith(f"sbmpc.{name}")


@pytest.mark.parametrize("path", sorted(SCEN.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_scenario_validates(path):
    valid("scenario", read_yaml_text(path))


@pytest.mark.parametrize("change", [
    {"planer": {}}, {"cost": "speed"}, {"planner": {"branching": 1000}}, {"goal": {"x": 1}},
    {"planner": {"device": "tpu"}}, {"run": {"trigger": "sometimes"}},
])
def test_broken_scenarios_fail_the_schema_and_the_validator(change, tmp_path):
    from sbmpc import scenario as SC
    from sbmpc.errors import InputError
    doc = dict(read_yaml_text(SCEN / "flat.yaml"), **change)
    with pytest.raises(jsonschema.ValidationError):
        valid("scenario", doc)
    with pytest.raises(InputError):
        SC.parse(doc, "doc")


def test_the_validator_runs_the_schema(monkeypatch, tmp_path, capsys):
    """The scenario loader runs the schema after its own checks: a rule only the schema
    holds (here a stricter stand-in requiring a description) refuses the file with the
    schema's words, exit 2, one message."""
    from sbmpc import scenario as SC
    from sbmpc.errors import InputError
    strict = schemas.scenario()
    strict["required"] = strict["required"] + ["description"]
    monkeypatch.setattr(SC, "json_schema", lambda: strict)
    doc = read_yaml_text(SCEN / "flat.yaml")
    doc.pop("description", None)
    with pytest.raises(InputError, match=r"'description' is a required property \(schema\)"):
        SC.parse(doc, "doc")
    f = tmp_path / "s.yaml"
    f.write_text("\n".join(line for line in (SCEN / "flat.yaml").read_text().splitlines()
                           if not line.startswith("description")))
    assert main(["plan", str(f), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "(schema)" in err and "Traceback" not in err


def test_outputs_validate(tmp_path, capsys):
    assert main(["plan", str(SCEN / "flat.yaml"), "--json", str(tmp_path / "p.json"), "--quiet"]) == 0
    valid("plan", json.loads((tmp_path / "p.json").read_text()))
    # an energy plan names the time plan it was checked against, and says so
    capsys.readouterr()
    assert main(["plan", str(SCEN / "flat.yaml"), "--cost", "energy", "--json", str(tmp_path / "e.json"), "--quiet"]) == 0
    e = json.loads((tmp_path / "e.json").read_text())
    valid("plan", e)
    assert e["rival"]["cost"] == "time" and e["rival"]["energy_J"] >= e["energy_J"] > 0
    assert e["planning_time_s"] >= e["rival"]["planning_time_s"]
    assert f"checked against the time plan: {e['rival']['energy_J']:.1f} J" in capsys.readouterr().out
    assert main(["plan", str(SCEN / "unreachable.yaml"), "--json", str(tmp_path / "u.json"), "--quiet"]) == 1
    valid("plan", json.loads((tmp_path / "u.json").read_text()))
    assert main(["compare", str(SCEN / "runup_ramp.yaml"), "--out", str(tmp_path / "c"), "--quiet"]) == 0
    valid("compare", json.loads((tmp_path / "c" / "compare.json").read_text()))
    assert main(["run", str(SCEN / "flat.yaml"), "--json", str(tmp_path / "r.json"), "--quiet"]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    valid("run", r)
    import jsonschema                       # the contract's keys are required, not just allowed
    from sbmpc.schemas import run as run_schema
    for broken in ({k: v for k, v in r.items() if k != "trajectory"}, {k: v for k, v in r.items() if k != "planning_time_s"},
                   dict(r, plans="garbage"), dict(r, trajectory={k: v for k, v in r["trajectory"].items() if k != "yaw_rate"})):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(broken, run_schema())
    assert main(["synth", "--effect", "none", "--duration", "20", "--out", str(tmp_path / "s.csv")]) == 0
    assert main(["diagnose", str(tmp_path / "s.csv"), "--json", str(tmp_path / "d.json")]) == 0
    valid("diagnosis", json.loads((tmp_path / "d.json").read_text()))
