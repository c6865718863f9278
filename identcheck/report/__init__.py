"""Results into output, in one place: :mod:`~identcheck.report.json_out` (each result's ``to_dict()`` as
plain sorted JSON), :mod:`~identcheck.report.text` (what the verbs print on a terminal) and the figures
(:mod:`~identcheck.report.figure_io`, :mod:`~identcheck.report.plan_figure`,
:mod:`~identcheck.report.diagnose_figures`, drawn with matplotlib's object API)."""
