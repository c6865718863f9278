"""Outputs that are inputs under another name, writes the machine refuses, placeholders for missing samples and
truncation at a block boundary: each an exit-2 message or a warning in the JSON, never a traceback, an exit 3 or
a changed input (the ``run`` fixture).

Before: the guard against overwriting an input compared path strings, so a symbolic or hard link to the trial
or the model given as an output replaced the input; a write that failed mid-way (a full disk) was an internal
error with a traceback; a C3D cut exactly at a 512-byte block was read as complete (ezc3d rewrites POINT:FRAMES
to what it read); markers at exactly (0, 0, 0), the exporters' placeholder for a missing sample, were read as
positions at the lab's origin; a certificate with a zero denominator or a 5000-digit number stopped ``verify``
with a traceback."""
from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

from fuzz_support import LEG


@pytest.mark.parametrize("link", ["symlink", "hardlink"])
@pytest.mark.parametrize("target", ["trial", "model"])
def test_an_output_linked_to_an_input_is_refused(run, corpus, tmp_path, link, target):
    trial, model = tmp_path / "in.trc", tmp_path / "leg.toml"
    shutil.copy(corpus / "leg.trc", trial)
    shutil.copy(LEG, model)
    out = tmp_path / "out.trc"
    (os.symlink if link == "symlink" else os.link)(trial if target == "trial" else model, out)
    res = run(["fit", model, trial, "--json", "--export-markers", out], inputs=[trial, model])
    assert res.code == 2 and "is an input file" in res.err and "--export-markers" in res.err
    if target == "model":                         # simulate reads only the model
        sim = run(["simulate", model, "--out", out, "--frames", "20"], inputs=[trial, model])
        assert sim.code == 2 and "is an input file" in sim.err


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
def test_a_write_the_disk_refuses_is_exit_2_naming_the_file(run, corpus, tmp_path):
    out = tmp_path / "full.trc"
    os.symlink("/dev/full", out)
    res = run(["simulate", LEG, "--out", out, "--frames", "20"])
    assert res.code == 2 and str(out) in res.err and "No space left" in res.err


