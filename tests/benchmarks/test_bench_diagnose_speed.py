"""benchmarks/bench_diagnose_speed.py on a folder of two small simulated trials (one clean, one with an outlier
burst) against HEAD: both versions run, their reports agree, the summary has both clocks, results.json's other
keys are kept; a folder without trials is refused by name."""
import json
import shutil
import sys
from pathlib import Path

import pytest

from identcheck import api

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_diagnose_speed")
MODEL = ROOT / "examples" / "diagnose_leg.toml"


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs the git checkout")
def test_both_versions_agree_on_two_trials(tmp_path, capsys):
    folder = tmp_path / "trials"
    folder.mkdir()
    for stem, effect in (("clean", None), ("spikes", "outliers")):
        api.simulate(MODEL, folder / f"{stem}.trc", seed=2, n_frames=200, noise_mm=0.5, effect=effect)
        shutil.copy(MODEL, folder / f"{stem}.toml")
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main([str(folder), "--baseline", "HEAD", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    doc = data["diagnose_speed"]
    assert doc["n"] == 2 and doc["differ"] == 0
    assert all(r["agree"] and "error" not in r["current"] for r in doc["rows"])
    assert {r["trial"]: [e[0] for e in r["current"]["effects"]] for r in doc["rows"]}["clean.trc"] == []
    assert set(doc["summary"]) == {"wall_s", "cpu_s"} and doc["summary"]["cpu_s"]["max"]["current"] > 0
    assert "reports differ on 0 of 2 trials" in capsys.readouterr().out


def test_a_folder_without_trials_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="no .trc or .c3d trial"):
        bench.main([str(tmp_path), "--baseline", "HEAD", "--out", str(tmp_path / "r.json")])
