"""Inject one named effect into a simulated trial, so that ``diagnose`` can be tested.

``identcheck diagnose`` claims to find where the rigid-joint model and a trial disagree and to
name the missing effect (CONTRACT.md lists them). That claim can only be checked on trials in
which the effect, its place and its size are known: :func:`inject_effect` takes the rigid
:class:`~identcheck.simulate.rigid.Simulation` of :func:`~identcheck.simulate.rigid.simulate` and returns a
new one carrying exactly one effect, drawn at random (seeded) within realistic ranges, and
recorded in ``settings["effect"] = {"name", "where", "params", "seed"}`` (plain JSON values),
which :meth:`~identcheck.simulate.rigid.Simulation.save_truth` writes with the truth.
``identcheck simulate MODEL --out TRIAL --effect NAME`` does the same from the shell.

Effects on the body (``soft_tissue``, ``marker_slip``, ``joint_translation``, ``extra_dof``,
``time_offset``, ``spatial_distortion``) move the clean positions; the noisy trial is the new
clean one plus the same noise, with the same gaps. Effects of labelling or recording
(``marker_swap``, ``outliers``) edit the noisy trial only. ``truth`` stays the rigid truth;
:func:`true_centre_world` gives joint centres with the effect included.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from identcheck.errors import InputError
from identcheck.io.jsonable import plain

if TYPE_CHECKING:  # pragma: no cover
    from identcheck.simulate.rigid import Simulation

EFFECTS = ("soft_tissue", "marker_slip", "marker_swap", "joint_translation", "extra_dof",
           "time_offset", "outliers", "spatial_distortion")
"""Effect names of CONTRACT.md that :func:`inject_effect` can inject."""

SEED_OFFSET = 1000003
"""``identcheck simulate --seed S --effect NAME`` injects with seed ``S + SEED_OFFSET``."""

MONOMIALS = ("x^2", "y^2", "z^2", "xy", "xz", "yz")
"""Order of the rows of ``spatial_distortion``'s ``coefficients`` (in scaled coordinates)."""

SOURCE = "inject_effect"


@dataclass(frozen=True)
class _Change:
    """What one injector produces: new clean or new noisy positions, and the record."""

    where: dict
    params: dict
    clean: np.ndarray | None = None   # (F, M, 3): body effects
    trial: np.ndarray | None = None   # (F, M, 3): recording effects
    gaps: np.ndarray | None = None    # (F, M): only when the effect moves gaps (marker_swap)


# ---------------------------------------------------------------------- entry points
def inject_effect(sim: "Simulation", name: str, seed: int = 0) -> "Simulation":
    """A new simulation whose trial carries the effect `name`, drawn from `seed`.

    Parameters
    ----------
    sim : Simulation
        A rigid simulation (from :func:`~identcheck.simulate.rigid.simulate`); it is not modified.
    name : str
        One of :data:`EFFECTS`.
    seed : int
        Seeds the draw of the effect's place, timing and magnitude.

    Returns
    -------
    Simulation
        ``trial`` and ``clean`` carry the effect, ``truth`` is unchanged, ``settings["effect"]``
        records it.

    Raises
    ------
    InputError
        Unknown effect name, a simulation that already carries one, or an effect the model
        cannot carry (e.g. ``extra_dof`` without a revolute joint).
    """
    if name not in EFFECTS:
        raise InputError([f"unknown effect {name!r} (valid effects: {', '.join(EFFECTS)})"], source=SOURCE)
    if "effect" in sim.settings:
        raise InputError([f"the simulation already carries effect {sim.settings['effect']['name']!r}; "
                          "inject one effect per simulation"], source=SOURCE)
    change = _INJECTORS[name](sim, np.random.default_rng(seed))
    return _apply(sim, name, seed, change)


