"""``sbmpc schema``: print the JSON Schema of a file sbmpc reads or writes."""
from __future__ import annotations

import json


def add_parsers(sub):
    from ..schemas import SCHEMAS
    p = sub.add_parser("schema", help="print the JSON Schema of a scenario, plan, compare, run or diagnosis file",
                       description="Print the JSON Schema (draft 2020-12) of one of the files sbmpc reads or "
                       "writes, for editors and validators (docs/formats.md describes each key).")
    p.add_argument("name", metavar="FILE", choices=tuple(SCHEMAS), help=f"which file: {', '.join(SCHEMAS)}")
    p.set_defaults(func=run_schema)


def run_schema(args) -> int:
    from ..schemas import get
    print(json.dumps(get(args.name), indent=1))
    return 0
