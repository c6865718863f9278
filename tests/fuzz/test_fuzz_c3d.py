"""Malformed C3D files, made from a valid one: cut at every section (header, parameter section record by record,
data frame by frame), single bytes and 16-bit words changed anywhere in the header and parameter section, and
header fields that disagree with the parameters.

ezc3d (C++) reads what the header and parameter section say without checking it: before the reader walked the
parameter section itself, a file cut inside it, or a single changed byte, made ezc3d loop forever or crash the
interpreter (segmentation fault), and its own messages ("vector::_M_default_append") reached the user. So every
variant is read by ``identcheck identify`` in a child process, a batch at a time: a crash or a hang fails the
test naming the variant instead of killing the test run. Each must end in exit 0/1 (a readable variant) or
exit 2 naming the file, with no traceback; the files are unchanged."""
from __future__ import annotations

import json
import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, strategies as st

from fuzz_support import FUZZ, LEG, digest

pytest.importorskip("ezc3d")

WORKER = """
import json, sys, io, contextlib
from identcheck import cli
for line in open(sys.argv[1]):
    path = line.strip()
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = cli.main(["identify", sys.argv[2], path, "--joint", "hip_r"])
    print(json.dumps({"path": path, "code": code, "err": err.getvalue()}), flush=True)
"""


