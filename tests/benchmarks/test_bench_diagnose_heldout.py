"""benchmarks/bench_diagnose_heldout.py's summary split by trial category: every single-effect and clean row is
counted once under each key, and a row counts as named first only when its first named effect is the true one."""
import json
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


visible = st.one_of(st.none(), st.floats(min_value=0.0, max_value=1e7, allow_nan=False))
single_row = st.fixed_dictionaries({
    "truth": st.sampled_from(NAMES).map(lambda n: [n]), "named": st.lists(st.sampled_from(NAMES), max_size=3),
    "visible_chi2": visible,
    "indistinguishable": st.lists(st.lists(st.sampled_from(NAMES), max_size=2), max_size=3)})
pair_row = st.fixed_dictionaries({
    "truth": st.lists(st.sampled_from(NAMES), min_size=2, max_size=2, unique=True),
    "named": st.lists(st.sampled_from(NAMES), max_size=3),
    "own_visible_chi2": st.lists(visible, min_size=0, max_size=2),
    "indistinguishable": st.lists(st.lists(st.sampled_from(NAMES), max_size=2), max_size=3)})


@settings(max_examples=100, deadline=None)
@given(st.lists(single_row, max_size=20), st.lists(pair_row, max_size=20))
def test_visibility_bins_count_each_measured_row_once(single, pairs):
    """Every row with its numbers lands in exactly one bin (a pair by the smaller of its effects' own visible χ²),
    and the counts are those of the rows in it: named first / both named, never more when the indistinguishable
    readings are counted too."""
    out = bench.by_visibility(single, pairs)
    measured = [r for r in single if r["visible_chi2"] is not None]
    complete = [r for r in pairs if len(r["own_visible_chi2"]) == 2 and None not in r["own_visible_chi2"]]
    assert sum(b["single"] for b in out) == len(measured)
    assert sum(b["pairs"] for b in out) == len(complete)
    json.dumps(out, allow_nan=False)                 # as results.json is written
    points = bench.pair_points(pairs)                # the figure's row: one point a complete pair, at its weaker
    assert [x for x, _ in points] == [min(r["own_visible_chi2"]) for r in complete]
    assert sum(ok for _, ok in points) == sum(b["both_told_apart"] for b in out)
    for b in out:
        below = float("inf") if b["visible_chi2_below"] is None else b["visible_chi2_below"]
        inside = [r for r in measured if b["visible_chi2_from"] <= r["visible_chi2"] < below]
        assert b["single"] == len(inside)
        assert b["named_first"] == sum(bool(r["named"]) and r["named"][0] == r["truth"][0] for r in inside)
        assert b["named_first"] <= b["named_first_or_indistinguishable"] <= b["single"]
        both = [r for r in complete if b["visible_chi2_from"] <= min(r["own_visible_chi2"]) < below]
        assert b["pairs"] == len(both)
        assert b["both_named"] == sum(all(t in r["named"] for t in r["truth"]) for r in both)
        assert b["both_named"] <= b["both_told_apart"] <= b["pairs"]


def test_an_effect_reported_indistinguishable_from_a_named_one_is_told_apart():
    row = {"named": ["marker_swap", "soft_tissue"], "indistinguishable": [[], ["joint_translation"]]}
    assert bench.told_apart("joint_translation", row) and bench.told_apart("marker_swap", row)
    assert not bench.told_apart("outliers", row)
