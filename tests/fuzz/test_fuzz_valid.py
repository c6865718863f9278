"""Valid variants of the reference trial give the reference's numbers: the coordinates in metres (the header
saying m), CRLF line ends, a UTF-8 byte-order mark, UTF-16, unicode marker names (in the model too), every
coordinate offset by 100 m, and a C3D in metres.

Tolerance. ``fit --json`` prints distances to 0.001 mm; the variants change only how the same numbers are
written, so each distance must agree within 0.002 mm (one unit of the last printed digit either side) except
where the variant itself rounds: metres written with 8 decimals round at 1e-5 mm; a C3D stores float32, whose
step at 1-2 m from the origin is about 1e-4 mm, and at 100 m about 0.008 mm. Noise of 0.3 mm makes the fit's
own spread across such rounding far smaller than its 95 % intervals (about +-0.3 mm here), so 0.002 mm for the
text variants and 0.01 mm for the offset and the C3D are tight bounds, not loose ones."""
from __future__ import annotations

import json

import numpy as np
import pytest

from identcheck.io.c3d import write_c3d

from identcheck.io.trc import read_trc, write_trc

from fuzz_support import DIAGNOSE_LEG, LEG

UNICODE = {"RTHI": "Oberschenkel_Ä", "RKNE": "膝", "RANK": "Ακρο"}


def _distances(doc: dict) -> dict:
    """joint -> marker -> distance of a fit document."""
    return {j: v["marker_distances"] for j, v in doc["joints"].items()}


def _close(got: dict, want: dict, tol: float, rename=None) -> None:
    rename = rename or {}
    for joint, dist in want.items():
        for marker, d in dist.items():
            g = got[joint][rename.get(marker, marker)]
            assert abs(g - d) <= tol, (joint, marker, g, d)


def _trc_lines(corpus) -> list[str]:
    return (corpus / "leg.trc").read_text().split("\n")


def _in_metres(corpus) -> str:
    """The reference TRC with Units m and every coordinate divided by 1000 (8 decimals)."""
    lines = _trc_lines(corpus)
    lines[2] = lines[2].replace("\tmm\t", "\tm\t", 1)
    for i in range(6, len(lines)):
        if lines[i].strip():
            cells = lines[i].split("\t")
            lines[i] = "\t".join(cells[:2] + [f"{float(c) / 1000:.8f}" if c else "" for c in cells[2:]])
    return "\n".join(lines)


def _offset(corpus, mm: float) -> str:
    """The reference TRC with `mm` added to every coordinate."""
    lines = _trc_lines(corpus)
    for i in range(6, len(lines)):
        if lines[i].strip():
            cells = lines[i].split("\t")
            lines[i] = "\t".join(cells[:2] + [f"{float(c) + mm:.8f}" if c else "" for c in cells[2:]])
    return "\n".join(lines)


VARIANTS = {
    "metres": (lambda c: _in_metres(c).encode(), 0.002),
    "crlf": (lambda c: (c / "leg.trc").read_bytes().replace(b"\n", b"\r\n"), 0.002),
    "bom": (lambda c: b"\xef\xbb\xbf" + (c / "leg.trc").read_bytes(), 0.002),
    "utf16": (lambda c: (c / "leg.trc").read_text().encode("utf-16"), 0.002),
    "offset_100m": (lambda c: _offset(c, 100_000.0).encode(), 0.01),
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_a_valid_variant_gives_the_reference_numbers(run, corpus, leg_fit, tmp_path, variant):
    """Each variant: exit 0, and every joint's marker distances within the tolerance of the reference."""
    make, tol = VARIANTS[variant]
    path = tmp_path / f"{variant}.trc"
    path.write_bytes(make(corpus))
    res = run(["fit", LEG, path, "--json"])
    assert res.code == 0, res.err
    _close(_distances(json.loads(res.out)), _distances(leg_fit), tol)


def test_unicode_marker_names_give_the_reference_numbers(run, corpus, leg_fit, tmp_path):
    """Markers renamed to non-ASCII names in the trial and the model alike: exit 0, the same distances."""
    text, model = (corpus / "leg.trc").read_text(), LEG.read_text()
    for old, new in UNICODE.items():
        text, model = text.replace(f"\t{old}\t", f"\t{new}\t", 1), model.replace(f'"{old}"', f'"{new}"')
    path, model_path = tmp_path / "unicode.trc", tmp_path / "unicode.toml"
    path.write_text(text, encoding="utf-8")
    model_path.write_text(model, encoding="utf-8")
    res = run(["fit", model_path, path, "--json"])
    assert res.code == 0, res.err
    _close(_distances(json.loads(res.out)), _distances(leg_fit), 0.002, rename=UNICODE)


def test_a_c3d_in_metres_gives_the_reference_numbers(run, corpus, leg_fit, leg_markers, tmp_path):
    """The reference markers written as a C3D whose POINT:UNITS says m: exit 0, the same distances within
    float32's rounding."""
    import ezc3d

    xyz, labels, rate = leg_markers
    path = tmp_path / "metres.c3d"
    write_c3d(path, xyz, labels, rate)
    c3d = ezc3d.c3d(str(path))
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    points = np.ones((4, len(labels), len(xyz)))
    points[:3] = xyz.transpose(2, 1, 0) / 1000.0
    c3d["data"]["points"] = points
    c3d.write(str(path))
    res = run(["fit", LEG, path, "--json"])
    assert res.code == 0, res.err
    _close(_distances(json.loads(res.out)), _distances(leg_fit), 0.01)


def test_diagnose_gives_the_same_numbers_100_m_from_the_origin(run, corpus, tmp_path):
    """diagnose on the diagnose trial and on it moved by 100 m: the same gaps, effects and marker distances
    (before, the gap moved by 0.01 mm and distances by up to 0.1 mm: float64 sums of squares of coordinates)."""
    data = read_trc(corpus / "dleg.trc")
    moved = tmp_path / "moved.trc"
    write_trc(moved, data.xyz + 100_000.0, data.labels, data.rate_hz)
    want, got = (run(["diagnose", DIAGNOSE_LEG, p, "--json"]) for p in (corpus / "dleg.trc", moved))
    assert want.code == got.code == 0, (want.err, got.err)
    want, got = json.loads(want.out), json.loads(got.out)
    assert [e["name"] for e in got["effects"]] == [e["name"] for e in want["effects"]]
    for key in ("gap_before", "gap_after", "noise_floor"):
        assert abs(got[key] - want[key]) <= 0.002, key
    _close(_distances(got), _distances(want), 0.01)
