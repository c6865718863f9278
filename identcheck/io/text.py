"""Bytes of a text input file (TRC trial, TOML model) to text, whatever editor saved them.

Windows editors and spreadsheets save UTF-8 with a byte-order mark, or UTF-16 ("Unicode text"); both are the
same file to the user, so both read as if saved as plain UTF-8. One function, so that the trial and the model
readers agree on what a text file is.
"""
from __future__ import annotations

import codecs

BOMS = ((codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))
"""Byte-order marks and the codec that reads a file starting with each."""


def decode(raw: bytes, fallback: str | None = None) -> str:
    """`raw` as text: by its byte-order mark (UTF-8 or UTF-16), else as UTF-8, else as `fallback` if given.

    Raises
    ------
    UnicodeDecodeError
        Neither the mark's codec nor UTF-8 reads the bytes, and no `fallback` is given (its ``start`` is the
        first byte that is not text).
    """
    codec = next((name for bom, name in BOMS if raw.startswith(bom)), "utf-8")
    try:
        return raw.decode(codec)
    except UnicodeDecodeError:
        if fallback is None:
            raise
        return raw.decode(fallback)
