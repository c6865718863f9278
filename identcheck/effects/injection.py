"""What every effect's injector shares: the change it produces, how a change becomes a new simulation,
and small draws and geometry on the rigid truth.

Each named effect (``identcheck/effects/<name>.py``) injects itself (``Effect.inject(sim, rng)``) for
``identcheck simulate --effect NAME``, so that ``diagnose`` can be tested on trials in which the effect,
its place and its size are known. Effects on the body (soft tissue, slip, joint translation, extra DOF,
delay, distortion) move the clean positions, and the noisy trial is the new clean one plus the same noise,
with the same gaps; effects of labelling or recording (swap, outliers) edit the noisy trial only. The rigid
truth stays the truth; :func:`identcheck.effects.registry.true_centre_world` gives joint centres with the
effect included.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from identcheck.bundle.hypothesis import rescale
from identcheck.errors import InputError
from identcheck.geometry.rotations import rotvec_matrix
from identcheck.io.jsonable import plain

SOURCE = "inject_effect"
SEED_OFFSET = 1000003
"""``identcheck simulate --seed S --effect NAME`` injects with seed ``S + SEED_OFFSET``."""
MONOMIALS = ("x^2", "y^2", "z^2", "xy", "xz", "yz")
"""Order of the quadratic monomials of ``spatial_distortion`` (injected coefficients and fitted fields)."""


@dataclass(frozen=True)
class Change:
    """What one injector produces: new clean or new noisy positions, and the record."""

    where: dict
    params: dict
    clean: np.ndarray | None = None   # (F, M, 3): body effects
    trial: np.ndarray | None = None   # (F, M, 3): recording effects
    gaps: np.ndarray | None = None    # (F, M): only when the effect moves gaps (marker_swap)


def apply_change(sim, name: str, seed: int, change: Change):
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


def cannot(name: str, why: str) -> InputError:
    """The error for an effect this model cannot carry, saying why."""
    return InputError([f"effect {name!r} cannot be injected: {why}"], source=SOURCE)


def pick(rng: np.random.Generator, options):
    """One of `options`, uniformly."""
    return options[int(rng.integers(len(options)))]


def draw_frame(rng: np.random.Generator, low: float, high: float, n_frames: int) -> int:
    """An integer frame uniform in [low, high], clipped to [0, n_frames - 1] when the range is empty."""
    lo, hi = math.ceil(low), math.floor(high)
    lo = min(max(lo, 0), n_frames - 1)
    return int(rng.integers(lo, max(lo, min(hi, n_frames - 1)) + 1))


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def unit_vectors(rng: np.random.Generator, k: int) -> np.ndarray:
    """`k` random unit vectors, uniform on the sphere, shape (k, 3)."""
    return unit(rng.normal(size=(k, 3)))


def marker_column(sim, marker: str) -> int:
    return sim.trial.index(marker)


def rotations(sim, segment: str) -> np.ndarray:
    """World-from-segment rotations of the rigid truth, shape (F, 3, 3)."""
    return sim.truth.segments[segment].poses[:, :3, :3]


def rotate(rot: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per-frame rotation of per-frame vectors: (F, 3, 3) x (F, 3) -> (F, 3)."""
    return np.einsum("fij,fj->fi", rot, v)


def subtree(model, segment: str) -> list[str]:
    """`segment` and every segment below it, parents before children."""
    out = [segment]
    for seg in out:
        out.extend(j.child for j in model.child_joints(seg))
    return out


def subtree_columns(sim, segment: str) -> list[int]:
    """Trial columns of the markers of `segment` and of every segment below it."""
    return [marker_column(sim, m) for s in subtree(sim.model, segment) for m in sim.model.segments[s].markers]


def normalised_angle(joint, low: float) -> np.ndarray:
    """The joint's angle (hinge angle, or a ball joint's rotation vector on its first motion
    axis, the flexion) rescaled from its [min, max] to [low, 1]; zeros if it does not move."""
    angle = joint.angles_deg if joint.angles_deg.ndim == 1 else joint.angles_deg @ joint.motion_axes[:, 0]
    return rescale(angle, low)


def extra_rotation_world(rot_parent: np.ndarray, axis_parent, angle_deg) -> np.ndarray:
    """World rotations R_P Rot(b, psi) R_P^T of ``extra_dof``, shape (F, 3, 3)."""
    turn = rotvec_matrix(np.deg2rad(np.asarray(angle_deg))[:, None] * np.asarray(axis_parent))
    return rot_parent @ turn @ np.swapaxes(rot_parent, 1, 2)


def monomials(u: np.ndarray) -> np.ndarray:
    """The 6 quadratic monomials of :data:`MONOMIALS`, shape (..., 6), of points (..., 3)."""
    x, y, z = u[..., 0], u[..., 1], u[..., 2]
    return np.stack([x * x, y * y, z * z, x * y, x * z, y * z], axis=-1)


def diameter(points: np.ndarray) -> float:
    """Largest distance between two of `points` (F, 3) lying in a plane: the widest of their
    projections on 360 directions of that plane (under by at most 1e-5 relative)."""
    if len(points) < 2:
        return 0.0
    centred = points - points.mean(axis=0)
    plane = np.linalg.svd(centred, full_matrices=False)[2][:2]
    angle = np.linspace(0.0, np.pi, 360, endpoint=False)
    dirs = np.stack([np.cos(angle), np.sin(angle)])
    return float(np.ptp(centred @ plane.T @ dirs, axis=0).max())


