"""identcheck.batch.summary: one row per job x joint from the verb's own JSON, an error row per failed job, the
same columns and types in CSV and Parquet, and the exit code from the number of failed jobs."""
import json
from pathlib import Path

import pytest

from identcheck.batch import summary
from identcheck.batch.inputs import resolve

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "diagnose_leg.toml"

FIT = {"joints": {
    "hip": {"type": "spherical", "case": "spherical(3,3)", "estimator": "whole-tree maximum likelihood",
            "identifiable": True, "unique": True, "marker_distances": {"RGT": 404.1},
            "marker_distances_ci95": {"RGT": [403.9, 404.3]}, "rms_residual": 0.67, "uncertainty_mm": 0.11,
            "practical": {"verdict": "determined"}},
    "knee": {"type": "revolute", "case": "revolute(4,3)", "estimator": "whole-tree maximum likelihood",
             "identifiable": True, "unique": False, "marker_distances": {"RANK": None},
             "marker_distances_ci95": {}, "rms_residual": 0.73, "uncertainty_mm": None,
             "practical": {"verdict": "undetermined"}}},
    "noise": {"sigma_mm": 0.5}, "warnings": [{"message": "labels RKNE and RTHI swapped in frames 3-9"}]}
DIAGNOSE = {"joints": {"hip": {"type": "spherical", "unique": True, "marker_distances": {"RGT": 1.0}}},
            "noise_sigma_mm": 0.52, "gap_before": 3.1, "gap_after": 0.7,
            "effects": [{"name": "marker_slip"}, {"name": "soft_tissue"}]}


def _jobs(tmp_path, verb="fit", n=2):
    for k in range(n):
        (tmp_path / f"t{k}.trc").write_bytes(b"")
    return resolve(verb, [str(MODEL)] + [str(tmp_path / f"t{k}.trc") for k in range(n)])


def _done(ok=True, seconds=1.5, warned=()):
    return {"status": "done", "ok": ok, "error": None, "seconds": seconds, "warnings": list(warned)}


def test_rows_per_job_and_joint_with_the_contract_values(tmp_path):
    job, other = _jobs(tmp_path)
    rows = summary.job_rows(job, FIT, _done(False, warned=["nearly coplanar"]), "ab" * 32, "9.9", "x.json")
    assert [r["joint"] for r in rows] == ["hip", "knee"] and all(tuple(r) == summary.COLUMNS for r in rows)
    hip, knee = rows
    assert hip["estimator"] == "whole-tree maximum likelihood" and hip["practical"] == "determined"
    assert json.loads(hip["marker_distances"]) == {"RGT": 404.1}
    assert json.loads(hip["marker_distances_ci95"]) == {"RGT": [403.9, 404.3]}
    assert hip["noise_mm"] == 0.5 and hip["rms_residual"] == 0.67 and knee["unique"] is False
    assert json.loads(hip["warnings"]) == ["labels RKNE and RTHI swapped in frames 3-9", "nearly coplanar"]
    assert hip["settings_hash"] == job.settings_hash and hip["identcheck_version"] == "9.9"
    assert hip["ok"] is False and hip["status"] == "done" and hip["error"] is None
    (err,) = summary.job_rows(other, None, {"status": "error", "ok": None, "error": "t1.trc: not a TRC file",
                                            "seconds": 0.1, "warnings": []}, None, "9.9", None)
    assert err["joint"] is None and err["error"] == "t1.trc: not a TRC file" and err["json"] is None


def test_diagnose_rows_carry_the_effects_and_gaps(tmp_path):
    (job,) = _jobs(tmp_path, "diagnose", 1)
    (row,) = summary.job_rows(job, DIAGNOSE, _done(), "h", "9.9", "x.json")
    assert json.loads(row["effects"]) == ["marker_slip", "soft_tissue"]
    assert (row["gap_before"], row["gap_after"], row["noise_mm"]) == (3.1, 0.7, 0.52) and row["estimator"] is None


def test_csv_and_parquet_hold_the_same_typed_table(tmp_path):
    a, b = _jobs(tmp_path)
    rows = summary.job_rows(a, FIT, _done(), "h", "9.9", "a.json") + \
        summary.job_rows(b, None, {"status": "error", "ok": None, "error": 'bad, "quoted"\nline two', "seconds": 0.0,
                                   "warnings": []}, "h", "9.9", None)
    df = summary.table(rows)
    csv_path, pq_path = summary.write(df, tmp_path)
    back = pd.read_parquet(pq_path)
    assert list(back.columns) == list(summary.COLUMNS) and len(back) == 3
    assert str(back["rms_residual"].dtype) == "float64" and str(back["ok"].dtype) == "boolean"
    assert str(back["error"].dtype).startswith("str") and back["error"].iloc[2] == 'bad, "quoted"\nline two'
    from_csv = pd.read_csv(csv_path, keep_default_na=False)
    assert list(from_csv["job"]) == list(back["job"]) and from_csv["error"].iloc[2] == 'bad, "quoted"\nline two'
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("summary")) == ["summary.csv",
                                                                                         "summary.parquet"]


@pytest.mark.parametrize("statuses, code", [(["done", "skipped"], 0), (["done", "error", "skipped"], 1),
                                            (["error", "error"], 2), (["error"], 2), (["skipped"], 0)])
def test_exit_code_says_how_many_jobs_failed(tmp_path, statuses, code):
    jobs = _jobs(tmp_path, n=len(statuses))
    rows = []
    for job, status in zip(jobs, statuses):
        if status == "error":
            rows += summary.job_rows(job, None, {"status": "error", "ok": None, "error": "x", "seconds": 0,
                                                 "warnings": []}, "h", "9.9", None)
        else:
            rows += summary.job_rows(job, FIT, {**_done(ok=status == "done"), "status": status}, "h", "9.9", "j")
    df = summary.table(rows)
    assert summary.exit_code(df) == code
    doc = summary.counts(df, tmp_path)
    assert (doc["jobs"], doc["failed"]) == (len(statuses), statuses.count("error"))
    assert doc["negative"] == statuses.count("skipped") and len(doc["errors"]) == doc["failed"]
    json.dumps(doc)
