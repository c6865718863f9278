"""The batch on a Dask cluster: resolve the jobs, skip those done by an earlier run, submit the rest one task per
job, write each JSON and its summary rows as it finishes, and return the summary.

The cluster is a :class:`distributed.LocalCluster` of worker processes (one thread each, BLAS and OpenMP limited
to one thread in every worker by the environment set before it starts, and again by ``threadpoolctl`` around
each job), or an existing cluster given by its scheduler's address. No cluster starts when every job is done.
The client writes every file (a remote cluster's workers need only read the inputs, at the same paths).
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import logging
import os
import shutil
import sys
from datetime import datetime, timezone

from identcheck.batch import extra, inputs, jobs, summary
from identcheck.batch.store import Store, input_hash
from identcheck.errors import InputError

ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
              "NUMEXPR_NUM_THREADS", "BLIS_NUM_THREADS", "IDENTCHECK_THREADS")
"""Set to 1 in a local cluster's workers before they start (the BLAS libraries read them when loaded; identcheck's
own profile likelihoods read ``IDENTCHECK_THREADS``): the cluster runs one job per core already."""


def run(verb: str, inputs_, out, *, verbs, model=None, frames=None, noise_mm=None, motion=None, seed: int = 0,
        fast: bool = False, workers: int | None = None, scheduler: str | None = None, dashboard: str = ":8787",
        progress: bool = False):
    """Run a batch (see :func:`identcheck.api.batch` for the parameters); returns the summary DataFrame.

    `verbs` maps each verb name to the function that runs it (the api's ``fit``, ``diagnose``, ``plan``).

    Raises
    ------
    ImportError
        A package of the ``batch`` extra is missing (the message names ``pip install 'identcheck[batch]'``).
    InputError
        Bad inputs (before anything is written), or a scheduler that cannot be reached.
    """
    extra.require()
    todo = inputs.resolve(verb, inputs_, model=model, frames=frames, noise_mm=noise_mm, motion=motion, seed=seed,
                          fast=fast)
    if workers is not None and workers < 1:
        raise InputError([f"--workers {workers}: 1 or more"])
    if workers is not None and scheduler:
        raise InputError(["--workers sizes the local cluster; with --scheduler the cluster's own workers run the "
                          "jobs: give one of them"])
    store = Store(out)
    with store.locked():
        return _run_locked(verb, todo, store, verbs, workers, scheduler, dashboard, progress)


def _run_locked(verb, todo, store, verbs, workers, scheduler, dashboard, progress):
    """:func:`run` once the output folder is held by this run alone."""
    say = _say if progress else (lambda msg: None)
    import identcheck

    version = identcheck.__version__
    rows: dict = {}                   # job name -> its summary rows
    pending = []                      # (job, input hash) to run
    for job in todo:                  # reading only: what an earlier run of this batch has done
        try:
            sha = input_hash(job.input_files)
        except OSError as exc:
            rows[job.name] = summary.job_rows(job, None, jobs.failed(exc), None, version, None)
            continue
        record = store.done(job, sha, version)
        if record is None:
            pending.append((job, sha))
            continue
        outcome = {"status": "skipped", "ok": record.get("ok"), "error": None, "seconds": record.get("seconds"),
                   "warnings": record.get("warnings", [])}
        rows[job.name] = summary.job_rows(job, store.read(job), outcome, sha, version, store.json_path(job).name)
    unreadable = _failed(rows)
    say(f"{_jobs(len(todo))}: {len(rows) - unreadable} done earlier (skipped), {len(pending)} to run"
        + (f", {unreadable} unreadable" if unreadable else ""))
    store.clean()
    with _client(workers, scheduler, dashboard, store.scratch, len(pending)) if pending else \
            contextlib.nullcontext() as client:
        store.prepare()
        with summary.Stream(store.out) as stream:
            stream.add([r for job in todo if job.name in rows for r in rows[job.name]])
            if client is not None:
                say(f"dashboard: {_dashboard(client)}")
                futures = {client.submit(jobs.run_job, job, verbs[verb], pure=False): (job, sha)
                           for job, sha in pending}
                with _bar(verb, len(todo), len(rows), progress) as bar:
                    for future in _as_completed(futures):
                        job, sha = futures.pop(future)
                        rows[job.name] = _finish(store, job, sha, version, future)
                        stream.add(rows[job.name])
                        bar.update(1)
                        bar.set_postfix(failed=_failed(rows), refresh=False)
    df = summary.table(r for job in todo if job.name in rows for r in rows[job.name])
    summary.write(df, store.out)
    doc = summary.counts(df)
    say(f"{_jobs(doc['jobs'])}: {doc['done']} done, {doc['skipped']} skipped, {doc['failed']} failed; "
        f"summary in {store.out / 'summary.csv'} and .parquet")
    return df


def _finish(store, job, sha, version, future) -> list:
    """Save a finished job's JSON and record (or discard a stale one when it failed); its summary rows."""
    try:
        outcome = future.result()
    except (Exception, asyncio.CancelledError, concurrent.futures.CancelledError) as exc:  # a killed worker, ...
        outcome = jobs.failed(exc)
    finally:
        future.release()
    if outcome["status"] != "done":
        store.discard(job)
        return summary.job_rows(job, None, outcome, sha, version, None)
    record = {"job": job.name, "verb": job.verb, "model": job.model, "trial": job.trial,
              "settings": dict(job.settings), "settings_hash": job.settings_hash, "input_hash": sha,
              "identcheck_version": version, "ok": outcome["ok"], "seconds": outcome["seconds"],
              "warnings": outcome["warnings"], "finished": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    store.save(job, outcome["text"], record)
    return summary.job_rows(job, json.loads(outcome["text"]), outcome, sha, version, store.json_path(job).name)


def _jobs(n: int) -> str:
    return f"{n} job" + ("" if n == 1 else "s")


def _failed(rows: dict) -> int:
    return sum(1 for r in rows.values() if r and r[0]["status"] == "error")


def _as_completed(futures):
    from distributed import as_completed

    return as_completed(list(futures))


@contextlib.contextmanager
def _client(workers, scheduler, dashboard, scratch, n_jobs):
    """A Dask client: of the cluster at `scheduler`, or of a new local cluster of worker processes (closed, and
    its scratch space removed, on leaving)."""
    import dask
    from distributed import Client, LocalCluster

    from identcheck.batch.quiet_workers import QuietWorkers

    if scheduler:
        with _quiet_logs():
            try:
                client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError([f"--scheduler {scheduler}: cannot connect ({jobs.message(exc)})"]) from None
            try:
                yield client
            finally:
                client.close()
        return
    n = workers or min(_cpus(), n_jobs)
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **dict.fromkeys(ONE_THREAD, 1)}
    scratch.mkdir(parents=True, exist_ok=True)
    try:
        with _quiet_logs(), dask.config.set({"distributed.nanny.pre-spawn-environ": environ,
                                             "temporary-directory": str(scratch)}):
            try:
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=dashboard,
                                       silence_logs=logging.CRITICAL, local_directory=str(scratch))
            except (RuntimeError, OSError, ValueError) as exc:     # Dask wraps what stopped it in a RuntimeError
                raise InputError([f"the local cluster did not start ({jobs.message(exc.__cause__ or exc)}); "
                                  f"check --dashboard {dashboard} (':0' takes any free port)"]) from None
            client = Client(cluster)
            try:
                client.register_plugin(QuietWorkers())
                yield client
            finally:
                client.close()
                cluster.close()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


@contextlib.contextmanager
def _quiet_logs(level=logging.ERROR):
    """The local cluster's own logging (every worker started, registered, closed) held to `level` while it runs:
    the batch reports its progress itself."""
    loggers = [logging.getLogger(name) for name in ("distributed", "bokeh", "tornado")]
    before = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(level)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, before):
            lg.setLevel(lv)


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _dashboard(client) -> str:
    import importlib.util

    if importlib.util.find_spec("bokeh") is None:
        return "not available (the dashboard needs bokeh: pip install bokeh)"
    return client.dashboard_link


def _bar(verb, total, done, progress):
    """The progress bar on stderr: jobs finished of all, rate, ETA (the skipped ones counted as finished)."""
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="job", desc=f"identcheck batch {verb}", file=sys.stderr,
                disable=not progress, dynamic_ncols=True, smoothing=0.1)


def _say(msg: str) -> None:
    print(f"identcheck batch: {msg}", file=sys.stderr, flush=True)

