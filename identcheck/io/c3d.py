"""C3D marker files through ezc3d (optional dependency: ``pip install identcheck[c3d]``).

ezc3d returns ``data["points"]`` with shape (4, n_markers, n_frames) and, for every sample
whose residual is negative (the C3D "invalid point" flag), NaN coordinates; this reader also
applies the residual flag itself so it does not depend on that behaviour. Residual 0 means
"valid, gap-filled or without residual" and is kept.

C3D stores coordinates as 32-bit floats, so a write -> read round trip is exact only to float32
precision (about 1e-4 mm at 1 m from the origin).
"""
from __future__ import annotations

import math
import os
import struct
import warnings
from pathlib import Path

import numpy as np

from identcheck.errors import InputError
from identcheck.io.trc import MarkerData, duplicates, read_bytes, unit_factor

INSTALL_HINT = "reading and writing C3D files needs ezc3d: pip install identcheck[c3d]"


class MissingDependencyError(InputError, ImportError):
    """An optional dependency is not installed (an :class:`InputError` and an ImportError)."""


def _ezc3d(source: str):
    try:
        import ezc3d
    except ImportError:
        raise MissingDependencyError([INSTALL_HINT], source=source) from None
    return ezc3d


def _header_frames(raw: bytes) -> int | None:
    """Frame count announced by the raw 512-byte C3D header, or None if it cannot tell."""
    if len(raw) < 512 or raw[1] != 0x50:
        return None
    param_start = (raw[0] - 1) * 512
    big = len(raw) > param_start + 3 and raw[param_start + 3] == 86  # 84 Intel, 85 DEC, 86 MIPS
    first, last = struct.unpack((">" if big else "<") + "HH", raw[6:10])
    if last == 0xFFFF or last < first:  # long files keep the count in POINT:FRAMES only
        return None
    return last - first + 1


def _header_layout(raw: bytes) -> dict | None:
    """What the raw header says about the data: the point scale (negative: floats), analog samples per frame
    and the data start block; None for a DEC (VAX float) file, whose header scale this does not decode."""
    param_start = (raw[0] - 1) * 512
    proc = raw[param_start + 3] if len(raw) > param_start + 3 else 84
    if proc == 85:
        return None
    order = ">" if proc == 86 else "<"
    scale = struct.unpack(order + "f", raw[12:16])[0]
    analog = struct.unpack(order + "H", raw[4:6])[0]
    start = struct.unpack(order + "H", raw[16:18])[0]
    return {"scale": scale, "analog": analog, "start": start}


def _frame_bytes(layout: dict, n_points: int) -> int:
    """Bytes of one frame: points and analog samples, 2-byte integers or 4-byte floats as the header's scale
    sign says."""
    return (4 * n_points + layout["analog"]) * (4 if layout["scale"] < 0 else 2)


def _frames_in_file(raw: bytes, layout: dict, n_points: int, data_start: int) -> int | None:
    """How many whole frames the file's bytes hold from its data start."""
    per_frame = _frame_bytes(layout, n_points)
    start = (data_start - 1) * 512
    if per_frame <= 0 or start <= 0 or start > len(raw):
        return None
    return (len(raw) - start) // per_frame