def test_a_c3d_cut_at_a_block_boundary_is_truncated(run, corpus, tmp_path):
    raw = (corpus / "leg.c3d").read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(raw[:(len(raw) // 2) // 512 * 512])
    res = run(["fit", LEG, cut, "--json"])
    assert res.code == 2 and "truncated file" in res.err and "200 frames" in res.err


def test_zero_placeholders_are_gaps_and_the_warning_is_in_the_json(run, corpus, tmp_path):
    from identcheck.trial import Trial

    t = Trial.from_file(corpus / "leg.trc")
    xyz = t.as_array()
    k = t.labels.index("RTHI")
    xyz[50:80, k] = 0.0
    path = tmp_path / "zeros.trc"
    Trial(xyz, t.labels, t.rate_hz).to_file(path)
    res = run(["fit", LEG, path, "--json"])
    assert res.code in (0, 1)
    warnings = [w["message"] for w in json.loads(res.out)["warnings"]]
    assert any("(0, 0, 0)" in w and "RTHI (30 frames)" in w for w in warnings), warnings
    assert not any(w.get("kind") == "model_misfit" and "RTHI" in w.get("markers", [])
                   for w in json.loads(res.out)["warnings"])


def test_frames_beyond_the_file_are_said_in_the_json(run, corpus):
    res = run(["fit", LEG, corpus / "leg.trc", "--json", "--frames", "0:120"])
    warnings = [w["message"] for w in json.loads(res.out)["warnings"]]
    assert any("reaches beyond the file's frames (1 to 200): using 1:120" in w for w in warnings), warnings


@pytest.mark.parametrize("field", ["parameter", "angle", "point"])
def test_a_certificate_with_a_zero_denominator_fails_verification(run, tmp_path, field):
    from identcheck.certify.seal import HASH_KEY, digest

    cert = tmp_path / "cert.json"
    assert run(["rank", "revolute", "2", "1", "--save", cert]).code == 0
    doc = json.loads(cert.read_text())
    if field == "parameter":
        doc["parameters"][sorted(doc["parameters"])[0]] = "1/0"
    elif field == "angle":
        doc["samples"][0]["t"][0] = "1/0"
    else:
        doc["samples"][0]["xyz"][0] = "1/0"
    doc.pop(HASH_KEY)
    doc[HASH_KEY] = digest(doc)                 # sealed again: only the value is wrong
    cert.write_text(json.dumps(doc))
    res = run(["verify", cert, "--json"])
    assert res.code == 1 and "zero denominator" in res.out


def test_a_number_too_long_to_read_is_not_a_certificate(run, tmp_path):
    cert = tmp_path / "cert.json"
    assert run(["rank", "revolute", "2", "1", "--save", cert]).code == 0
    text = cert.read_text().replace('"seed": 0', '"seed": 1' + "0" * 5000)
    cert.write_text(text)
    res = run(["verify", cert])
    assert res.code == 2 and "too long to read" in res.err


@pytest.mark.parametrize("extra", [["--frames", "300"], ["--motion", "flexion"],
                                   ["--motion", "small", "--frames", "50"]])
def test_plan_options_for_the_noise_prediction_need_noise(run, extra):
    """--motion and --frames describe the capture --noise-mm predicts: without it they were ignored in silence."""
    res = run(["plan", LEG, "--fast"] + extra)
    assert res.code == 2 and "--noise-mm" in res.err and extra[1] in res.err


def test_a_static_trial_names_two_markers(run, corpus, tmp_path):
    """The static-trial message names the pair that moved most, two different markers even when none moved."""
    from identcheck.trial import Trial

    t = Trial.from_file(corpus / "leg.trc")
    still = Trial(t.as_array()[:1].repeat(50, axis=0), t.labels, t.rate_hz)
    path = tmp_path / "still.trc"
    still.to_file(path)
    res = run(["skeleton", path, "--out", tmp_path / "m.toml"])
    assert res.code == 2 and "static" in res.err
    pair = res.err.split("(spread, ")[1].split(")")[0].split("-")
    assert len(pair) == 2 and pair[0] != pair[1]


def test_metres_labelled_mm_is_one_message_about_units(run, corpus, tmp_path):
    """A file in metres that says mm: every marker within a millimetre of every other, said once as a units
    problem (it was a list of 45 'markers coincide: one marker under two labels?')."""
    from identcheck.trial import Trial

    t = Trial.from_file(corpus / "leg.trc")
    path = tmp_path / "metres.trc"
    Trial(t.as_array() / 1000.0, t.labels, t.rate_hz).to_file(path)
    res = run(["fit", LEG, path, "--json"])
    assert res.code == 2 and "metres in a file that says mm" in res.err and "two labels" not in res.err


def test_a_label_too_long_for_c3d_is_refused_before_writing(tmp_path):
    """C3D stores a label in at most 255 bytes: a longer one was written, and the file did not read back."""
    from identcheck.errors import InputError
    from identcheck.trial import Trial

    long = "M" * 300
    t = Trial(np.zeros((3, 2, 3)) + 1.0, ["A", long], 100.0)
    with pytest.raises(InputError, match="300 bytes long; a C3D file stores at most 255"):
        t.to_file(tmp_path / "long.c3d")
    assert not (tmp_path / "long.c3d").exists()
    t.to_file(tmp_path / "long.trc")
    assert Trial.from_file(tmp_path / "long.trc").labels == ("A", long)


def test_degenerate_data_with_json_is_still_one_document(run, corpus, tmp_path):
    """identify on a static knee trial stops on degenerate data (exit 1, a negative answer): with --json it printed
    nothing on stdout, against the contract's one document; now a document saying so, naming the file."""
    from fuzz_support import KNEE
    from identcheck.trial import Trial

    t = Trial.from_file(corpus / "knee.trc")
    xyz = t.as_array()
    xyz[:] = xyz[0]
    path = tmp_path / "still.trc"
    Trial(xyz, t.labels, t.rate_hz).to_file(path)
    res = run(["identify", KNEE, path, "--json"])
    doc = json.loads(res.out)
    assert res.code == 1 and doc["ok"] is False and str(path) in doc["degenerate"]
