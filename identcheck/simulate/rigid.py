"""Synthetic trials with exactly known joint parameters: the ground truth for every solver.

:func:`simulate` turns a :class:`~identcheck.io.model.Model` into marker trajectories that
satisfy the rigid-joint constraints to machine precision (before noise), and returns the
truth alongside: marker positions in their segment frames, segment poses, joint centres and
hinge axes in both adjacent segment frames, and joint angles.

Conventions
-----------
- World frame: z up, millimetres. Segment frames are right-handed, mm.
- A segment whose model gives ``positions`` uses the frame those positions are written in,
  with the origin at its proximal joint centre (unless the joint gives ``centre_child``) and
  anatomical axes x anterior, y left, z proximal; its distal joint centres default to
  ``(0, 0, -length_mm)``. Other segments get a random (seeded) frame: a random rotation of the
  anatomical axes and an origin about 40 mm (per coordinate) away from the proximal joint
  centre, as a technical marker-cluster frame would be.
- Kinematics of a joint with parent P and child C (poses world-from-segment, 4x4)::

      W_C(t) = W_P(t) @ [[R(t), c_P - R(t) c_C], [0, 1]],   R(t) = Exp(omega(t)) R_rest

  so the joint centre ``W_P c_P == W_C c_C`` at every frame. ``omega(t)`` (the rotation vector
  in the parent frame) is ``theta(t) a_P`` for a revolute joint, which keeps the hinge axis
  fixed in both frames (``R(t) a_C == a_P``).
- Revolute "centre": when the model gives neither centre, the point on the hinge axis closest
  to the child frame's origin.
- Joint angles: revolute ``theta`` in degrees, shape (n_frames,); spherical ``omega`` in
  degrees, shape (n_frames, 3), in the parent frame.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.errors import InputError
from identcheck.geometry.kinematics import chain_poses
from identcheck.io.atomic import atomic_write
from identcheck.io.model import Model
from identcheck.trial import FORMATS, Trial

ROOT_HEIGHT_MM = 950.0
"""Height of the root segment's reference point above the floor."""
ROOT_ROM_DEG = 20.0
"""Peak-to-peak rotation of the root about each world axis when ``root_motion``."""
ROOT_SWAY_MM = 200.0
"""Peak-to-peak translation of the root along each world axis when ``root_motion``."""
FREQ_HZ = (0.2, 2.0)
"""Range of the frequencies of the random sinusoids that drive every angle."""
MARKER_RANGE_MM = (30.0, 200.0)
"""Drawn markers lie this far from their nearest joint centre (and no closer to any)."""
MIN_MARKER_GAP_MM = 25.0
MIN_AXIS_DISTANCE_MM = 20.0
MIN_SPREAD_MM = 10.0


# ---------------------------------------------------------------------- truth containers
@dataclass(frozen=True)
class SegmentTruth:
    """True geometry and motion of one segment.

    Attributes
    ----------
    name : str
    marker_local : dict of str to numpy.ndarray
        Marker positions in the segment frame, each shape (3,), mm.
    poses : numpy.ndarray
        World-from-segment transforms, shape (n_frames, 4, 4), mm.
    length_mm : float
    """

    name: str
    marker_local: dict
    poses: np.ndarray
    length_mm: float

    def markers_world(self) -> np.ndarray:
        """Marker positions in the world, shape (n_frames, n_markers, 3), mm."""
        local = np.array(list(self.marker_local.values())).reshape(-1, 3)
        return np.einsum("fij,mj->fmi", self.poses[:, :3, :3], local) + self.poses[:, None, :3, 3]


@dataclass(frozen=True)
class JointTruth:
    """True parameters and motion of one joint.

    Attributes
    ----------
    name, type, parent, child : str
    centre_parent, centre_child : numpy.ndarray
        Joint centre (revolute: a point on the hinge axis) in the parent / child frame,
        shape (3,), mm.
    axis_parent, axis_child : numpy.ndarray or None
        Unit hinge direction in the parent / child frame, shape (3,) (revolute only).
    angles_deg : numpy.ndarray
        Revolute: hinge angle, shape (n_frames,). Spherical: rotation vector of the child
        relative to its rest orientation, in the parent frame, shape (n_frames, 3).
    n_axes : int
        How many independent rotation axes the motion exercises (revolute: 1).
    motion_axes : numpy.ndarray
        Those axes, unit columns in the parent frame, shape (3, n_axes); the angles projected
        on them, ``angles_deg @ motion_axes`` (spherical), each span ``rom_deg`` peak to peak.
    """

    name: str
    type: str
    parent: str
    child: str
    centre_parent: np.ndarray
    centre_child: np.ndarray
    axis_parent: np.ndarray | None
    axis_child: np.ndarray | None
    angles_deg: np.ndarray
    n_axes: int
    motion_axes: np.ndarray


