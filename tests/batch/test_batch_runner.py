"""identcheck.batch.runner without a cluster: a finished job is saved (JSON, then its record) and a failed one,
even one Dask itself reports (a killed worker), is an error row that removes what an earlier run left for it."""
import json
from pathlib import Path

from identcheck.batch import runner
from identcheck.batch.inputs import resolve
from identcheck.batch.store import Store, input_hash

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "diagnose_leg.toml"


class Finished:
    """A stand-in for a Dask future that has finished (with a result or an exception)."""

    def __init__(self, result=None, exc=None):
        self._result, self._exc, self.released = result, exc, False

    def result(self):
        if self._exc:
            raise self._exc
        return self._result

    def release(self):
        self.released = True


class KilledWorker(Exception):
    """As distributed raises when a task's worker died too often."""


def test_finish_saves_a_done_job_and_turns_a_lost_one_into_an_error_row(tmp_path):
    trial = tmp_path / "a.trc"
    trial.write_bytes(b"x")
    (job,) = resolve("fit", [str(MODEL), str(trial)])
    store = Store(tmp_path / "out")
    store.prepare()
    sha = input_hash(job.input_files)
    text = json.dumps({"joints": {"hip": {"unique": True}}, "warnings": []}, indent=2) + "\n"
    done = Finished({"status": "done", "text": text, "ok": True, "error": None, "seconds": 1.25, "warnings": []})
    (row,) = runner._finish(store, job, sha, "9.9", done)
    assert done.released and row["status"] == "done" and row["joint"] == "hip" and row["json"] == f"{job.name}.json"
    assert store.json_path(job).read_text() == text
    record = store.done(job, sha, "9.9")
    assert record["seconds"] == 1.25 and record["ok"] is True and record["settings"] == dict(job.settings)

    lost = Finished(exc=KilledWorker("Attempted to run task on 3 different workers; all died"))
    (row,) = runner._finish(store, job, sha, "9.9", lost)
    assert row["status"] == "error" and row["error"] == "KilledWorker: Attempted to run task on 3 different workers; " \
                                                         "all died"
    assert not store.json_path(job).exists() and store.done(job, sha, "9.9") is None
