"""The inferred skeleton as a model file (CONTRACT.md, "Model file") that ``fit``, ``plan`` and ``diagnose`` read,
with the evidence for each joint as TOML comments.

:func:`model_text` prints the text; :func:`write_model` checks it by reading it back with the model reader
(:meth:`identcheck.io.model.Model.from_dict`) before it touches the disk, so a file the other verbs would reject
is never written.
"""
from __future__ import annotations

import json
import re

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from identcheck.errors import InputError
from identcheck.io.atomic import atomic_write
from identcheck.io.model import Model

_BARE = re.compile(r"[A-Za-z0-9_-]+")


def _key(name: str) -> str:
    """A TOML key: bare when it can be, else a quoted string."""
    return name if _BARE.fullmatch(name) else json.dumps(name, ensure_ascii=False)


def _string(s: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(s, ensure_ascii=False)


def _comment(lines) -> list:
    return ["# " + line.replace("\n", " ").replace("\r", " ") if line else "#" for line in lines]


def model_text(segments: dict, joints: list, header: list = ()) -> str:
    """The model file's text.

    Parameters
    ----------
    segments : dict of str to sequence of str
        Segment → its markers, in the order to write.
    joints : list of dict
        Each with ``name``, ``type``, ``parent``, ``child`` and ``comment`` (lines), parents before children.
    header : sequence of str
        Comment lines at the top.

    Returns
    -------
    str
    """
    out = _comment(header) + ['units = "mm"', ""]
    for name, markers in segments.items():
        out += [f"[segments.{_key(name)}]", "markers = [" + ", ".join(_string(m) for m in markers) + "]", ""]
    for j in joints:
        out += _comment(j.get("comment", ()))
        out += [f"[joints.{_key(j['name'])}]", f"type = {_string(j['type'])}", f"parent = {_string(j['parent'])}",
                f"child = {_string(j['child'])}", ""]
    return "\n".join(out)


def check_model(text: str, source: str) -> Model:
    """The model the text describes, read as ``fit`` would read it.

    Raises
    ------
    InputError
        The text is not a valid model (a bug of the writer, or names the model reader refuses).
    """
    try:
        return Model.from_dict(tomllib.loads(text), source=source)
    except tomllib.TOMLDecodeError as exc:                      # pragma: no cover - the writer's own output
        raise InputError([f"the inferred model is not valid TOML: {exc}"], source=source) from None


def write_model(path, text: str) -> Model:
    """Check `text` (:func:`check_model`), then write it to `path` (UTF-8); returns the model."""
    model = check_model(text, str(path))
    atomic_write(path, text)
    return model
