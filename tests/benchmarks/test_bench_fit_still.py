"""benchmarks/bench_fit_still.py on a folder in the near-static generator's output format (index.json, TRC, model,
truth.json), made here from identcheck's own simulator: a static sparse leg is scored as no confidently wrong
joint, its unbounded intervals are stored as strict JSON, and results.json's other keys are kept."""
import json
import shutil
import sys
from pathlib import Path

import pytest

from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_fit_still")


def test_benchmark_on_generator_format(tmp_path, capsys):
    folder = tmp_path / "trials"
    folder.mkdir()
    model = Model.from_toml(ROOT / "examples" / "sparse_leg.toml")
    sim = simulate(model, n_frames=200, seed=2, rom_deg=0.0, noise_mm=0.5)
    sim.trial.to_file(folder / "trial_0000.trc")
    shutil.copy(ROOT / "examples" / "sparse_leg.toml", folder / "trial_0000.toml")
    truth = {"marker_distances": {j: sim.truth.marker_distances(j) for j in model.joints}}
    (folder / "trial_0000.truth.json").write_text(json.dumps(truth))
    entry = {"id": "trial_0000", "motion": "static", "markerset": "sparse", "noise_model": "white",
             "files": {"trc": "trial_0000.trc", "toml": "trial_0000.toml", "truth.json": "trial_0000.truth.json"}}
    (folder / "index.json").write_text(json.dumps({"generator": "test", "seed": 0, "n": 1, "trials": [entry]}))
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main([str(folder), "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    summary = data["fit_still"]["summary"]
    assert summary["static x sparse"]["joints"] == 2 and summary["all"]["confidently_wrong_joints"] == 0
    assert summary["all"]["verdicts"].get("determined", 0) == 0
    assert any(x["half"] is None for x in data["fit_still"]["rows"][0]["rows"])      # unbounded, stored as null
    assert "conf.wrong" in capsys.readouterr().out
