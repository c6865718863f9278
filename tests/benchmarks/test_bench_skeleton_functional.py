"""benchmarks/bench_skeleton_functional.py on a folder in the functional generator's output format, made here from
identcheck's own simulator: two segments joined by a ball joint that moves. The moving joint is found and typed,
nothing mixes its sides, and results.json's other keys are kept."""
import json
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
bench = pytest.importorskip("bench_skeleton_functional")
from strategies_skeleton import make_case  # noqa: E402


def test_benchmark_on_generator_format(tmp_path, capsys):
    folder = tmp_path / "trials"
    folder.mkdir()
    case = make_case(5, 2, counts=[4, 4], parents=[0], types=["spherical"], noise_mm=0.2, n_frames=300)
    case.trial.to_file(folder / "trial_0000.trc")
    truth = {"segments": case.segments, "root": "s0", "units": [["s0"], ["s1"]], "moving_joints": ["j1"],
             "joints": [{"name": "j1", "parent": "s0", "child": "s1", "type": "spherical", "moving": True}],
             "noise": {"sigma_mm": 0.2, "kind": "white"}}
    (folder / "trial_0000.truth.json").write_text(json.dumps(truth))
    (folder / "index.json").write_text(json.dumps({"generator": "test", "seed": 0, "n": 1, "trials": [
        {"id": "trial_0000", "trc": "trial_0000.trc", "truth": "trial_0000.truth.json", "categories": ["hip"]}]}))
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main([str(folder), "--out", str(out), "--key", "k"]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    (row,) = data["k"]["rows"]
    (moving,) = row["moving"]
    assert moving["child_whole"] and moving["parent_whole"] and moving["joint_found"] and moving["type_right"]
    assert moving["leak"] is False and row["all_found"]
    assert data["k"]["summary"]["by_moving_joint"]["j1"]["joint_found"] == 1.0
    assert "found%" in capsys.readouterr().out
