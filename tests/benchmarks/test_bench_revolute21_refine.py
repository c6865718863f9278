"""benchmarks/bench_revolute21_refine.py: the revolute (2,1) least squares of this tree and of a baseline commit run on
the same problems; against itself (HEAD) both find the same best joints, and results.json's other keys are kept."""
import json
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_revolute21_refine")


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs the git checkout")
def test_side_by_side_against_itself(tmp_path, monkeypatch):
    from identcheck.estimate import revolute21

    committed = bench.baseline_module("HEAD")
    monkeypatch.setattr(bench, "baseline_module", lambda rev: revolute21)   # the working tree on both sides
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--baseline", "HEAD", "--problems", "3", "--samples", "60", "--max-nfev", "30",
                       "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    row = data["revolute21_refine"]
    assert row["problems"] == 3 and row["current_worse"] == 0 and row["current_better"] == 0
    assert row["baseline_code"]["as_good_as_truth"] == row["current_code"]["as_good_as_truth"]
    assert hasattr(committed, "fit")                      # the baseline's module is loaded from git