def true_centre_world(sim: "Simulation", joint: str) -> np.ndarray:
    """True centre of `joint` in the world, shape (n_frames, 3), mm, including the effect.

    ``joint_translation`` moves its joint's centre and every centre below it; ``extra_dof``
    rotates the centres below its joint about that joint's centre; other effects leave the
    centres of the rigid truth (a delayed segment lags its markers, not the skeleton).
    """
    if joint not in sim.truth.joints:
        raise InputError([f"unknown joint {joint!r} (the model has: {', '.join(sim.truth.joints)})"],
                         source=SOURCE)
    centre = sim.truth.centre_world(joint)
    effect = sim.settings.get("effect") or {}
    if effect.get("name") not in ("joint_translation", "extra_dof"):
        return centre
    moved = effect["where"]["joint"]
    below = _subtree(sim.model, sim.model.joints[moved].child)
    rot_p = _rotations(sim, sim.model.joints[moved].parent)
    if effect["name"] == "joint_translation":
        if joint == moved or sim.model.joints[joint].parent in below:
            centre = centre + _rotate(rot_p, np.asarray(effect["params"]["translation_parent"]))
        return centre
    if sim.model.joints[joint].parent not in below:
        return centre
    turn = _extra_rotation_world(rot_p, effect["params"]["axis_parent"], effect["params"]["angle_deg"])
    pivot = sim.truth.centre_world(moved)
    return pivot + _rotate(turn, centre - pivot)


# ---------------------------------------------------------------------- injectors (body)
def _soft_tissue(sim, rng) -> _Change:
    """One child-segment marker wobbles on its segment with the proximal joint angle a(t):
    d = u1 A1 a + u2 A2 (a^2 - mean a^2), in the segment frame."""
    model = sim.model
    options = [s for s in model.segments if s != model.root and model.segments[s].markers]
    if not options:
        raise _cannot("soft_tissue", "it needs a marker on a segment below a joint, and every marker "
                                     "of the model is on the root segment")
    seg = _pick(rng, options)
    marker = _pick(rng, model.segments[seg].markers)
    joint = model.parent_joint(seg).name
    a = _normalised_angle(sim.truth.joints[joint], low=-1.0)
    u1, u2 = _unit_vectors(rng, 2)
    a1, a2 = rng.uniform(5.0, 10.0), rng.uniform(2.0, 5.0)
    local = np.outer(a1 * a, u1) + np.outer(a2 * (a ** 2 - np.mean(a ** 2)), u2)
    clean = sim.clean.as_array()
    clean[:, _col(sim, marker)] += _rotate(_rotations(sim, seg), local)
    return _Change(where={"markers": [marker], "segment": seg, "joint": joint},
                   params={"amplitude_mm": _diameter(local),
                           "max_displacement_mm": float(np.linalg.norm(local, axis=1).max()),
                           "linear_mm": a1, "quadratic_mm": a2, "linear_direction": u1,
                           "quadratic_direction": u2, "displacement_local": local},
                   clean=clean)


def _marker_slip(sim, rng) -> _Change:
    """One marker jumps on its segment at frame k (in [F/4, 3F/4]) by 6-15 mm and stays."""
    model, n = sim.model, sim.clean.n_frames
    if not model.markers:
        raise _cannot("marker_slip", "the model has no marker")
    marker = _pick(rng, model.markers)
    seg = model.marker_segment(marker)
    frame = _draw_frame(rng, 0.25 * n, 0.75 * n, n)
    size = rng.uniform(6.0, 15.0)
    step = size * _unit_vectors(rng, 1)[0]
    clean = sim.clean.as_array()
    clean[frame:, _col(sim, marker)] += _rotations(sim, seg)[frame:] @ step
    return _Change(where={"markers": [marker], "segment": seg, "frame": frame},
                   params={"step_mm": size, "step_local": step}, clean=clean)


