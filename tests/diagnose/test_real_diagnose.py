"""`identcheck diagnose` on a measured recording (not a simulation).

The smallest real trial diagnose accepts: the OpenSim gait example (opensim_subject01_walk1.trc, one
stride at 60 Hz, 151 frames, three markers on each of pelvis, right thigh and right shank) with the
dense leg model examples/real_walk_leg.toml. There is no ground truth, so the checks are on what
must hold whatever the subject: the contract's JSON keys, the gaps shrinking step by step and
chaining, a positive noise floor, an untouched input file, and clear input errors.

The full run goes through ``python -m identcheck diagnose --json`` in a subprocess with one BLAS
thread: the fits are many small dense solves, for which BLAS threads cost more wall time than they
save on a busy machine.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from identcheck import cli
from identcheck.diagnose.workflow import diagnose
from identcheck.io.model import Model
from identcheck.trial import Trial
from real_data import real_file

ROOT = Path(__file__).resolve().parents[2]
TRIAL = real_file("opensim_subject01_walk1.trc")
MODEL = ROOT / "examples" / "real_walk_leg.toml"
EFFECT_NAMES = {"soft_tissue", "marker_slip", "marker_swap", "joint_translation", "extra_dof", "time_offset",
                "outliers", "spatial_distortion"}

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not TRIAL.exists(), reason=f"real data not found: {TRIAL}")]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def run():
    """(JSON document, stderr, input hash before, input hash after) of one CLI run."""
    before = _sha256(TRIAL)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    proc = subprocess.run([sys.executable, "-m", "identcheck", "diagnose", str(MODEL), str(TRIAL), "--json"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode in (0, 1), proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    return json.loads(proc.stdout), proc.stderr, before, _sha256(TRIAL)


def test_contract_keys(run):
    doc = run[0]
    for key in ("noise_floor", "gap_before", "gap_after", "effects", "joints"):
        assert key in doc, key
    assert set(doc["joints"]) == {"hip_r", "knee_r"}
    for e in doc["effects"]:
        assert set(e) >= {"name", "where", "gap_before", "gap_after"}, e
        assert e["name"] in EFFECT_NAMES, e["name"]
        assert isinstance(e["where"], dict)
    for j in doc["joints"].values():
        assert {"type", "marker_distances", "rms_residual"} <= set(j)


def test_gaps(run):
    doc = run[0]
    assert doc["noise_floor"] > 0
    assert doc["gap_before"] > 0
    assert doc["gap_after"] <= doc["gap_before"]
    effects = doc["effects"]
    for e in effects:
        assert e["gap_after"] <= e["gap_before"], e
    for prev, e in zip(effects, effects[1:]):
        assert e["gap_before"] == pytest.approx(prev["gap_after"], abs=1e-6), (prev, e)
    if effects:
        assert effects[0]["gap_before"] == pytest.approx(doc["gap_before"], abs=1e-6)
        assert effects[-1]["gap_after"] == pytest.approx(doc["gap_after"], abs=1e-6)
    else:
        assert doc["gap_after"] == pytest.approx(doc["gap_before"], abs=1e-6)


def test_a_gait_trial_is_not_rigid(run):
    """Skin markers in gait move on the bone: the rigid-joint gap is well above the noise floor and
    diagnose names at least one effect for it."""
    doc = run[0]
    assert doc["gap_before"] > 2 * doc["noise_floor"]
    assert doc["effects"], "a walking trial with skin markers explained by a rigid model plus noise?"


def test_input_file_unchanged(run):
    _, _, before, after = run
    assert before == after


def test_two_marker_root_is_started_through_its_joint(tmp_path):
    """The pelvis with two markers (it had been refused: "diagnose needs three or more on every segment") is posed
    through the hip, its fit started from the closed-form joints: the real walk is diagnosed, the effects it names are
    named ones and close part of the gap, and both joints carry a verdict."""
    text = MODEL.read_text().replace('["R.ASIS", "L.ASIS", "V.Sacral"]', '["R.ASIS", "L.ASIS"]')
    assert '["R.ASIS", "L.ASIS"]' in text
    (tmp_path / "two.toml").write_text(text)
    rep = diagnose(Model.from_toml(tmp_path / "two.toml"), Trial.from_file(TRIAL)).to_dict()
    assert {e["name"] for e in rep["effects"]} <= EFFECT_NAMES
    assert rep["gap_after"] < rep["gap_before"]
    assert {j: v["practical"]["verdict"] in ("determined", "ambiguous", "undetermined")
            for j, v in rep["joints"].items()} == {"hip_r": True, "knee_r": True}


def test_cli_missing_marker(tmp_path, capsys):
    trial = Trial.from_file(TRIAL)
    gone = "R.Thigh.Rear"
    trial.select([m for m in trial.labels if m != gone]).to_file(tmp_path / "walk_missing.trc")
    rc = cli.main(["diagnose", str(MODEL), str(tmp_path / "walk_missing.trc")])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert gone in err
    assert "Traceback" not in err
