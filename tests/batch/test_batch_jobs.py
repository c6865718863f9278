"""identcheck.batch.jobs in this process: a job's outcome is a plain dict; a failure is its clear message (an
InputError's own, else type and message), never a traceback; the call is the CLI's; BLAS runs on one thread."""
import json
import warnings
from pathlib import Path

from identcheck.batch import jobs
from identcheck.batch.inputs import resolve
from identcheck.errors import IdentifiabilityWarning, InputError

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "diagnose_leg.toml"


class Answer:
    """A stand-in result: the verb's JSON and verdict."""

    def __init__(self, ok=True):
        self.ok = ok

    def to_dict(self):
        return {"joints": {"hip": {"unique": self.ok}}, "warnings": []}


def _job(tmp_path, verb="fit"):
    trial = tmp_path / "a.trc"
    trial.write_bytes(b"")
    return resolve(verb, [str(MODEL), str(trial)], frames="2:9")[0]


def test_a_done_job_returns_the_verbs_json_text_and_verdict(tmp_path):
    seen = {}

    def verb(model, trial, frames=None):
        seen.update(model=model, trial=trial, frames=frames)
        warnings.warn("nearly coplanar", IdentifiabilityWarning)
        warnings.warn("library chatter", DeprecationWarning)
        return Answer(ok=False)

    job = _job(tmp_path)
    out = jobs.run_job(job, verb)
    assert seen == {"model": job.model, "trial": job.trial, "frames": "2:9"}
    assert out["status"] == "done" and out["ok"] is False and out["error"] is None and out["seconds"] >= 0
    assert out["text"].endswith("}\n") and json.loads(out["text"]) == Answer(False).to_dict()
    assert out["warnings"] == ["nearly coplanar"]
    json.dumps(out)                                       # plain: nothing but JSON values crosses the wire


def test_failures_are_one_clear_line_not_a_traceback(tmp_path):
    job = _job(tmp_path)

    def bad_file(*a, **k):
        raise InputError(["truncated header: only 1 line(s)"], source="a.trc")

    def bug(*a, **k):
        raise ZeroDivisionError("a bug")

    def silent(*a, **k):
        raise KeyError

    for verb, msg in ((bad_file, "a.trc: truncated header: only 1 line(s)"), (bug, "ZeroDivisionError: a bug"),
                      (silent, "KeyError")):
        out = jobs.run_job(job, verb)
        assert out["status"] == "error" and out["error"] == msg and out["text"] is None and out["ok"] is None
        assert "Traceback" not in out["error"]
        json.dumps(out)


def test_blas_runs_on_one_thread_inside_a_job(tmp_path):
    from threadpoolctl import threadpool_info

    def verb(*a, **k):
        assert {i["num_threads"] for i in threadpool_info()} <= {1}
        return Answer()

    import numpy  # noqa: F401  (load a BLAS, so that there is a pool to limit)
    assert jobs.run_job(_job(tmp_path), verb)["status"] == "done"


def test_plan_jobs_pass_the_cli_options():
    calls = []

    def plan(model, **kw):
        calls.append(kw)
        return type("P", (), {"all_identifiable": True, "to_dict": lambda self: {}})()

    (fast,) = resolve("plan", [str(MODEL)], fast=True)
    (swept,) = resolve("plan", [str(MODEL)], noise_mm=0.5, motion="flexion", frames=200, seed=3)
    for job in (fast, swept):
        assert jobs.run_job(job, plan)["ok"] is True
    assert calls[0] == {"seed": 0, "motion": False, "robust": False}
    assert calls[1] == {"seed": 3, "motion": True, "robust": True, "noise_mm": 0.5, "practical_motion": "flexion",
                        "frames": 200}
