"""Pieces of the JSON Schemas (:mod:`sbmpc.schemas`, and the scenario's own in
:func:`sbmpc.scenario.json_schema`): number and null types, objects."""
from __future__ import annotations

NUM = {"type": "number"}
NUM_OR_NULL = {"type": ["number", "null"]}
STR_OR_NULL = {"type": ["string", "null"]}


def obj(props: dict, required=(), extra: bool = True) -> dict:
    out = {"type": "object", "properties": props}
    if required:
        out["required"] = list(required)
    if not extra:
        out["additionalProperties"] = False
    return out
