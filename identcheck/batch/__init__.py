"""``identcheck batch``: the ``fit``, ``diagnose`` and ``plan`` verbs over many trials (or models x noise levels
x motions) on a Dask cluster, one JSON per job and a summary table with one row per job x joint; resumable,
and a failed job is an error row, never the end of the batch.

Modules, one job each: :mod:`~identcheck.batch.extra` (the optional packages it needs),
:mod:`~identcheck.batch.inputs` (paths, globs, folders, manifests -> jobs), :mod:`~identcheck.batch.jobs` (one job
in a worker -> a plain dict), :mod:`~identcheck.batch.store` (the output folder: atomic JSON, what each was
computed from), :mod:`~identcheck.batch.summary` (rows, CSV and Parquet), :mod:`~identcheck.batch.runner` (the
cluster: submit, stream, resume). The Python entry point is :func:`identcheck.api.batch`, which hands the runner
the api's verbs, so a batch job and ``identcheck fit MODEL TRIAL --json`` make the same call.

This file stays empty of imports: ``identcheck.batch`` is also the name of the verb (see
``identcheck/__init__.py``), and ``import identcheck`` imports this package.
"""