@dataclass(frozen=True)
class Truth:
    """Everything :func:`simulate` knows about the synthetic subject."""

    segments: dict
    joints: dict

    def centre_world(self, joint: str) -> np.ndarray:
        """Joint centre in the world, shape (n_frames, 3), mm (same from either segment)."""
        j = self.joints[joint]
        pose = self.segments[j.parent].poses
        return pose[:, :3, :3] @ j.centre_parent + pose[:, :3, 3]

    def axis_world(self, joint: str) -> np.ndarray:
        """Hinge direction in the world, shape (n_frames, 3); revolute joints only."""
        j = self.joints[joint]
        if j.axis_parent is None:
            raise ValueError(f"joint {joint!r} is {j.type}: it has no hinge axis")
        return self.segments[j.parent].poses[:, :3, :3] @ j.axis_parent

    def marker_distances(self, joint: str) -> dict[str, float]:
        """Each adjacent marker's distance to the joint, in mm (the ``fit`` JSON quantity).

        Spherical: distance to the joint centre. Revolute: distance to the hinge axis.
        Markers of the parent segment come first.
        """
        j = self.joints[joint]
        out = {}
        for seg, centre, axis in ((j.parent, j.centre_parent, j.axis_parent),
                                  (j.child, j.centre_child, j.axis_child)):
            for name, p in self.segments[seg].marker_local.items():
                d = p - centre
                if axis is not None:
                    d = d - (d @ axis) * axis
                out[name] = float(np.linalg.norm(d))
        return out

    def to_dict(self, poses: bool = True) -> dict:
        """JSON-ready dictionary (lists of floats; poses only if `poses`)."""
        segs = {}
        for s in self.segments.values():
            segs[s.name] = {"length_mm": s.length_mm,
                            "marker_local": {m: p.tolist() for m, p in s.marker_local.items()}}
            if poses:
                segs[s.name]["poses"] = s.poses.tolist()
        joints = {}
        for j in self.joints.values():
            joints[j.name] = {
                "type": j.type, "parent": j.parent, "child": j.child, "n_axes": j.n_axes,
                "centre_parent": j.centre_parent.tolist(), "centre_child": j.centre_child.tolist(),
                "axis_parent": None if j.axis_parent is None else j.axis_parent.tolist(),
                "axis_child": None if j.axis_child is None else j.axis_child.tolist(),
                "marker_distances": self.marker_distances(j.name),
                "angles_deg": j.angles_deg.tolist(), "motion_axes": j.motion_axes.tolist(),
            }
        return {"segments": segs, "joints": joints}

    @classmethod
    def from_dict(cls, d: dict) -> "Truth":
        """Inverse of :meth:`to_dict` (with poses)."""
        arr = lambda v: None if v is None else np.asarray(v, dtype=np.float64)  # noqa: E731
        segs = {name: SegmentTruth(name, {m: arr(p) for m, p in s["marker_local"].items()},
                                   arr(s["poses"]), float(s["length_mm"]))
                for name, s in d["segments"].items()}
        joints = {name: JointTruth(name, j["type"], j["parent"], j["child"], arr(j["centre_parent"]),
                                   arr(j["centre_child"]), arr(j["axis_parent"]), arr(j["axis_child"]),
                                   arr(j["angles_deg"]), int(j["n_axes"]), arr(j["motion_axes"]))
                  for name, j in d["joints"].items()}
        return cls(segs, joints)


