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
import shutil
import struct
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from identcheck.errors import InputError
from identcheck.io.atomic import replacing
from identcheck.io.trc import (FARTHEST_MM, MarkerData, check_units, duplicates, far_samples, read_bytes,
                               unit_factor)

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


PROCESSORS = {84: "<", 85: "<", 86: ">"}
"""C3D processor-type byte (Intel, DEC, MIPS) -> the byte order of its integers."""

PARAMETER_TYPES = {-1: "characters", 1: "bytes", 2: "integers", 4: "floats"}
"""Parameter data types of a C3D file."""

MAX_DIMENSIONS = 7
"""A C3D parameter has at most 7 dimensions (the format's own limit)."""

_MAX_RECORDS = 65536  # more parameter records than any writer makes: a file whose links loop

REQUIRED = {("POINT", "USED"), ("POINT", "SCALE"), ("POINT", "RATE"), ("POINT", "DATA_START"),
            ("ANALOG", "GEN_SCALE")}
"""Numeric parameters ezc3d reads a first value of while opening any file: each must be present and hold a
finite number (ezc3d reads an empty one past its end)."""

IF_GROUP = {"ROTATION": ({("ROTATION", "USED"), ("ROTATION", "DATA_START")}, {("ROTATION", "RATIO"),
                                                                              ("ROTATION", "RATE")})}
"""Optional groups ezc3d reads when present: the parameters each then needs all of, and those it needs one of."""

NUMERIC = REQUIRED | {("POINT", "FRAMES"), ("ANALOG", "USED"), ("ANALOG", "RATE"), ("ROTATION", "USED"),
                      ("ROTATION", "DATA_START"), ("ROTATION", "RATIO"), ("ROTATION", "RATE")}
"""Parameters that must hold a finite number when present."""

NOT_NEGATIVE = {("POINT", "USED"), ("POINT", "DATA_START"), ("POINT", "FRAMES"), ("ANALOG", "USED"),
                ("ANALOG", "RATE"), ("ROTATION", "USED"), ("ROTATION", "DATA_START"), ("ROTATION", "RATIO"),
                ("ROTATION", "RATE")}
"""Counts, block numbers and rates: ezc3d sizes its reading by them, and reads a negative one as about 2**64."""


class _Record(NamedTuple):
    """One record of a C3D parameter section: a group (``group`` < 0, its id) or a parameter of group ``group``."""

    pos: int
    name: str
    group: int
    kind: int = 0
    dims: tuple = ()
    values: tuple = ()


def _structure_problems(raw: bytes) -> list[str]:
    """What keeps a C3D file's header and parameter section from being read safely, naming the byte, group or
    parameter (empty: safe to hand to ezc3d).

    ezc3d trusts these bytes: on a file cut inside its parameter section, a record whose links point outside it,
    or a parameter it needs that is missing, empty or of another type, it loops forever, crashes the interpreter
    (seen with ezc3d 1.7 on single-byte changes) or raises a message in its own terms. So the section is walked
    and checked here first, and every problem is said in the file's terms."""
    if raw[0] < 2:
        return [f"header byte 1 puts the parameter section at block {raw[0]}; it follows the header (block 2 "
                "or later)"]
    start = (raw[0] - 1) * 512
    if len(raw) < start + 4:
        return [f"the file ends at byte {len(raw)}, before its parameter section (block {raw[0]}, byte {start})"]
    n_blocks, proc = raw[start + 2], raw[start + 3]
    if proc not in PROCESSORS:
        return [f"parameter section byte 4 (byte {start + 3} of the file): processor type {proc} is none of 84 "
                "(Intel), 85 (DEC), 86 (MIPS)"]
    if n_blocks == 0 or len(raw) < start + 512 * n_blocks:
        return [f"the file ends at byte {len(raw)}, inside its parameter section ({n_blocks} blocks from byte "
                f"{start}): the file is cut short"]
    records: list[_Record] = []
    problem = _walk(raw, start + 4, start + 512 * n_blocks, proc, records)
    if problem:
        return [problem]
    return _meaning_problems(records) or _header_problems(raw, records, raw[0] + n_blocks, PROCESSORS[proc])


