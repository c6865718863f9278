"""Every file identcheck writes appears whole or not at all.

A result, model, figure or trial is written to a temporary name in its own folder, flushed to the disk and moved
into place with ``os.replace`` (atomic on one file system). A full disk, a killed run or a library that fails
midway leaves the previous file (or none) and no partial one: a user never finds a half-written model or a C3D
file cut short where the command said it wrote one.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import uuid
from pathlib import Path

TMP_PREFIX = ".tmp-"


def temporary_name(path) -> Path:
    """A fresh name beside `path` for its content while it is written, keeping its ending (a writer such as
    ezc3d or matplotlib chooses the format, or appends one, from it)."""
    path = Path(path)
    return path.with_name(f"{TMP_PREFIX}{os.getpid()}.{uuid.uuid4().hex[:8]}.{path.name}")


def _sync(path: Path) -> None:
    """Flush what a library wrote to `path` to the disk (a full disk shows here if the library hid it)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def replacing(path):
    """Yield a temporary path to write `path`'s content to (by any library); when the block ends without an
    exception the content is flushed and moved to `path`, otherwise the temporary file is removed and `path` is
    left as it was. A symbolic link is followed (its target is replaced, the link kept); a path that is no
    regular file (a device, a FIFO) gets the content copied into it from a temporary folder, as no file can be
    moved onto it."""
    asked = str(path)
    path = Path(os.path.realpath(path))        # through a symbolic link to its target, which is what is meant
    if path.exists() and not path.is_file():     # a device or a FIFO (/dev/stdout, /dev/null): copied into
        with tempfile.TemporaryDirectory() as folder:
            tmp = Path(folder) / path.name
            yield tmp
            with open(tmp, "rb") as src, open(path, "wb") as dst:
                shutil.copyfileobj(src, dst)
        return
    tmp = temporary_name(path)
    try:
        yield tmp
        _sync(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename in (str(tmp), tmp) or exc.filename2 in (str(tmp), tmp):
            # said of the file the user named, not of the temporary name it was being written under
            raise OSError(exc.errno, exc.strerror, asked) from exc
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write(path, data: bytes | str) -> Path:
    """Write `data` (text is written as UTF-8) to `path` through a temporary file (:func:`replacing`). The file
    gets the usual permissions (0666 less the umask)."""
    path = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with replacing(path) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
    return path
