"""Results as JSON: one plain, sorted document per result, written with the standard ``json`` module.

Every result object of identcheck has ``to_dict()``, which gives the JSON keys of docs/contract.md with only
JSON values (dict, list, str, int, float, bool, None). Nothing is converted here: a value the encoder
does not know is a bug in the result's ``to_dict`` and raises ``TypeError`` (no ``default=str``
that would hide it as a string).
"""
from __future__ import annotations

import json
from pathlib import Path

from identcheck.io.atomic import atomic_write


def document(result) -> dict:
    """The JSON document of ``result``: its ``to_dict()``, or ``result`` itself when it is a dict already."""
    return result.to_dict() if hasattr(result, "to_dict") else result


def dumps(result, indent: int | None = 2, sort_keys: bool = True) -> str:
    """``result`` (a result object or a dict) as JSON text, keys sorted, two-space indented.

    Raises
    ------
    TypeError
        A value is not JSON (a numpy scalar, a SymPy number, ...): the result's ``to_dict`` must
        convert it.
    """
    return json.dumps(document(result), indent=indent, sort_keys=sort_keys, allow_nan=True)


def write(path, result, indent: int | None = 2, sort_keys: bool = False) -> Path:
    """Write ``result`` as JSON to ``path`` (a saved certificate or table, which ``verify`` re-reads)."""
    path = Path(path)
    atomic_write(path, dumps(result, indent=indent, sort_keys=sort_keys))
    return path
