"""Values made JSON-plain, and JSON-like values made read-only.

:func:`plain` turns numpy arrays and scalars into lists, floats and ints (and read-only mappings and
tuples back into dicts and lists), so that every result can be written with the standard ``json``
module and nothing is hidden by ``default=str``. :func:`frozen` is its inverse for result objects: a
nested document of dicts and lists becomes read-only mappings and tuples, so a frozen result cannot be
changed through the documents it holds either.
"""
from __future__ import annotations

import sys
from collections.abc import Mapping
from types import MappingProxyType


def plain(value):
    """`value` with numpy arrays and scalars turned into lists, floats and ints, mappings into dicts and
    tuples into lists (for JSON).

    NumPy is not imported for this: a value can hold NumPy's arrays or scalars only once NumPy is loaded, so a verb
    that never loads it (``plan``) does not pay its import here."""
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    np = sys.modules.get("numpy")
    if np is None:
        return value
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def frozen(value):
    """A read-only copy of a JSON-like `value`: dicts become read-only mappings, lists tuples (recursively).

    ``plain(frozen(doc)) == doc`` for a JSON document ``doc``.
    """
    if isinstance(value, Mapping):
        return MappingProxyType({k: frozen(v) for k, v in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value