@dataclass(frozen=True)
class Simulation:
    """Result of :func:`simulate`.

    Attributes
    ----------
    trial : Trial
        What a camera system would record: noise and occlusion gaps (NaN) included.
    clean : Trial
        The exact marker positions (no noise, no gaps).
    truth : Truth
    model : Model
    gaps : numpy.ndarray
        True where ``trial`` is occluded, shape (n_frames, n_markers).
    settings : dict
        The arguments of the :func:`simulate` call (seed included).
    """

    trial: Trial
    clean: Trial
    truth: Truth
    model: Model
    gaps: np.ndarray
    settings: dict = field(default_factory=dict)

    def save_truth(self, path, poses: bool = True) -> None:
        """Write the truth and the settings as JSON (see :func:`load_truth`)."""
        doc = {"settings": self.settings, "labels": list(self.trial.labels), **self.truth.to_dict(poses)}
        atomic_write(path, json.dumps(doc, indent=2, sort_keys=True))


def load_truth(path) -> Truth:
    """Read a truth JSON written by :meth:`Simulation.save_truth` (with poses)."""
    return Truth.from_dict(json.loads(Path(path).read_text()))


# ---------------------------------------------------------------------- entry points
def simulate(model: Model, n_frames: int = 200, rate_hz: float = 100.0, rom_deg: float = 60.0,
             n_axes: int | None = None, root_motion: bool = True, noise_mm: float = 0.0,
             seed: int = 0, occlusion: float = 0.0) -> Simulation:
    """Simulate a trial of `model` with known joint parameters.

    Parameters
    ----------
    model : Model
        Segments, markers and joints. Segment ``positions``, ``length_mm`` and joint
        ``axis``, ``centre_parent``, ``centre_child`` are used when given, drawn otherwise.
    n_frames : int
    rate_hz : float
    rom_deg : float
        Range of motion: peak-to-peak amplitude, in degrees, of each exercised joint angle
        (revolute hinge angle; each exercised rotation-vector component of a spherical joint).
    n_axes : {None, 1, 2, 3}
        How many rotation axes of each spherical joint move (anatomical flexion, then
        abduction, then axial rotation); None = 3. Fewer axes give the degenerate motions
        under which a spherical joint's centre is not identifiable.
    root_motion : bool
        Move the root segment (rotation ``ROOT_ROM_DEG``, translation ``ROOT_SWAY_MM``
        peak-to-peak per world axis); otherwise it stays at rest.
    noise_mm : float
        Standard deviation of Gaussian noise added to every coordinate of ``trial``, mm.
    seed : int
        Seeds everything (``np.random.default_rng``). Geometry, motion, noise and gaps use
        independent streams: changing `noise_mm` or `occlusion` leaves ``clean`` unchanged.
    occlusion : float
        Fraction of frames, in [0, 1], in which some marker is missing; gaps are contiguous
        runs (3 to n_frames / 10 frames) on randomly chosen markers.

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Invalid arguments (all listed), or markers that cannot be placed non-degenerately.

    Examples
    --------
    >>> sim = simulate(Model.from_toml("examples/leg.toml"), noise_mm=0.5, seed=1)  # doctest: +SKIP
    >>> sim.trial.as_array().shape                                                  # doctest: +SKIP
    (200, 10, 3)
    """
    _check_args(n_frames, rate_hz, rom_deg, n_axes, noise_mm, occlusion)
    n_axes = 3 if n_axes is None else int(n_axes)
    geo_rng, motion_rng, noise_rng, gap_rng = (np.random.default_rng(s)
                                               for s in np.random.SeedSequence(seed).spawn(4))
    geo = _geometry(model, geo_rng)
    locals_ = _place_markers(model, geo, geo_rng)
    t = np.arange(n_frames) / rate_hz
    poses, angles, axes = _motion(model, geo, t, rom_deg, n_axes, root_motion, motion_rng)

    segments = {name: SegmentTruth(name, locals_[name], poses[name], geo.length[name])
                for name in model.segments}
    joints = {}
    for name in model.joint_order:
        j = model.joints[name]
        rev = j.type == "revolute"
        joints[name] = JointTruth(name, j.type, j.parent, j.child, geo.c_parent[name],
                                  geo.c_child[name], geo.a_parent.get(name), geo.a_child.get(name),
                                  angles[name], 1 if rev else n_axes, axes[name])
    truth = Truth(segments, joints)

    clean = np.concatenate([segments[s].markers_world() for s in model.segments], axis=1)
    noisy = clean + (noise_rng.normal(0.0, noise_mm, clean.shape) if noise_mm > 0 else 0.0)
    gaps = _gaps(gap_rng, n_frames, clean.shape[1], occlusion)
    noisy[gaps] = np.nan
    source = f"simulate({model.source}, seed={seed})"
    settings = dict(model=model.source, n_frames=n_frames, rate_hz=float(rate_hz),
                    rom_deg=float(rom_deg), n_axes=n_axes, root_motion=bool(root_motion),
                    noise_mm=float(noise_mm), seed=seed, occlusion=float(occlusion))
    return Simulation(trial=Trial(noisy, model.markers, rate_hz, source),
                      clean=Trial(clean, model.markers, rate_hz, source + " clean"),
                      truth=truth, model=model, gaps=gaps, settings=settings)


