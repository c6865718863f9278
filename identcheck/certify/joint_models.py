"""Joint models given only as a symbolic parametrisation, for the local identifiability engine.

A model maps constant parameters (the same in every sample) and per-sample variable parameters
to the coordinates of the q child markers in the frame F of the parent's p markers (Pham et al.,
section II-A). Nothing is eliminated by hand: :mod:`identcheck.certify.jacobian` decides local
identifiability from the exact rank of the Jacobian of this map at random rational points.

Canonical frames (what the per-sample parent variables are)
-----------------------------------------------------------
p ≥ 3  the parent is fully posed: F is the frame of its markers, no per-sample parent variable.
p = 2  A1 at the origin, A2 on +z; the parent's roll θ about A1A2 is a per-sample angle (the
       joint's constants are then taken with the parent's roll gauge fixed, e.g. a spherical
       centre at (r, 0, d) in the parent before the roll, as in Pham's Fig. 1).
p = 1  A at the origin, axes parallel to the lab's; the parent's orientation is free per sample
       (three Euler angles φ0, ψ0, ξ0 = Rz·Ry·Rz; for a spherical joint only the direction of the
       centre from A matters, two angles, since the child's own orientation is free anyway).
p = 0  F is the lab frame and the parent's pose is free per sample (rotation and translation),
       so the child's pose is free too: only the child's own rigid shape is observable.

The child's markers are constants in the child's frame; the joint's degrees of freedom are
per-sample variables. Every parametrisation for p ≥ 1 is minimal: the gauge of each frame is
fixed canonically (listed per joint below), so there is no constant that the data cannot see
by construction. For p = 0 (and inside every model anyway) gauge does not matter: the engine
only asks about ``interest`` quantities, and a quantity f is locally identifiable iff its
gradient is orthogonal to the Jacobian's null space, which contains every gauge direction.

What "the joint parameters" are
-------------------------------
``interest`` lists gauge-invariant quantities: the joint's place relative to the parent's
markers (constants, e.g. the DH (d, r, α) of a hinge seen from A1A2, or the distance of a single
marker A to the centre), its place relative to the child's markers (marker-to-centre distances,
marker-to-axis distances, axial offsets), and, per sample (Pham's Π_v^(i), Definition 1), the
joint's position in F in one sample (e.g. the roll θ of the centre about A1A2). With p = 0 no
quantity relates the joint to a parent marker; the joint parameters are then only those
relative to the child's markers, and none of them is observable (the child's pose is free).
A case whose markers define no joint quantity at all (e.g. (0, 0), or a prismatic joint with a
single child marker and no parent marker) has an empty ``interest`` and is reported as not
identifiable (``vacuous``).

Joints
------
revolute   hinge axis z_D of a frame D in the parent; the child turns about it by β. Parent side:
           p ≥ 3 D = DH(θ0, d, r, α) with θ0 constant; p = 2 the same with θ per sample (Pham III-A);
           p = 1 the axis passes through (r, 0, 0) along z of the parent, whose orientation is free;
           p = 0 D is the free parent pose. Child markers (ρ_k cos γ_k, ρ_k sin γ_k, l_k) in D,
           γ_1 = 0 (fixes the origin of β); l_k is the axial offset from the foot of the common
           perpendicular with A1A2 (p ≥ 2) or from the foot of the perpendicular from A (p = 1).
spherical  centre J; p ≥ 3 J = (x_J, y_J, z_J); p = 2 J = Rz(θ)(r, 0, d); p = 1 J = r·u(φ0, ψ0);
           p = 0 J = t (per-sample translation). Child: q = 1 B = J + ρ u(φ, ψ) (Pham IV-A);
           q ≥ 2 B_k = J + R(φ, ψ, ξ) b_k with b_1 = ρ1 e_x, b_2 = ρ2 (cos γ, sin γ, 0) (IV-C),
           b_3 = ρ3 (cos δ3 cos ε3, sin δ3 cos ε3, sin ε3).
universal  two perpendicular axes meeting at the centre J: axis 1 fixed in the parent (z of a
           frame U at J), axis 2 fixed in the child (the child's x axis); the child's orientation
           is U·Rz(β1)·Rx(β2). Parent side: p ≥ 3 U = T(x_J, y_J, z_J)·Rz(μ)·Ry(ν); p = 2
           U = Rz(θ)·T(r, 0, d)·Rz(μ)·Ry(ν); p = 1 U = R(φ0, ψ0, ξ0)·T(0, 0, r)·Ry(ν) (ν is the
           angle between AJ and axis 1); p = 0 U is the free parent pose. Child markers
           b_1 = (h1, 0, m1) (fixes the origin of β2), b_k = (h_k, v_k, w_k): h_k is the offset
           along axis 2 from J.
prismatic  the child translates by s along a direction u fixed in both links, its orientation
           relative to the parent constant. Child marker k is at U·(b_k + s e_z) in the parent,
           U's z axis = u. p ≥ 3 U = Rz(μ)·Ry(ν); p = 2 U = Rz(θ)·Ry(ν); p = 1 U = R(φ0, ψ0, ξ0);
           p = 0 U is the free parent pose. b_1 = (e1, f1, 0) (B1's axial coordinate is the
           origin of s), with f1 = 0 for p = 1 and b_1 = 0, b_2 = (e2, 0, g2) for p = 0;
           b_k = (e_k, f_k, g_k): (e_k, f_k) is the offset of B_k's track from the slide axis
           through the parent's frame, g_k = u·(B_k − B_1) at any s.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import sympy as sp

from identcheck.errors import InputError
from identcheck.symbols import ALPHA, BETA, GAMMA, PHI, PSI, THETA, XI, Angle, d, l, r, rho, rho1, rho2, x_J, y_J, z_J

JOINTS = ("revolute", "spherical", "universal", "prismatic")
MARKERS = range(0, 4)


def _angle(name: str) -> Angle:
    return Angle(name, sp.Symbol(name, real=True), sp.Symbol(f"c_{name}", real=True),
                 sp.Symbol(f"s_{name}", real=True))


# the parent's orientation per sample (p = 1, p = 0) and translation (p = 0)
PHI0, PSI0, XI0 = _angle("phi0"), _angle("psi0"), _angle("xi0")
TX, TY, TZ = sp.symbols("t_x t_y t_z", real=True)
# revolute: the hinge's DH roll when the parent is fully posed; child markers 2, 3
THETA0 = _angle("theta0")
GAMMA2, GAMMA3 = _angle("gamma2"), _angle("gamma3")
rho3 = sp.Symbol("rho3", positive=True)
l1, l2, l3 = sp.symbols("l1 l2 l3", real=True)
# spherical: direction of the third child marker from the centre
DELTA3, EPS3 = _angle("delta3"), _angle("epsilon3")
# universal / prismatic: direction of the parent-fixed axis (azimuth μ, tilt ν); joint angles
MU, NU = _angle("mu"), _angle("nu")
BETA1, BETA2 = _angle("beta1"), _angle("beta2")
h1, h2, h3, m1, v2, w2, v3, w3 = sp.symbols("h1 h2 h3 m1 v2 w2 v3 w3", real=True)
# prismatic: slide, child markers in the slide frame U
s_slide = sp.Symbol("s", real=True)
e1, f1, e2, f2, g2, e3, f3, g3 = sp.symbols("e1 f1 e2 f2 g2 e3 f3 g3", real=True)


@dataclass(frozen=True)
class Interest:
    """A gauge-invariant joint quantity whose local identifiability is asked.

    Either ``angle`` (the angle itself) or ``expr`` (a polynomial in the model's symbols) is
    set. ``per_sample`` quantities involve the variables of one sample (sample 0).
    """

    name: str
    description: str
    expr: sp.Expr | None = None
    angle: Angle | None = None
    per_sample: bool = False


@dataclass(frozen=True)
class JointModel:
    """A joint case given only as a symbolic parametrisation.

    Attributes
    ----------
    constants : tuple of Symbol
        Constant length-like parameters (drawn positive when the symbol is positive).
    constant_angles : tuple of Angle
        Constant angles, as (cos, sin) pairs.
    per_sample_lengths : tuple of Symbol
        Per-sample non-angle variables (a prismatic slide, the parent's translation for p = 0).
    variables : tuple of Angle
        Per-sample angles.
    outputs : ImmutableMatrix
        The 3q coordinates of the child's markers in F, polynomial in all the symbols above.
    interest : tuple of Interest
        The joint quantities whose identifiability is asked.
    """

    name: str
    joint: str
    p: int
    q: int
    constants: tuple
    constant_angles: tuple
    variables: tuple
    per_sample_lengths: tuple
    outputs: sp.Matrix
    interest: tuple
    notes: tuple = field(default_factory=tuple)

    @property
    def key(self) -> str:
        return f"{self.joint}({self.p},{self.q})"

    @property
    def trig_pairs(self) -> tuple:
        return tuple((a.cos, a.sin) for a in self.constant_angles + self.variables)

    @property
    def constant_columns(self) -> list:
        """Column names of the constants: lengths, then angles."""
        return [str(s) for s in self.constants] + [a.name for a in self.constant_angles]

    @property
    def variable_columns(self) -> list:
        """Column names of one sample's variables: lengths, then angles."""
        return [str(s) for s in self.per_sample_lengths] + [a.name for a in self.variables]


# -- rotations, polynomial in (cos, sin) pairs --------------------------------------------------
def Rz(a: Angle) -> sp.Matrix:
    return sp.Matrix([[a.cos, -a.sin, 0], [a.sin, a.cos, 0], [0, 0, 1]])


def Ry(a: Angle) -> sp.Matrix:
    return sp.Matrix([[a.cos, 0, a.sin], [0, 1, 0], [-a.sin, 0, a.cos]])


def Rx(a: Angle) -> sp.Matrix:
    return sp.Matrix([[1, 0, 0], [0, a.cos, -a.sin], [0, a.sin, a.cos]])


def zyz(a: Angle, b: Angle, c: Angle) -> sp.Matrix:
    """Rz(a)·Ry(b)·Rz(c) — the convention of :func:`identcheck.derive.spherical22.rotation`."""
    return Rz(a) * Ry(b) * Rz(c)


def direction(az: Angle, el: Angle) -> sp.Matrix:
    """Unit vector of azimuth ``az`` and elevation ``el`` (Pham IV-A, derive/spherical31)."""
    return sp.Matrix([az.cos * el.cos, az.sin * el.cos, el.sin])


class _Pose:
    """A rigid transform x ↦ R x + t, composed left to right."""

    def __init__(self, R=None, t=None):
        self.R = sp.eye(3) if R is None else R
        self.t = sp.zeros(3, 1) if t is None else t

    def __mul__(self, other: "_Pose") -> "_Pose":
        return _Pose(self.R * other.R, self.R * other.t + self.t)

    def apply(self, v) -> sp.Matrix:
        return self.R * sp.Matrix(v) + self.t


def _T(x_, y_, z_) -> _Pose:
    return _Pose(t=sp.Matrix([x_, y_, z_]))


def _rot(R) -> _Pose:
    return _Pose(R=R)


def _expand(m: sp.Matrix) -> sp.Matrix:
    return m.applyfunc(sp.expand)


class _Builder:
    def __init__(self, joint: str, p: int, q: int):
        self.joint, self.p, self.q = joint, p, q
        self.constants, self.constant_angles = [], []
        self.variables, self.per_sample_lengths = [], []
        self.interest, self.notes = [], []

    def const(self, *syms):
        self.constants += syms

    def const_angle(self, *angles):
        self.constant_angles += angles

    def var(self, *angles):
        self.variables += angles

    def slide(self, *syms):
        self.per_sample_lengths += syms

    def ask(self, name, description, expr=None, angle=None, per_sample=False):
        self.interest.append(Interest(name, description, expr=expr, angle=angle, per_sample=per_sample))

    def parent_pose(self, *, full_rotation=True) -> _Pose:
        """The parent's per-sample pose in F for p ≤ 1 (p = 2's roll is joint-specific)."""
        if self.p == 1:
            self.var(PHI0, PSI0, XI0)
            return _rot(zyz(PHI0, PSI0, XI0))
        if self.p == 0:
            self.var(PHI0, PSI0, XI0)
            self.slide(TX, TY, TZ)
            return _T(TX, TY, TZ) * _rot(zyz(PHI0, PSI0, XI0))
        return _Pose()

    def ask_parent_orientation(self, what: str):
        """For p = 1: the parent's orientation in F (hence the joint's place in F) in sample 0."""
        for a in (PHI0, PSI0, XI0):
            self.ask(a.name, f"{what} in F in sample 0: Euler angle {a.name} of the parent",
                     angle=a, per_sample=True)

    def build(self, outputs) -> JointModel:
        out = sp.Matrix(outputs) if outputs else sp.zeros(0, 1)
        return JointModel(
            name=f"{self.joint}({self.p},{self.q})", joint=self.joint, p=self.p, q=self.q,
            constants=tuple(self.constants), constant_angles=tuple(self.constant_angles),
            variables=tuple(self.variables), per_sample_lengths=tuple(self.per_sample_lengths),
            outputs=sp.ImmutableMatrix(_expand(out)), interest=tuple(self.interest), notes=tuple(self.notes))


# -- revolute -----------------------------------------------------------------------------------
def _dh(theta: Angle) -> _Pose:
    """Pham's DH frame D(θ; d, r, α) (same matrix as derive.revolute.dh_matrix)."""
    ct, st, ca, sa = theta.cos, theta.sin, ALPHA.cos, ALPHA.sin
    R = sp.Matrix([[ct, -st * ca, st * sa], [st, ct * ca, -ct * sa], [0, sa, ca]])
    return _Pose(R, sp.Matrix([r * ct, r * st, d]))


def _revolute(b: _Builder) -> list:
    p, q = b.p, b.q
    if p >= 3:
        b.const(d, r)
        b.const_angle(THETA0, ALPHA)
        D = _dh(THETA0)
        b.ask("theta0", "DH roll of the hinge axis about A1A2 in the parent's frame", angle=THETA0)
        b.ask("d", "DH offset along A1A2 of the common perpendicular", expr=d)
        b.ask("r", "distance between the line A1A2 and the hinge axis", expr=r)
        b.ask("alpha", "angle between A1A2 and the hinge axis", angle=ALPHA)
    elif p == 2:
        b.const(d, r)
        b.const_angle(ALPHA)
        b.var(THETA)
        D = _dh(THETA)
        b.ask("d", "DH offset along A1A2 of the common perpendicular (Pham III-A)", expr=d)
        b.ask("r", "distance between the line A1A2 and the hinge axis", expr=r)
        b.ask("alpha", "angle between A1A2 and the hinge axis", angle=ALPHA)
        b.ask("theta", "roll of the hinge axis about A1A2 in F in sample 0 (Pi_v)", angle=THETA, per_sample=True)
    elif p == 1:
        b.const(r)
        D = b.parent_pose() * _T(r, 0, 0)
        b.ask("r", "distance from A to the hinge axis (Pham III-B)", expr=r)
        b.ask_parent_orientation("the hinge axis")
    else:
        D = b.parent_pose()
    b.var(BETA)
    if q == 0:
        return []
    if q == 1:
        markers = [(rho, l, None)]
    else:
        markers = [(rho1, l1, None), (rho2, l2, GAMMA2), (rho3, l3, GAMMA3)][:q]
    outs = []
    for k, (rk, lk, gk) in enumerate(markers, start=1):
        b.const(rk, lk)
        if gk is not None:
            b.const_angle(gk)
        bk = sp.Matrix([rk, 0, lk]) if gk is None else sp.Matrix([rk * gk.cos, rk * gk.sin, lk])
        outs += list(D.apply(Rz(BETA) * bk))
    for k, (rk, lk, gk) in enumerate(markers, start=1):
        b.ask(str(rk), f"distance from B{k} to the hinge axis", expr=rk)
        if p >= 1:
            b.ask(str(lk), f"axial offset of B{k} from the foot of the parent's perpendicular", expr=lk)
        elif k >= 2:
            b.ask(f"{lk}-{markers[0][1]}", f"axial offset of B{k} from B1", expr=lk - markers[0][1])
        if gk is not None:
            b.ask(gk.name, f"angle about the hinge axis from B1 to B{k}", angle=gk)
    return outs


# -- spherical ----------------------------------------------------------------------------------
def _spherical(b: _Builder) -> list:
    p, q = b.p, b.q
    if p >= 3:
        b.const(x_J, y_J, z_J)
        J = sp.Matrix([x_J, y_J, z_J])
        for s in (x_J, y_J, z_J):
            b.ask(str(s), f"centre coordinate {s} in the parent's frame", expr=s)
    elif p == 2:
        b.const(d, r)
        b.var(THETA)
        J = sp.Matrix([r * THETA.cos, r * THETA.sin, d])
        b.ask("d", "height of the centre along A1A2 (Pham IV-B, IV-C)", expr=d)
        b.ask("r", "distance of the centre from the line A1A2", expr=r)
        b.ask("theta", "roll of the centre about A1A2 in F in sample 0 (Pi_v)", angle=THETA, per_sample=True)
    elif p == 1:
        b.const(r)
        b.var(PHI0, PSI0)
        J = r * direction(PHI0, PSI0)
        b.ask("r", "distance from A to the centre", expr=r)
        b.ask("phi0", "azimuth of the centre seen from A in F in sample 0", angle=PHI0, per_sample=True)
        b.ask("psi0", "elevation of the centre seen from A in F in sample 0", angle=PSI0, per_sample=True)
    else:
        b.slide(TX, TY, TZ)
        J = sp.Matrix([TX, TY, TZ])
        b.notes.append("p = 0: the centre is the parent's free per-sample translation")
    if q == 0:
        return []
    if q == 1:
        b.const(rho)
        b.var(PHI, PSI)
        b.ask("rho", "distance from B to the centre", expr=rho)
        return list(J + rho * direction(PHI, PSI))
    b.var(PHI, PSI, XI)
    R = zyz(PHI, PSI, XI)
    b.const(rho1, rho2)
    b.const_angle(GAMMA)
    local = [sp.Matrix([rho1, 0, 0]), sp.Matrix([rho2 * GAMMA.cos, rho2 * GAMMA.sin, 0])]
    if q >= 3:
        b.const(rho3)
        b.const_angle(DELTA3, EPS3)
        local.append(rho3 * direction(DELTA3, EPS3))
    outs = []
    for bk in local:
        outs += list(J + R * bk)
    for k, rk in enumerate((rho1, rho2, rho3)[:q], start=1):
        b.ask(str(rk), f"distance from B{k} to the centre", expr=rk)
    return outs


# -- universal ----------------------------------------------------------------------------------
def _universal(b: _Builder) -> list:
    p, q = b.p, b.q
    if p >= 3:
        b.const(x_J, y_J, z_J)
        b.const_angle(MU, NU)
        U = _T(x_J, y_J, z_J) * _rot(Rz(MU) * Ry(NU))
        for s in (x_J, y_J, z_J):
            b.ask(str(s), f"centre coordinate {s} in the parent's frame", expr=s)
        b.ask("mu", "azimuth of axis 1 in the parent's frame", angle=MU)
        b.ask("nu", "tilt of axis 1 from A1A2 (the parent's z axis)", angle=NU)
    elif p == 2:
        b.const(d, r)
        b.const_angle(MU, NU)
        b.var(THETA)
        U = _rot(Rz(THETA)) * _T(r, 0, d) * _rot(Rz(MU) * Ry(NU))
        b.ask("d", "height of the centre along A1A2", expr=d)
        b.ask("r", "distance of the centre from the line A1A2", expr=r)
        b.ask("mu", "azimuth of axis 1 about A1A2 relative to the centre's", angle=MU)
        b.ask("nu", "angle between A1A2 and axis 1", angle=NU)
        b.ask("theta", "roll of the centre about A1A2 in F in sample 0 (Pi_v)", angle=THETA, per_sample=True)
    elif p == 1:
        b.const(r)
        b.const_angle(NU)
        U = b.parent_pose() * _T(0, 0, r) * _rot(Ry(NU))
        b.ask("r", "distance from A to the centre", expr=r)
        b.ask("nu", "angle between AJ and axis 1", angle=NU)
        b.ask_parent_orientation("the centre and axis 1")
    else:
        U = b.parent_pose()
    b.var(BETA1, BETA2)
    if q == 0:
        return []
    R = Rz(BETA1) * Rx(BETA2)
    local = [(h1, sp.Matrix([h1, 0, m1]), (h1, m1)), (h2, sp.Matrix([h2, v2, w2]), (h2, v2, w2)),
             (h3, sp.Matrix([h3, v3, w3]), (h3, v3, w3))][:q]
    outs = []
    for k, (hk, bk, syms) in enumerate(local, start=1):
        b.const(*syms)
        outs += list(U.apply(R * bk))
        b.ask(f"|JB{k}|^2", f"squared distance from B{k} to the centre", expr=(bk.T * bk)[0])
        b.ask(str(hk), f"offset of B{k} along axis 2 from the centre", expr=hk)
    return outs


# -- prismatic ----------------------------------------------------------------------------------
def _prismatic(b: _Builder) -> list:
    p, q = b.p, b.q
    if p >= 3:
        b.const_angle(MU, NU)
        U = _rot(Rz(MU) * Ry(NU))
        b.ask("mu", "azimuth of the slide direction in the parent's frame", angle=MU)
        b.ask("nu", "tilt of the slide direction from A1A2 (the parent's z axis)", angle=NU)
    elif p == 2:
        b.const_angle(NU)
        b.var(THETA)
        U = _rot(Rz(THETA) * Ry(NU))
        b.ask("nu", "angle between A1A2 and the slide direction", angle=NU)
        b.ask("theta", "azimuth of the slide direction about A1A2 in F in sample 0", angle=THETA, per_sample=True)
    else:
        U = b.parent_pose()
        if p == 1:
            for a in (PHI0, PSI0):
                b.ask(a.name, f"slide direction in F in sample 0: Euler angle {a.name}", angle=a, per_sample=True)
    b.slide(s_slide)
    if q == 0:
        return []
    if p >= 2:
        local = [(e1, f1, None), (e2, f2, g2), (e3, f3, g3)]
    elif p == 1:
        local = [(e1, None, None), (e2, f2, g2), (e3, f3, g3)]
    else:
        local = [(None, None, None), (e2, None, g2), (e3, f3, g3)]
    outs = []
    for k, (ek, fk, gk) in enumerate(local[:q], start=1):
        b.const(*(s for s in (ek, fk, gk) if s is not None))
        bk = sp.Matrix([0 if s is None else s for s in (ek, fk, gk)])
        outs += list(U.apply(bk + sp.Matrix([0, 0, s_slide])))
        if p >= 2:
            b.ask(f"e{k}", f"offset of B{k}'s track from the slide axis through A1, along x of U", expr=ek)
            b.ask(f"f{k}", f"offset of B{k}'s track from the slide axis through A1, along y of U", expr=fk)
        elif p == 1:
            b.ask(f"|A track{k}|^2", f"squared distance from A to B{k}'s track",
                  expr=ek**2 + (0 if fk is None else fk) ** 2)
        if k >= 2:
            b.ask(f"g{k}", f"slide-direction component of B{k} - B1 (direction relative to the child)", expr=gk)
    return outs


_BUILD = {"revolute": _revolute, "spherical": _spherical, "universal": _universal, "prismatic": _prismatic}


@lru_cache(maxsize=None)
def model(joint: str, p: int, q: int) -> JointModel:
    """The parametrised joint model for ``joint`` with p parent and q child markers (0..3)."""
    joint = str(joint).lower()
    if joint not in JOINTS:
        raise InputError(f"unknown joint type {joint!r}; known types: {', '.join(JOINTS)}")
    p, q = int(p), int(q)
    if p not in MARKERS or q not in MARKERS:
        raise InputError(f"marker counts must be in 0..3, got ({p},{q})")
    from identcheck.derive.cache import entry

    return entry("joint_models", _models_key(), (joint, p, q), lambda: _build(joint, p, q))


def _build(joint: str, p: int, q: int) -> JointModel:
    """:func:`model`'s work: SymPy builds and expands the outputs (a tenth of a second per case; kept on disk
    between processes, keyed by :func:`_models_key`)."""
    b = _Builder(joint, p, q)
    outs = _BUILD[joint](b)
    return b.build(outs)


@lru_cache(maxsize=1)
def _models_key() -> str:
    """What a model depends on: this module and the symbols, with SymPy's version."""
    from pathlib import Path

    from identcheck.derive.cache import files_key

    here = Path(__file__).resolve()
    return files_key([here, here.parents[1] / "symbols.py"])


def all_models() -> list:
    return [model(j, p, q) for j in JOINTS for p in MARKERS for q in MARKERS]


# the cases an existing hand derivation covers: derive.<name>.results["forward"]
DERIVED = {("revolute", 2, 1): "revolute21", ("spherical", 3, 1): "spherical31",
           ("spherical", 2, 2): "spherical22"}


def agrees_with_derivation(m: JointModel) -> bool:
    """True when the model's outputs equal the hand derivation's ``forward`` identically."""
    from identcheck import derive

    dv = derive.get(DERIVED[(m.joint, m.p, m.q)], disk_cache=False)
    fwd = sp.Matrix(dv.result("forward"))
    return fwd.shape == m.outputs.shape and all(sp.expand(a - b_) == 0 for a, b_ in zip(fwd, m.outputs))
