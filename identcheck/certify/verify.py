"""Re-check a saved certificate or table from its own data (``identcheck verify``).

The file names its format; each format has its own checker, which trusts none of the saved derived
numbers: rank certificates are rebuilt from their sample points, counterexamples re-verified at 50
digits, local certificates replayed, tables re-checked row by row.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass

from identcheck.certify import counterexamples, jacobian
from identcheck.certify import exact_rank
from identcheck.certify import seal, table
from identcheck.errors import InputError
from identcheck.io.text import read_input

CHECKS = {exact_rank.FORMAT: lambda c: exact_rank.verify(c).problems, jacobian.FORMAT: jacobian.replay,
          counterexamples.FORMAT: counterexamples.verify_dict, table.FORMAT: table.verify}
"""format name -> function(document) -> list of problems (empty: verified). A sealed (``/2``) certificate is
checked as its ``/1`` body after its hash (:mod:`identcheck.certify.seal`)."""

FORMATS = sorted(set(CHECKS) | set(seal.SEALED))
"""Every format ``verify`` reads."""


@dataclass(frozen=True)
class VerifyResult:
    """The verdict on one saved certificate.

    Attributes
    ----------
    ok : bool
        Every check passed.
    problems : tuple of str
        One sentence per failed check, naming the row and field.
    certificate : str
        Where the certificate came from (its file).
    format : str
        The certificate's format name.
    """

    ok: bool
    problems: tuple
    certificate: str
    format: str

    def to_dict(self) -> dict:
        """``{"ok", "problems", "certificate", "format"}``, as ``identcheck verify --json`` prints it."""
        return {"ok": self.ok, "problems": list(self.problems), "certificate": self.certificate,
                "format": self.format}


def read(path) -> dict:
    """The JSON object saved in ``path``.

    Raises
    ------
    InputError
        The file is missing, is not JSON, or holds no JSON object.
    """
    raw = read_input(path, "certificate file (JSON)")
    try:
        doc = json.loads(raw.decode("utf-8-sig"))      # (a byte-order mark, as some editors save, is not content)
    except UnicodeDecodeError as exc:
        raise InputError([f"not UTF-8 text (byte {exc.start}): a certificate is a JSON file"], source=str(path)) from None
    except json.JSONDecodeError as exc:
        raise InputError([f"not JSON (line {exc.lineno}, column {exc.colno}): {exc.msg}"], source=str(path)) from None
    except RecursionError:
        raise InputError(["JSON nested too deeply to be a certificate"], source=str(path)) from None
    except ValueError as exc:          # an integer beyond Python's 4300-digit limit for reading text
        raise InputError([f"not a certificate: it holds a number too long to read ({str(exc).split(':')[0]})"],
                         source=str(path)) from None
    if not isinstance(doc, dict):
        raise InputError(["a certificate is a JSON object"], source=str(path))
    return doc


MAX_DIGITS = 4000
"""The most digits a number written in a certificate may have, and the largest power of ten it may carry (``1e4000``):
below the 4300 digits Python turns into text by default. A certificate's own numbers are fractions of a few hundred
digits at most; ``1e100000000`` in a sample had kept ``verify`` computing an exact 10^100000000 past any time limit,
and ``1e4300`` had been rejected with Python's own message, naming no field."""
MAX_TEXT = 100_000
"""The longest text (characters) one field of a certificate may hold."""
_NUMBER = re.compile(r"\s*[+-]?(?:\d[\d_]*\.?\d*|\.\d+)(?:[eE][+-]?(\d+))?"
                     r"(?:\s*/\s*[+-]?(?:\d[\d_]*\.?\d*|\.\d+)(?:[eE][+-]?(\d+))?)?\s*")


def oversized(doc, path: str = "") -> list[str]:
    """The fields of `doc` (a JSON value) no certificate holds: a text longer than :data:`MAX_TEXT`, or a number
    written as text with more than :data:`MAX_DIGITS` digits or a power of ten beyond it, each as
    ``"field PATH: ..."``; checked before anything is computed from them."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += oversized(v, f"{path}.{k}" if path else str(k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += oversized(v, f"{path}[{i}]")
    elif isinstance(doc, str):
        if len(doc) > MAX_TEXT:
            out.append(f"field {path}: a text of {len(doc)} characters, beyond the {MAX_TEXT} a certificate holds")
        else:
            number = _NUMBER.fullmatch(doc)
            powers = [e for e in number.groups() if e] if number else []
            digits = sum(c.isdigit() for c in doc) if number else 0
            if any(len(e.lstrip("0")) > 6 or int(e) > MAX_DIGITS for e in powers) or digits > MAX_DIGITS:
                out.append(f"field {path}: the number {doc[:40]!r}{'...' if len(doc) > 40 else ''} has more than "
                           f"{MAX_DIGITS} digits or a power of ten beyond 1e{MAX_DIGITS}, which no certificate holds")
    return out


def verify(certificate, source: str | None = None, progress=None) -> VerifyResult:
    """Re-check ``certificate`` (a path to a saved certificate or table, or its JSON object).

    Parameters
    ----------
    certificate : str, os.PathLike or dict
    source : str, optional
        Name reported for a dict (default ``"<dict>"``); a path names itself.
    progress : callable, optional
        Called with a line of text as the checks go (a table takes tens of seconds).

    Raises
    ------
    InputError
        Unreadable file or an unknown format.
    """
    if isinstance(certificate, dict):
        doc, source = certificate, source or "<dict>"
    else:
        doc, source = read(certificate), source or str(certificate)
    fmt = doc.get("format")
    if not isinstance(fmt, str) or fmt not in FORMATS:
        raise InputError([f"unknown certificate format {fmt!r} (expected one of {', '.join(FORMATS)})"],
                         source=source)
    huge = oversized(doc)
    if huge:
        return VerifyResult(ok=False, problems=tuple(f"malformed {fmt} document ({p})" for p in huge),
                            certificate=source, format=fmt)
    if progress:
        progress(f"re-checking {source} ({fmt}) from its own data")
    problems = []
    try:
        body = doc
        if fmt in seal.SEALED:
            body, problems = seal.unseal(doc)
        kind = body["format"]
        problems += CHECKS[kind](body, progress=progress) if kind == table.FORMAT else CHECKS[kind](body)
    except (KeyError, TypeError, AttributeError, IndexError, ValueError) as exc:
        # a field missing or of the wrong type: the file is not a certificate of its stated format; that is a
        # rejection (exit 1), with what was missing, never a traceback
        what = f"field {exc.args[0]!r} missing" if isinstance(exc, KeyError) else \
            "a field holds a value of another kind than the format's (a number, text, list or object where another " \
            "is expected)"
        problems = problems + [f"malformed {fmt} document ({what})"]
    return VerifyResult(ok=not problems, problems=tuple(problems), certificate=source, format=fmt)
