"""The docs match the code: every command's synopsis in docs/commands.md names exactly
the options its parser takes (issue 63: `compare` and `run` lacked `--bag`, `--frame` and
`--margin`), and every subcommand has a section."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from sbmpc.commands.cli import build_parser

DOC = Path(__file__).resolve().parents[1] / "docs" / "commands.md"


def _subparsers():
    p = build_parser()
    sub = next(a for a in p._actions if a.__class__.__name__ == "_SubParsersAction")
    return sub.choices


def _synopses(text: str) -> dict:
    """{command: its synopsis text} of every line in a code block that starts with
    'sbmpc COMMAND' (continuation lines, indented, joined; ``import`` per dataset)."""
    out, cur, inside = {}, None, False
    for line in text.splitlines():
        if line.startswith("```"):
            inside, cur = not inside, None
            continue
        if not inside:
            continue
        words = line.split()
        if line.startswith("sbmpc ") and not words[1].startswith("-"):
            cur = words[1] if words[1] != "import" else f"import {words[2]}"
            out[cur] = out.get(cur, "") + " " + line
        elif cur is not None and line.startswith(" "):
            out[cur] += " " + line
        else:
            cur = None
    return out


def _flags(parser) -> set:
    return {o for a in parser._actions for o in a.option_strings if o.startswith("--") and o != "--help"}


@pytest.mark.parametrize("command", sorted(_subparsers()))
def test_each_commands_synopsis_names_exactly_its_options(command):
    text = DOC.read_text()
    syn = _synopses(text)
    parser = _subparsers()[command]
    if command == "import":
        have = set()
        for k, v in syn.items():
            if k.startswith("import"):
                have |= set(re.findall(r"--[a-z][a-z0-9-]*", v))
    else:
        assert command in syn, f"docs/commands.md has no synopsis for sbmpc {command}"
        have = set(re.findall(r"--[a-z][a-z0-9-]*", syn[command])) - {"--debug"}
    want = _flags(parser)
    assert have == want, (f"sbmpc {command}: in the docs, not the parser: {sorted(have - want)}; "
                          f"in the parser, not the docs: {sorted(want - have)}")
    assert f"`sbmpc {command}`" in text
