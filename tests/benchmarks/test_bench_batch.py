"""benchmarks/bench_batch.py --quick: one row per run, the rerun skips every job, other keys of results.json kept."""
import json
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow      # the fast lane (pytest -m 'not slow') leaves these out

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
pytest.importorskip("distributed")
bench = pytest.importorskip("bench_batch")


def test_quick_run_rows_and_json(tmp_path):
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--quick", "--trials", "3", "--frames", "150", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True} and "batch" not in data
    doc = data["batch_quick"]
    assert doc["settings"]["trials"] == 3 and doc["machine"]["nproc"] >= 1
    rows = doc["rows"]
    assert [r["workers"] for r in rows] == [0, 1, 2, 2]
    assert [r["jobs_run"] for r in rows] == [3, 3, 3, 0] and rows[-1]["skipped"] == 3
    assert all(r["wall_s"] > 0 and r["trials_per_min"] > 0 for r in rows) and rows[0]["speedup_vs_serial"] == 1.0