def _ends_whole(raw: bytes, layout: dict, n_points: int, start, n_frames: int) -> bool:
    """Whether the file ends where a writer would end it after `n_frames` frames: at the first 512-byte block
    boundary after the last frame (a file cut in transfer ends anywhere)."""
    first = ((int(start[0]) if start is not None and len(start) else layout["start"]) - 1) * 512
    end = first + n_frames * _frame_bytes(layout, n_points)
    return len(raw) % 512 == 0 and -(-end // 512) * 512 == len(raw)


def _value(params: dict, group: str, name: str):
    try:
        return params[group][name]["value"]
    except (KeyError, TypeError):
        return None


def read_c3d(path) -> MarkerData:
    """Read the 3-D points of a C3D file.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    MarkerData
        ``xyz`` shape (n_frames, n_markers, 3) in mm (converted from ``POINT:UNITS``), NaN
        where the point is invalid (negative residual); ``labels`` from ``POINT:LABELS``
        (continued in ``LABELS2``, ... past 255 points), stripped; ``rate_hz`` from
        ``POINT:RATE``.

    Raises
    ------
    InputError
        Missing, empty, truncated or non-C3D file, unknown units, no points or frames,
        missing or duplicated labels; all listed at once. ezc3d not installed
        (:class:`MissingDependencyError`, also an ImportError).

    Warns
    -----
    UserWarning
        ``POINT:UNITS`` absent (millimetres assumed).
    """
    path = Path(path)
    src = str(path)
    raw = read_bytes(path)
    if not raw:
        raise InputError(["empty file"], source=src)
    if len(raw) < 512 or raw[1] != 0x50:
        raise InputError(["not a C3D file (its first 512-byte header block lacks the C3D key "
                          "byte 0x50)"], source=src)
    ezc3d = _ezc3d(src)
    try:
        c3d = ezc3d.c3d(src)
    except Exception as exc:  # ezc3d raises OSError/RuntimeError with its own text
        raise InputError([f"not a readable C3D file: truncated or malformed (ezc3d says: "
                          f"{str(exc).strip()})"], source=src) from None
    params = c3d["parameters"]
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)
    problems: list[str] = []
    n_points = points.shape[1] if points.ndim == 3 else 0
    n_frames = points.shape[2] if points.ndim == 3 else 0
    if n_points == 0:
        problems.append("no 3-D points (POINT:USED = 0)")
    if n_frames == 0:
        problems.append("no frames")
    announced = _header_frames(raw)
    layout = _header_layout(raw)
    scale, start = _value(params, "POINT", "SCALE"), _value(params, "POINT", "DATA_START")
    in_file = None
    if layout is not None and scale is not None and len(scale) and np.isfinite(layout["scale"]) \
            and layout["scale"] != 0 and float(scale[0]) != 0 and (float(scale[0]) < 0) != (layout["scale"] < 0):
        problems.append(f"POINT:SCALE is {float(scale[0]):g} ({'floating-point' if float(scale[0]) < 0 else 'integer'} "
                        f"data) but the header's scale is {layout['scale']:g} "
                        f"({'floating-point' if layout['scale'] < 0 else 'integer'} data): the two disagree on how "
                        "the coordinates are stored, so any number read would be wrong")
    elif layout is not None and n_points:
        in_file = _frames_in_file(raw, layout, n_points, int(start[0]) if start is not None and len(start)
                                  else layout["start"])
    frames_param = _value(params, "POINT", "FRAMES")
    frames_param = int(frames_param[0]) if frames_param is not None and len(frames_param) else None
    if announced is not None and n_frames > announced:
        problems.append(f"POINT:FRAMES says {frames_param} frames but the header's frame range says {announced}: "
                        f"the {n_frames - announced} frames past the header's last would be read from padding")
    elif in_file is not None and n_frames > in_file:
        problems.append(f"POINT:FRAMES says {n_frames} frames but the file holds only {in_file} after its data "
                        f"start: the last {n_frames - in_file} would be invented")
    elif announced is not None and n_frames < announced:
        if layout is not None and n_frames == frames_param and _ends_whole(raw, layout, n_points, start, n_frames):
            warnings.warn(f"{src}: the header's frame range announces {announced} frames; POINT:FRAMES and the "
                          f"file size agree on {n_frames}, which are read", UserWarning, stacklevel=3)
        else:
            problems.append(f"truncated file: the header announces {announced} frames but only "
                            f"{n_frames} are present")
    elif frames_param is not None and n_frames < frames_param and announced is None:
        problems.append(f"truncated file: POINT:FRAMES announces {frames_param} frames but only {n_frames} are present")
    rate_hz = _rate(params, c3d, problems)
    units = _value(params, "POINT", "UNITS")
    if not units or not str(units[0]).strip():
        warnings.warn(f"{src}: no POINT:UNITS parameter; assuming mm", UserWarning, stacklevel=3)
        factor = 1.0
    else:
        factor = unit_factor(units[0], "POINT:UNITS", problems)
    labels = _labels(params, n_points, problems)
    if problems:
        raise InputError(problems, source=src)
    residuals = c3d["data"].get("meta_points", {}).get("residuals")
    xyz = points[:3].transpose(2, 1, 0) * factor
    if residuals is not None and np.shape(residuals)[1:] == (n_points, n_frames):
        xyz[(np.asarray(residuals)[0] < 0).T] = np.nan
    try:
        first = int(c3d["header"]["points"]["first_frame"])
    except (KeyError, TypeError, ValueError):
        first = 0
    return MarkerData(np.ascontiguousarray(xyz), labels, rate_hz, first)


