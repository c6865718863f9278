"""An independent oracle for :mod:`identcheck.certify.tree_rank`: the whole-tree Jacobian written with the
root's pose and the joint angles as the per-frame unknowns (every marker row involves every joint above
it), one dense matrix per frame, W accumulated as Σ_i {λ C_i : λ V_i = 0} and reduced by FLINT.

This is the formulation the package used before its equations were rewritten segment by segment; it is
kept here only to check that rewrite: a different parametrisation of the per-frame unknowns, a different
random point, and a different algorithm must give the same dim W and the same verdicts."""
from __future__ import annotations

import random

import flint

from identcheck.certify import tree_rank
from identcheck.certify.tree_equations import axis_rotation_derivative
from identcheck.exact.algebra import add, axis_rotation, cross, mm, mv, sub, transpose
from identcheck.exact.linalg import Field


class DenseTree:
    """Frames of the joint-angle Jacobian at one random point, accumulated into W."""

    def __init__(self, spec, field_kind="GFp", seed=0):
        self.spec = spec
        rng = random.Random(f"reference/{seed}/{field_kind}")
        self.F = Field(field_kind, rng)
        self.draw = tree_rank._Draw(self.F, rng)
        self.cols = tree_rank.constant_columns(spec)     # the layout the gradients are written in
        axes = {}
        for name, kind, _, _ in spec.joints:
            if kind == "revolute":
                R = self.draw.rotation()
                axes[name] = ([R[i][2] for i in range(3)], [R[i][0] for i in range(3)], [R[i][1] for i in range(3)])
        self.k = tree_rank._Constants(m={m: self.draw.vector() for ms in spec.markers.values() for m in ms},
                                      c={j[0]: self.draw.vector() for j in spec.joints}, a=axes)
        self.frozen_angles = {n: self._turn(n, kind) for n, kind, _, _ in spec.joints if n in spec.frozen}
        self.var_offset, nv = {}, 6
        for name, kind, _, _ in spec.joints:
            if name not in spec.frozen:
                self.var_offset[name] = nv
                nv += tree_rank.VARS_PER_JOINT[kind]
        self.n_vars = nv
        self.W, self.pivots, self.frames = [], [], 0

    def _turn(self, name, kind):
        if kind == "spherical":
            return (self.draw.rotation(), None)
        c, s = self.draw.angle()
        return (axis_rotation(self.k.a[name][0], c, s), (c, s))

    def _rref(self, rows, ncols):
        if not rows:
            return []
        M = flint.nmod_mat(rows, self.F.p) if self.F.p else flint.fmpq_mat(len(rows), ncols, [v for r in rows for v in r])
        R, r = M.rref()
        flat = R.entries()
        return [flat[i * ncols:(i + 1) * ncols] for i in range(r)]

    def _frame_rows(self):
        spec, k, F = self.spec, self.k, self.F
        zero = F(0)
        pose = {spec.root: (self.draw.rotation(), self.draw.vector())}
        at = {}
        for name, kind, par, chi in spec.joints:
            RP, tP = pose[par]
            Q, cs = self.frozen_angles.get(name) or self._turn(name, kind)
            pose[chi] = (mm(RP, Q), add(mv(RP, k.c[name]), tP))
            at[name] = (RP, tP, Q, cs)
        ncols = self.n_vars + self.cols.n
        base = self.n_vars
        rows = []
        for s, ms in spec.markers.items():
            for m in ms:
                R, t = pose[s]
                x = add(mv(R, k.m[m]), t)
                block = [[zero] * ncols for _ in range(3)]
                e = [[F(1), zero, zero], [zero, F(1), zero], [zero, zero, F(1)]]
                for a in range(3):
                    col = cross(e[a], x)
                    for r in range(3):
                        block[r][a] = col[r]
                        block[r][3 + a] = e[a][r]
                        block[r][base + self.cols.marker[m] + a] = R[r][a]
                seg = s
                while seg != spec.root:
                    name, kind, par, _ = spec.parent_joint[seg]
                    RP, tP, Q, cs = at[name]
                    rel = sub(x, pose[seg][1])
                    v0 = self.var_offset[name] if name in self.var_offset else base + self.cols.frozen[name]
                    axes = [[RP[0][a], RP[1][a], RP[2][a]] for a in range(3)] if kind == "spherical" \
                        else [mv(RP, k.a[name][0])]
                    for a, ax in enumerate(axes):
                        col = cross(ax, rel)
                        for r in range(3):
                            block[r][v0 + a] = col[r]
                    for a in range(3):
                        for r in range(3):
                            block[r][base + self.cols.centre[name] + a] = RP[r][a]
                    if kind == "revolute":
                        a_, u_, w_ = k.a[name]
                        c, s_ = cs
                        z = mv(transpose(Q), sub(mv(transpose(RP), sub(x, tP)), k.c[name]))
                        for b, tv in enumerate((u_, w_)):
                            col = mv(RP, mv(axis_rotation_derivative(a_, tv, c, s_), z))
                            for r in range(3):
                                block[r][base + self.cols.tangent[name] + b] = col[r]
                    seg = par
                rows.extend(block)
        return rows

    def add_frame(self):
        red = self._rref(self._frame_rows(), self.n_vars + self.cols.n)
        new = [r[self.n_vars:] for r in red if all(v == 0 for v in r[:self.n_vars])]
        self.W = self._rref(self.W + new, self.cols.n)
        self.pivots = [next(j for j, v in enumerate(r) if v != 0) for r in self.W]
        self.frames += 1
        return len(self.W)

    def in_w(self, grad) -> bool:
        g = [self.F(0)] * self.cols.n
        for i, v in grad.items():
            g[i] = g[i] + v
        for piv, row in zip(self.pivots, self.W):
            if g[piv] != 0:
                f = g[piv]
                g = [a - f * b for a, b in zip(g, row)]
        return not any(v != 0 for v in g)


class _DenseState:
    def __init__(self, dense):
        self.tj = dense

    def in_joint_span(self, joint, grads):
        return [self.tj.in_w(g) for g in grads]


def dense_verdicts(spec, frames: int, field_kind="GFp", seed=0) -> tuple:
    """(dim W, {joint: (local, undetermined labels, judged points, set-aside points)}) after ``frames``
    generic frames, judged by tree_rank's own rules."""
    d = DenseTree(spec, field_kind, seed)
    for _ in range(frames):
        dim = d.add_frame()
    asked = {j[0]: tree_rank.quantities(d, j[0]) for j in spec.joints}
    points, judged, verdict = tree_rank._judge(_DenseState(d), asked)
    return dim, {n: (bool(judged[n]) and not verdict[n], sorted(verdict[n]), points[n]) for n in asked}
