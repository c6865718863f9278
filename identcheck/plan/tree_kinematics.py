"""Forward kinematics of a whole marker plan, in one flat parameter vector, in floats or at 50 digits.

The witnesses of :mod:`identcheck.plan.witness_search` need the same skeleton evaluated two ways: in
float64 to search (Jacobians by differences, Gauss-Newton) and in mpmath to verify that a
constructed alternative puts every marker where it was measured to far below any rounding.
One function, :func:`positions`, serves both: it is written with array operations that work on
float arrays and on object arrays of ``mpmath.mpf`` alike.

Parameters (the joint constraints hold exactly for every value, so only the markers can fail):

- constants: each marker's position on its segment (3); each joint's centre in its parent (3) and
  in its child (3); each hinge's direction in its parent (3, normalised when used) and the child's
  rest orientation (a quaternion, 4, normalised);
- per frame: the root's orientation (a quaternion, 4) and position (3); each ball joint's relative
  rotation (a quaternion, 4); each hinge's angle (1).

Child pose: R_C = R_P · rel, t_C = (R_P c + t_P) − R_C e, with rel = Rot(â, θ) · Rest (hinge) or
Rot(q̂) (ball): the centre is the same point of both segments and a hinge keeps its axis, exactly.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import mpmath
import numpy as np
from scipy.spatial.transform import Rotation

from identcheck.certify.tree_rank import TreeSpec, adjacent_points
from identcheck.geometry.kinematics import chain_poses
from identcheck.geometry.rotations import (axis_rotation, elementwise as _fn, matrix_quaternion as _quat_from_matrix,
                                           quaternion_matrix as quat_matrix)

DPS = 50


# -- the parameter layout ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Layout:
    """Where each constant and per-frame variable sits in the flat vector ``[constants | frame 0 | frame 1 ...]``.

    ``judged``: ((joint, (parent-side points, child-side points)), ...), the points the whole-tree verdict
    judged each joint against (:attr:`identcheck.certify.tree_rank.JointRank.points`); a joint not listed is
    measured against all its :func:`~identcheck.certify.tree_rank.adjacent_points`."""

    spec: TreeSpec
    judged: tuple = ()

    @cached_property
    def markers(self) -> list:
        return [m for s in self.segments for m in self.spec.markers[s]]

    @cached_property
    def segments(self) -> list:
        return [self.spec.root] + [j[3] for j in self.spec.joints]

    @cached_property
    def const(self) -> dict:
        """name -> slice into the constants: ``m:NAME``, ``c:JOINT``, ``e:JOINT``, ``a:JOINT``, ``rest:JOINT``."""
        out, i = {}, 0
        for m in self.markers:
            out[f"m:{m}"] = slice(i, i + 3); i += 3
        for name, kind, _, _ in self.spec.joints:
            out[f"c:{name}"] = slice(i, i + 3); i += 3
            out[f"e:{name}"] = slice(i, i + 3); i += 3
            if kind == "revolute":
                out[f"a:{name}"] = slice(i, i + 3); i += 3
                out[f"rest:{name}"] = slice(i, i + 4); i += 4
        return out

    @cached_property
    def n_const(self) -> int:
        return max((s.stop for s in self.const.values()), default=0)

    @cached_property
    def frame(self) -> dict:
        """name -> slice into one frame's variables: ``root_q``, ``root_t``, ``q:JOINT`` / ``theta:JOINT``."""
        out = {"root_q": slice(0, 4), "root_t": slice(4, 7)}
        i = 7
        for name, kind, _, _ in self.spec.joints:
            k = 4 if kind == "spherical" else 1
            out[("q:" if kind == "spherical" else "theta:") + name] = slice(i, i + k); i += k
        return out

    @cached_property
    def per_frame(self) -> int:
        return max(s.stop for s in self.frame.values())

    def size(self, n_frames: int) -> int:
        return self.n_const + n_frames * self.per_frame

    def split(self, x, n_frames: int):
        """(constants, per-frame variables (F, per_frame)) views of a flat vector."""
        return x[:self.n_const], x[self.n_const:].reshape(n_frames, self.per_frame)


# -- forward kinematics --------------------------------------------------------------------------------
def tree_poses(layout: Layout, const, frames) -> dict:
    """segment -> (R (F, 3, 3), t (F, 3)) for constants ``const`` and per-frame variables ``frames``."""
    L = layout
    rel = {}
    for name, kind, par, chi in L.spec.joints:
        if kind == "spherical":
            rel[name] = quat_matrix(frames[:, L.frame["q:" + name]])
        else:
            rest = quat_matrix(const[L.const["rest:" + name]])
            rel[name] = axis_rotation(const[L.const["a:" + name]], frames[:, L.frame["theta:" + name].start]) @ rest
    R, t, _ = chain_poses([(name, par, chi) for name, _, par, chi in L.spec.joints], L.spec.root,
                          quat_matrix(frames[:, L.frame["root_q"]]), frames[:, L.frame["root_t"]], rel,
                          {name: const[L.const["c:" + name]] for name, *_ in L.spec.joints},
                          {name: const[L.const["e:" + name]] for name, *_ in L.spec.joints})
    return R, t


def positions(layout: Layout, x, n_frames: int):
    """Every marker in every frame, (F, M, 3), in ``layout.markers`` order (floats or mpf, as ``x``)."""
    const, frames = layout.split(x, n_frames)
    R, t = tree_poses(layout, const, frames)
    cols = []
    for s in layout.segments:
        for m in layout.spec.markers[s]:
            cols.append(R[s] @ const[layout.const["m:" + m]] + t[s])
    if not cols:
        return np.zeros((n_frames, 0, 3), dtype=x.dtype)
    return np.stack(cols, axis=1)


