"""The batch's output folder: everything a batch writes is in it, and each file appears whole or not at all.

Layout of ``OUT/``::

    <job>.json                  the verb's JSON, byte for byte what ``identcheck VERB ... --json`` prints
    summary.csv, summary.parquet one row per job x joint (:mod:`identcheck.batch.summary`)
    .identcheck-batch/<job>.json what the job's JSON was computed from: the SHA-256 of its input files, the
                                settings hash, the identcheck version, the JSON's own SHA-256 (resume)
    .identcheck-batch/dask/     the local cluster's scratch space while it runs (removed after)

Each file is written to a temporary name in its folder and moved into place with ``os.replace`` (atomic on one
file system): a batch killed at any instant leaves whole JSONs (and at most a ``.tmp-*`` file and the scratch space,
removed by the next run). A job is done when its record matches the inputs, settings and version of this run and its JSON
still has the bytes recorded; the record is written after the JSON, so a JSON without a record is computed again.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from pathlib import Path

from identcheck.errors import InputError
from identcheck.io.atomic import TMP_PREFIX, atomic_write

STATE = ".identcheck-batch"


def file_sha256(path) -> str:
    """SHA-256 (hex) of a file's bytes, read in blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def input_hash(paths) -> str:
    """SHA-256 (hex) of the input files' bytes in order (model, then trial), each preceded by its length, so
    that no two different sets of files give the same stream.

    Raises
    ------
    OSError
        A file cannot be read.
    """
    h = hashlib.sha256()
    for path in paths:
        data = Path(path).read_bytes()
        h.update(len(data).to_bytes(8, "big"))
        h.update(data)
    return h.hexdigest()


class Store:
    """The output folder of one batch (see the module docstring for its layout)."""

    def __init__(self, out):
        self.out = Path(out)
        self.state = self.out / STATE

    @contextlib.contextmanager
    def locked(self):
        """Hold the output folder for this run alone (an advisory lock on ``.identcheck-batch/lock``, released when
        the run ends or dies): two runs into one folder would each clean the other's temporary files and write a
        summary of their own jobs only, losing the other's rows without a word.

        Raises
        ------
        InputError
            Another run holds the folder (its process id named)."""
        try:
            import fcntl
        except ImportError:             # no advisory locks here (Windows): one run at a time is the user's care
            yield
            return
        self.state.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.state / "lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
                raise InputError([f"another identcheck batch (process {holder}) is writing to this folder; two runs "
                                  "into one output folder would overwrite each other's summary: wait for it to "
                                  "end, or give another --out"], source=str(self.out)) from None
            os.ftruncate(fd, 0)
            os.pwrite(fd, str(os.getpid()).encode(), 0)
            yield
        finally:
            os.close(fd)                # closing releases the lock

    def clean(self) -> None:
        """Remove what a killed run left: temporary files, the local cluster's scratch space (creates nothing)."""
        for folder in (self.out, self.state):
            for stale in folder.glob(f"{TMP_PREFIX}*") if folder.is_dir() else ():
                if stale.is_file():
                    stale.unlink(missing_ok=True)
        shutil.rmtree(self.scratch, ignore_errors=True)

    def prepare(self) -> None:
        """Create the folders."""
        self.state.mkdir(parents=True, exist_ok=True)

    @property
    def scratch(self) -> Path:
        """The local cluster's scratch space (inside the output folder: a batch writes nowhere else)."""
        return self.state / "dask"

    def json_path(self, job) -> Path:
        return self.out / f"{job.name}.json"

    def record_path(self, job) -> Path:
        return self.state / f"{job.name}.json"

    def done(self, job, inputs_sha256: str, version: str) -> dict | None:
        """The record of `job` when its JSON was computed from these inputs, with these settings, by this version
        of identcheck, and is still intact; None when the job must run."""
        try:
            record = json.loads(self.record_path(job).read_text(encoding="utf-8"))
            same = (record.get("input_hash") == inputs_sha256 and record.get("settings_hash") == job.settings_hash
                    and record.get("identcheck_version") == version)
            return record if same and file_sha256(self.json_path(job)) == record.get("json_sha256") else None
        except (OSError, ValueError, AttributeError):
            return None

    def save(self, job, text: str, record: dict) -> dict:
        """Write the job's JSON `text`, then its record (with the JSON's SHA-256 added); returns the record."""
        data = text.encode("utf-8")
        atomic_write(self.json_path(job), data)
        record = {**record, "json_sha256": hashlib.sha256(data).hexdigest()}
        atomic_write(self.record_path(job), (json.dumps(record, indent=1, sort_keys=True) + "\n").encode())
        return record

    def discard(self, job) -> None:
        """Remove the job's JSON and record from an earlier run (the job failed now: they no longer answer it)."""
        self.record_path(job).unlink(missing_ok=True)
        self.json_path(job).unlink(missing_ok=True)

    def read(self, job) -> dict:
        """The job's JSON document."""
        return json.loads(self.json_path(job).read_text(encoding="utf-8"))