def _shown_name(name: str, most: int = 40) -> str:
    """A record's name as a message quotes it: as it is when short and printable; a long printable one cut to its
    start and length; one with bytes that are no text by its printable start and its length, saying its length byte
    looks corrupt (it then runs on through the following records' bytes, and the message had quoted some 200
    characters of them)."""
    if name.isprintable():
        return repr(name) if len(name) <= most else f"{name[:most]!r}... ({len(name)} characters)"
    start = "".join(c if c.isprintable() else "?" for c in name[:24])
    return f"{start!r}... (a name of {len(name)} bytes, not text: its length byte looks corrupt)"


def _walk(raw: bytes, pos: int, end: int, proc: int, records: list) -> str:
    """Read the parameter records from byte `pos` into `records`; the first record that does not lie inside the
    section (`end`), end where the next one starts, or declare a known type and 1 to 7 dimensions ('' if none)."""
    order = PROCESSORS[proc]
    for _ in range(_MAX_RECORDS):
        if pos + 2 > end:
            return f"parameter section: a record at byte {pos} runs past the section's end (byte {end})"
        n_name, group = struct.unpack("bb", raw[pos:pos + 2])
        if n_name == 0:
            return ""
        link = pos + 2 + abs(n_name)
        name = raw[pos + 2:link].decode("latin-1")
        what = f"{'parameter' if group > 0 else 'group'} {_shown_name(name)} at byte {pos}"
        if group == 0:
            return f"{what}: group id 0 (groups are numbered from 1)"
        if link + 2 > end:
            return f"{what} runs past the section's end (byte {end})"
        offset = struct.unpack(order + "H", raw[link:link + 2])[0]
        body = link + 2
        record = _Record(pos, name, group)
        if group > 0:
            if body + 2 > end:
                return f"{what} runs past the section's end (byte {end})"
            kind, n_dims = struct.unpack("bB", raw[body:body + 2])
            if kind not in PARAMETER_TYPES:
                return f"{what}: data type {kind} is none of -1 (characters), 1 (bytes), 2 (integers), 4 (floats)"
            if n_dims > MAX_DIMENSIONS or (kind == -1 and n_dims == 0):
                return (f"{what}: {n_dims} dimensions ({'characters need 1 or more, ' if kind == -1 else ''}"
                        f"at most {MAX_DIMENSIONS})")
            dims = tuple(raw[body + 2:body + 2 + n_dims])
            data = body + 2 + n_dims
            body = data + abs(kind) * math.prod(dims)
            if body <= end:
                record = _Record(pos, name, group, kind, dims, _numbers(raw[data:body], kind, proc))
        if body + 1 > end or body + 1 + raw[body] > end:
            return f"{what} runs past the section's end (byte {end})"
        records.append(record)
        if offset == 0:
            return ""
        if link + offset != body + 1 + raw[body]:
            return (f"{what}: its bytes end at byte {body + 1 + raw[body]} but it links the next record to byte "
                    f"{link + offset}")
        pos = link + offset
    return f"parameter section: more than {_MAX_RECORDS} records (their links loop)"


def _stored_frames(raw: bytes) -> int | None:
    """POINT:FRAMES as the file stores it (None if absent): ezc3d sets the parameter it returns to the frames it
    could read, so a file cut at a block boundary would seem to agree with itself. Stored as a signed 16-bit
    integer, a count above 32767 reads negative and is taken modulo 65536."""
    start = (raw[0] - 1) * 512
    n_blocks, proc = raw[start + 2], raw[start + 3]
    records: list[_Record] = []
    _walk(raw, start + 4, start + 512 * n_blocks, proc, records)
    groups = {-r.group: r.name.upper() for r in records if r.group < 0}
    for r in records:
        if r.group > 0 and groups.get(r.group) == "POINT" and r.name.upper() == "FRAMES" and r.values:
            value = int(r.values[0])
            return value + 65536 if r.kind == 2 and value < 0 else value
    return None


