"""Trial: recorded (or simulated) marker trajectories in one stored form.

Inside a :class:`Trial` positions are float64 millimetres, shape (n_frames, n_markers, 3),
with NaN for occluded samples, whatever the file said. Build one with a ``from_*`` method and
read it with ``as_array`` / ``marker`` / ``select``; it is never modified in place.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np

from identcheck.errors import InputError
from identcheck.io.c3d import read_c3d, write_c3d
from identcheck.io.text import plain
from identcheck.io.trc import FARTHEST_MM, UNITS_TO_MM, duplicates, far_samples, read_trc, write_trc

COINCIDENT_MM = 1.0
"""Two markers closer than this in every frame where both are seen are one marker under two labels: the balls
of real markers are several millimetres wide, so their centres cannot come this close, let alone stay so."""

LONGEST_SEGMENT_MM = 3000.0
"""The farthest two markers of a segment may lie apart (the median over the frames where both are seen) unless the
model declares the segment longer (``length_mm``): no limb, trunk or head is 3 m long. A segment spanning more is a
trial whose units field scaled its numbers up (millimetres in a file that says cm made a thigh 3.7 m long, and every
joint was reported 10 times too far, exit 0), or markers mislabelled across bodies."""

METRES_ROOM_MM = 20.0
"""A model's markers that coincide in pairs but none of whose coordinates reaches this ("mm") are a capture volume in
metres read as mm (a room of a few metres), not markers exported under several labels: those, in mm, lie hundreds of
millimetres from the volume's origin."""

LONGEST_SHARE = 4.0
"""The farthest two markers of a segment whose length the model declares (``length_mm``) may lie at most this many
times that length apart (the median over the frames where both are seen), and at least :data:`LONGEST_DECLARED_MM`
apart whatever it declares: the bundled models' simulations span at most 1.2 times theirs (a foot's heel to toe beside
its declared length), and a length given for ``simulate`` may be short of a segment's marker spread (a pelvis's to its
hips, beside markers on both iliac spines). A segment spanning more is a trial whose numbers are ten times too large
for their units, or a length written in the wrong unit: a shank declared 400 mm whose markers lay 1.65 m apart, and a
foot declared 200 mm at 2.3 m, had been fitted (exit 1, no warning)."""

LONGEST_DECLARED_MM = 1000.0
"""The least a declared length lets a segment's markers lie apart (:data:`LONGEST_SHARE`): a short length given for
``simulate`` does not refuse a trial whose markers spread under a metre."""

SMALLEST_REACH_SHARE = 1 / 4
"""A segment the model declares L long (``length_mm``) has some marker, on it or on a segment within two joints of
it, at least L/4 away from its markers (the median over the frames where both are seen; not every marker of the
model: on a whole body a head marker 1.2 m from a thigh, read in centimetres as 120 mm, would pass a thigh of 420
mm): the markers of a body spread over its segments' lengths (a thigh cluster lies half a thigh from the pelvis and
from the shank's markers; the bundled models' simulations reach 0.73 to 4.6 times their declared lengths, the least
the minimal knee of Pham et al., whose thigh markers lie 0.73 of the thigh from its shank marker). A trial whose
farthest marker is nearer is in a larger unit than its units field says: centimetres in a file that says mm put every
hip 10 times too near its markers, called ``unique`` and ``determined`` with exit 0 (the bundled models then reached
0.07 to 0.46 of their lengths, each model below a quarter on one segment at least). Without a declared length no body
size is wrong (a mouse's markers are millimetres apart), and nothing is checked."""

SPAN_FRAMES = 1000
"""Frames (evenly spread) a segment's span is read over: the median needs no more, and a long trial's every frame
would cost seconds (30 000 frames of 40 markers)."""

SUBJECT_SEPARATOR = ":"
"""What ends a subject prefix in a marker label (Vicon Nexus writes ``Subject:Marker``): :meth:`Trial.unprefixed`."""

FORMATS = (".trc", ".c3d")
"""File extensions :meth:`Trial.from_file` and :meth:`Trial.to_file` understand."""