def _rate(params: dict, c3d, problems: list[str]) -> float:
    rate = _value(params, "POINT", "RATE")
    try:
        rate_hz = float(rate[0]) if rate is not None and len(rate) else float(c3d["header"]["points"]["frame_rate"])
    except (TypeError, ValueError, KeyError):
        rate_hz = float("nan")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        problems.append(f"POINT:RATE = {rate!r} is not a positive frame rate")
        return 1.0
    return rate_hz


def _labels(params: dict, n_points: int, problems: list[str]) -> tuple[str, ...]:
    labels: list[str] = []
    for key in ["LABELS"] + [f"LABELS{k}" for k in range(2, 100)]:
        value = _value(params, "POINT", key)
        if value is None:
            break
        labels += [str(v).strip() for v in value]
    if len(labels) < n_points:
        problems.append(f"POINT:LABELS names {len(labels)} points but the file has {n_points}")
        return tuple(labels)
    labels = labels[:n_points]
    empty = [i for i, lab in enumerate(labels) if not lab]
    if empty:
        problems.append(f"POINT:LABELS: point(s) {', '.join(str(i) for i in empty)} have an empty label")
    for lab, idx in duplicates(labels).items():
        if lab:
            problems.append(f"POINT:LABELS: duplicate marker label {lab!r} (points "
                            f"{', '.join(str(i) for i in idx)})")
    return tuple(labels)


def write_c3d(path, xyz: np.ndarray, labels, rate_hz: float, first_frame: int = 0) -> None:
    """Write marker trajectories as a C3D file (float storage, ``POINT:UNITS = "mm"``).

    Parameters
    ----------
    path : str or os.PathLike
    xyz : array_like
        shape (n_frames, n_markers, 3), mm; NaN samples are written as invalid points
        (negative residual).
    labels : sequence of str
    rate_hz : float
    first_frame : int
        The header's first frame, as ezc3d reports it (what :func:`read_c3d` returns).

    Raises
    ------
    InputError
        ezc3d missing (:class:`MissingDependencyError`) or the file cannot be written.
    """
    path = Path(path)
    ezc3d = _ezc3d(str(path))
    xyz = np.asarray(xyz, dtype=np.float64)
    n_frames, n_markers = xyz.shape[:2]
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate_hz)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    points = np.ones((4, n_markers, n_frames))
    points[:3] = xyz.transpose(2, 1, 0)
    c3d["data"]["points"] = points
    c3d["header"]["points"]["first_frame"] = max(int(first_frame), 0)
    # ezc3d appends ".c3d" to any other ending (".C3D" included): write beside, then rename
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.c3d")
    try:
        c3d.write(str(tmp))
        os.replace(tmp, path)
    except Exception as exc:
        tmp.unlink(missing_ok=True)
        raise InputError([f"cannot write C3D file ({str(exc).strip()})"], source=str(path)) from None
