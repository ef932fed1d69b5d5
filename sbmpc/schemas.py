"""JSON Schemas (draft 2020-12) of the files sbmpc reads and writes: ``scenario`` (the
YAML, as data), ``plan``, ``compare``, ``run``, ``diagnosis``. ``sbmpc schema NAME``
prints one. The scenario schema's numeric ranges are the validator's own tables
(:data:`sbmpc.scenario._SETTING_RANGES`, ``_RUN_RANGES``), so the two cannot drift
apart; the output schemas are checked against real outputs by the tests.
"""
from __future__ import annotations

from .scenario import json_schema as scenario
from .schema_parts import NUM, NUM_OR_NULL, STR_OR_NULL, obj as _obj


def _trajectory() -> dict:
    from .trajectory import TRAJECTORY_KEYS
    return _obj({k: {"type": "array", "items": NUM} for k in TRAJECTORY_KEYS},
                ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W", "energy_J"))


def plan() -> dict:
    from .planning.plan import FAILURES
    check = _obj({"dt": NUM, "reached": {"type": "boolean"}, "travel_time_s": NUM_OR_NULL, "energy_J": NUM_OR_NULL,
                  "reason": STR_OR_NULL, "miss_m": NUM_OR_NULL, "drift_allowance_m": NUM_OR_NULL},
                 ("dt", "reached"))
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema", "$id": "sbmpc.plan/1", "title": "sbmpc plan JSON",
        **_obj({
            "schema": {"const": "sbmpc.plan/1"}, "scenario": {"type": "string"}, "cost": {"enum": ["time", "energy"]},
            "status": {"enum": ["found", "no_path"]}, "reason": STR_OR_NULL,
            "travel_time_s": NUM_OR_NULL, "energy_J": NUM_OR_NULL, "length_m": NUM_OR_NULL,
            "planning_time_s": NUM, "nodes_expanded": {"type": "integer"}, "edges_simulated": {"type": "integer"},
            "controls": {"type": "array", "items": _obj({"wl": NUM, "wr": NUM, "duration_s": NUM},
                                                        ("wl", "wr", "duration_s"), extra=False)},
            "trajectory": {"oneOf": [_trajectory(), {"type": "object", "maxProperties": 0}]},
            "nodes": {"type": "integer"}, "invalid_edges": {"type": "object", "additionalProperties": {"type": "integer"}},
            "found_by": {"type": "string"}, "controller_rate_check": {"oneOf": [check, {"type": "null"}]},
            "repairs": {"type": "integer"},
            "polish": {"type": ["object", "null"]},
            "coarse": {"oneOf": [_obj({"status": {"enum": ["found", "no_path"]}, "expansions": {"type": "integer"},
                                       "edges_simulated": {"type": "integer"}, "seconds": NUM, "cost": NUM_OR_NULL,
                                       "half_width_m": NUM},
                                      ("status", "expansions", "half_width_m")),
                                 {"type": "null"}]},
            "rival": {"oneOf": [_obj({"cost": {"const": "time"}, "status": {"enum": ["found", "no_path"]},
                                      "travel_time_s": NUM_OR_NULL, "energy_J": NUM_OR_NULL,
                                      "planning_time_s": NUM, "checked": {"type": "boolean"},
                                      "kept_margin": {"type": "boolean"}},
                                     ("cost", "status", "energy_J")),
                                {"type": "null"}]},
            "failure": {"enum": [*FAILURES, None]},
            "margin": {"oneOf": [_margin(), {"type": "null"}]},
        }, ("schema", "scenario", "cost", "status", "reason", "travel_time_s", "energy_J", "planning_time_s",
            "nodes_expanded", "edges_simulated", "controls", "trajectory"))}


def _margin() -> dict:
    """The plan JSON's ``margin`` (sbmpc.planning.margin.report, plan.search_plan)."""
    where = {"t": NUM, "x": NUM, "y": NUM}
    return _obj({"margin": NUM, "margin_turn": NUM, "tip_margin_deg": NUM, "heading_deg": NUM,
                 "grade_deg": NUM, "drive_headroom": _obj({"least": NUM, **where}, ("least", "t", "x", "y")),
                 "turn_headroom": {"oneOf": [_obj({"least": NUM, **where}, ("least", "t", "x", "y")), {"type": "null"}]},
                 "tip": _obj({"least_deg": NUM, **where}, ("least_deg", "t", "x", "y")),
                 "kept": {"type": "boolean"}, "note": STR_OR_NULL,
                 "robustness": _obj({"samples": {"type": "integer"}, "relative_sd": NUM, "seed": {"type": "integer"},
                                     "p_stall": NUM, "p_tip": NUM, "p_miss": NUM},
                                    ("samples", "p_stall", "p_tip", "p_miss"))},
                ("margin", "drive_headroom", "tip", "kept"))


def compare() -> dict:
    summary = plan()
    summary = {k: v for k, v in summary.items() if k not in ("$schema", "$id", "title")}
    summary["required"] = [r for r in summary["required"] if r != "trajectory"]
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": "sbmpc.compare/1",
            "title": "sbmpc compare.json",
            **_obj({"schema": {"const": "sbmpc.compare/1"}, "scenario": {"type": "string"},
                    "plans": _obj({"time": summary, "energy": summary}, ("time", "energy")),
                    "total_time_s": NUM,
                    "tradeoff": _obj({"time_saved_s": NUM, "energy_saved_J": NUM, "holds": {"type": "boolean"}},
                                     ("time_saved_s", "energy_saved_J", "holds"))},
                   ("schema", "scenario", "plans"))}


