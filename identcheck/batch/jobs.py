"""One batch job, run in a Dask worker: the verb's call, exactly as the command line makes it, and its JSON text,
exactly as ``identcheck VERB ... --json`` prints it; or the error, as one clear line of text.

The worker returns a plain dict (no result object, no exception crosses the wire): a failure in one job is that
job's error row, and the batch goes on. The verb itself is handed in (:func:`identcheck.api.batch` passes
``api.fit``, ``api.diagnose``, ``api.plan``), so this layer calls the api's verbs without importing the layer
above it.
"""
from __future__ import annotations

import time
import warnings

from identcheck.errors import IdentifiabilityWarning, InputError
from identcheck.report import json_out

VERDICT = {"fit": "ok", "diagnose": "consistent", "plan": "all_identifiable"}
"""The result attribute whose truth makes the verb exit 0 (else 1, a negative answer) on the command line."""


def call(job, verb):
    """`verb` (``api.fit``, ``api.diagnose`` or ``api.plan``) on `job`, with the arguments ``identcheck VERB``
    would pass: ``fit`` / ``diagnose`` the model, the trial and ``--frames``; ``plan`` ``--seed``, ``--fast``,
    ``--noise-mm``, ``--motion`` and ``--frames``."""
    s = job.settings
    if job.verb == "plan":
        kw = {"seed": s["seed"], "motion": not s["fast"], "robust": not s["fast"]}
        if s["noise_mm"] is not None:
            kw.update(noise_mm=s["noise_mm"], practical_motion=s["motion"], frames=s["frames"])
        return verb(job.model, **kw)
    return verb(job.model, job.trial, frames=s["frames"])


def message(exc: BaseException) -> str:
    """The error of a failed job as one readable text, never a traceback: an :class:`InputError`'s own message
    (it names the file, line, marker or frame), otherwise the exception's type and message."""
    if isinstance(exc, InputError):
        return str(exc)
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def failed(exc: BaseException, seconds: float = 0.0, warned=()) -> dict:
    """The outcome of a job that raised `exc` (here, or in Dask: a killed worker, a lost connection)."""
    return {"status": "error", "text": None, "ok": None, "error": message(exc), "seconds": seconds,
            "warnings": list(warned)}


def run_job(job, verb) -> dict:
    """Run `job` with `verb` in this process (a Dask worker) with BLAS and OpenMP on one thread.

    Returns
    -------
    dict
        ``status`` ("done" or "error"), ``text`` (the verb's JSON as ``--json`` prints it, newline included;
        None on error), ``ok`` (the verb's verdict, :data:`VERDICT`), ``error`` (None or the message of
        :func:`message`), ``seconds`` (wall time of the call), ``warnings`` (the messages of the
        :class:`~identcheck.errors.IdentifiabilityWarning` raised during the call, which ``identcheck VERB`` prints
        on stderr; other Python warnings are silenced, as they would clutter the workers' stderr).
    """
    from threadpoolctl import threadpool_limits

    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("ignore")                       # library chatter stays out of the summary ...
        warnings.simplefilter("always", IdentifiabilityWarning)  # ... what the CLI prints as a warning goes in
        try:
            with threadpool_limits(limits=1):
                result = call(job, verb)
            text = json_out.dumps(result) + "\n"
            ok = bool(getattr(result, VERDICT[job.verb]))
        except Exception as exc:             # any failure is this job's error row, never the end of the batch
            return failed(exc, time.perf_counter() - start, _messages(caught))
    return {"status": "done", "text": text, "ok": ok, "error": None, "seconds": time.perf_counter() - start,
            "warnings": _messages(caught)}


def _messages(caught) -> list:
    """The distinct messages of recorded warnings, in order."""
    out = []
    for w in caught:
        msg = str(w.message)
        if msg not in out:
            out.append(msg)
    return out
