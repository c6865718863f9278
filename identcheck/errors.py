"""Error and warning types shared by every part of identcheck.

Loaders collect every problem they find and raise one :class:`InputError`; the CLI maps it
to exit code 2. Solvers raise :class:`DegenerateError` when the data cannot decide (never a
silent wrong number).
"""
from __future__ import annotations


MAX_PROBLEM_CHARS = 1000
"""Longest problem sentence shown: one that quotes a value from a file (a marker name, a cell) could otherwise be
as long as the file."""


def _shortened(problem) -> str:
    """`problem` as text, cut to :data:`MAX_PROBLEM_CHARS` with a note of how much was left out."""
    text = str(problem)
    if len(text) <= MAX_PROBLEM_CHARS:
        return text
    return f"{text[:MAX_PROBLEM_CHARS]}... ({len(text) - MAX_PROBLEM_CHARS:,} characters more)"


class InputError(ValueError):
    """Bad user input (file, marker, joint type, option); lists every problem found at once.

    Parameters
    ----------
    problems : list of str
        One human-readable sentence per problem, each naming the file, line, key, marker or
        frame it concerns.
    source : str, optional
        The file (or other source) the problems were found in; prefixed to the message.
    segment : str, optional
        The segment of a model the problem keeps from being posed or moved, when there is one: a whole-tree
        fit can leave that segment, and what hangs from it, out and fit the rest.
    """

    def __init__(self, problems, source: str | None = None, segment: str | None = None):
        self.segment = segment
        if isinstance(problems, str):
            problems = [problems]
        self.problems = [_shortened(p) for p in problems]
        self.source = source
        head = f"{source}: " if source else ""
        if len(self.problems) == 1:
            msg = head + self.problems[0]
        else:
            msg = head + f"{len(self.problems)} problems:\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(msg)

    def naming(self, source: str, prefix: str = "") -> "InputError":
        """The same problems, each after `prefix`, as found in `source`.

        For an error raised on arrays below the readers (an estimator knows no file): the verb that read the
        file re-raises it naming the file, and, with `prefix`, the joint or segment it was working on."""
        return InputError([prefix + p for p in self.problems], source=source, segment=self.segment)


class DegenerateError(ValueError):
    """The samples do not determine the answer (singular system, coincident markers, α = 0, ...).

    ``segment``, when given, names the model segment the samples fail to pose or move (see :class:`InputError`).
    ``leave_out``, when given, says why a whole-tree fit may leave out the joint above that segment, with every
    joint below it, and go on with the rest (as ``fit`` does) rather than stop: the segment's markers are seen in
    too few frames, or the joint above it is a case no motion identifies."""

    def __init__(self, *args, segment: str | None = None, leave_out: str | None = None):
        super().__init__(*args)
        self.segment = segment
        self.leave_out = leave_out


class DerivationError(RuntimeError):
    """A symbolic identity that must hold exactly did not reduce to zero."""


class IdentifiabilityWarning(UserWarning):
    """Usable but near-degenerate data: the answer is sensitive to noise."""


class KindedWarning(UserWarning):
    """A warning with the ``kind`` the verbs' JSON ``warnings`` give it (:func:`warning_kind`), the same whichever
    verb says it."""

    kind = "warning"


class UnitsWarning(KindedWarning):
    """The coordinates and the units they are read in disagree in a way that only suggests a mistake (a body spanning
    a few "millimetres", or ten metres): the answer is computed, and every distance in it is off by the same factor
    if the suspicion is right."""

    kind = "units"


class SubjectPrefixWarning(KindedWarning):
    """A Vicon ``Subject:`` prefix was taken off the trial's labels to match the model's markers."""

    kind = "subject_prefix"


class GrossErrorWarning(KindedWarning):
    """Samples far from where their neighbours in time put their marker were left out."""

    kind = "gross_error"


def warning_kind(category: type) -> str:
    """The ``kind`` a warning of this class has in the JSON ``warnings``: a :class:`KindedWarning`'s own (``units``,
    ``subject_prefix``, ``gross_error``), else the class's name."""
    return category.kind if issubclass(category, KindedWarning) else category.__name__


class StaleCodeWarning(RuntimeWarning):
    """A committed generated module no longer matches its derivation's sources: the functions were derived
    again at run time (SymPy, seconds). ``identcheck derive --regenerate`` rewrites the module."""
