"""benchmarks/bench_clean_false_alarms.py: its clean trials carry the noise they say (white, or AR(1) of the stated
lag-1 coefficient, at the stated level), and a run diagnoses every trial and writes its key, keeping the others."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_clean_false_alarms")


def test_the_trials_carry_the_noise_they_state(tmp_path):
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate
    from identcheck.trial import Trial

    model = Model.from_toml(bench.MODEL)
    for t in bench.make_trials(tmp_path, 2, 3000, 40):
        noise = Trial.from_file(t["path"]).as_array() - simulate(model, n_frames=3000, seed=t["seed"]).clean.as_array()
        assert np.std(noise) == pytest.approx(t["sigma_mm"], rel=0.1)
        lag1 = np.corrcoef(noise[1:].ravel(), noise[:-1].ravel())[0, 1]
        assert lag1 == pytest.approx(t["phi"], abs=0.05)


def test_a_run_diagnoses_every_trial(tmp_path):
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--trials", "2", "--frames", "300", "--out", str(out), "--key", "k"]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    s = data["k"]["summary"]["current"]
    assert s["trials"] == 2 and s["white"]["trials"] == 1 and s["ar1"]["trials"] == 1
    assert [r["seed"] for r in data["k"]["rows"]["current"]] == [1000, 1001]