def _joint_translation(sim, rng) -> _Change:
    """A joint centre moves in its parent frame along v by A (2a(t) − 1)², a the joint angle scaled
    to [0, 1]: at rest mid-range, A away at either end of the range; the child segment and everything
    below it follow. The profile is even on purpose: a translation linear in a hinge's angle,
    perpendicular to the axis, is to first order a rigid hinge about a shifted axis
    ((I − Rot θ)Δc ≈ θ Δc × a), so data cannot tell that part from a rigid joint elsewhere."""
    model = sim.model
    options = [j for j in model.joint_order if _subtree_columns(sim, model.joints[j].child)]
    if not options:
        raise _cannot("joint_translation", "no joint has a marker on its child segment or below it")
    joint = _pick(rng, options)
    a = _normalised_angle(sim.truth.joints[joint], low=0.0)
    direction = _unit_vectors(rng, 1)[0]
    size = rng.uniform(8.0, 15.0)
    delta = np.outer(size * (2 * a - 1) ** 2, direction)
    clean = sim.clean.as_array()
    cols = _subtree_columns(sim, model.joints[joint].child)
    clean[:, cols] += _rotate(_rotations(sim, model.joints[joint].parent), delta)[:, None]
    return _Change(where={"joint": joint},
                   params={"amplitude_mm": size, "direction_parent": direction, "translation_parent": delta,
                           "moved_segments": _subtree(model, model.joints[joint].child)},
                   clean=clean)


def _extra_dof(sim, rng) -> _Change:
    """A hinge also turns about an axis b perpendicular to its own (in the parent frame), by a
    smooth angle of 12-25 deg peak to peak; the child subtree turns about the joint centre."""
    from identcheck.simulate.rigid import _smooth

    model = sim.model
    hinges = [j for j in model.joint_order if model.joints[j].type == "revolute"]
    if not hinges:
        raise _cannot("extra_dof", "it adds a second rotation to a revolute joint, and the model has none")
    options = [j for j in hinges if _subtree_columns(sim, model.joints[j].child)]
    if not options:
        raise _cannot("extra_dof", "no revolute joint has a marker on its child segment or below it")
    joint = _pick(rng, options)
    hinge = sim.truth.joints[joint].axis_parent
    b = rng.normal(size=3)
    b = _unit(b - (b @ hinge) * hinge)
    rom = rng.uniform(12.0, 25.0)
    psi = rom * _smooth(rng, sim.clean.times, 1)[:, 0]
    turn = _extra_rotation_world(_rotations(sim, model.joints[joint].parent), b, psi)
    pivot = sim.truth.centre_world(joint)[:, None]
    clean = sim.clean.as_array()
    cols = _subtree_columns(sim, model.joints[joint].child)
    clean[:, cols] = pivot + np.einsum("fij,fmj->fmi", turn, clean[:, cols] - pivot)
    return _Change(where={"joint": joint},
                   params={"extra_rom_deg": rom, "axis_parent": b, "angle_deg": psi,
                           "moved_segments": _subtree(model, model.joints[joint].child)},
                   clean=clean)


def _time_offset(sim, rng) -> _Change:
    """One segment's markers lag by 20-50 ms: x(t) becomes x(t - tau) (cubic spline)."""
    from scipy.interpolate import CubicSpline

    model = sim.model
    options = [s for s in model.segments if model.segments[s].markers]
    if not options:
        raise _cannot("time_offset", "the model has no marker")
    if sim.clean.n_frames < 2:
        raise _cannot("time_offset", "a delay needs at least 2 frames")
    seg = _pick(rng, options)
    delay_ms = rng.uniform(20.0, 50.0)
    t = sim.clean.times
    clean = sim.clean.as_array()
    cols = [_col(sim, m) for m in model.segments[seg].markers]
    clean[:, cols] = CubicSpline(t, clean[:, cols], axis=0)(t - delay_ms / 1000.0)
    return _Change(where={"segment": seg, "delay_ms": delay_ms},
                   params={"delay_frames": delay_ms / 1000.0 * sim.clean.rate_hz}, clean=clean)


def _spatial_distortion(sim, rng) -> _Change:
    """A smooth quadratic warp of the capture volume, x + f(x), with max |f| over the data A
    (8-15 mm); f is quadratic in the coordinates scaled to the data's bounding box."""
    x = sim.clean.as_array()
    if x.shape[1] == 0:
        raise _cannot("spatial_distortion", "the model has no marker")
    flat = x.reshape(-1, 3)
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    centre, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, 1.0)
    mono = _monomials((x - centre) / half)
    coef = rng.normal(size=(6, 3))
    size = rng.uniform(8.0, 15.0)
    peak = np.linalg.norm(mono @ coef, axis=-1).max()
    if not peak > 0:
        raise _cannot("spatial_distortion", "every marker sits at one point")
    coef *= size / peak
    return _Change(where={}, params={"amplitude_mm": size, "centre": centre, "half_extent": half,
                                     "coefficients": coef, "monomials": list(MONOMIALS)},
                   clean=x + mono @ coef)