def read_in_child(paths: list[Path], tmp_path: Path, timeout: float = 240.0) -> dict:
    """path -> {"code", "err"} of ``identcheck identify LEG path --joint hip_r`` for every path, run in one
    child process; fails naming the variant being read when the child crashes or hangs."""
    listing = tmp_path / "variants.txt"
    listing.write_text("".join(f"{p}\n" for p in paths))
    before = {p: digest(p) for p in paths}
    try:
        proc = subprocess.run([sys.executable, "-c", WORKER, str(listing), str(LEG)], capture_output=True, text=True,
                              timeout=timeout)
        outcome, lines = proc.returncode, proc.stdout
    except subprocess.TimeoutExpired as exc:
        outcome, lines = "hung", (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else exc.stdout or ""
    done = {r["path"]: r for r in map(json.loads, lines.splitlines())}
    if len(done) < len(paths):
        pytest.fail(f"reading {paths[len(done)]} {'crashed' if outcome != 'hung' else 'hung'} "
                    f"(child exit {outcome}): {getattr(proc, 'stderr', '')[-2000:] if outcome != 'hung' else ''}")
    assert all(digest(p) == before[p] for p in paths), "a variant was changed by reading it"
    return done


def check(results: dict) -> None:
    """Every variant: no traceback, exit 0/1, or exit 2 naming its file."""
    for path, r in results.items():
        assert "Traceback" not in r["err"] and r["code"] in (0, 1, 2), (path, r)
        if r["code"] == 2:
            assert path in r["err"], (path, r["err"])


def records(raw: bytes) -> dict:
    """(GROUP, NAME) -> (record byte, data byte, type, dims) of every parameter, read the way the C3D format
    describes them (independently of identcheck's reader)."""
    start = (raw[0] - 1) * 512
    pos, groups, out = start + 4, {}, {}
    while True:
        n, gid = struct.unpack("bb", raw[pos:pos + 2])
        if n == 0:
            return out
        name = raw[pos + 2:pos + 2 + abs(n)].decode()
        link = pos + 2 + abs(n)
        offset = struct.unpack("<H", raw[link:link + 2])[0]
        if gid < 0:
            groups[-gid] = name
        else:
            kind, nd = struct.unpack("bB", raw[link + 2:link + 4])
            dims = tuple(raw[link + 4:link + 4 + nd])
            out[(groups[gid], name)] = (pos, link + 4 + nd, kind, dims)
        if offset == 0:
            return out
        pos = link + offset


def _variant(tmp_path: Path, raw: bytes, name: str) -> Path:
    path = tmp_path / name
    path.write_bytes(raw)
    return path


def test_a_file_cut_at_every_section_is_named(corpus, tmp_path):
    """Cut inside the header, at and inside every parameter record, and at and inside frames of the data:
    exit 2 naming the file (the whole file reads)."""
    raw = (corpus / "leg.c3d").read_bytes()
    data_start = (struct.unpack("<H", raw[16:18])[0] - 1) * 512
    frame = 10 * 4 * 4
    cuts = [0, 1, 100, 511, 512, 513, 515]
    for pos, _, _, _ in records(raw).values():
        cuts += [pos, pos + 1, pos + 3]
    cuts += [data_start - 1, data_start, data_start + 7]
    cuts += [data_start + k * frame + extra for k in (1, 2, 50, 199) for extra in (0, 9)]
    paths = [_variant(tmp_path, raw[:c], f"cut{c}.c3d") for c in sorted(set(cuts))]
    results = read_in_child(paths + [corpus / "leg.c3d"], tmp_path)
    check(results)
    assert all(results[str(p)]["code"] == 2 for p in paths), [(p, results[str(p)]) for p in paths
                                                               if results[str(p)]["code"] != 2]
    assert results[str(corpus / "leg.c3d")]["code"] == 0


@FUZZ
@given(changes=st.lists(st.tuples(st.integers(0, 2047), st.integers(0, 255)), min_size=150, max_size=150),
       words=st.lists(st.tuples(st.integers(0, 1023), st.sampled_from([0x8000, 0xFFFF, 0x7FFF, 0x0100, 0])),
                      min_size=50, max_size=50))
def test_changed_bytes_of_the_header_and_parameters_never_crash(corpus, tmp_path, changes, words):
    """150 variants with one byte changed and 50 with one 16-bit word changed, anywhere in the header and the
    parameter section (a count, a type, a dimension, a link, a name length, a rate's bytes): each is read or
    named, never a crash or a hang."""
    raw = (corpus / "leg.c3d").read_bytes()
    limit = (struct.unpack("<H", raw[16:18])[0] - 1) * 512
    paths = []
    for k, (pos, value) in enumerate(changes):
        b = bytearray(raw)
        b[pos % limit] = value
        paths.append(_variant(tmp_path, bytes(b), f"byte{k}.c3d"))
    for k, (pos, value) in enumerate(words):
        b = bytearray(raw)
        b[2 * pos % limit:2 * pos % limit + 2] = struct.pack("<H", value)
        paths.append(_variant(tmp_path, bytes(b), f"word{k}.c3d"))
    check(read_in_child(paths, tmp_path))


def _patched(raw: bytes, param, value: bytes) -> bytes:
    """`raw` with the data of parameter `param` replaced by `value` (same length)."""
    _, at, _, _ = records(raw)[param]
    return raw[:at] + value + raw[at + len(value):]


def _header_count(raw: bytes) -> int:
    first, last = struct.unpack("<HH", raw[6:10])
    return last - first + 1


def test_header_and_parameters_that_disagree_are_named(corpus, tmp_path):
    """POINT:USED against the header's point count, the header's data start past the file, POINT:RATE not a
    number, an unknown POINT:UNITS or one (m) that puts the markers kilometres apart, POINT:DATA_START negative,
    POINT:SCALE of the other sign than the header's, both scales saying integers over float data, POINT:FRAMES
    past the header's frame range: exit 2 naming the field (and never ezc3d's own words)."""
    raw = (corpus / "leg.c3d").read_bytes()
    cases = {
        "used.c3d": (_patched(raw, ("POINT", "USED"), struct.pack("<h", 11)), ["POINT:USED", "header"]),
        "start.c3d": (raw[:16] + struct.pack("<H", 900) + raw[18:], ["data start", "block 900"]),
        "rate.c3d": (_patched(raw, ("POINT", "RATE"), struct.pack("<f", math.nan)), ["POINT:RATE"]),
        "units.c3d": (_patched(raw, ("POINT", "UNITS"), b"in"), ["POINT:UNITS", "'in'"]),
        "metres.c3d": (_patched(raw, ("POINT", "UNITS"), b"m "), ["POINT:UNITS says m", "coordinates are in mm"]),
        "dstart.c3d": (_patched(raw, ("POINT", "DATA_START"), struct.pack("<h", -3)), ["POINT:DATA_START"]),
        "scale.c3d": (raw[:12] + struct.pack("<f", 0.1) + raw[16:], ["POINT:SCALE", "header"]),
        # float data declared as integers in both places: the data section holds twice the bytes
        "both_scales.c3d": (_patched(raw[:12] + struct.pack("<f", 0.1) + raw[16:], ("POINT", "SCALE"),
                                     struct.pack("<f", 0.1)), ["POINT:SCALE", "integers", "floating-point"]),
        # POINT:FRAMES beyond the header's frame range (ezc3d reads the header's and says nothing)
        "frames.c3d": (_patched(raw, ("POINT", "FRAMES"), struct.pack("<h", _header_count(raw) + 1)),
                       ["POINT:FRAMES", "header"]),
    }
    paths = {name: _variant(tmp_path, data, name) for name, (data, _) in cases.items()}
    results = read_in_child(list(paths.values()), tmp_path)
    check(results)
    for name, (_, words) in cases.items():
        r = results[str(paths[name])]
        assert r["code"] == 2 and all(w in r["err"] for w in words), (name, r["err"])
        assert "ezc3d" not in r["err"], (name, r["err"])


def test_a_corrupt_name_length_is_quoted_short(corpus, tmp_path):
    """A parameter's name-length byte corrupted runs its name on through the next records' bytes: the message names
    the file, quotes the name's printable start and says its length looks corrupt, never some 100 raw bytes."""
    raw = bytearray((corpus / "leg.c3d").read_bytes())
    at = raw.index(b"DESCRIPTIONS")
    assert raw[at - 2] == len(b"DESCRIPTIONS")
    raw[at - 2] = 100
    path = _variant(tmp_path, bytes(raw), "name_length.c3d")
    r = read_in_child([path], tmp_path)[str(path)]
    assert r["code"] == 2 and str(path) in r["err"] and "length byte looks corrupt" in r["err"], r["err"]
    quoted = r["err"].split("parameter ", 1)[1].split(" at byte")[0]
    assert quoted.isprintable() and len(quoted) < 120, quoted


@pytest.mark.parametrize("value", [1e30, -1e7, math.inf])
def test_a_far_sample_is_named_by_frame_and_marker(run, corpus, tmp_path, leg_markers, value):
    """A sample 10 km away, 1e30 (a sentinel for 'missing') or infinite in a C3D: exit 2 naming the marker
    and the frame (before: 'no frame has a valid pose', naming neither): row 57 of a C3D whose header's 1-based
    first frame is 1 is its frame 58."""
    from identcheck.io.c3d import write_c3d

    xyz, labels, rate = leg_markers
    xyz = xyz.copy()
    xyz[57, labels.index("RTHI"), 1] = value
    path = tmp_path / "far.c3d"
    write_c3d(path, xyz, labels, rate)
    res = run(["fit", LEG, path])
    assert res.code == 2 and res.names(path, "'RTHI'", "frame 58"), res.err
