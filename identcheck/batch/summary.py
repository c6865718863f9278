"""The batch's summary table: one row per job x joint (one row for a job that failed), as CSV while the jobs
finish, then as ``summary.csv`` and ``summary.parquet`` in job order.

Rows are made from the job's JSON document (the verb's own), so a job skipped on resume gives the same row as
when it ran. Nested values (marker distances, their intervals, the adopted effects, warnings) are JSON text, one
cell each, so the CSV and the Parquet file hold the same columns.
"""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from identcheck.io.atomic import atomic_write

COLUMNS = (
    "job", "verb", "trial", "model", "frames", "motion",
    "joint", "type", "case", "estimator", "identifiable", "unique", "practical",
    "marker_distances", "marker_distances_ci95", "rms_residual", "uncertainty_mm",
    "noise_mm", "effects", "gap_before", "gap_after",
    "ok", "status", "error", "warnings", "seconds",
    "identcheck_version", "settings_hash", "input_hash", "json",
)
"""The summary's columns, in order:

job, verb, trial, model
    the job's name (its JSON is ``<job>.json``, column ``json``), the verb and its input files
frames, motion
    ``fit`` / ``diagnose``: the frame range (empty: all); ``plan``: the predicted capture's frames and motion
joint, type, case, estimator, identifiable, unique
    per joint, as in the verb's JSON (``estimator``: ``fit`` only)
practical
    the practical verdict (``determined``, ``ambiguous``, ``undetermined``) where the verb gives one
marker_distances, marker_distances_ci95
    JSON objects: marker -> mm, marker -> [lo, hi] (95 %)
rms_residual, uncertainty_mm
    mm, per joint
noise_mm
    the noise: estimated from the trial (``fit``, ``diagnose``: sigma per coordinate) or assumed (``plan``)
effects, gap_before, gap_after
    ``diagnose``: the adopted effects (a JSON list of names, most important first) and the gap in mm
ok
    the verb's answer: true where ``identcheck VERB`` exits 0, false where it exits 1 (not unique, not
    identifiable, gap not explained), empty on error
status, error
    ``done`` (ran now), ``skipped`` (done by an earlier run with the same inputs, settings and version) or
    ``error``, with the message (an ``InputError``'s own, else the exception's type and message)
warnings
    JSON list: the JSON's ``warnings`` messages (``fit``) and the identifiability warnings raised
seconds
    wall time of the verb's call (for a skipped job: of the run that made its JSON)
identcheck_version, settings_hash, input_hash
    what the job's answer depends on besides the code: the SHA-256 of its settings and of its input files
"""
STATUSES = ("done", "skipped", "error")
FLOATS = ("rms_residual", "uncertainty_mm", "noise_mm", "gap_before", "gap_after", "seconds")
BOOLEANS = ("identifiable", "unique", "ok")
"""Typed columns (floats with NaN, booleans with NA); the others are text: every batch writes the same types,
whatever its verb, so that summaries of several batches concatenate."""


def job_rows(job, doc: dict | None, outcome: dict, input_sha256: str | None, version: str, json_name: str | None):
    """The rows of one job: one per joint of its JSON document `doc`, or one (no joint) when it failed.

    Parameters
    ----------
    job : identcheck.batch.inputs.Job
    doc : dict or None
        The verb's JSON document; None when the job failed.
    outcome : dict
        ``status``, ``ok``, ``error``, ``seconds``, ``warnings`` (see :func:`identcheck.batch.jobs.run_job`).
    """
    s = job.settings
    common = {
        "job": job.name, "verb": job.verb, "trial": job.trial, "model": job.model,
        "frames": None if s.get("frames") is None else str(s["frames"]),
        "motion": s.get("motion"),
        "ok": outcome.get("ok"), "status": outcome["status"], "error": outcome.get("error"),
        "seconds": None if outcome.get("seconds") is None else round(float(outcome["seconds"]), 3),
        "identcheck_version": version, "settings_hash": job.settings_hash, "input_hash": input_sha256,
        "json": json_name,
    }
    if doc is None:
        return [_row(common, warnings=_json(list(outcome.get("warnings") or [])) or None)]
    top = _top(job, doc)
    said = [w.get("message", str(w)) if isinstance(w, dict) else str(w) for w in doc.get("warnings", [])]
    warned = said + [w for w in outcome.get("warnings") or [] if w not in said]
    common.update(top, warnings=_json(warned))
    rows = []
    for name, j in (doc.get("joints") or {}).items():
        rows.append(_row(common, joint=name, type=j.get("type"), case=j.get("case"), estimator=j.get("estimator"),
                         identifiable=j.get("identifiable"), unique=j.get("unique"),
                         practical=(j.get("practical") or {}).get("verdict"),
                         marker_distances=_json(j.get("marker_distances")),
                         marker_distances_ci95=_json(j.get("marker_distances_ci95")),
                         rms_residual=j.get("rms_residual"), uncertainty_mm=j.get("uncertainty_mm")))
    return rows or [_row(common)]


