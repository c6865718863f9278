"""benchmarks/bench_skeleton.py on a folder in the held-out generator's output format (index.json, TRC,
truth.json), made here from identcheck's own simulator: rows, summary, table, and results.json's other keys
kept."""
import json
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
bench = pytest.importorskip("bench_skeleton")
from strategies_skeleton import make_case  # noqa: E402


def test_benchmark_on_generator_format(tmp_path, capsys):
    folder = tmp_path / "trials"
    folder.mkdir()
    trials = []
    for k, (seed, loose) in enumerate([(3, 0), (4, 1)]):
        case = make_case(seed, 3, noise_mm=0.3, loose=loose, n_frames=200)
        stem = f"trial_{k:04d}"
        case.trial.to_file(folder / f"{stem}.trc")
        truth = {"segments": case.segments, "root": "s0", "unattached_markers": case.loose,
                 "joints": [{"name": f"J{i}", "parent": sorted(e)[0], "child": sorted(e)[1], "type": t}
                            for i, (e, t) in enumerate(case.types.items())]}
        (folder / f"{stem}.truth.json").write_text(json.dumps(truth))
        trials.append({"id": stem, "trc": f"{stem}.trc", "truth": f"{stem}.truth.json",
                       "categories": ["random"] + (["unattached_marker"] if loose else []), "params": {}})
    (folder / "index.json").write_text(json.dumps({"generator": "test", "seed": 0, "n": 2, "trials": trials}))
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main([str(folder), "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    summary = data["skeleton"]["summary"]
    assert summary["all"]["trials"] == 2 and summary["all"]["grouping_exact"] == 1.0
    assert summary["all"]["tree_exact"] == 1.0 and summary["all"]["types_right"] == 1.0
    assert set(summary["by_category"]) == {"random", "unattached_marker"}
    assert "group%" in capsys.readouterr().out