def _format(path: Path) -> str:
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise InputError([f"unknown trial file extension {path.suffix or '(none)'!r} "
                          f"(expected one of {', '.join(FORMATS)}, any case)"], source=str(path))
    return ext


def frame_range(spec: str) -> tuple[int | None, int | None]:
    """``START:END`` (the file's own frame numbers, both included) as ``(start, end)``, None for an end left out.

    The one parser of ``--frames START:END`` (:meth:`Trial.frames`, and the batch manifest's ``frames`` column,
    checked before any file is read).

    Raises
    ------
    ValueError
        Not two integers (either may be empty) around one colon.
    """
    a, b = str(spec).split(":")

    def number(text: str) -> int | None:
        text = text.strip()
        if not text:
            return None
        if not plain(text):
            raise ValueError(f"{text!r} is not a frame number")
        return int(text)

    return number(a), number(b)


def _float_array(xyz, source: str, copy: bool = False) -> np.ndarray:
    try:
        return np.array(xyz, dtype=np.float64) if copy else np.asarray(xyz, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError([f"xyz is not a numeric array ({exc})"], source=source) from None


def zeros_as_gaps(xyz, labels, source: str) -> np.ndarray:
    """The positions read from a file with every sample at exactly (0, 0, 0) made occluded (NaN), with a warning
    naming the markers and how many frames each.

    Exporters write a missing sample as zeros as often as they leave it empty (older Vicon and Motion Analysis
    TRCs, C3Ds whose residual word was not set); a marker really at the origin to the last digit in all three
    coordinates does not happen. Read as a position, such a gap became a marker jumping to the lab's origin,
    which a fit blamed on skin motion and ``diagnose`` on slips and extra joint rotations."""
    xyz = np.array(xyz, dtype=float)
    if xyz.ndim != 3 or xyz.shape[-1] != 3:
        return xyz                     # the Trial reports the shape
    zero = np.all(xyz == 0.0, axis=2)
    if zero.any():
        xyz[zero] = np.nan
        counts = zero.sum(axis=0)
        named = ", ".join(f"{labels[m]} ({counts[m]} frame{'s' if counts[m] > 1 else ''})"
                          for m in np.flatnonzero(counts)[:8])
        more = f" and {int((counts > 0).sum()) - 8} more markers" if (counts > 0).sum() > 8 else ""
        warnings.warn(f"{source}: {int(zero.sum())} sample(s) at exactly (0, 0, 0) read as occluded (the usual "
                      f"placeholder for a missing sample): {named}{more}", UserWarning, stacklevel=3)
    return xyz


class Trial:
    """Marker trajectories: shape (n_frames, n_markers, 3) float64 mm, NaN = occluded.

    Use the ``from_*`` constructors; ``Trial(...)`` is the same as :meth:`from_array` with
    ``units="mm"``.

    Examples
    --------
    >>> import numpy as np
    >>> t = Trial.from_array(np.zeros((5, 2, 3)), ["A", "B"], rate_hz=100.0, units="m")
    >>> t.n_frames, t.n_markers, t.marker("B").shape
    (5, 2, (5, 3))
    """

    __slots__ = ("_xyz", "_labels", "_index", "_rate_hz", "_source", "_first_frame", "_numbered")

    def __init__(self, xyz, labels: Sequence[str], rate_hz: float, source: str = "<array>",
                 first_frame: int | None = None, numbered: bool | None = None):
        problems: list[str] = []
        xyz = _float_array(xyz, source, copy=True)  # copy: the trial owns its data
        if xyz.ndim != 3 or xyz.shape[2] != 3:
            problems.append(f"expected xyz of shape (n_frames, n_markers, 3), got {xyz.shape}")
        elif xyz.shape[0] == 0:
            problems.append("no frames (n_frames = 0)")
        labels = tuple(labels)
        bad = [lab for lab in labels if not isinstance(lab, str) or not lab.strip()]
        if bad:
            problems.append(f"marker labels must be non-empty strings, got {bad!r}")
        if xyz.ndim == 3 and len(labels) != xyz.shape[1]:
            problems.append(f"{len(labels)} labels for {xyz.shape[1]} markers")
        for lab, idx in duplicates(labels).items():
            problems.append(f"duplicate marker label {lab!r} (markers {', '.join(map(str, idx))})")
        try:
            rate_hz = float(rate_hz)
        except (TypeError, ValueError):
            rate_hz = float("nan")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            problems.append(f"rate_hz must be a positive number of Hz, got {rate_hz!r}")
        far = far_samples(xyz) if not problems else ()
        if len(far):
            f, m = far[0]
            problems.append(f"infinite coordinate or one farther than {FARTHEST_MM / 1e6:g} km from the origin in "
                            f"{len(far)} sample(s) (first: frame {int(first_frame or 0) + f}, row {f}, marker "
                            f"{labels[m]!r}): not marker positions; use NaN for occluded samples")
        if problems:
            raise InputError(problems, source=source)
        xyz.flags.writeable = False
        self._xyz = xyz
        self._labels = labels
        self._index = {lab: i for i, lab in enumerate(labels)}
        self._rate_hz = rate_hz
        self._source = source
        self._first_frame = 0 if first_frame is None else int(first_frame)
        # whether a file numbered the frames (default: when a first frame is given); an array's rows are counted
        # from 0 here and written from 1, whatever part of it is cut or rebuilt
        self._numbered = first_frame is not None if numbered is None else bool(numbered)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_array(cls, xyz, labels: Sequence[str], rate_hz: float, units: str = "mm",
                   source: str = "<array>") -> "Trial":
        """Trial from an array.

        Parameters
        ----------
        xyz : array_like
            Marker positions, shape (n_frames, n_markers, 3), in `units`; NaN = occluded.
        labels : sequence of str
            One unique name per marker.
        rate_hz : float
            Frame rate in Hz.
        units : {"mm", "cm", "m"}
            Units of `xyz`; stored as mm.
        source : str
            Name used in error messages.

        Raises
        ------
        InputError
            Wrong shape, label count or duplicates, bad rate, unknown units, infinite values.
        """
        key = str(units).strip().lower()
        if key not in UNITS_TO_MM:
            raise InputError([f"unknown units {units!r} (allowed: {', '.join(UNITS_TO_MM)})"],
                             source=source)
        return cls(_float_array(xyz, source) * UNITS_TO_MM[key], labels, rate_hz, source)

    @classmethod
    def from_trc(cls, path) -> "Trial":
        """Read an OpenSim TRC file (see :func:`identcheck.io.trc.read_trc`); samples at exactly (0, 0, 0) are
        occluded (:func:`zeros_as_gaps`)."""
        data = read_trc(path)
        return cls(zeros_as_gaps(data.xyz, data.labels, str(path)), data.labels, data.rate_hz, source=str(path),
                   first_frame=data.first_frame)

    @classmethod
    def from_c3d(cls, path) -> "Trial":
        """Read the points of a C3D file (see :func:`identcheck.io.c3d.read_c3d`); samples at exactly (0, 0, 0)
        are occluded (:func:`zeros_as_gaps`)."""
        data = read_c3d(path)
        return cls(zeros_as_gaps(data.xyz, data.labels, str(path)), data.labels, data.rate_hz, source=str(path),
                   first_frame=data.first_frame)

    @classmethod
    def from_file(cls, path) -> "Trial":
        """Read a ``.trc`` or ``.c3d`` file, chosen by extension (any case).

        Raises
        ------
        InputError
            Unknown extension, or any problem the reader finds.
        """
        path = Path(path)
        return cls.from_trc(path) if _format(path) == ".trc" else cls.from_c3d(path)

    # ------------------------------------------------------------------ views
    @property
    def xyz(self) -> np.ndarray:
        """Read-only positions, shape (n_frames, n_markers, 3), mm (use :meth:`as_array` to edit)."""
        return self._xyz

    @property
    def labels(self) -> tuple[str, ...]:
        return self._labels

    @property
    def rate_hz(self) -> float:
        return self._rate_hz

    @property
    def source(self) -> str:
        """File (or other origin) the trial came from, for messages."""
        return self._source

    @property
    def n_frames(self) -> int:
        return self._xyz.shape[0]

    @property
    def n_markers(self) -> int:
        return self._xyz.shape[1]

    @property
    def times(self) -> np.ndarray:
        """Frame times in s from the first frame, shape (n_frames,)."""
        return np.arange(self.n_frames) / self._rate_hz

    @property
    def gaps(self) -> np.ndarray:
        """True where a marker is occluded, shape (n_frames, n_markers)."""
        return np.isnan(self._xyz).any(axis=2)

    def as_array(self) -> np.ndarray:
        """A writable copy of the positions, shape (n_frames, n_markers, 3), mm."""
        return self._xyz.copy()

    def index(self, name: str) -> int:
        """Column of marker `name`; InputError if the trial has no such marker."""
        try:
            return self._index[name]
        except KeyError:
            raise InputError([f"no marker {name!r} in the trial (it has {self.n_markers}: "
                              f"{', '.join(self._labels)})"], source=self._source) from None

    def seen(self, labels: Sequence[str]) -> set:
        """The names of `labels` the trial has and shows at least once (a frame with all three coordinates)."""
        return {m for m in labels
                if m in self._index and bool(np.isfinite(self._xyz[:, self._index[m]]).all(axis=1).any())}

    def marker(self, name: str) -> np.ndarray:
        """Trajectory of one marker, shape (n_frames, 3), mm (a copy)."""
        return self._xyz[:, self.index(name)].copy()

    def require_usable(self, labels: Sequence[str], where: dict | None = None, lengths: dict | None = None,
                       neighbours: dict | None = None) -> None:
        """Raise unless every label is in the trial, visible in at least one frame, no two of them coincide and no
        segment's markers lie farther apart than a body segment can.

        Parameters
        ----------
        labels : sequence of str
            The model's markers.
        where : dict, optional
            label -> the model's segment holding it (named in the message).
        lengths : dict, optional
            segment -> its declared length (mm), which sets how far apart its markers may lie in place of
            :data:`LONGEST_SEGMENT_MM` (:data:`LONGEST_SHARE` of it), and which its markers must reach a share of
            (:data:`SMALLEST_REACH_SHARE`).
        neighbours : dict, optional
            segment -> the segments near it (the model's: within two joints): a segment's reach is measured to its
            own markers and theirs (default: to every marker of `labels`).

        Raises
        ------
        InputError
            Names, at once, every marker missing from the trial, every marker never visible (not silently dropped:
            its segment and the joints beside it would change case without a word), every pair of markers
            that coincide (:meth:`coincident`), and every segment whose markers lie farther apart than a body
            segment can (:data:`LONGEST_SEGMENT_MM`, or :data:`LONGEST_SHARE` times its declared length: a units
            field that scaled the numbers up).
        """
        where = where or {}
        seg = lambda lab: f" (segment {where[lab]!r})" if lab in where else ""  # noqa: E731
        problems = []
        for lab in labels:
            if lab not in self._index:
                prefixed = [t for t in self._labels if t.endswith(SUBJECT_SEPARATOR + lab)]
                hint = "" if not prefixed else (
                    f" (the trial has {', '.join(map(repr, prefixed[:3]))}: a subject prefix, as Vicon writes "
                    "'Subject:Marker', which is removed by itself only when one prefix makes every marker of the "
                    f"model match; name the model's marker {prefixed[0]!r}, or fix the trial's labels)")
                problems.append(f"marker {lab!r}{seg(lab)} of the model is not in the trial{hint}")
            elif not np.isfinite(self._xyz[:, self._index[lab]]).all(axis=1).any():
                problems.append(f"marker {lab!r}{seg(lab)} is in the model but never visible in the trial's frames "
                                f"{self.frame_number(0)} to {self.frame_number(self.n_frames - 1)} (every sample is "
                                "empty): fix its labelling, choose other frames, or remove it from the model")
        present = [lab for lab in labels if lab in self._index]
        pairs = self.coincident(present)
        every = len(present) * (len(present) - 1) // 2
        close = sorted({lab for pair in pairs for lab in pair})
        span = float(np.nanmax(np.abs(self.select(close).as_array()))) if close else float("inf")
        if len(present) >= 3 and (len(pairs) == every or (2 * len(pairs) >= every and span < METRES_ROOM_MM)):
            # every marker, or most pairs, within a millimetre of each other, in a room's size in metres: one scale
            # error, not many labelling ones (metres labelled mm put a leg's 45 pairs 43 times within a millimetre,
            # and each had been listed as two labels of one marker, units never mentioned); one marker exported under
            # several labels, in mm, stays a labelling problem
            how = "all" if len(pairs) == every else f"{len(pairs)} pairs of the"       # (all: `close` is every one)
            raise InputError(problems + [f"{how} {len(present)} markers of the model lie within {COINCIDENT_MM:g} mm "
                                         f"of each other in every frame (no coordinate beyond {span:.3g} mm): the "
                                         "coordinates look like metres in a file that says mm; fix its units field"],
                             source=self._source)
        for a, b in pairs:
            problems.append(f"markers {a!r}{seg(a)} and {b!r}{seg(b)} coincide: closer than {COINCIDENT_MM:g} mm in "
                            "every frame where both are seen, which two real markers cannot be; one marker exported "
                            "under two labels? fix the labelling, or remove one from the model")
        problems += self._overlong_segments(present, where, lengths or {})
        problems += self._undersized_segments(present, where, lengths or {}, neighbours)
        if problems:
            raise InputError(problems, source=self._source)

    def _median_distances(self, a: Sequence[str], b: Sequence[str]) -> np.ndarray:
        """The median distance (mm) between each marker of `a` and each of `b` over the frames where both are seen
        (at most :data:`SPAN_FRAMES` of them, evenly spread), (len(a), len(b)); NaN where two are never seen together
        or are the same marker."""
        rows = np.unique(np.linspace(0, self.n_frames - 1, min(self.n_frames, SPAN_FRAMES)).astype(int))
        xa = self._xyz[np.ix_(rows, [self._index[n] for n in a])]
        xb = self._xyz[np.ix_(rows, [self._index[n] for n in b])]
        d = np.linalg.norm(xa[:, :, None] - xb[:, None], axis=3)                    # (frames, a, b)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)                      # (pairs never seen together)
            out = np.nanmedian(d, axis=0)
        out[np.array(a)[:, None] == np.array(b)[None, :]] = np.nan
        return out

    def _undersized_segments(self, labels: Sequence[str], where: dict, declared: dict,
                             neighbours: dict | None = None) -> list[str]:
        """A problem for each segment the model declares long (`declared`: segment -> mm, ``length_mm``) none of whose
        markers lies :data:`SMALLEST_REACH_SHARE` of that length from a marker of its own or of a segment near it
        (`neighbours`: segment -> segments; default every marker of `labels`; `where`: label -> segment), naming the
        farthest pair: a units field that scaled the numbers down. (Measured to every marker of a whole body, a head
        1.2 m from a thigh, read as 120 mm, would have let centimetres pass.)"""
        out = []
        for segment, length in declared.items():
            own = [lab for lab in labels if where.get(lab) == segment]
            near = set(neighbours.get(segment, ())) | {segment} if neighbours is not None else None
            partners = [lab for lab in labels if near is None or where.get(lab) in near]
            if not own or not length or len(partners) < 2:
                continue
            d = self._median_distances(own, partners)
            if not np.isfinite(d).any():
                continue
            i, j = np.unravel_index(np.nanargmax(d), d.shape)
            reach = float(d[i, j])
            if reach < SMALLEST_REACH_SHARE * float(length):
                out.append(f"segment {segment!r} is declared {float(length):g} mm long (length_mm), but no marker on "
                           f"it or near it lies farther than {reach:.1f} mm from its markers ({own[i]!r} to "
                           f"{partners[j]!r}, median over the frames where both are seen): are the coordinates in a "
                           f"larger unit than the file's units field says (centimetres in a file that says mm)? fix "
                           f"the units field, or the model's length_mm")
        return out

    def _overlong_segments(self, labels: Sequence[str], where: dict, declared: dict) -> list[str]:
        """A problem for each segment (`where`: label -> segment) two of whose markers among `labels` lie more than
        :data:`LONGEST_SEGMENT_MM` apart or, where the model declares the segment's length (`declared`: segment -> mm,
        ``length_mm``), more than :data:`LONGEST_SHARE` times that and :data:`LONGEST_DECLARED_MM`: the median of the
        two markers' distance over the frames where both are seen (at most :data:`SPAN_FRAMES` of them, evenly
        spread), naming the farthest pair."""
        by_segment: dict = {}
        for lab in labels:
            if lab in where:
                by_segment.setdefault(where[lab], []).append(lab)
        out = []
        for segment, names in by_segment.items():
            length = float(declared.get(segment) or 0.0)
            limit = max(LONGEST_SHARE * length, LONGEST_DECLARED_MM) if length > 0 else LONGEST_SEGMENT_MM
            d = self._median_distances(names, names)
            if not np.isfinite(d).any():
                continue
            i, j = np.unravel_index(np.nanargmax(d), d.shape)
            widest, pair = float(d[i, j]), (names[i], names[j])
            if widest > limit:
                if length > 0:
                    out.append(f"segment {segment!r} is declared {length:g} mm long (length_mm), but its markers span "
                               f"{widest / 1000:.3g} m ({pair[0]!r} to {pair[1]!r}, median over the frames where both "
                               f"are seen), over {limit / length:.3g} times that: are the coordinates ten times too "
                               f"large for their units (millimetres in a file that says cm, a scale factor off)? fix "
                               f"the units field, the labels, or the model's length_mm")
                    continue
                out.append(f"segment {segment!r} spans {widest / 1000:.3g} m ({pair[0]!r} to {pair[1]!r}, median over "
                           f"the frames where both are seen): no body segment is that long; are the coordinates in a "
                           f"smaller unit than the file's units field says (millimetres in a file that says cm or m)? "
                           f"fix the units field or the labels; a body truly that long (a boat, an oar) passes with "
                           f"its length_mm declared in the model")
        return out

    def unprefixed(self, labels: Sequence[str]) -> tuple["Trial", str | None]:
        """The trial with a subject prefix taken off its labels, when that alone makes them match `labels`.

        Vicon Nexus labels a subject's markers ``Subject:Marker`` (``Name:RASI``); a model names them ``RASI``.
        When no marker of `labels` is in the trial, but every one of them is there behind one and the same
        prefix ending in ``:``, the prefix is removed from every label that carries it (a label it would make
        equal to another is left as it is) and a warning naming the prefix is returned. Otherwise the trial is
        returned as it is (:meth:`require_usable` then names the prefixed labels in its message).

        Parameters
        ----------
        labels : sequence of str
            The model's markers.

        Returns
        -------
        trial : Trial
            This trial, or one with the prefix removed.
        warning : str or None
            The warning to report when the prefix was removed.

        Examples
        --------
        >>> import numpy as np
        >>> t = Trial.from_array(np.zeros((2, 2, 3)), ["Sub:RASI", "Sub:LASI"], rate_hz=100.0)
        >>> t2, warning = t.unprefixed(["RASI", "LASI"])
        >>> t2.labels
        ('RASI', 'LASI')
        """
        labels = list(labels)
        if not labels or any(lab in self._index for lab in labels):
            return self, None
        common = None
        for lab in labels:
            found = {t[:-len(lab)] for t in self._labels
                     if t.endswith(SUBJECT_SEPARATOR + lab) and len(t) > len(lab) + 1}
            common = found if common is None else common & found
            if not common:
                return self, None
        if len(common) != 1:
            return self, None
        (prefix,) = common
        taken = set(self._labels)
        renamed = []
        for t in self._labels:
            short = t[len(prefix):] if t.startswith(prefix) else t
            renamed.append(short if short == t or short not in taken else t)
        if len(set(renamed)) != len(renamed):           # two prefixed labels with the same marker name: leave them
            return self, None
        n = sum(a != b for a, b in zip(renamed, self._labels))
        return self.replace(labels=renamed), (
            f"{self._source}: the trial's marker labels carry the subject prefix {prefix!r} (Vicon's 'Subject:Marker') "
            f"and none of the model's markers is in the trial without it: the prefix was removed from {n} label(s) "
            f"so that they match the model (e.g. {prefix + labels[0]!r} is read as {labels[0]!r})")

    def coincident(self, labels: Sequence[str]) -> list[tuple[str, str]]:
        """Pairs of `labels` that are seen together in some frame and are closer than :data:`COINCIDENT_MM` in
        every frame where both are seen: one marker under two labels (two real markers cannot overlap), which
        leaves its segment without a pose in any frame.

        Pairs are screened on up to 64 frames spread over the trial first, so a trial of many markers and frames
        costs little; only pairs that stay close there are checked on every frame."""
        cols = [self._index[lab] for lab in labels]
        xyz = self._xyz[:, cols]
        near = np.ones((len(cols), len(cols)), dtype=bool)
        for f in np.unique(np.linspace(0, self.n_frames - 1, min(self.n_frames, 64)).astype(int)):
            with np.errstate(invalid="ignore"):
                near &= ~(np.linalg.norm(xyz[f, :, None] - xyz[f, None, :], axis=2) >= COINCIDENT_MM)
        pairs = []
        for i, k in zip(*np.nonzero(np.triu(near, 1))):
            d = np.linalg.norm(xyz[:, i] - xyz[:, k], axis=1)
            both = np.isfinite(d)
            if both.any() and (d[both] < COINCIDENT_MM).all():
                pairs.append((labels[i], labels[k]))
        return pairs

    def recentred(self) -> tuple["Trial", np.ndarray]:
        """The trial moved so that the median of its samples is near the origin, and the move (whole mm).

        Joint parameters do not depend on where the capture volume's origin is, but sums of squares of
        coordinates do, in float64: a volume 100 m from its origin moved fitted distances by a millimetre. The
        verbs fit the recentred trial and add the move back to whatever they write in world coordinates. The move
        is rounded to whole millimetres so that subtracting it loses no digit of the file's numbers."""
        seen = np.isfinite(self._xyz).all(axis=2)
        offset = np.round(np.median(self._xyz[seen], axis=0)) if seen.any() else np.zeros(3)
        return (self if not offset.any() else self.replace(xyz=self._xyz - offset)), offset

    def select(self, labels: Sequence[str]) -> "Trial":
        """Trial with only `labels`, in that order.

        Raises
        ------
        InputError
            Names every requested marker the trial lacks, at once.
        """
        labels = tuple(labels)
        missing = [lab for lab in labels if lab not in self._index]
        if missing:
            raise InputError([f"marker(s) missing from the trial: {', '.join(missing)}"],
                             source=self._source)
        cols = [self._index[lab] for lab in labels]
        return Trial(self._xyz[:, cols], labels, self._rate_hz, self._source, self._first_frame, self._numbered)

    def replace(self, xyz=None, labels=None, rate_hz=None, source=None, first_frame=None) -> "Trial":
        """A new trial with some parts replaced (positions in mm); the rest is shared. A `first_frame` given is a
        file's numbering (written as given), not an array's row count."""
        return Trial(self._xyz if xyz is None else xyz,
                     self._labels if labels is None else labels,
                     self._rate_hz if rate_hz is None else rate_hz,
                     self._source if source is None else source,
                     self._first_frame if first_frame is None else first_frame,
                     self._numbered if first_frame is None else True)

    @property
    def first_frame(self) -> int:
        """The file's own number of row 0 (TRC Frame#, C3D header first frame); for a trial made from an array, the
        row's own count (0, or the first row kept by :meth:`frames`)."""
        return self._first_frame

    def frame_number(self, row) -> int | np.ndarray:
        """The file's frame number(s) of row index(es) `row`."""
        return self.first_frame + np.asarray(row) if np.ndim(row) else self.first_frame + int(row)

    def frames(self, spec: str) -> "Trial":
        """The frames ``START:END`` of the file's own numbering, both included (either end may be left out).

        Raises
        ------
        InputError
            Not ``START:END`` with integers, or a range holding no frame of the trial (the message gives
            the trial's own range).
        """
        first, last = self.first_frame, self.first_frame + self.n_frames - 1
        try:
            start, end = frame_range(spec)
        except ValueError:
            raise InputError([f"--frames {spec!r}: expected START:END in the file's frame numbers "
                              f"({first}:{last} here)"], source=self._source) from None
        if start is not None and end is not None and end < start:         # (both given: an end filled in is no END)
            raise InputError([f"--frames {spec}: END before START (give START:END, both included, in the file's "
                              f"frame numbers: {first} to {last} here)"], source=self._source)
        start = first if start is None else start
        end = last if end is None else end
        if end < start or end < first or start > last:
            raise InputError([f"--frames {spec}: no frame of the trial in that range (the file's frames are "
                              f"{first} to {last})"], source=self._source)
        if start < first or end > last:
            warnings.warn(f"{self._source}: --frames {spec} reaches beyond the file's frames ({first} to {last}): "
                          f"using {max(start, first)}:{min(end, last)}", UserWarning, stacklevel=2)
        lo, hi = max(start, first) - first, min(end, last) - first
        return Trial(self._xyz[lo:hi + 1], self._labels, self._rate_hz, self._source, first + lo, self._numbered)

    # ------------------------------------------------------------------ writers
    def to_trc(self, path) -> None:
        """Write an OpenSim TRC file in mm, its frames numbered as the file this trial was read from (from 0 when
        that file's were); a trial made from an array has its row r written as frame r + 1, cut or not."""
        write_trc(path, self._xyz, self._labels, self._rate_hz, first_frame=self._file_numbering())

    def to_c3d(self, path) -> None:
        """Write a C3D file in mm (32-bit float coordinates), numbered as :meth:`to_trc` numbers a TRC; a C3D header
        numbers frames from 1 to 65535 (16 bits), so a trial numbered from 0 or below, or beyond 65535, is written
        from 1, with a warning (numbered from 70000, it had been written from 4464: the number less 65536)."""
        from identcheck.io.c3d import MAX_FRAMES

        first = self._file_numbering()
        last = first + self.n_frames - 1
        if first < 1 or last > MAX_FRAMES:
            warnings.warn(f"{path}: a C3D file numbers its frames from 1 to {MAX_FRAMES}: the trial's frames {first} "
                          f"to {last} are written as 1 to {self.n_frames}", UserWarning, stacklevel=2)
            first = 1
        write_c3d(path, self._xyz, self._labels, self._rate_hz, first_frame=first)

    def _file_numbering(self) -> int:
        """The number a written file gives row 0: the file's own, or one more than the row's own count for a trial
        no file numbered (an array's row r is written as frame r + 1, cut or not)."""
        return self._first_frame if self._numbered else self._first_frame + 1

    def to_file(self, path) -> None:
        """Write ``.trc`` or ``.c3d`` by extension (any case)."""
        path = Path(path)
        self.to_trc(path) if _format(path) == ".trc" else self.to_c3d(path)

    def __repr__(self) -> str:
        return (f"Trial(n_frames={self.n_frames}, n_markers={self.n_markers}, "
                f"rate_hz={self._rate_hz:g}, source={self._source!r})")