# ---------------------------------------------------------------------- injectors (recording)
def _marker_swap(sim, rng) -> _Change:
    """Two markers at least 40 mm apart (on average) exchange labels for 10-30 % of the frames,
    inside [5 %, 95 %] of the trial."""
    x, n = sim.clean.xyz, sim.clean.n_frames
    apart = np.array([np.linalg.norm(x - x[:, [i]], axis=2).mean(axis=0) for i in range(x.shape[1])])
    first, second = np.nonzero(np.triu(apart >= 40.0, k=1))
    if not len(first):
        raise _cannot("marker_swap", "it needs two markers at least 40 mm apart on average")
    k = int(rng.integers(len(first)))
    cols = [int(first[k]), int(second[k])]
    span = int(rng.integers(max(1, math.ceil(0.1 * n)), max(1, math.floor(0.3 * n)) + 1))
    start = _draw_frame(rng, 0.05 * n, 0.95 * n - span + 1, n - span + 1)
    rows = slice(start, start + span)
    trial, gaps = sim.trial.as_array(), np.array(sim.gaps, dtype=bool)
    trial[rows, cols] = trial[rows][:, cols[::-1]]
    gaps[rows, cols] = gaps[rows][:, cols[::-1]]
    labels = sim.trial.labels
    return _Change(where={"markers": [labels[cols[0]], labels[cols[1]]], "frames": [start, start + span - 1]},
                   params={"mean_distance_mm": float(apart[cols[0], cols[1]])}, trial=trial, gaps=gaps)


def _outliers(sim, rng) -> _Change:
    """A fraction 0.3-1 % (at least 3) of the visible samples get a gross error of 15-60 mm."""
    visible = np.flatnonzero(~np.asarray(sim.gaps).ravel())
    if not len(visible):
        raise _cannot("outliers", "the trial has no visible sample")
    rate = rng.uniform(0.003, 0.01)
    count = int(min(len(visible), max(3, round(rate * len(visible)))))
    frames, cols = np.divmod(np.sort(rng.choice(visible, count, replace=False)), sim.trial.n_markers)
    errors = rng.uniform(15.0, 60.0, count)[:, None] * _unit_vectors(rng, count)
    trial = sim.trial.as_array()
    trial[frames, cols] += errors
    labels = sim.trial.labels
    return _Change(where={"markers": sorted({labels[c] for c in cols}),
                          "frames": sorted({int(f) for f in frames}), "count": count},
                   params={"fraction": rate, "samples": [[int(f), labels[c]] for f, c in zip(frames, cols)],
                           "errors_mm": errors, "sizes_mm": np.linalg.norm(errors, axis=1)},
                   trial=trial)


_INJECTORS = {"soft_tissue": _soft_tissue, "marker_slip": _marker_slip, "marker_swap": _marker_swap,
              "joint_translation": _joint_translation, "extra_dof": _extra_dof, "time_offset": _time_offset,
              "outliers": _outliers, "spatial_distortion": _spatial_distortion}


# ---------------------------------------------------------------------- helpers
def _apply(sim, name: str, seed: int, change: _Change):
    """The new Simulation: body effects keep the old noise and gaps; the record goes in settings."""
    tag = f" + {name}"
    if change.clean is not None:
        trial = change.clean + (sim.trial.xyz - sim.clean.xyz)   # same noise, NaN in the same gaps
        clean = sim.clean.replace(xyz=change.clean, source=sim.clean.source + tag)
    else:
        trial, clean = change.trial, sim.clean
    gaps = np.array(sim.gaps if change.gaps is None else change.gaps, dtype=bool)
    record = {"name": name, "where": plain(change.where), "params": plain(change.params), "seed": int(seed)}
    return dataclasses.replace(sim, trial=sim.trial.replace(xyz=trial, source=sim.trial.source + tag),
                               clean=clean, gaps=gaps, settings={**sim.settings, "effect": record})