def run() -> dict:
    from .planning.plan import FAILURES
    pe = _obj({"travel_time_s": NUM_OR_NULL, "energy_J": NUM_OR_NULL, "length_m": NUM_OR_NULL},
              ("travel_time_s", "energy_J"))
    row = _obj({"t": NUM, "x": NUM, "y": NUM, "why": {"type": "string"}, "status": {"enum": ["found", "no_path"]},
                "reason": STR_OR_NULL, "failure": {"enum": [*FAILURES, None]}, "planning_time_s": NUM,
                "nodes_expanded": {"type": "integer"}, "predicted_travel_time_s": NUM_OR_NULL,
                "predicted_energy_J": NUM_OR_NULL, "controls": {"type": "integer"}, "warm_start": {"type": "boolean"},
                "goal_radius_m": NUM, "found_by": STR_OR_NULL, "rival": {"type": ["object", "null"]}},
               ("t", "x", "y", "why", "status", "planning_time_s", "nodes_expanded", "controls"))
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": "sbmpc.run/1", "title": "sbmpc run JSON",
            **_obj({"schema": {"const": "sbmpc.run/1"}, "scenario": {"type": "string"}, "cost": {"enum": ["time", "energy"]},
                    "vehicle": {"type": "string"}, "truth": {"type": "string"},
                    "status": {"enum": ["reached", "failed"]}, "reason": STR_OR_NULL,
                    "replans": {"type": "integer"}, "planning_time_s": NUM, "travel_time_s": NUM_OR_NULL,
                    "energy_J": NUM_OR_NULL, "predicted": pe, "executed": pe,
                    "prediction_error": _obj({"travel_time": NUM_OR_NULL, "energy": NUM_OR_NULL}),
                    "stalls": {"type": "integer"}, "periods": {"type": "integer"}, "guarded": {"type": "integer"},
                    "weaker_from_t": NUM_OR_NULL,
                    "trigger": {"enum": ["tolerance", "every"]},
                    "first_planning_time_s": NUM_OR_NULL, "replan_time_s": {"type": "array", "items": NUM},
                    "tolerance": _obj({"xy_m": NUM, "yaw_deg": NUM, "v_m_s": NUM}),
                    "warm_start": {"type": "string"},
                    "horizon": _obj({"horizon_s": NUM, "plans": {"type": "integer"}, "first_s": NUM,
                                     "replan_median_s": NUM, "replan_p95_s": NUM, "replan_max_s": NUM,
                                     "expansions_median": NUM, "kept_previous": {"type": "integer"},
                                     "from_measured": {"type": "integer"}, "fallbacks": {"type": "integer"},
                                     "fallback_s": {"type": "array", "items": NUM}, "settled": {"type": "integer"},
                                     "rejoined": {"type": "integer"}, "shortened": {"type": "integer"},
                                     "beside_made": {"type": "integer"},
                                     "beside_median_s": NUM},
                                    ("horizon_s", "plans", "first_s", "replan_p95_s", "fallbacks")),
                    "plans": {"type": "array", "items": row},
                    "trajectory": {"oneOf": [_trajectory(), {"type": "object", "maxProperties": 0}]}},
                   ("schema", "scenario", "cost", "vehicle", "truth", "status", "reason", "replans",
                    "planning_time_s", "travel_time_s", "energy_J", "predicted", "executed", "stalls", "periods",
                    "trigger", "plans", "trajectory"))}


def diagnosis() -> dict:
    from dynamics.discrepancy import CANDIDATES
    cand = _obj({"effect": {"enum": list(CANDIDATES)}, "params": {"type": "object", "additionalProperties": NUM},
                 "stderr": {"type": "object"}, "heldout_error": NUM, "gain": NUM, "bic_delta": NUM_OR_NULL,
                 "whiteness_q": NUM_OR_NULL, "at_bound": {"type": "array", "items": {"type": "string"}},
                 "fitted_on": {"enum": ["channels", "pose", "heldout"]}, "pose_gain": NUM_OR_NULL, "evidence": NUM_OR_NULL,
                 "reach": NUM_OR_NULL, "train_evidence": NUM_OR_NULL, "train_reach": NUM_OR_NULL},
                ("effect", "params", "heldout_error", "gain"))
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": "sbmpc.diagnosis/1",
            "title": "sbmpc diagnosis JSON",
            **_obj({"schema": {"const": "sbmpc.diagnosis/1"},
                    "baseline": _obj({"heldout_error": NUM, "rmse": {"type": "object"}}, ("heldout_error", "rmse")),
                    "candidates": {"type": "array", "items": cand},
                    "cause": {"enum": ["none", "unexplained"] + list(CANDIDATES)}, "gain": NUM, "margin": NUM,
                    "evidence_threshold": NUM, "explained_share": NUM_OR_NULL, "share_threshold": NUM,
                    "hint": {"enum": [None] + list(CANDIDATES)},
                    "residual": {"type": "object"},
                    "decided_on": {"enum": ["heldout", "heldout_only", "training", "pose", None]},
                    "rivals": {"type": "array", "items": {"type": "string"}},
                    "channels": {"type": "array", "items": {"type": "string"}},
                    "extended_vehicle": STR_OR_NULL, "extended_grade_deg": NUM,
                    "extended_grade_toward_deg": NUM_OR_NULL, "run": {"type": "string"}, "diagnosis_time_s": NUM},
                   ("schema", "baseline", "candidates", "cause", "gain"))}


SCHEMAS = {"scenario": scenario, "plan": plan, "compare": compare, "run": run, "diagnosis": diagnosis}


def get(name: str) -> dict:
    """The JSON Schema of ``name`` (one of :data:`SCHEMAS`)."""
    return SCHEMAS[name]()
