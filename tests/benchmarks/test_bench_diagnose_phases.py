"""benchmarks/bench_diagnose_phases.py: its clock charges every second to exactly one step (random nested calls with a
fake clock), and on a small simulated trial the steps' seconds add up to the whole, the rigid start, the detectors and
the final fit are among them, and results.json's other keys are kept."""
import json
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from identcheck import api

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_diagnose_phases")

calls = st.recursive(st.tuples(st.sampled_from("abc"), st.floats(0.0, 5.0), st.just([])),
                     lambda inner: st.tuples(st.sampled_from("abc"), st.floats(0.0, 5.0), st.lists(inner, max_size=3)),
                     max_leaves=12)


@settings(max_examples=200, deadline=None)
@given(st.lists(calls, max_size=4), st.floats(0.0, 5.0))
def test_every_second_goes_to_the_innermost_step(tree, outside):
    """A fake clock advances by each call's own time before its callees; the exclusive seconds charged to each label
    are the sums of its calls' own times, and everything adds up to the clock's whole advance."""
    now = [0.0]
    clock = bench.PhaseClock(clock=lambda: now[0])
    own = {"other": outside}

    def run(call):
        label, self_time, children = call
        clock.enter(label)
        now[0] += self_time
        own[label] = own.get(label, 0.0) + self_time
        for child in children:
            run(child)
        clock.leave()

    clock.start()
    now[0] += outside
    for call in tree:
        run(call)
    seconds = clock.stop()
    assert sum(seconds.values()) == pytest.approx(now[0])
    for label, t in own.items():
        assert seconds.get(label, 0.0) == pytest.approx(t)


def test_a_small_trial_is_split_into_steps(tmp_path):
    folder = tmp_path / "trials"
    folder.mkdir()
    model = ROOT / "examples" / "diagnose_leg.toml"
    (folder / "t.toml").write_text(model.read_text())
    api.simulate(model, folder / "t.trc", seed=3, n_frames=300, noise_mm=0.5)
    out = tmp_path / "results.json"
    out.write_text(json.dumps({"kept": {"x": 1}}))
    res = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_diagnose_phases.py"), str(folder),
                          "--out", str(out), "--key", "phases"], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["kept"] == {"x": 1}
    row = doc["phases"]["rows"][0]
    assert sum(row["phases_s"].values()) == pytest.approx(row["cpu_s"], abs=0.01)
    assert {"rigid start", "detectors", "final fit"} <= set(row["phases_s"])
    assert row["normal_builds"].get("rigid start", 0) > 0
    assert sum(v["share"] for v in doc["phases"]["summary"].values()) == pytest.approx(1.0, abs=1e-3)