def _numbers(data: bytes, kind: int, proc: int) -> tuple:
    """A numeric parameter's values (empty for characters; DEC floats, whose VAX format this does not decode, as
    zeros: only their count is checked)."""
    order = PROCESSORS[proc]
    if kind == 1:
        return struct.unpack(f"{len(data)}b", data)
    if kind == 2:
        return struct.unpack(f"{order}{len(data) // 2}h", data)
    if kind == 4 and proc != 85:
        return struct.unpack(f"{order}{len(data) // 4}f", data)
    return (0.0,) * (len(data) // 4) if kind == 4 else ()


def _meaning_problems(records: list) -> list[str]:
    """Groups and parameters ezc3d would misread: a parameter of no group, two groups with one id or name, a
    parameter twice in its group, a parameter of :data:`REQUIRED` (or of a present group of :data:`IF_GROUP`)
    missing, one of :data:`NUMERIC` empty, not numeric or not finite, one of :data:`NOT_NEGATIVE` negative (but a
    16-bit POINT:FRAMES, which counts up to 65535 and reads negative above 32767: see :func:`_stored_frames`)."""
    groups: dict[int, str] = {}
    problems = []
    for r in records:
        if r.group < 0:
            if -r.group in groups or r.name.upper() in groups.values():
                problems.append(f"group {r.name!r} at byte {r.pos}: a second group with id {-r.group} or that name")
            groups[-r.group] = r.name.upper()
    params = {}
    for r in (r for r in records if r.group > 0):
        key = (groups.get(r.group), r.name.upper())
        if r.group not in groups:
            problems.append(f"parameter {r.name!r} at byte {r.pos} belongs to group {r.group}, which the file "
                            "does not define")
        elif key in params:
            problems.append(f"parameter {key[0]}:{key[1]} at byte {r.pos}: a second parameter of that name")
        params[key] = r
    needed = set(REQUIRED)
    for group, (every, one_of) in IF_GROUP.items():
        if group in groups.values():
            needed |= every
            if not one_of & set(params):
                problems.append(f"the {group} group has none of " + ", ".join(f"{g}:{n}" for g, n in sorted(one_of)))
    problems += [f"no {g}:{n} parameter (a C3D file needs it{', even without analog data' if g == 'ANALOG' else ''})"
                 for g, n in sorted(needed - set(params))]
    for key in sorted(NUMERIC & set(params)):
        r, where = params[key], f"parameter {key[0]}:{key[1]} at byte {params[key].pos}"
        if r.kind == -1 or not r.values or not math.isfinite(r.values[0]):
            held = "characters" if r.kind == -1 else "nothing" if not r.values else r.values[0]
            problems.append(f"{where} holds {held}, not a number")
        elif key in NOT_NEGATIVE and r.values[0] < 0 and not (key == ("POINT", "FRAMES") and r.kind == 2):
            problems.append(f"{where} is {r.values[0]:g}: a count, block number or rate, never negative")
    return problems


def _header_problems(raw: bytes, records: list, first_data_block: int, order: str) -> list[str]:
    """The header against the parameters: the point count against POINT:USED, and the data start (header and
    POINT:DATA_START) after the parameter section and inside the file."""
    groups = {-r.group: r.name.upper() for r in records if r.group < 0}
    value = {(groups[r.group], r.name.upper()): r.values[0] for r in records if r.group > 0 and r.values}
    n_points, data_start = struct.unpack(order + "H", raw[2:4])[0], struct.unpack(order + "H", raw[16:18])[0]
    problems = []
    if value[("POINT", "USED")] != n_points:
        problems.append(f"POINT:USED says {value[('POINT', 'USED')]:g} points but the header (word 2) says "
                        f"{n_points}")
    blocks = -(-len(raw) // 512)
    for where, block in (("the header's data start (word 9)", data_start),
                         ("POINT:DATA_START", int(value[("POINT", "DATA_START")]))):
        if not first_data_block <= block <= blocks:
            problems.append(f"{where} is block {block}, outside the file's data (blocks {first_data_block} to "
                            f"{blocks}): no frame can be read")
    layout = _header_layout(raw)
    in_file = _frames_in_file(raw, layout, n_points, data_start) if layout is not None and n_points else None
    if not problems and in_file == 0:
        problems.append(f"the file ends at byte {len(raw)}, before the end of its first frame (data from byte "
                        f"{(data_start - 1) * 512}, {_frame_bytes(layout, n_points)} bytes a frame): the file is "
                        "cut short")
    announced = _header_frames(raw)
    frames = value.get(("POINT", "FRAMES"))
    if not problems and frames is not None and announced is not None and frames > announced:
        problems.append(f"POINT:FRAMES says {frames:g} frames but the header's frame range (words 4-5) says "
                        f"{announced}: the two disagree on how many frames the file holds")
    if not problems and in_file and layout["scale"] > 0 and announced and in_file >= 2 * announced:
        problems.append(f"the header's scale ({layout['scale']:g}) and POINT:SCALE say the coordinates are 2-byte "
                        f"integers, but the data section holds {in_file} such frames where the header announces "
                        f"{announced}: twice the bytes, as 4-byte floating-point data would take (is the sign of "
                        "the scale flipped?)")
    return problems


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


def _value(params: dict, group: str, name: str, problems: list[str], text: bool = False):
    """The values of parameter GROUP:NAME as ezc3d gives them (None when absent). A parameter of the other
    kind than expected (characters when `text`, numbers otherwise) or, for numbers, empty or not finite, adds a
    problem naming it and gives None."""
    try:
        entry = params[group][name]
        value = entry["value"]
    except (KeyError, TypeError):
        return None
    if text != (entry.get("type") == -1):
        problems.append(f"{group}:{name} holds {'numbers' if text else 'characters'} where "
                        f"{'characters' if text else 'a number'} belong(s)")
        return None
    if text:
        return [str(v) for v in value]
    value = np.asarray(value, dtype=float).ravel()
    if not len(value) or not np.isfinite(value[0]):
        problems.append(f"{group}:{name} is {'empty' if not len(value) else f'{value[0]:g}'}, not a number")
        return None
    return value


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
    broken = _structure_problems(raw)
    if broken:
        raise InputError([f"not a readable C3D file: {broken[0]}"], source=src)
    ezc3d = _ezc3d(src)
    try:
        c3d = ezc3d.c3d(src)
    except Exception as exc:  # what the checks above do not foresee: ezc3d's own words, marked as such
        raise InputError([f"not a readable C3D file: malformed in a way these checks do not name; the C3D library "
                          f"(ezc3d) stopped with: {str(exc).strip()}"], source=src) from None
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
    scale, start = _value(params, "POINT", "SCALE", problems), _value(params, "POINT", "DATA_START", problems)
    in_file = None
    if scale is not None and len(scale) and float(scale[0]) == 0:
        problems.append("POINT:SCALE is 0: the C3D library multiplies every stored coordinate by it, so every "
                        "marker would read as 0 (never visible); a valid file gives the length of one stored integer "
                        "unit (positive), or a negative number for floating-point data")
    elif layout is not None and scale is not None and len(scale) and np.isfinite(layout["scale"]) \
            and layout["scale"] != 0 and float(scale[0]) != 0 and (float(scale[0]) < 0) != (layout["scale"] < 0):
        problems.append(f"POINT:SCALE is {float(scale[0]):g} ({'floating-point' if float(scale[0]) < 0 else 'integer'} "
                        f"data) but the header's scale is {layout['scale']:g} "
                        f"({'floating-point' if layout['scale'] < 0 else 'integer'} data): the two disagree on how "
                        "the coordinates are stored, so any number read would be wrong")
    elif layout is not None and n_points:
        in_file = _frames_in_file(raw, layout, n_points, int(start[0]) if start is not None and len(start)
                                  else layout["start"])
    frames_param = _value(params, "POINT", "FRAMES", problems)
    frames_param = int(frames_param[0]) if frames_param is not None and len(frames_param) else None
    stored = _stored_frames(raw)
    frames_param = stored if stored is not None else frames_param
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
    units = _value(params, "POINT", "UNITS", problems, text=True)
    if not units or not units[0].strip():
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
        # the header's first frame is 1-based (C3D's own numbering, what Nexus, QTM and Mokka show); ezc3d gives it
        # less one
        first = int(c3d["header"]["points"]["first_frame"]) + 1
    except (KeyError, TypeError, ValueError):
        first = 1
    check_units(xyz, factor, "POINT:UNITS", src)
    far = far_samples(xyz)
    if len(far):
        raise InputError([f"{len(far)} sample(s) farther than {FARTHEST_MM / 1e6:g} km from the origin, or infinite "
                          f"(first: frame {first + far[0][0]}, marker {labels[far[0][1]]!r}, "
                          f"{np.array2string(xyz[tuple(far[0])], precision=4)} mm): not marker positions (a sentinel "
                          "for a missing sample? mark it invalid with a negative residual)"], source=src)
    return MarkerData(np.ascontiguousarray(xyz), labels, rate_hz, first)


def _rate(params: dict, c3d, problems: list[str]) -> float:
    """POINT:RATE (the header's frame rate when absent), Hz; a problem when it is not positive."""
    rate = _value(params, "POINT", "RATE", problems)
    try:
        rate_hz = float(rate[0]) if rate is not None else float(c3d["header"]["points"]["frame_rate"])
    except (TypeError, ValueError, KeyError):
        rate_hz = float("nan")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        problems.append(f"POINT:RATE = {rate_hz:g} is not a positive frame rate")
        return 1.0
    return rate_hz


def _labels(params: dict, n_points: int, problems: list[str]) -> tuple[str, ...]:
    labels: list[str] = []
    for key in ["LABELS"] + [f"LABELS{k}" for k in range(2, 100)]:
        value = _value(params, "POINT", key, problems, text=True)
        if value is None:
            break
        labels += [v.strip() for v in value]
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


MAX_LABEL_BYTES = 255
"""Longest label a C3D parameter can hold (its dimensions are single bytes)."""

MAX_FRAMES = 65535
"""Most frames a C3D file's header and its 16-bit POINT:FRAMES can count (ezc3d silently keeps only these)."""


def write_c3d(path, xyz: np.ndarray, labels, rate_hz: float, first_frame: int = 1) -> None:
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
        The number of the first frame, 1-based as the C3D header holds it (what :func:`read_c3d` returns; at least 1,
        as a TRC file's first Frame#, and the last frame at most :data:`MAX_FRAMES`: the header's numbers are 16-bit,
        and ezc3d would write them less 65536).

    Raises
    ------
    InputError
        ezc3d missing (:class:`MissingDependencyError`), a label C3D cannot store (longer than 255 bytes: a
        parameter's dimension is one byte, and the file would not read back), more than :data:`MAX_FRAMES` frames
        (ezc3d would write only the first 65535), a last frame numbered beyond it, or the file cannot be written.
    """
    path = Path(path)
    if len(xyz) > MAX_FRAMES:
        raise InputError([f"{len(xyz)} frames; a C3D file counts at most {MAX_FRAMES} (its header and POINT:FRAMES "
                          "are 16-bit): write a TRC file, or fewer frames"], source=str(path))
    if max(int(first_frame), 1) + len(xyz) - 1 > MAX_FRAMES:
        raise InputError([f"frames numbered {first_frame} to {int(first_frame) + len(xyz) - 1}; a C3D header numbers "
                          f"them at most to {MAX_FRAMES} (16-bit): number them from 1, or write a TRC file"],
                         source=str(path))
    long = [lab for lab in labels if len(str(lab).encode("utf-8")) > MAX_LABEL_BYTES]
    if long:
        raise InputError([f"marker label {lab[:40]!r}... is {len(lab.encode('utf-8'))} bytes long; a C3D file stores "
                          f"at most {MAX_LABEL_BYTES}: shorten it, or write a TRC file" for lab in long[:3]],
                         source=str(path))
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
    c3d["header"]["points"]["first_frame"] = max(int(first_frame), 1) - 1        # (ezc3d's is the header's less 1)
    try:
        with replacing(path) as tmp:
            beside = tmp.with_name(tmp.name + ".c3d")    # ezc3d appends ".c3d" to any other ending, ".C3D" too
            try:
                c3d.write(str(beside))
                os.replace(beside, tmp)
            finally:
                beside.unlink(missing_ok=True)
            _check_written(tmp, xyz.shape)
    except Exception as exc:
        raise InputError([f"cannot write C3D file ({str(exc).strip()})"], source=str(path)) from None


def _check_written(path: Path, shape: tuple) -> None:
    """Check the C3D file ezc3d wrote holds every frame of every marker: ezc3d reports no failed write (a full disk
    leaves a file cut short, and a success). The file's own structure is read, not its numbers (a file may be
    written with samples its reader then refuses)."""
    raw = path.read_bytes()
    n_frames, n_markers = shape[:2]
    problem = ""
    if len(raw) < 512 or raw[1] != 0x50:
        problem = f"its header is cut short ({len(raw)} bytes)"
    else:
        broken = _structure_problems(raw)
        layout = _header_layout(raw)
        held = None if broken or layout is None else _frames_in_file(raw, layout, n_markers, layout["start"])
        if broken:
            problem = broken[0]
        elif held is not None and held < n_frames:
            problem = f"it holds {held} of the {n_frames} frames"
    if problem:
        free = shutil.disk_usage(path.parent).free
        raise OSError(f"the file written does not read back: {problem}; its disk has {free} bytes free")
