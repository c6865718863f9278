"""Marker-plan model: segments, their markers and the joints that connect them (TOML).

The model file is the one described in docs/contract.md (reference: docs/model.md)::

    units = "mm"
    [segments.pelvis]
    markers = ["LASI", "RASI", "SACR"]
    [segments.thigh_r]
    markers = ["RGT", "RTHI", "RKNE"]
    [joints.hip_r]
    type = "spherical"
    parent = "pelvis"
    child = "thigh_r"

Optional extensions, used by :mod:`identcheck.simulate.rigid` to make a synthetic subject
deterministic (all coordinates in the file's ``units``, converted to mm on load):

- ``[segments.NAME.positions]`` ``MARKER = [x, y, z]``: marker position in the segment frame;
- ``segments.NAME.length_mm``: segment length in mm;
- ``joints.NAME.axis = [x, y, z]``: hinge direction of a revolute joint, in the parent frame;
- ``joints.NAME.centre_parent`` / ``centre_child``: joint centre (revolute: a point on the
  hinge axis) in the parent / child segment frame.

and, for ``fit``'s comparison with Davis et al.'s (1991) hip-centre regression (:mod:`identcheck.fit.anatomy`),
the subject's measurements, always in mm:

- ``[subject]`` ``leg_length_mm`` (both legs) or ``right_leg_length_mm`` / ``left_leg_length_mm``, and
  ``marker_diameter_mm`` (default 14, Plug-in Gait's).

Every problem in a file is collected and reported at once in a single :class:`InputError`
that names the file and the TOML key.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from identcheck.errors import InputError
from identcheck.io.text import read_toml

JOINT_TYPES = ("revolute", "spherical")
"""Joint types a model may declare."""

MODEL_UNITS = {"mm": 1.0, "m": 1000.0}
"""Allowed ``units`` values and their factor to millimetres."""

TOP_KEYS = ("units", "segments", "joints", "subject")
SUBJECT_KEYS = {"leg_length_mm": (300.0, 1500.0), "right_leg_length_mm": (300.0, 1500.0),
                "left_leg_length_mm": (300.0, 1500.0), "marker_diameter_mm": (2.0, 40.0)}
"""The ``[subject]`` keys and the range (mm) a value must lie in: a leg of 0.9 written as metres is an error."""
SEGMENT_KEYS = ("markers", "positions", "length_mm")
JOINT_KEYS = ("type", "parent", "child", "axis", "centre_parent", "centre_child")

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Segment:
    """A rigid body carrying markers.

    Attributes
    ----------
    name : str
    markers : tuple of str
        Marker names in file order; may be empty.
    positions : dict of str to tuple of 3 float, optional
        Marker positions in the segment frame, in mm (only those the file gives).
    length_mm : float, optional
        Segment length in mm, if the file gives it.
    """

    name: str
    markers: tuple[str, ...] = ()
    positions: dict[str, Vec3] | None = None
    length_mm: float | None = None


@dataclass(frozen=True)
class Joint:
    """A joint between a parent and a child segment.

    Attributes
    ----------
    name : str
    type : str
        One of :data:`JOINT_TYPES`.
    parent, child : str
        Segment names.
    axis : tuple of 3 float, optional
        Unit hinge direction in the parent frame (revolute only), if the file gives it.
    centre_parent, centre_child : tuple of 3 float, optional
        Joint centre (revolute: a point on the hinge axis) in the parent / child frame, mm.
    """

    name: str
    type: str
    parent: str
    child: str
    axis: Vec3 | None = None
    centre_parent: Vec3 | None = None
    centre_child: Vec3 | None = None


@dataclass(frozen=True)
class Model:
    """A tree of segments joined by joints, with the markers each segment carries.

    Build it with :meth:`from_toml` or :meth:`from_dict`; direct construction (for example
    through ``dataclasses.replace``) checks the tree too.

    Attributes
    ----------
    segments : dict of str to Segment
    joints : dict of str to Joint
    units : str
        The ``units`` key of the file ("mm" or "m"); positions are stored in mm regardless.
    source : str
        Where the model came from, used in error messages.
    subject : dict of str to float
        The ``[subject]`` measurements (mm), those the file gives.
    root : str
        The one segment that is no joint's child.
    joint_order : tuple of str
        Joint names, every parent's joint before its children's (breadth first from the root).
    markers : tuple of str
        Every marker name, segment by segment in file order.
    """

    segments: dict[str, Segment]
    joints: dict[str, Joint] = field(default_factory=dict)
    units: str = "mm"
    source: str = "<dict>"
    subject: dict = field(default_factory=dict)
    root: str = field(init=False)
    joint_order: tuple[str, ...] = field(init=False)
    markers: tuple[str, ...] = field(init=False)
    _marker_segment: dict[str, str] = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        problems = _check_parts(self.segments, self.joints) + _check_tree(self.segments, self.joints)
        if problems:
            raise InputError(problems, source=self.source)
        root, order = _order(self.segments, self.joints)
        owner = {m: s.name for s in self.segments.values() for m in s.markers}
        object.__setattr__(self, "root", root)
        object.__setattr__(self, "joint_order", order)
        object.__setattr__(self, "markers", tuple(owner))
        object.__setattr__(self, "_marker_segment", owner)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_toml(cls, path) -> "Model":
        """Load and check a model file.

        Parameters
        ----------
        path : str or os.PathLike
            TOML model file (docs/model.md).

        Returns
        -------
        Model

        Raises
        ------
        InputError
            File missing or unreadable, TOML syntax error (with its line), or any model
            problem (all listed at once, each naming its TOML key).

        Examples
        --------
        >>> model = Model.from_toml("examples/leg.toml")   # doctest: +SKIP
        >>> model.root, model.joint_order                  # doctest: +SKIP
        ('pelvis', ('hip_r', 'knee_r', 'ankle_r'))
        """
        data, source = read_toml(path, "model file")
        return cls.from_dict(data, source=source)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "<dict>") -> "Model":
        """Build a model from the dictionary a TOML model file parses to.

        Parameters
        ----------
        d : mapping
            ``{"units": ..., "segments": {...}, "joints": {...}}`` as in the TOML file.
        source : str
            Name used in error messages.

        Returns
        -------
        Model

        Raises
        ------
        InputError
            Every problem found (missing keys, wrong types, unknown segments or joint types,
            duplicate markers, cycles, several roots), at once.
        """
        problems: list[str] = []
        if not isinstance(d, Mapping):
            raise InputError([f"expected a table of model keys, got {type(d).__name__}"],
                             source=source)
        _unknown_keys(d, TOP_KEYS, "", problems)
        units = d.get("units", "mm")
        if not isinstance(units, str) or units not in MODEL_UNITS:
            problems.append(f"units: {units!r} is not a known unit (allowed: "
                            f"{', '.join(MODEL_UNITS)})")
            units = "mm"
        scale = MODEL_UNITS[units]
        segments = _parse_segments(d.get("segments"), scale, problems)
        joints, dropped = _parse_joints(d.get("joints", {}), segments, scale, problems)
        problems += _check_tree(segments, joints, check_roots=not dropped) + _reserved_markers(segments, joints)
        subject = _parse_subject(d.get("subject", {}), problems)
        if problems:
            raise InputError(problems, source=source)
        return cls(segments=segments, joints=joints, units=units, source=source, subject=subject)

    # ------------------------------------------------------------------ queries
    def marker_segment(self, name: str) -> str:
        """Name of the segment carrying marker `name`.

        Raises
        ------
        InputError
            The model has no such marker.
        """
        try:
            return self._marker_segment[name]
        except KeyError:
            raise InputError([_unknown("marker", name, self.markers)], source=self.source) from None

    def require_markers_in(self, trial, names=None) -> None:
        """:meth:`identcheck.trial.Trial.require_usable` for the model's markers (or `names` of them) in `trial`, each
        named with its segment, each segment's declared length (``length_mm``) allowed for its span and asked of its
        markers' reach to the markers of the segments within two joints of it."""
        names = self.markers if names is None else names
        beside: dict = {}
        for j in self.joints.values():
            beside.setdefault(j.parent, set()).add(j.child)
            beside.setdefault(j.child, set()).add(j.parent)
        # within two joints: a shank marker at the tuberosity and a thigh marker at the epicondyle are 6 cm apart,
        # the pelvis's markers beyond them half a metre
        near = {s: set(b).union(*(beside[t] for t in b)) for s, b in beside.items()}
        trial.require_usable(names, {m: self.marker_segment(m) for m in names},
                             {name: seg.length_mm for name, seg in self.segments.items() if seg.length_mm}, near)

    def parent_joint(self, segment: str) -> Joint | None:
        """The joint whose child is `segment` (None for the root)."""
        return next((j for j in self.joints.values() if j.child == segment), None)

    def child_joints(self, segment: str) -> tuple[Joint, ...]:
        """Joints whose parent is `segment`, in ``joint_order``."""
        return tuple(self.joints[n] for n in self.joint_order if self.joints[n].parent == segment)

    def joint_markers(self, joint: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """Markers on the parent and on the child segment of `joint` (the p and q of a case)."""
        j = self.joints[joint]
        return self.segments[j.parent].markers, self.segments[j.child].markers

    def joint_points(self, segment: str) -> int:
        """How many points the joints beside `segment` fix on it once their other segments are posed: a ball joint's
        centre one, a hinge's axis two (three in general position pose a segment without markers)."""
        return sum(1 if j.type == "spherical" else 2 for j in self.joints.values() if segment in (j.parent, j.child))

    def segments_below(self, segment: str) -> set:
        """`segment` and every segment hanging from it."""
        out, stack = set(), [segment]
        while stack:
            seg = stack.pop()
            out.add(seg)
            stack += [j.child for j in self.child_joints(seg)]
        return out

    def without_subtrees(self, joints) -> tuple["Model", dict]:
        """(this model without `joints` and everything hanging from them, {each joint left out: the one of `joints`
        it is or hangs below}, parents first): what a whole-tree fit leaves out when a segment cannot be posed (a
        foot without markers), so that the rest of the tree is fitted."""
        cut: dict = {}                                             # segment left out -> the joint of `joints` above it
        gone: dict = {}
        for j in self.joint_order:                                 # parents before children
            jt = self.joints[j]
            if j in joints or jt.parent in cut:
                cut[jt.child] = j if j in joints else cut[jt.parent]
                gone[j] = cut[jt.child]
        keep = {j: jt for j, jt in self.joints.items() if j not in gone}
        return replace(self, segments={n: s for n, s in self.segments.items() if n not in cut}, joints=keep), gone

    def below_root(self) -> tuple["Model", dict]:
        """(the model below its root while nothing poses the root, {each joint left out: the root's joint it is or
        hangs below}): a root with no marker whose joints lend fewer than three points (:meth:`joint_points`) is left
        out with its joints, and the subtree of its child that holds joints (and of those, the most markers) kept,
        again while its own root is posed by nothing; the model itself and {} when the root is posed (or has no
        joint). The other subtrees of such a root are left out with it: its pose, which would join them, is not seen.
        (A root with markers the trial never shows is refused before this, as any such marker is.)"""
        model, gone = self, {}
        while True:
            down = model.child_joints(model.root)
            if model.segments[model.root].markers or model.joint_points(model.root) >= 3 or not down:
                return model, gone

            def weight(joint) -> tuple:
                below = model.segments_below(joint.child)
                return len(below) > 1, sum(len(model.segments[s].markers) for s in below)

            keep = max(down, key=weight)
            inside = model.segments_below(keep.child)
            for n in model.joint_order:
                j = model.joints[n]
                if j.parent not in inside:
                    gone[n] = n if j.parent == model.root else gone[model.parent_joint(j.parent).name]
            model = replace(model, segments={n: s for n, s in model.segments.items() if n in inside},
                            joints={n: j for n, j in model.joints.items() if j.parent in inside})

    def to_dict(self) -> dict:
        """The TOML-shaped dictionary (coordinates in mm, ``units = "mm"``); ``from_dict`` inverts it."""
        segs = {}
        for s in self.segments.values():
            entry: dict[str, Any] = {"markers": list(s.markers)}
            if s.positions:
                entry["positions"] = {m: list(p) for m, p in s.positions.items()}
            if s.length_mm is not None:
                entry["length_mm"] = s.length_mm
            segs[s.name] = entry
        joints = {}
        for j in self.joints.values():
            entry = {"type": j.type, "parent": j.parent, "child": j.child}
            for key in ("axis", "centre_parent", "centre_child"):
                if getattr(j, key) is not None:
                    entry[key] = list(getattr(j, key))
            joints[j.name] = entry
        out = {"units": "mm", "segments": segs, "joints": joints}
        if self.subject:
            out["subject"] = dict(self.subject)
        return out


# ---------------------------------------------------------------------- parsing helpers
def _parse_subject(raw, problems: list[str]) -> dict:
    """The ``[subject]`` table: each key known, each value a number of mm within its plausible range."""
    if not isinstance(raw, Mapping):
        problems.append(f"subject: expected a table ([subject]), got {type(raw).__name__}")
        return {}
    _unknown_keys(raw, tuple(SUBJECT_KEYS), "subject.", problems)
    out = {}
    for key, (lo, hi) in SUBJECT_KEYS.items():
        if key not in raw:
            continue
        v = raw[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            problems.append(f"subject.{key}: expected a number of mm, got {v!r}")
        elif not lo <= v <= hi:
            problems.append(f"subject.{key}: {v} mm is outside {lo:g}..{hi:g} mm (the value is always in mm)")
        else:
            out[key] = float(v)
    if "leg_length_mm" in out and ("right_leg_length_mm" in out or "left_leg_length_mm" in out):
        problems.append("subject: give leg_length_mm (both legs) or right_/left_leg_length_mm, not both")
    return out

def _unknown(kind: str, name: str, known) -> str:
    known = list(known)
    close = difflib.get_close_matches(str(name), known, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    listing = ", ".join(known) if known else "none"
    return f"unknown {kind} {name!r} (known: {listing}){hint}"


def _unknown_keys(table: Mapping, allowed, where: str, problems: list[str]) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append(f"{where}{key}: unknown key (allowed: {', '.join(allowed)}){hint}")


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


LARGEST_MM = 1e5
"""No length, marker position or joint centre of a model may exceed 100 m: no body or prop comes near, and a larger
number is a typo or a unit mistake that would overflow what is computed from it (1e300 mm did, in ``simulate``)."""


def _vec3(value, key: str, problems: list[str], scale: float = 1.0, bounded: bool = True) -> Vec3 | None:
    """Three finite numbers times `scale`; `bounded`: a position, within :data:`LARGEST_MM` (an axis is not)."""
    if (isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value)):
        out = tuple(float(v) * scale for v in value)
        if not bounded or max(map(abs, out)) <= LARGEST_MM:
            return out
        problems.append(f"{key}: {value!r} is more than {LARGEST_MM / 1000:g} m from the origin (a typo or a unit "
                        "mistake?)")
        return None
    problems.append(f"{key}: expected 3 finite numbers [x, y, z], got {value!r}")
    return None


def _parse_segments(raw, scale: float, problems: list[str]) -> dict[str, Segment]:
    if raw is None:
        problems.append("segments: missing; add at least one [segments.NAME] table")
        return {}
    if not isinstance(raw, Mapping):
        problems.append(f"segments: expected a table of segments, got {type(raw).__name__}")
        return {}
    if not raw:
        problems.append("segments: empty; add at least one [segments.NAME] table")
    segments: dict[str, Segment] = {}
    owner: dict[str, str] = {}
    for name, table in raw.items():
        key = f"segments.{name}"
        if not isinstance(table, Mapping):
            problems.append(f"{key}: expected a table, got {type(table).__name__}")
            continue
        _unknown_keys(table, SEGMENT_KEYS, key + ".", problems)
        markers = table.get("markers")
        if markers is None:
            problems.append(f"{key}.markers: missing (use markers = [] for a segment without markers)")
            markers = []
        elif not (isinstance(markers, list) and all(isinstance(m, str) and m.strip() for m in markers)):
            problems.append(f"{key}.markers: expected a list of non-empty marker names, got {markers!r}")
            markers = [m for m in markers if isinstance(m, str) and m.strip()] if isinstance(markers, list) else []
        kept = []
        for m in markers:
            if m != m.strip():      # a trial's labels are read without them: the name could never be found
                problems.append(f"{key}.markers: {m!r} has spaces at its start or end, which no label read from a "
                                f"C3D or TRC file keeps (it would never be found in a trial): write {m.strip()!r}")
                continue
            if m in owner:
                where = "twice in" if owner[m] == name else f"in both segments.{owner[m]}.markers and"
                problems.append(f"duplicate marker {m!r}: listed {where} {key}.markers")
                continue
            owner[m] = name
            kept.append(m)
        positions = _parse_positions(table.get("positions"), key, kept, scale, problems)
        length = table.get("length_mm")
        if length is not None and not (_is_number(length) and 0 < length <= LARGEST_MM):
            problems.append(f"{key}.length_mm: expected a positive number of mm up to {LARGEST_MM:g} (100 m), got "
                            f"{length!r}")
            length = None
        segments[name] = Segment(name=name, markers=tuple(kept), positions=positions,
                                 length_mm=None if length is None else float(length))
    return segments


def _parse_positions(raw, key: str, markers, scale: float, problems: list[str]):
    if raw is None:
        return None
    if not isinstance(raw, Mapping):
        problems.append(f"{key}.positions: expected a table MARKER = [x, y, z], got {type(raw).__name__}")
        return None
    out: dict[str, Vec3] = {}
    for m, value in raw.items():
        if m not in markers:
            problems.append(f"{key}.positions.{m}: marker not listed in {key}.markers")
            continue
        p = _vec3(value, f"{key}.positions.{m}", problems, scale)
        if p is not None:
            out[m] = p
    names = list(out)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if math.dist(out[a], out[b]) < 1e-9:
                problems.append(f"{key}.positions: markers {a!r} and {b!r} are at the same position")
    return out or None


def _parse_joints(raw, segments, scale: float, problems: list[str]) -> tuple[dict[str, Joint], bool]:
    """Joints with valid ends, and whether some joint was left out for bad ends."""
    if not isinstance(raw, Mapping):
        problems.append(f"joints: expected a table of joints, got {type(raw).__name__}")
        return {}, True
    joints: dict[str, Joint] = {}
    dropped = False
    for name, table in raw.items():
        key = f"joints.{name}"
        if not isinstance(table, Mapping):
            problems.append(f"{key}: expected a table, got {type(table).__name__}")
            continue
        _unknown_keys(table, JOINT_KEYS, key + ".", problems)
        values = {k: table.get(k) for k in ("type", "parent", "child")}
        for k, v in values.items():
            if v is None:
                problems.append(f"{key}.{k}: missing")
            elif not isinstance(v, str):
                problems.append(f"{key}.{k}: expected a string, got {v!r}")
        jtype = values["type"]
        if isinstance(jtype, str) and jtype.strip().lower() in JOINT_TYPES:
            jtype = jtype.strip().lower()       # "Revolute" as `identcheck rank` and `table` take it
        elif isinstance(jtype, str):
            problems.append(f"{key}.type: unknown joint type {jtype!r} (allowed: {', '.join(JOINT_TYPES)})")
        # a joint with good ends stays in the tree whatever else is wrong with it, so that
        # its segments are not also reported as disconnected
        ok = True
        for k in ("parent", "child"):
            v = values[k]
            if not isinstance(v, str):
                ok = False
            elif segments and v not in segments:
                problems.append(f"{key}.{k}: " + _unknown("segment", v, segments))
                ok = False
        if ok and values["parent"] == values["child"]:
            problems.append(f"{key}: parent and child are the same segment {values['parent']!r}")
            ok = False
        axis = None
        if "axis" in table:
            axis = _vec3(table["axis"], f"{key}.axis", problems, bounded=False)
            if axis is not None and math.hypot(*axis) < 1e-12:
                problems.append(f"{key}.axis: must not be the zero vector")
                axis = None
            elif axis is not None:
                n = math.hypot(*axis)
                axis = tuple(a / n for a in axis)
            if jtype == "spherical":
                problems.append(f"{key}.axis: only a revolute joint has a hinge axis")
        centres = {k: _vec3(table[k], f"{key}.{k}", problems, scale) if k in table else None
                   for k in ("centre_parent", "centre_child")}
        if ok:
            joints[name] = Joint(name=name, type=jtype, parent=values["parent"],
                                 child=values["child"], axis=axis, **centres)
        dropped |= not ok
    return joints, dropped


# ---------------------------------------------------------------------- virtual markers
def virtual_names(joint: str, kind: str) -> tuple:
    """The names of a joint's virtual markers: ``JOINT.centre`` (ball), ``JOINT.axis0``, ``JOINT.axis1`` (hinge)."""
    return (f"{joint}.centre",) if kind == "spherical" else (f"{joint}.axis0", f"{joint}.axis1")


def reserved_names(joints) -> dict[str, str]:
    """Virtual-marker name -> its joint, for the joints named in `joints`, of either type: no measured marker
    may carry one (fit, plan and ``--export-markers`` add markers of these names beside the measured ones)."""
    return {n: j for j in joints for kind in JOINT_TYPES for n in virtual_names(j, kind)}


def refuse_exported_points(trial, joints) -> None:
    """Raise InputError when `trial` holds a marker named like a virtual marker of one of `joints` (``hip_r.centre``,
    ``knee_r.axis0``): a file ``--export-markers`` wrote, whose joint points are a fit's output, not measured
    markers. ``fit`` refused such a file; ``diagnose`` had fitted it as measured, and named no effect."""
    reserved = reserved_names(joints)
    clash = sorted(set(reserved) & set(trial.labels))
    if clash:
        raise InputError([f"marker {m!r} carries the name fit gives a virtual marker of joint {reserved[m]!r}; rename "
                          "it" for m in clash] + [
            "a file `--export-markers` wrote holds such points: they are a fit's output, not measured markers; use "
            "the trial it was exported from"], source=trial.source)


def _reserved_markers(segments: Mapping[str, Segment], joints: Mapping[str, Joint]) -> list[str]:
    """A marker named like a joint's virtual marker (``hip_r.centre``): the two would be taken for each other."""
    reserved = reserved_names(joints)
    return [f"segments.{s.name}.markers: marker {m!r} carries the name of a virtual marker of joint "
            f"{reserved[m]!r} (its centre or a point of its hinge axis); rename the marker"
            for s in segments.values() for m in s.markers if m in reserved]


# ---------------------------------------------------------------------- tree checks
def _check_parts(segments: Mapping[str, Segment], joints: Mapping[str, Joint]) -> list[str]:
    """Joint types, duplicate markers and markers named like virtual ones, for models built without
    :meth:`Model.from_dict`."""
    problems = [f"joints.{j.name}.type: unknown joint type {j.type!r} (allowed: {', '.join(JOINT_TYPES)})"
                for j in joints.values() if j.type not in JOINT_TYPES]
    problems += _reserved_markers(segments, joints)
    owner: dict[str, str] = {}
    for s in segments.values():
        for m in s.markers:
            if m in owner:
                problems.append(f"duplicate marker {m!r}: listed in both segments.{owner[m]}.markers "
                                f"and segments.{s.name}.markers")
            owner[m] = s.name
    return problems


def _check_tree(segments: Mapping[str, Segment], joints: Mapping[str, Joint],
                check_roots: bool = True) -> list[str]:
    """Problems with the joint tree: two parents, cycles, several roots.

    `check_roots` is False when a joint was already rejected for its ends: its child would
    look like a second root, which is a consequence, not a separate problem.
    """
    problems: list[str] = []
    if not segments:
        return problems  # already reported by the parser, or nothing to check
    parent_of: dict[str, Joint] = {}
    for j in joints.values():
        if j.parent not in segments or j.child not in segments:
            problems.append(f"joints.{j.name}: connects unknown segments {j.parent!r} -> {j.child!r}")
            continue
        if j.child in parent_of:
            first = parent_of[j.child]
            problems.append(
                f"segment {j.child!r} has two parents: joints.{first.name} (parent {first.parent!r}) "
                f"and joints.{j.name} (parent {j.parent!r}); joints must form a tree")
            continue
        parent_of[j.child] = j
    cycles = _cycles(segments, [j for j in joints.values()
                                if j.parent in segments and j.child in segments])
    problems += cycles
    roots = [s for s in segments if s not in parent_of]
    if len(roots) > 1 and check_roots:
        problems.append(
            f"more than one root segment (segments that are no joint's child): {', '.join(roots)}; "
            "the segments are not all connected by joints")
    elif not roots and not cycles:  # pragma: no cover - implied by a cycle
        problems.append("no root segment: every segment is some joint's child")
    return problems


def _cycles(segments, joints) -> list[str]:
    """One problem per joint that closes a loop (joints taken as undirected edges)."""
    adjacent: dict[str, list[tuple[str, str]]] = {s: [] for s in segments}
    problems = []
    for j in joints:
        path = _path(adjacent, j.child, j.parent)
        if path is None:
            adjacent[j.parent].append((j.child, j.name))
            adjacent[j.child].append((j.parent, j.name))
            continue
        segs, names = path
        chain = " -> ".join(segs + [segs[0]])
        names = ", ".join(f"joints.{n}" for n in names + [j.name])
        problems.append(f"joints form a cycle: {chain} ({names}); joints must form a tree")
    return problems


def _path(adjacent, start: str, goal: str):
    """Segments and joints on the path start -> goal (breadth first), or None."""
    back = {start: None}
    queue = [start]
    while queue:
        s = queue.pop(0)
        if s == goal:
            segs, names = [], []
            while back[s] is not None:
                segs.append(s)
                s, name = back[s]
                names.append(name)
            return [start] + segs[::-1], names[::-1]
        for other, name in adjacent[s]:
            if other not in back:
                back[other] = (s, name)
                queue.append(other)
    return None


def _order(segments, joints) -> tuple[str, tuple[str, ...]]:
    """Root and breadth-first joint order (file order among siblings)."""
    children = {s: [] for s in segments}
    for j in joints.values():
        children[j.parent].append(j.name)
    root = next(s for s in segments if all(j.child != s for j in joints.values()))
    order: list[str] = []
    queue = [root]
    while queue:
        s = queue.pop(0)
        for name in children[s]:
            order.append(name)
            queue.append(joints[name].child)
    return root, tuple(order)


def left_out_reasons(gone: dict, why: str, by: str) -> dict:
    """{joint: why it is left out} for `gone` ({joint left out: the joint it is or hangs below},
    :meth:`Model.without_subtrees`, :meth:`Model.below_root`): `why` for the joints themselves, and for those below them
    that they hang below one `by` (the verb) left out, and why."""
    return {j: why if j == above else f"it hangs below {above}, which {by} left out: {why}"
            for j, above in gone.items()}


def unposed_root(full: Model, below: Model, done: str) -> str:
    """Why the joints :meth:`Model.below_root` leaves out are left out (`full` the model, `below` what it kept, `done`
    what is done with the rest: "fitted", "diagnosed")."""
    return (f"the root {full.root!r} has no marker and its joints lend fewer than three points, so "
            f"nothing poses it (nor what joins it to segment {below.root!r}); the tree from segment {below.root!r} "
            f"down is {done} without them")
