"""A standalone certificate's version and content hash.

A certificate saved on its own (``identcheck rank --save``; a local certificate or a counterexample written by a
library call) is *sealed*: its body (the ``/1`` document its module builds and its checker re-checks) under the
``/2`` format name, with ``sha256``, the SHA-256 of the sealed document without that key, in canonical JSON
(sorted keys, no spaces). ``verify`` checks the hash first (an edited file is named as such before any
re-computation) and then re-checks the body as before. Certificates saved before the seal existed (``/1`` on
their own) stay verifiable: their every field is rebuilt from their data, as it always was.

Inside a table the certificates stay ``/1`` bodies: the table's own ``sha256`` covers its rows
(:mod:`identcheck.certify.table`), with the same :func:`digest`.
"""
from __future__ import annotations

import hashlib
import json

HASH_KEY = "sha256"

SEALED = {"identcheck.rank-certificate/2": "identcheck.rank-certificate/1",
          "identcheck.local-certificate/2": "identcheck.local-certificate/1",
          "identcheck.counterexample/2": "identcheck.counterexample/1"}
"""sealed format -> the format of its body."""

BODY_TO_SEALED = {body: sealed for sealed, body in SEALED.items()}


def digest(obj) -> str:
    """SHA-256 (hex) of `obj` in canonical JSON: keys sorted, no spaces, non-ASCII escaped (``\\u2264``)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def seal(body: dict) -> dict:
    """The standalone form of certificate `body` (a ``/1`` document): the same fields under the ``/2`` format,
    plus ``sha256`` over all of them.

    Raises
    ------
    ValueError
        `body`'s format has no sealed form.
    """
    fmt = body.get("format")
    if fmt not in BODY_TO_SEALED:
        raise ValueError(f"no sealed form for format {fmt!r} (known: {', '.join(sorted(BODY_TO_SEALED))})")
    doc = {k: v for k, v in body.items() if k != HASH_KEY}
    doc["format"] = BODY_TO_SEALED[fmt]
    doc[HASH_KEY] = digest(doc)
    return doc


def unseal(doc: dict) -> tuple[dict, list]:
    """(the body of sealed certificate `doc`, problems with its seal). The body is what its format's checker
    re-checks; a problem names ``sha256`` (missing, not a hash, or not the content's)."""
    problems = []
    said = doc.get(HASH_KEY)
    content = {k: v for k, v in doc.items() if k != HASH_KEY}
    if said is None:
        problems.append(f"sha256: missing (a {doc.get('format')} certificate carries the hash of its content)")
    elif not isinstance(said, str) or said != digest(content):
        problems.append("sha256: not the hash of the certificate's content: the file was edited after it was "
                        "saved; every field is re-checked below")
    body = dict(content, format=SEALED[doc["format"]])
    return body, problems