def _top(job, doc) -> dict:
    """The job-level cells taken from the verb's document: noise, effects, gaps."""
    if job.verb == "plan":
        return {"noise_mm": job.settings.get("noise_mm")}
    noise = doc.get("noise_sigma_mm")
    if noise is None and isinstance(doc.get("noise"), dict):
        noise = doc["noise"].get("sigma_mm")
    top = {"noise_mm": noise}
    if job.verb == "diagnose":
        top.update(effects=_json([e.get("name") for e in doc.get("effects", [])]),
                   gap_before=doc.get("gap_before"), gap_after=doc.get("gap_after"))
    return top


def _row(common: dict, **cells) -> dict:
    row = dict.fromkeys(COLUMNS)
    row.update(common)
    row.update(cells)
    return row


def _json(value):
    """A nested value as compact JSON text (None stays None)."""
    return None if value is None else json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=True)


class Stream:
    """``summary.csv`` written as the jobs finish (a header, then each job's rows appended and flushed), so that
    the table can be followed during a long batch; :func:`write` replaces it by the final one in job order."""

    def __init__(self, out):
        self.path = Path(out) / "summary.csv"
        self._fh = None

    def __enter__(self):
        self._fh = open(self.path, "w", newline="", encoding="utf-8")
        self._writer = csv.DictWriter(self._fh, fieldnames=COLUMNS)
        self._writer.writeheader()
        self._fh.flush()
        return self

    def add(self, rows) -> None:
        self._writer.writerows(rows)
        self._fh.flush()

    def __exit__(self, *exc):
        self._fh.close()
        return False


def table(rows):
    """The rows as a pandas DataFrame with :data:`COLUMNS` (typed: :data:`FLOATS`, :data:`BOOLEANS`, text), in
    the given order."""
    import pandas as pd

    df = pd.DataFrame.from_records(list(rows), columns=list(COLUMNS))
    types = {c: "float64" if c in FLOATS else "boolean" if c in BOOLEANS else "string" for c in COLUMNS}
    return df.astype(types)


def write(df, out) -> tuple:
    """Write `df` as ``OUT/summary.csv`` and ``OUT/summary.parquet`` (each atomically); returns both paths."""
    out = Path(out)
    text = io.StringIO()
    df.to_csv(text, index=False)
    csv_path = atomic_write(out / "summary.csv", text.getvalue().encode("utf-8"))
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return csv_path, atomic_write(out / "summary.parquet", buf.getvalue())


def counts(df, out=None) -> dict:
    """Jobs by status and the failed ones with their messages (one entry per job, not per row).

    Returns
    -------
    dict
        ``jobs``, ``done``, ``skipped``, ``failed`` (counts), ``negative`` (jobs whose verb answered no),
        ``errors`` (``[{"job", "trial", "model", "error"}]``), and ``summary`` (the two files) when `out` is given.
    """
    import pandas as pd

    per_job = df.drop_duplicates("job")
    n = {s: int((per_job["status"] == s).sum()) for s in STATUSES}
    doc = {"jobs": len(per_job), "done": n["done"], "skipped": n["skipped"], "failed": n["error"],
           "negative": int((per_job["ok"] == False).fillna(False).sum()),  # noqa: E712  (NA: failed, not no)
           "errors": [{k: None if pd.isna(r[k]) else str(r[k]) for k in ("job", "trial", "model", "error")}
                      for r in per_job[per_job["status"] == "error"].to_dict("records")]}
    if out is not None:
        doc["summary"] = [str(Path(out) / "summary.csv"), str(Path(out) / "summary.parquet")]
    return doc


def exit_code(df) -> int:
    """How many jobs failed, in the codes of CONTRACT.md: 0 none, 1 some, 2 all (docs/batch.md)."""
    per_job = df.drop_duplicates("job")
    failed = int((per_job["status"] == "error").sum())
    return 0 if failed == 0 else 2 if failed == len(per_job) else 1
