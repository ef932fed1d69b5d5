"""The last bad inputs (issue 47): each refused before the work with one line naming the
file and the limit, exit 2: deep YAML, a 400-digit height range, PNG and .npy headers
that claim too many cells (judged from the header, the data never read), and no warning
line before a refusal."""
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from sbmpc.commands.cli import main

ROOT = Path(__file__).resolve().parents[1]


def one_line(capsys, rc):
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert "\n" not in err and "Traceback" not in err, err
    return err


def _scenario(tmp_path, map_line: str) -> Path:
    p = tmp_path / "s.yaml"
    p.write_text(f"name: s\nmap: {map_line}\nterrain: asphalt\nvehicle: p3at\n"
                 "start: {x: 1.0, y: 1.0}\ngoal: {x: 3.0, y: 3.0}\n")
    return p


def _png_header(path: Path, w: int, h: int, depth: int = 16) -> None:
    """A PNG that is only a signature and an IHDR claiming w x h grey pixels (no data)."""
    ihdr = struct.pack(">IIBBBBB", w, h, depth, 0, 0, 0, 0)
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk)


def test_deeply_nested_yaml_is_refused_in_one_line(tmp_path, capsys):
    deep = tmp_path / "s.yaml"
    deep.write_text("name: " + "[" * 5000 + "]" * 5000 + "\n")
    err = one_line(capsys, main(["plan", str(deep)]))
    assert str(deep) in err and "nested at most 64 levels" in err
    mid = tmp_path / "m.yaml"
    mid.write_text("name: " + "[" * 100 + "]" * 100 + "\n")          # parses, but deeper than the limit
    err = one_line(capsys, main(["plan", str(mid)]))
    assert "nested at most 64 levels deep, found more" in err
    ok = tmp_path / "ok.yaml"
    ok.write_text("name: " + "[" * 60 + "]" * 60 + "\n")           # within the limit: judged on its merits
    assert main(["plan", str(ok)]) == 2
    err = capsys.readouterr().err
    assert "levels deep" not in err and "name: expected a non-empty string" in err


def test_a_400_digit_height_range_is_refused_naming_the_key(tmp_path, capsys):
    png = tmp_path / "h.png"
    _png_header(png, 4, 4)
    s = _scenario(tmp_path, "{file: h.png, resolution: 1.0, height_range: [0, " + "9" * 400 + "]}")
    err = one_line(capsys, main(["plan", str(s)]))
    assert "map.height_range" in err and "an integer of 400 digits" in err


@pytest.mark.parametrize("w, h", [(65535, 65535), (12000, 12000)])
def test_a_png_whose_header_claims_too_many_cells_is_refused_from_its_header(tmp_path, capsys, w, h):
    """The file holds no image data at all: refused from the header, nothing decoded."""
    png = tmp_path / "h.png"
    _png_header(png, w, h)
    s = _scenario(tmp_path, "{file: h.png, resolution: 1.0, height_range: [0, 2]}")
    err = one_line(capsys, main(["plan", str(s)]))
    assert str(png) in err and "at most 25 million cells" in err and f"{h} x {w}" in err


def test_a_npy_whose_header_claims_1e10_cells_is_refused_from_its_header(tmp_path, capsys):
    npy = tmp_path / "h.npy"
    header = {"descr": "<f8", "fortran_order": False, "shape": (100000, 100000)}
    with open(npy, "wb") as f:
        np.lib.format.write_array_header_1_0(f, header)       # the header alone: no 80 GB of data
    s = _scenario(tmp_path, "{file: h.npy, resolution: 1.0}")
    err = one_line(capsys, main(["plan", str(s)]))
    assert str(npy) in err and "shape (100000, 100000)" in err and "at most 25 million" in err


def test_an_8bit_png_refused_for_its_size_prints_the_refusal_alone(tmp_path, capsys):
    png = tmp_path / "h.png"
    _png_header(png, 6000, 6000, depth=8)
    s = _scenario(tmp_path, "{file: h.png, resolution: 1.0, height_range: [0, 2]}")
    err = one_line(capsys, main(["plan", str(s)]))
    assert "8-bit" not in err and "at most 25 million cells" in err


@pytest.mark.parametrize("command", [["plan"], ["run"], ["compare", "--out", "cmp"]])
def test_a_scenario_with_a_nul_byte_gets_one_line(tmp_path, capsys, command):
    """A NUL byte in a scenario: the YAML parser's message has a line break in it (the
    character, then where); every message is one line (issue 63), and the file is left as
    it was."""
    p = _scenario(tmp_path, "{generate: {size: [10, 10]}}")
    data = p.read_bytes().replace(b"name: s", b"name: s\x00")
    p.write_bytes(data)
    args = [command[0], str(p)] + [str(tmp_path / a) if a == "cmp" else a for a in command[1:]]
    err = one_line(capsys, main(args))
    assert "malformed YAML" in err and "special characters are not allowed" in err
    assert p.read_bytes() == data
