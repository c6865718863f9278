"""The ``--segments FILE`` of ``identcheck skeleton``: which markers move together, when the user knows it.

A small TOML file, one line per segment::

    [segments]
    pelvis = ["RASI", "LASI", "RPSI", "LPSI"]
    thigh_r = ["RTH1", "RTH2", "RTH3"]

A model file (CONTRACT.md, ``[segments.NAME] markers = [...]``) is read as well: its segments are taken, its
``units`` and ``joints`` are ignored (the skeleton verb infers the joints). Every problem of the file is
collected and raised at once in one :class:`~identcheck.errors.InputError` naming the file and the key; the
markers are checked against the trial by the caller, who has it.
"""
from __future__ import annotations

from collections.abc import Mapping

from identcheck.errors import InputError
from identcheck.io.text import read_toml

IGNORED_KEYS = ("units", "joints")
"""Top-level keys of a model file that a segments file may carry and that are not read."""


def read_segments(path) -> dict[str, tuple[str, ...]]:
    """Segment name → its marker labels (file order) from a segments file.

    Parameters
    ----------
    path : str or os.PathLike
        ``[segments] NAME = ["M1", "M2", ...]``, or a model file.

    Returns
    -------
    dict of str to tuple of str

    Raises
    ------
    InputError
        Missing or unreadable file, TOML syntax error, no ``[segments]`` table, a segment that is not a list of
        marker names, an empty segment, or a marker listed twice (all at once, naming the file and the key).

    Examples
    --------
    >>> read_segments("legs.toml")                      # doctest: +SKIP
    {'pelvis': ('RASI', 'LASI', 'RPSI', 'LPSI'), 'thigh_r': ('RTH1', 'RTH2', 'RTH3')}
    """
    data, source = read_toml(path, "segments file")
    return segments_from_dict(data, source)


def segments_from_dict(data: Mapping, source: str = "<dict>") -> dict[str, tuple[str, ...]]:
    """:func:`read_segments` on the parsed TOML (a mapping); same checks, same errors."""
    problems: list[str] = []
    for key in data:
        if key != "segments" and key not in IGNORED_KEYS:
            problems.append(f"{key}: unknown key (a segments file has one table, [segments])")
    raw = data.get("segments")
    if raw is None:
        raise InputError(problems + ['segments: missing; write [segments] then one line per segment: '
                                     'NAME = ["M1", "M2", ...]'], source=source)
    if not isinstance(raw, Mapping) or not raw:
        raise InputError(problems + ["segments: expected a table of NAME = [markers] lines, got "
                                     f"{'an empty table' if isinstance(raw, Mapping) else type(raw).__name__}"],
                         source=source)
    out: dict[str, tuple[str, ...]] = {}
    owner: dict[str, str] = {}
    for name, value in raw.items():
        key = f"segments.{name}"
        if isinstance(value, Mapping):                       # a model file: [segments.NAME] markers = [...]
            key, value = key + ".markers", value.get("markers")
        if not (isinstance(value, list) and all(isinstance(m, str) and m.strip() for m in value)):
            problems.append(f"{key}: expected a list of marker names [\"M1\", \"M2\", ...], got {value!r}")
            continue
        if not value:
            problems.append(f"{key}: no markers; a segment needs at least one")
            continue
        kept = []
        for m in value:
            if m in owner:
                where = "twice in" if owner[m] == name else f"in both segments.{owner[m]} and"
                problems.append(f"duplicate marker {m!r}: listed {where} {key}")
                continue
            owner[m] = name
            kept.append(m)
        out[name] = tuple(kept)
    if problems:
        raise InputError(problems, source=source)
    return out
