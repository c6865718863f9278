"""benchmarks/bench_diagnose_heldout.py's summary split by trial category: every single-effect and clean row is
counted once under each key, and a row counts as named first only when its first named effect is the true one."""
import sys
from pathlib import Path

from hypothesis import given, settings, strategies as st

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import bench_diagnose_heldout as bench  # noqa: E402

NAMES = ("outliers", "marker_slip", "soft_tissue")
row = st.fixed_dictionaries({
    "kind": st.sampled_from(["single", "clean"]), "truth": st.sampled_from(NAMES).map(lambda n: [n]),
    "named": st.lists(st.sampled_from(NAMES), max_size=3), "gaps": st.booleans(),
    "layout": st.sampled_from(["clusters", "anatomical"]), "motion": st.sampled_from(["gait", "sit_to_stand"]),
    "noise": st.sampled_from(["white", "ar1"])})


@settings(max_examples=100, deadline=None)
@given(st.lists(row, max_size=30))
def test_each_category_key_partitions_the_rows(rows):
    single = [r for r in rows if r["kind"] == "single"]
    clean = [r for r in rows if r["kind"] == "clean"]
    out = bench.by_category(single, clean)
    for key in ("gaps", "layout", "motion", "noise"):
        parts = [v for k, v in out.items() if k.startswith(key + "=")]
        assert sum(p["single"] for p in parts) == len(single) and sum(p["clean"] for p in parts) == len(clean)
        assert sum(p["named_first"] for p in parts) == sum(bool(r["named"]) and r["named"][0] == r["truth"][0]
                                                          for r in single)
        assert sum(p["nothing_named"] for p in parts) == sum(not r["named"] for r in clean)
