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


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 6), min_size=2, max_size=6), st.integers(0, 2**16), st.booleans(), st.booleans())
def test_misplaced_markers_are_the_ones_moved(sizes, seed, loose, merge):
    """A true grouping, then a found one with some markers moved to another segment, a loose marker put in a
    segment, or two whole segments merged: the misplaced markers are exactly the moved ones (for a merge, the
    smaller segment's), and they count as reported when, and only when, the report names them all."""
    import random
    rng = random.Random(seed)
    segments = {f"S{k}": [f"S{k}M{i}" for i in range(n)] for k, n in enumerate(sizes)}
    truth = {"segments": segments, "unattached_markers": ["L0"] if loose else []}
    found = {f"g{k}": list(ms) for k, ms in enumerate(segments.values())}
    expected = set()
    if merge:
        big, small = sorted(range(len(sizes)), key=lambda k: (-sizes[k], k))[:2]
        found[f"g{big}"] += found.pop(f"g{small}")
        expected = set(segments[f"S{small}"])
    else:
        donors = [k for k, n in enumerate(sizes) if n >= 3 and sizes[(k + 1) % len(sizes)] >= 2]
        if donors:                       # a donor that keeps its majority, a recipient that keeps its own
            k = rng.choice(donors)
            m = found[f"g{k}"].pop()
            found[f"g{(k + 1) % len(sizes)}"].append(m)
            expected = {m}
    unassigned = []
    if loose:
        if rng.random() < 0.5:
            found[next(iter(found))].append("L0")
            expected.add("L0")
        else:
            unassigned = ["L0"]
    doc = {"segments": found, "unassigned_markers": unassigned, "cannot_place": [], "grouping": {"widened": {}},
           "may_be_two_segments": [], "markers_on_joints": []}
    assert bench.misplaced_markers(truth, doc) == expected
    assert not expected & bench.named_in_reports(doc)
    doc["markers_on_joints"] = [{"marker": m} for m in expected]
    assert expected <= bench.named_in_reports(doc)
