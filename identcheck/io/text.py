"""Bytes of a text input file (TRC trial, TOML model) to text, whatever editor saved them.

Windows editors and spreadsheets save UTF-8 with a byte-order mark, or UTF-16 ("Unicode text"); both are the
same file to the user, so both read as if saved as plain UTF-8. One function, so that the trial and the model
readers agree on what a text file is.
"""
from __future__ import annotations

import codecs
import os
import stat
from pathlib import Path

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from identcheck.errors import InputError

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


def plain(text: str) -> bool:
    """Whether `text` holds only what capture software writes in a number: ASCII, no digit groups. Python's
    ``float`` and ``int`` also read ``1_000`` and the digits of other scripts (full-width ``１２３``); in a trial or
    an argument those are an edit or a corruption, and read as numbers they would be silent wrong ones."""
    return text.isascii() and "_" not in text


MAX_INPUT_BYTES = 4 << 30
"""Largest input file read: a TRC of a C3D file's most frames (65 535) of 300 markers is about 1.5 GB."""


def read_input(path, kind: str) -> bytes:
    """The bytes of the input file at `path` (`kind`, e.g. "TOML model file", says what was expected); every way
    it can fail is an InputError naming the file: missing, a directory, no regular file (a device such as
    /dev/zero or a FIFO would be read without end), larger than :data:`MAX_INPUT_BYTES`, unreadable."""
    source = str(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError(["file not found"], source=source) from None
    except OSError as exc:
        raise InputError([f"cannot read file: {exc.strerror or exc}"], source=source) from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError([f"is a directory, expected a {kind}"], source=source)
    if not stat.S_ISREG(info.st_mode):
        raise InputError([f"is not a regular file (a device, FIFO or socket), expected a {kind}"], source=source)
    if info.st_size > MAX_INPUT_BYTES:
        raise InputError([f"{info.st_size:,} bytes: larger than any {kind} identcheck reads "
                          f"({MAX_INPUT_BYTES:,} bytes)"], source=source)
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise InputError([f"cannot read file: {exc.strerror or exc}"], source=source) from None


def read_toml(path, kind: str) -> tuple[dict, str]:
    """The TOML file at `path` parsed, and its name for messages; every way it can fail is an InputError naming
    the file (`kind`, e.g. "model file", says what was expected): missing, a directory, unreadable, not text,
    a syntax error, nested too deeply. One reader for every TOML input (models, segments files)."""
    source = str(path)
    try:
        text = decode(read_input(path, f"TOML {kind}"))
    except UnicodeDecodeError as exc:
        raise InputError([f"not UTF-8 text ({exc.reason} at byte {exc.start})"], source=source) from None
    try:
        return tomllib.loads(text), source
    except tomllib.TOMLDecodeError as exc:
        raise InputError([f"TOML syntax error: {exc}"], source=source) from None
    except RecursionError:
        raise InputError([f"arrays or tables nested too deeply to be a {kind}"], source=source) from None