def _cannot(name: str, why: str) -> InputError:
    """The error for an effect this model cannot carry, saying why."""
    return InputError([f"effect {name!r} cannot be injected: {why}"], source=SOURCE)


def _pick(rng: np.random.Generator, options):
    """One of `options`, uniformly."""
    return options[int(rng.integers(len(options)))]


def _draw_frame(rng: np.random.Generator, low: float, high: float, n_frames: int) -> int:
    """An integer frame uniform in [low, high], clipped to [0, n_frames - 1] when the range is empty."""
    lo, hi = math.ceil(low), math.floor(high)
    lo = min(max(lo, 0), n_frames - 1)
    return int(rng.integers(lo, max(lo, min(hi, n_frames - 1)) + 1))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _unit_vectors(rng: np.random.Generator, k: int) -> np.ndarray:
    """`k` random unit vectors, uniform on the sphere, shape (k, 3)."""
    return _unit(rng.normal(size=(k, 3)))


def _col(sim, marker: str) -> int:
    return sim.trial.index(marker)


def _rotations(sim, segment: str) -> np.ndarray:
    """World-from-segment rotations of the rigid truth, shape (F, 3, 3)."""
    return sim.truth.segments[segment].poses[:, :3, :3]


def _rotate(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-frame rotation of per-frame vectors: (F, 3, 3) x (F, 3) -> (F, 3)."""
    return np.einsum("fij,fj->fi", rot, v)


def _subtree(model, segment: str) -> list[str]:
    """`segment` and every segment below it, parents before children."""
    out = [segment]
    for seg in out:
        out.extend(j.child for j in model.child_joints(seg))
    return out


def _subtree_columns(sim, segment: str) -> list[int]:
    """Trial columns of the markers of `segment` and of every segment below it."""
    return [_col(sim, m) for s in _subtree(sim.model, segment) for m in sim.model.segments[s].markers]


def _normalised_angle(joint, low: float) -> np.ndarray:
    """The joint's angle (hinge angle, or a ball joint's rotation vector on its first motion
    axis, the flexion) rescaled from its [min, max] to [low, 1]; zeros if it does not move."""
    angle = joint.angles_deg if joint.angles_deg.ndim == 1 else joint.angles_deg @ joint.motion_axes[:, 0]
    lo, hi = angle.min(), angle.max()
    unit = (angle - lo) / (hi - lo) if hi > lo else np.zeros_like(angle)
    return low + (1.0 - low) * unit


def _extra_rotation_world(rot_parent: np.ndarray, axis_parent, angle_deg) -> np.ndarray:
    """World rotations R_P Rot(b, psi) R_P^T of ``extra_dof``, shape (F, 3, 3)."""
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_rotvec(np.deg2rad(np.asarray(angle_deg))[:, None] * np.asarray(axis_parent)).as_matrix()
    return rot_parent @ turn @ np.swapaxes(rot_parent, 1, 2)


def _monomials(u: np.ndarray) -> np.ndarray:
    """The 6 quadratic monomials of :data:`MONOMIALS`, shape (..., 6), of points (..., 3)."""
    x, y, z = u[..., 0], u[..., 1], u[..., 2]
    return np.stack([x * x, y * y, z * z, x * y, x * z, y * z], axis=-1)


def _diameter(points: np.ndarray) -> float:
    """Largest distance between two of `points` (F, 3) lying in a plane: the widest of their
    projections on 360 directions of that plane (under by at most 1e-5 relative)."""
    if len(points) < 2:
        return 0.0
    centred = points - points.mean(axis=0)
    plane = np.linalg.svd(centred, full_matrices=False)[2][:2]
    angle = np.linspace(0.0, np.pi, 360, endpoint=False)
    dirs = np.stack([np.cos(angle), np.sin(angle)])
    return float(np.ptp(centred @ plane.T @ dirs, axis=0).max())


