"""The local cluster's workers held quiet: their ``distributed`` loggers at CRITICAL for the worker's whole life.

``LocalCluster(silence_logs=...)`` lowers the workers' stream handlers only while each worker runs; a heartbeat
that races the scheduler's shutdown is logged after that, at ERROR with a traceback, although nothing failed.
A job's own failure is caught and reported by the batch (:mod:`identcheck.batch.jobs`), so nothing is lost."""
import logging

from distributed import WorkerPlugin

LOGGERS = ("distributed", "distributed.worker", "distributed.core", "distributed.comm", "distributed.utils_comm")


class QuietWorkers(WorkerPlugin):
    """Sets the workers' ``distributed`` loggers to CRITICAL when each worker starts (and again if it restarts)."""

    name = "identcheck-quiet-workers"

    def setup(self, worker):
        for name in LOGGERS:
            logging.getLogger(name).setLevel(logging.CRITICAL)