def to_mp(x: np.ndarray) -> np.ndarray:
    """A float vector as an object array of mpf (each float exactly)."""
    return np.array([mpmath.mpf(float(v)) for v in np.ravel(x)], dtype=object).reshape(np.shape(x))


# -- the gauge-invariant quantities of one joint ---------------------------------------------------------
def joint_quantities(layout: Layout, const, joint: str) -> dict:
    """label -> value of the quantities :mod:`identcheck.certify.tree_rank` judges ``joint`` by: each adjacent
    point's squared distance to the centre (ball) or hinge, and the hinge's axial offsets between them (the
    points of ``layout.judged`` when it names the joint)."""
    L = layout
    name, kind, par, chi = next(j for j in L.spec.joints if j[0] == joint)
    c, e = const[L.const["c:" + name]], const[L.const["e:" + name]]
    if kind == "revolute":
        a = const[L.const["a:" + name]]
        a = a / _fn(a, "sqrt")((a * a).sum())
        rest = quat_matrix(const[L.const["rest:" + name]])
        axes = {par: a, chi: rest.T @ a}           # the hinge direction in each segment's frame
    out, axial = {}, []
    points = dict(L.judged).get(joint) or adjacent_points(L.spec, joint)
    for side, pts in zip((par, chi), points):
        origin = c if side == par else e
        for pt in pts:
            y = _point(L, const, pt, side)
            w = y - origin
            if kind == "spherical":
                out[f"|{pt.name} - centre|^2"] = (w * w).sum()
                continue
            h = (w * axes[side]).sum()
            out[f"dist({pt.name}, hinge)^2"] = (w * w).sum() - h * h
            axial.append((pt.name, h))
    for (n0, h0), (n1, h1) in zip(axial, axial[1:]):
        out[f"axial({n1}) - axial({n0})"] = h1 - h0
    return out


def _point(L: Layout, const, pt, seg: str):
    if pt.kind == "marker":
        return const[L.const["m:" + pt.name]]
    j = next(j for j in L.spec.joints if j[0] == pt.name)
    return const[L.const[("c:" if j[2] == seg else "e:") + pt.name]]


# -- from the simulator's truth ------------------------------------------------------------------------
def from_truth(layout: Layout, truth) -> np.ndarray:
    """The flat parameter vector of :func:`identcheck.simulate.rigid.simulate`'s true subject (all its frames)."""
    L = layout
    R = {s: truth.segments[s].poses[:, :3, :3] for s in L.segments}
    t = {s: truth.segments[s].poses[:, :3, 3] for s in L.segments}
    local = {m: truth.segments[s].marker_local[m] for s in L.segments for m in L.spec.markers[s]}
    js = truth.joints
    return from_poses(L, R, t, local, {n: js[n].centre_parent for n in js}, {n: js[n].centre_child for n in js},
                      {n: js[n].axis_parent for n in js if js[n].axis_parent is not None})


def from_poses(layout: Layout, R: dict, t: dict, marker_local: dict, centre_parent: dict, centre_child: dict,
               axis_parent: dict) -> np.ndarray:
    """The flat vector of a skeleton given as world segment poses (R (F, 3, 3), t (F, 3) per segment) and
    constants. A hinge's angle is the turn of the relative rotation about its axis since frame 0 (exact
    when the poses keep the hinge; the nearest hinge motion otherwise, as a starting point)."""
    L = layout
    F = R[L.spec.root].shape[0]
    const = np.zeros(L.n_const)
    frames = np.zeros((F, L.per_frame))
    for m, v in marker_local.items():
        const[L.const["m:" + m]] = v
    frames[:, L.frame["root_q"]] = _quat_from_matrix(R[L.spec.root])
    frames[:, L.frame["root_t"]] = t[L.spec.root]
    for name, kind, par, chi in L.spec.joints:
        const[L.const["c:" + name]] = centre_parent[name]
        const[L.const["e:" + name]] = centre_child[name]
        rel = np.swapaxes(R[par], 1, 2) @ R[chi]
        if kind == "spherical":
            frames[:, L.frame["q:" + name]] = _quat_from_matrix(rel)
            continue
        a = np.asarray(axis_parent[name], dtype=float)
        a = a / np.linalg.norm(a)
        const[L.const["a:" + name]] = a
        const[L.const["rest:" + name]] = _quat_from_matrix(rel[0])
        turn = Rotation.from_matrix(rel @ rel[0].T).as_rotvec()      # Rot(a, θ_i − θ_0)
        frames[:, L.frame["theta:" + name].start] = turn @ a
    return np.concatenate([const, frames.ravel()])


def constants(layout: Layout, const) -> tuple:
    """(marker_local, centre_parent, centre_child, axis_parent) dicts of a constants vector."""
    L = layout
    local = {m: np.array(const[L.const["m:" + m]], dtype=float) for m in L.markers}
    cp = {n: np.array(const[L.const["c:" + n]], dtype=float) for n, *_ in L.spec.joints}
    cc = {n: np.array(const[L.const["e:" + n]], dtype=float) for n, *_ in L.spec.joints}
    ax = {n: np.array(const[L.const["a:" + n]], dtype=float) for n, k, *_ in L.spec.joints if k == "revolute"}
    return local, cp, cc, ax