# ---------------------------------------------------------------------- pieces
def _check_args(n_frames, rate_hz, rom_deg, n_axes, noise_mm, occlusion) -> None:
    problems = []
    if not (isinstance(n_frames, (int, np.integer)) and n_frames >= 1):
        problems.append(f"n_frames must be a positive integer, got {n_frames!r}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        problems.append(f"rate_hz must be positive, got {rate_hz!r}")
    if not (np.isfinite(rom_deg) and 0 <= rom_deg <= 360):
        problems.append(f"rom_deg must be in [0, 360], got {rom_deg!r}")
    if n_axes not in (None, 1, 2, 3):
        problems.append(f"n_axes must be None, 1, 2 or 3, got {n_axes!r}")
    if not (np.isfinite(noise_mm) and noise_mm >= 0):
        problems.append(f"noise_mm must be >= 0, got {noise_mm!r}")
    if not (np.isfinite(occlusion) and 0 <= occlusion <= 1):
        problems.append(f"occlusion must be a fraction in [0, 1], got {occlusion!r}")
    if problems:
        raise InputError(problems, source="simulate")


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Uniformly random rotation matrix, shape (3, 3)."""
    return Rotation.from_quat(rng.normal(size=4)).as_matrix()


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


@dataclass
class _Geometry:
    """Per-segment frames and per-joint parameters, all in segment frames, mm."""

    basis: dict = field(default_factory=dict)      # segment -> (3, 3) anatomical axes as columns
    origin: dict = field(default_factory=dict)     # segment -> (3,) proximal reference point
    length: dict = field(default_factory=dict)     # segment -> float, mm
    c_parent: dict = field(default_factory=dict)   # joint -> (3,)
    c_child: dict = field(default_factory=dict)    # joint -> (3,)
    a_parent: dict = field(default_factory=dict)   # revolute joint -> (3,) unit
    a_child: dict = field(default_factory=dict)    # revolute joint -> (3,) unit
    rest: dict = field(default_factory=dict)       # joint -> (3, 3) parent-from-child at rest


def _geometry(model: Model, rng: np.random.Generator) -> _Geometry:
    """Draw (or take from the model) segment frames, joint centres and hinge axes."""
    geo = _Geometry()
    for name in [model.root] + [model.joints[j].child for j in model.joint_order]:
        seg = model.segments[name]
        given = seg.positions is not None
        geo.basis[name] = np.eye(3) if given else _random_rotation(rng)
        drawn_length = rng.uniform(150.0, 450.0)
        geo.length[name] = seg.length_mm if seg.length_mm is not None else float(drawn_length)
        joint = model.parent_joint(name)
        offset = rng.normal(0.0, 40.0, 3)
        if joint is not None and joint.centre_child is not None:
            geo.origin[name] = np.array(joint.centre_child)
        else:
            geo.origin[name] = np.zeros(3) if given else offset
    for k, jname in enumerate(model.joint_order):
        j = model.joints[jname]
        bp, bc = geo.basis[j.parent], geo.basis[j.child]
        if j.parent == model.root:   # e.g. hips on a pelvis: lateral and below its centre
            local = np.array([rng.uniform(-30, 30), (-1) ** k * rng.uniform(60, 100), -rng.uniform(40, 100)])
        else:                        # at the distal end of the parent
            local = np.array([rng.normal(0, 10), rng.normal(0, 10), -geo.length[j.parent]])
        c_p = np.array(j.centre_parent) if j.centre_parent is not None else geo.origin[j.parent] + bp @ local
        c_c = geo.origin[j.child]
        rest = bp @ bc.T
        tilt = rng.normal(0.0, 0.15, 2)
        if j.type == "revolute":
            a_p = np.array(j.axis) if j.axis is not None else _unit(bp @ np.array([tilt[0], 1.0, tilt[1]]))
            a_c = rest.T @ a_p
            if j.centre_parent is None and j.centre_child is None:
                shift = c_c @ a_c            # slide along the hinge to the point nearest the child origin
                c_c, c_p = c_c - shift * a_c, c_p - shift * a_p
            geo.a_parent[jname], geo.a_child[jname] = a_p, a_c
        geo.c_parent[jname], geo.c_child[jname], geo.rest[jname] = c_p, c_c, rest
    return geo


def _joint_features(model: Model, geo: _Geometry, seg: str):
    """Joint centres and hinge lines (point, unit direction) on a segment, in its frame."""
    centres, lines = [], []
    for j in model.joints.values():
        for side, c, a in (("parent", geo.c_parent, geo.a_parent), ("child", geo.c_child, geo.a_child)):
            if getattr(j, side) == seg:
                centres.append(c[j.name])
                if j.name in a:
                    lines.append((c[j.name], a[j.name]))
    return centres, lines


def _place_markers(model: Model, geo: _Geometry, rng: np.random.Generator) -> dict:
    """Marker positions in their segment frames: given ones kept, the others drawn.

    Drawn markers lie 30-200 mm (``MARKER_RANGE_MM``) from their nearest joint centre, at
    least 25 mm from each other, 20 mm from any hinge axis on the segment, and (three or more
    markers) not collinear; rejection sampling, at most 500 tries per segment.
    """
    out = {}
    for name, seg in model.segments.items():
        given = dict(seg.positions or {})
        todo = [m for m in seg.markers if m not in given]
        centres, lines = _joint_features(model, geo, name)
        anchors = list(centres)
        if model.parent_joint(name) is not None and not model.child_joints(name):
            anchors.append(geo.origin[name] - geo.length[name] * geo.basis[name][:, 2])  # distal end
        if not anchors:
            anchors = [geo.origin[name]]
        fixed = np.array([given[m] for m in seg.markers if m in given]).reshape(-1, 3)
        for _ in range(500):
            pick = rng.integers(len(anchors), size=len(todo))
            dirs = rng.normal(size=(len(todo), 3))
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
            dist = rng.uniform(MARKER_RANGE_MM[0] + 10, MARKER_RANGE_MM[1] - 20, size=(len(todo), 1))
            drawn = np.array(anchors).reshape(-1, 3)[pick] + dist * dirs
            if _acceptable(drawn, fixed, centres, lines):
                break
        else:
            raise InputError([f"segments.{name}: cannot place {len(todo)} markers non-degenerately "
                              "(too many markers for one segment?)"], source=model.source)
        drawn_by_name = dict(zip(todo, drawn))
        out[name] = {m: np.array(given[m], dtype=np.float64) if m in given else drawn_by_name[m]
                     for m in seg.markers}
    return out


def _acceptable(drawn: np.ndarray, fixed: np.ndarray, centres, lines) -> bool:
    """Whether drawn markers, shape (k, 3), meet the placement rules of :func:`_place_markers`."""
    if len(drawn) == 0:
        return True
    every = np.vstack([fixed, drawn])
    gaps = np.linalg.norm(drawn[:, None] - every[None], axis=2)
    np.fill_diagonal(gaps[:, len(fixed):], np.inf)
    if gaps.min() < MIN_MARKER_GAP_MM:
        return False
    if centres:
        to_centres = np.linalg.norm(drawn[:, None] - np.array(centres)[None], axis=2)
        if to_centres.min() < MARKER_RANGE_MM[0] or to_centres.min(axis=1).max() > MARKER_RANGE_MM[1]:
            return False
    for point, axis in lines:
        d = drawn - point
        if np.linalg.norm(d - np.outer(d @ axis, axis), axis=1).min() < MIN_AXIS_DISTANCE_MM:
            return False
    if len(every) >= 3:
        spread = np.linalg.svd(every - every.mean(axis=0), compute_uv=False)[1]
        if spread < MIN_SPREAD_MM:
            return False
    return True


def smooth_profile(rng: np.random.Generator, t: np.ndarray, k: int) -> np.ndarray:
    """`k` smooth signals, shape (n_frames, k), each a sum of 3 random sinusoids (``FREQ_HZ``)
    rescaled to peak-to-peak 1, centred on 0 (all zeros for a single frame)."""
    freq = rng.uniform(*FREQ_HZ, size=(k, 3))
    phase = rng.uniform(0.0, 2 * np.pi, size=(k, 3))
    amp = rng.uniform(0.5, 1.0, size=(k, 3))
    s = (amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)).sum(axis=2)
    lo, hi = s.min(axis=0), s.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    return (s - (hi + lo) / 2) / span


def _motion(model, geo, t, rom_deg, n_axes, root_motion, rng):
    """World-from-segment poses, shape (n_frames, 4, 4) per segment; joint angles (degrees)
    and the exercised rotation axes, shape (3, n_axes), per joint."""
    n = len(t)
    rot = np.empty((n, 3, 3))
    trans = np.empty((n, 3))
    if root_motion:
        omega0 = np.deg2rad(ROOT_ROM_DEG) * smooth_profile(rng, t, 3)
        sway = ROOT_SWAY_MM * smooth_profile(rng, t, 3)
    else:
        omega0, sway = np.zeros((n, 3)), np.zeros((n, 3))
    root = model.root
    rot[:] = Rotation.from_rotvec(omega0).as_matrix() @ geo.basis[root].T
    trans[:] = np.array([0.0, 0.0, ROOT_HEIGHT_MM]) + sway - rot @ geo.origin[root]
    rel = {}
    angles, motion_axes = {}, {}
    for jname in model.joint_order:
        j = model.joints[jname]
        bp = geo.basis[j.parent]
        if j.type == "revolute":
            theta = np.deg2rad(rom_deg * smooth_profile(rng, t, 1)[:, 0] + rng.uniform(-15, 15))
            omega = theta[:, None] * geo.a_parent[jname]
            angles[jname] = np.rad2deg(theta)
            motion_axes[jname] = geo.a_parent[jname][:, None]
        else:   # flexion (anatomical y), abduction (x), axial rotation (z) of the parent
            axes = bp[:, [1, 0, 2]][:, :n_axes]
            amount = rom_deg * smooth_profile(rng, t, n_axes) + rng.uniform(-15, 15, n_axes)
            omega = np.deg2rad(amount) @ axes.T
            angles[jname] = np.rad2deg(omega)
            motion_axes[jname] = axes
        rel[jname] = Rotation.from_rotvec(omega).as_matrix() @ geo.rest[jname]
    rots, transl, _ = chain_poses([(jn, model.joints[jn].parent, model.joints[jn].child) for jn in model.joint_order],
                                  root, rot, trans, rel, geo.c_parent, geo.c_child)
    poses = {}
    for seg in model.segments:
        pose = np.zeros((n, 4, 4))
        pose[:, :3, :3], pose[:, :3, 3], pose[:, 3, 3] = rots[seg], transl[seg], 1.0
        poses[seg] = pose
    return poses, angles, motion_axes


def _gaps(rng: np.random.Generator, n_frames: int, n_markers: int, occlusion: float) -> np.ndarray:
    """Occlusion mask, shape (n_frames, n_markers): contiguous runs on random markers such that
    exactly ``round(occlusion * n_frames)`` frames miss at least one marker."""
    gaps = np.zeros((n_frames, n_markers), dtype=bool)
    target = int(round(occlusion * n_frames)) if n_markers else 0
    hit = np.zeros(n_frames, dtype=bool)
    longest = max(3, n_frames // 10)
    while hit.sum() < target:
        start = rng.choice(np.flatnonzero(~hit))
        span = np.arange(start, min(n_frames, start + rng.integers(3, longest + 1)))
        new = np.cumsum(~hit[span])
        span = span[new <= target - hit.sum()]
        gaps[span, rng.integers(n_markers)] = True
        hit[span] = True
    return gaps
