"""Constructed counterexamples: a second joint that reproduces every sample (Pham III-B, IV-B).

A :class:`Counterexample` holds measured samples (world marker positions), the true joint
geometry, an alternative geometry whose gauge-invariant quantities (marker-to-centre or
marker-to-axis distances) differ, and — for every sample — explicit parent and child poses of
the alternative that put every marker exactly where it was measured while keeping the joint
constraint (the same world centre; the same world hinge axis). :meth:`Counterexample.check`
verifies all of that in mpmath at 50 digits; nothing is taken on trust from the construction.

Constructions (all from the samples and the true invariants only):

``revolute11``   (1,1) hinge, A and B: B − A has length D with
                 D² = r² + ρ² + l² − 2rρ cos β, so an alternative (r', ρ', l') reproduces a
                 sample iff (r' − ρ')² + l'² ≤ D² ≤ (r' + ρ')² + l'². The paper's family
                 r' = r − δ, ρ' = ρ + δ (l' = l) keeps the outer radius and moves the inner one,
                 so it needs samples with D ≥ √((r − ρ − 2δ)² + l²) (its "distance from A
                 larger than Δ"); the exact family r'ρ' = rρ, r'² + ρ'² + l'² = r² + ρ² + l² keeps
                 both radii, so its output set is the same and every sample is reproduced.
``spherical21``  (2,1) ball joint: with B at distance R from the A1A2 line and height z,
                 h = z − d, an alternative (d, r', ρ') reproduces B iff
                 (R − r')² + h² ≤ ρ'² ≤ (R + r')² + h². For r' = r − δ, ρ' = ρ + δ the left
                 inequality always holds (triangle inequality); the right one holds for every
                 sample when ρ + δ ≤ r − δ, and otherwise only for samples with R ≥ ρ − r + 2δ
                 (not "for arbitrary B ∈ S" as printed: ERRATA E7).
``spherical11``  (1,1) ball joint: J' on the sphere of radius r' about A at distance ρ' from B,
                 possible iff |r' − ρ'| ≤ D ≤ r' + ρ'.
``free_parent``  p = 0: the parent carries no marker, so the joint may sit anywhere on the child.
:func:`swap` (Remark 1, (p, q) → (q, p)) and :func:`drop` (Remark 1, fewer markers) derive
counterexamples for the symmetric and the smaller cases.
"""
from __future__ import annotations

import random
from dataclasses import dataclass, field, replace

import mpmath
from mpmath import mpf

from identcheck.certify.seal import seal

DPS = 50
GUARD = 15


class ConstructionError(ValueError):
    """The construction cannot reproduce a sample (outside its range); names the sample."""

    def __init__(self, index: int, reason: str):
        super().__init__(f"sample {index}: {reason}")
        self.index = index


# -- small mpmath geometry -------------------------------------------------------------------------
def vec(v) -> mpmath.matrix:
    return mpmath.matrix([mpf(x) if not isinstance(x, mpmath.mpf) else x for x in v])


def _norm(v) -> mpf:
    return mpmath.sqrt(sum(x * x for x in v))


def _dot(u, v) -> mpf:
    return sum(a * b for a, b in zip(u, v))


def _cross(u, v) -> mpmath.matrix:
    return mpmath.matrix([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])


def rz(c, s) -> mpmath.matrix:
    return mpmath.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rotation_between(u, v) -> mpmath.matrix:
    """The rotation of least angle taking the direction of ``u`` to that of ``v``."""
    u = u / _norm(u)
    v = v / _norm(v)
    c = _dot(u, v)
    if c < -1 + mpf(10) ** (-mpmath.mp.dps // 2):          # antiparallel: half turn about a normal
        e = mpmath.matrix([1, 0, 0]) if abs(u[0]) < mpf("0.9") else mpmath.matrix([0, 1, 0])
        n = _cross(u, e)
        n = n / _norm(n)
        return 2 * n * n.T - mpmath.eye(3)
    k = _cross(u, v)
    K = mpmath.matrix([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return mpmath.eye(3) + K + K * K / (1 + c)


def quaternion_rotation(q) -> mpmath.matrix:
    """Rotation matrix of a (not necessarily unit) quaternion (w, x, y, z)."""
    w, x, y, z = (mpf(v) for v in q)
    n = w * w + x * x + y * y + z * z
    return mpmath.matrix([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                          [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                          [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]]) / n


@dataclass
class Frame:
    """A rigid transform x ↦ R x + t (R 3×3, t 3-vector, mpmath)."""

    R: mpmath.matrix
    t: mpmath.matrix

    @classmethod
    def identity(cls) -> "Frame":
        return cls(mpmath.eye(3), mpmath.matrix([0, 0, 0]))

    def apply(self, v) -> mpmath.matrix:
        return self.R * v + self.t

    def __mul__(self, other: "Frame") -> "Frame":
        return Frame(self.R * other.R, self.R * other.t + self.t)

    def inverse(self) -> "Frame":
        Rt = self.R.T
        return Frame(Rt, -(Rt * self.t))


@dataclass
class JointGeometry:
    """One joint-parameter set: markers in their link frames and the joint frame in each link.

    The child's pose is parent ∘ ``parent_joint`` ∘ motion ∘ ``child_joint``⁻¹, where the motion is
    Rz(β) for a revolute joint (its hinge is the z axis of the joint frames) and any rotation for a
    spherical joint (the joint frames' origin is the centre).
    """

    joint: str
    parent_markers: list
    child_markers: list
    parent_joint: Frame
    child_joint: Frame

    def marker_distances(self) -> dict:
        """Each marker's distance to the centre (spherical) or the hinge axis (revolute): A1.., B1.."""
        out = {}
        for prefix, pts, fr in (("A", self.parent_markers, self.parent_joint),
                                ("B", self.child_markers, self.child_joint)):
            for i, m in enumerate(pts, 1):
                w = m - fr.t
                if self.joint == "revolute":
                    ax = fr.R * mpmath.matrix([0, 0, 1])
                    w = w - _dot(w, ax) * ax
                out[f"{prefix}{i}"] = _norm(w)
        return out

    def swapped(self) -> "JointGeometry":
        return JointGeometry(self.joint, self.child_markers, self.parent_markers, self.child_joint, self.parent_joint)


@dataclass
class Pose:
    """World poses of the parent and the child links in one sample."""

    parent: Frame
    child: Frame


def markers_world(g: JointGeometry, pose: Pose) -> tuple:
    """World positions (A list, B list) of the markers of ``g`` in ``pose``."""
    return ([pose.parent.apply(a) for a in g.parent_markers], [pose.child.apply(b) for b in g.child_markers])


def joint_error(g: JointGeometry, pose: Pose) -> mpf:
    """How far ``pose`` is from satisfying the joint: 0 iff the joint frames share their origin
    (and, for a hinge, their z axis)."""
    P, C = pose.parent * g.parent_joint, pose.child * g.child_joint
    err = _norm(P.t - C.t)
    if g.joint == "revolute":
        ez = mpmath.matrix([0, 0, 1])
        err = max(err, _norm(P.R * ez - C.R * ez))
    return err


def child_pose(g: JointGeometry, parent: Frame, motion: mpmath.matrix) -> Frame:
    """The child's world pose for a parent pose and a joint rotation ``motion``."""
    return parent * g.parent_joint * Frame(motion, mpmath.matrix([0, 0, 0])) * g.child_joint.inverse()


# -- the counterexample ------------------------------------------------------------------------------
@dataclass
class Check:
    """What :meth:`Counterexample.check` measured (absolute, in the units of the samples)."""

    reproduction: mpf      # largest |alternative marker − measured marker|
    truth: mpf | None      # largest |true marker − measured marker| and joint violation (None: poses unknown)
    joint: mpf             # largest violation of the alternative's joint constraint
    change: mpf            # largest change of a marker distance (alternative − truth)
    tolerance: mpf
    ok: bool

    def to_dict(self) -> dict:
        return {"reproduction_error": mpmath.nstr(self.reproduction, 5),
                "truth_error": None if self.truth is None else mpmath.nstr(self.truth, 5), "joint_error": mpmath.nstr(self.joint, 5),
                "largest_distance_change": mpmath.nstr(self.change, 12), "tolerance": mpmath.nstr(self.tolerance, 3),
                "ok": self.ok}


@dataclass
class Counterexample:
    """Samples, the truth and an alternative joint with explicit per-sample poses reproducing them."""

    joint: str
    p: int
    q: int
    truth: JointGeometry
    alternative: JointGeometry
    data: list                 # per sample: (A list, B list) measured world positions
    poses: list                # per sample: Pose of the alternative
    construction: str
    delta: mpf
    notes: list = field(default_factory=list)
    truth_poses: list | None = None   # per sample: Pose of the truth (when known): the samples are its outputs

    @property
    def key(self) -> str:
        return f"{self.joint}({self.p},{self.q})"

    def check(self, dps: int = DPS) -> Check:
        """Rebuild every sample from the alternative at ``dps`` digits and measure the errors."""
        with mpmath.workdps(dps + GUARD):
            scale = max([_norm(x) for A, B in self.data for x in A + B] + [mpf(1)])
            rep = jerr = mpf(0)
            for (A, B), pose in zip(self.data, self.poses):
                A2, B2 = markers_world(self.alternative, pose)
                for u, v in zip(A + B, A2 + B2):
                    rep = max(rep, _norm(u - v))
                jerr = max(jerr, joint_error(self.alternative, pose))
            terr = None
            if self.truth_poses is not None:
                terr = mpf(0) if len(self.truth_poses) == len(self.data) else mpf("inf")
                for (A, B), pose in zip(self.data, self.truth_poses):
                    A2, B2 = markers_world(self.truth, pose)
                    terr = max([terr, joint_error(self.truth, pose)] + [_norm(u - v) for u, v in zip(A + B, A2 + B2)])
            t_dist, a_dist = self.truth.marker_distances(), self.alternative.marker_distances()
            change = max((abs(a_dist[k] - t_dist[k]) for k in t_dist), default=mpf(0))
            tol = scale * mpf(10) ** (-(dps - 10))
            ok = (len(self.data) == len(self.poses) and rep <= tol and jerr <= tol and (terr is None or terr <= tol)
                  and change > scale * mpf(10) ** (-(dps // 3)))
            return Check(rep, terr, jerr, change, tol, bool(ok))

    def sealed(self, digits: int = 60) -> dict:
        """The standalone counterexample: :meth:`to_dict` under format ``/2`` with its content hash
        (:func:`identcheck.certify.seal.seal`), which ``identcheck verify`` checks before re-verifying it."""
        return seal(self.to_dict(digits))

    def to_dict(self, digits: int = 60, check: Check | None = None) -> dict:
        """JSON form (format ``/1``, what a table embeds): everything :func:`from_dict` needs to re-check it
        (``digits`` significant digits). ``check``: this counterexample's :meth:`check` at the default precision
        when the caller has already run it (it is a third of a table's time), else it is run here."""
        s = lambda v: mpmath.nstr(v, digits)  # noqa: E731
        vecs = lambda vs: [[s(x) for x in v] for v in vs]  # noqa: E731
        chk = self.check() if check is None else check
        return {"format": FORMAT, "joint": self.joint, "p": self.p, "q": self.q, "case": self.key,
                "construction": self.construction, "delta": s(self.delta), "n_samples": len(self.data),
                "marker_distances_truth": {k: s(v) for k, v in self.truth.marker_distances().items()},
                "marker_distances_alternative": {k: s(v) for k, v in self.alternative.marker_distances().items()},
                "truth": _geometry_dict(self.truth, s), "alternative": _geometry_dict(self.alternative, s),
                "samples": [{"parent": vecs(A), "child": vecs(B)} for A, B in self.data],
                "poses": [{"parent": _frame_dict(P.parent, s), "child": _frame_dict(P.child, s)} for P in self.poses],
                "truth_poses": None if self.truth_poses is None else
                [{"parent": _frame_dict(P.parent, s), "child": _frame_dict(P.child, s)} for P in self.truth_poses],
                "check_50_digits": chk.to_dict(), "notes": list(self.notes)}


FORMAT = "identcheck.counterexample/1"


def _frame_dict(f: Frame, s) -> dict:
    return {"R": [[s(f.R[i, j]) for j in range(3)] for i in range(3)], "t": [s(f.t[i]) for i in range(3)]}


def _geometry_dict(g: JointGeometry, s) -> dict:
    return {"joint": g.joint, "parent_markers": [[s(x) for x in v] for v in g.parent_markers],
            "child_markers": [[s(x) for x in v] for v in g.child_markers],
            "parent_joint": _frame_dict(g.parent_joint, s), "child_joint": _frame_dict(g.child_joint, s)}


def _frame_from(d) -> Frame:
    return Frame(mpmath.matrix([[mpf(v) for v in row] for row in d["R"]]), vec(d["t"]))


def _geometry_from(d) -> JointGeometry:
    return JointGeometry(d["joint"], [vec(v) for v in d["parent_markers"]], [vec(v) for v in d["child_markers"]],
                         _frame_from(d["parent_joint"]), _frame_from(d["child_joint"]))


def from_dict(d: dict) -> Counterexample:
    """Rebuild a counterexample from :meth:`Counterexample.to_dict` (trusting none of its checks)."""
    if d.get("format") != FORMAT:
        raise ValueError(f"unknown counterexample format {d.get('format')!r}; expected {FORMAT}")
    with mpmath.workdps(DPS + GUARD):
        truth, alt = _geometry_from(d["truth"]), _geometry_from(d["alternative"])
        data = [([vec(v) for v in smp["parent"]], [vec(v) for v in smp["child"]]) for smp in d["samples"]]
        poses = [Pose(_frame_from(P["parent"]), _frame_from(P["child"])) for P in d["poses"]]
        tposes = None if d.get("truth_poses") is None else \
            [Pose(_frame_from(P["parent"]), _frame_from(P["child"])) for P in d["truth_poses"]]
        if (len(truth.parent_markers), len(truth.child_markers)) != (d["p"], d["q"]) or truth.joint != d["joint"]:
            raise ValueError("the truth's markers do not match the stated case")
        return Counterexample(d["joint"], d["p"], d["q"], truth, alt, data, poses, d["construction"], mpf(d["delta"]),
                              list(d.get("notes", [])), tposes)


def verify_dict(d: dict) -> list:
    """Problems found re-checking a serialised counterexample at 50 digits (empty: verified)."""
    try:
        cx = from_dict(d)
    except (KeyError, TypeError, ValueError) as exc:
        return [f"malformed counterexample: {exc}"]
    chk = cx.check()
    problems = []
    if chk.reproduction > chk.tolerance:
        problems.append(f"the alternative misses a sample by {mpmath.nstr(chk.reproduction, 5)}")
    if chk.joint > chk.tolerance:
        problems.append(f"the alternative's poses violate its joint by {mpmath.nstr(chk.joint, 5)}")
    if chk.truth is None:
        problems.append("no true poses: nothing shows the samples are outputs of the stated truth")
    elif chk.truth > chk.tolerance:
        problems.append(f"the truth misses a sample (or its joint) by {mpmath.nstr(chk.truth, 5)}")
    if not chk.ok and not problems:
        problems.append("the alternative has the same marker distances as the truth")
    return problems + _displayed(d, cx, chk)


DISPLAY_RTOL = mpf("1e-12")
"""Relative agreement asked of a displayed summary number (saved tables show some in double precision;
the geometry itself is checked at 50 digits)."""
DELTA_IS_DISTANCE_CHANGE = ("revolute11", "spherical21", "spherical11")
"""Constructions whose δ is the change of a marker distance (r' = r − δ, ρ' = ρ + δ)."""


def _displayed(d: dict, cx: "Counterexample", chk) -> list:
    """The summary fields a reader looks at, recomputed from the certificate's geometry and compared with
    what the file displays: case, sample count, both joints' marker distances, the 50-digit check and δ
    (where the construction defines δ as a distance change)."""
    out = []
    for field, value in (("case", cx.key), ("n_samples", len(cx.data))):
        if field in d and d[field] != value:
            out.append(f"{field}: the file says {d[field]!r}, the certificate's data give {value!r}")
    with mpmath.workdps(DPS + GUARD):
        scale = max([abs(v) for v in cx.truth.marker_distances().values()] + [mpf(1)])
        tol = scale * DISPLAY_RTOL
        for field, geo in (("marker_distances_truth", cx.truth), ("marker_distances_alternative", cx.alternative)):
            shown = d.get(field)
            if shown is None:
                continue
            real = geo.marker_distances()
            try:
                bad = sorted(k for k in set(shown) | set(real)
                             if k not in shown or k not in real or abs(mpf(shown[k]) - real[k]) > tol)
            except (TypeError, ValueError):
                bad = ["(not numbers)"]
            if bad:
                out.append(f"{field}: {', '.join(bad)} differ from the distances of the certificate's own joint")
        shown = d.get("check_50_digits")
        if isinstance(shown, dict):
            if shown.get("ok") != chk.ok:
                out.append(f"check_50_digits.ok: the file says {shown.get('ok')!r}, re-checking gives {chk.ok!r}")
            try:
                change = mpf(shown.get("largest_distance_change", "nan"))
                if abs(change - chk.change) > tol:
                    out.append(f"check_50_digits.largest_distance_change: the file says {shown['largest_distance_change']}, "
                               f"re-checking gives {mpmath.nstr(chk.change, 12)}")
            except (TypeError, ValueError):
                out.append("check_50_digits.largest_distance_change: not a number")
        if any(cx.construction.startswith(c) or f": {c}" in cx.construction for c in DELTA_IS_DISTANCE_CHANGE):
            t, a = cx.truth.marker_distances(), cx.alternative.marker_distances()
            changes = [abs(a[k] - t[k]) for k in t if k in a]
            if changes and min(abs(c - abs(cx.delta)) for c in changes) > tol:
                out.append(f"delta: the file says {mpmath.nstr(cx.delta, 12)}, but no marker distance changes by that "
                           f"much between the truth and the alternative")
    return out


# -- Remark 1 ------------------------------------------------------------------------------------
def swap(cx: Counterexample) -> Counterexample:
    """(p, q) → (q, p): exchange the links' roles (a joint's relative motion is symmetric)."""
    return Counterexample(cx.joint, cx.q, cx.p, cx.truth.swapped(), cx.alternative.swapped(),
                          [(B, A) for A, B in cx.data], [Pose(P.child, P.parent) for P in cx.poses],
                          f"symmetry of {cx.key} (Remark 1): {cx.construction}", cx.delta, list(cx.notes),
                          None if cx.truth_poses is None else [Pose(P.child, P.parent) for P in cx.truth_poses])


def drop(cx: Counterexample, parent_keep, child_keep) -> Counterexample:
    """Fewer markers (Remark 1): a second joint for more markers is one for any subset of them."""
    pk, ck = list(parent_keep), list(child_keep)
    sub = lambda g: replace(g, parent_markers=[g.parent_markers[i] for i in pk],  # noqa: E731
                            child_markers=[g.child_markers[i] for i in ck])
    return Counterexample(cx.joint, len(pk), len(ck), sub(cx.truth), sub(cx.alternative),
                          [([A[i] for i in pk], [B[i] for i in ck]) for A, B in cx.data], list(cx.poses),
                          f"fewer markers than {cx.key} (Remark 1): {cx.construction}", cx.delta, list(cx.notes),
                          cx.truth_poses)


# -- base constructions ------------------------------------------------------------------------------
def _canonical_revolute11(r, rho, l) -> JointGeometry:
    return JointGeometry("revolute", [vec([r, 0, 0])], [vec([rho, 0, l])], Frame.identity(), Frame.identity())


def revolute11_invariants(g: JointGeometry) -> tuple:
    """(r, ρ, l): A's and B's distances to the hinge and B's axial offset from A."""
    dist = g.marker_distances()
    ez = mpmath.matrix([0, 0, 1])
    za = _dot(g.parent_joint.inverse().apply(g.parent_markers[0]), ez)
    zb = _dot(g.child_joint.inverse().apply(g.child_markers[0]), ez)
    return dist["A1"], dist["B1"], zb - za


def revolute11_family(r, rho, l, delta, family: str = "exact") -> tuple:
    """Alternative (r', ρ', l'): ``paper`` r − δ, ρ + δ, l; ``exact`` r − δ, rρ/(r − δ), l' from
    r'² + ρ'² + l'² = r² + ρ² + l² (same output set). Raises ValueError outside the family's range."""
    r, rho, l, delta = (mpf(v) for v in (r, rho, l, delta))
    r2 = r - delta
    if r2 <= 0:
        raise ValueError(f"delta = {mpmath.nstr(delta, 6)} must be < r = {mpmath.nstr(r, 6)} (r' > 0)")
    if family == "paper":
        return r2, rho + delta, l
    if family != "exact":
        raise ValueError(f"unknown family {family!r} (paper | exact)")
    rho2 = r * rho / r2
    l2sq = r * r + rho * rho + l * l - r2 * r2 - rho2 * rho2
    if l2sq < 0:
        raise ValueError(f"delta = {mpmath.nstr(delta, 6)} is outside the exact family: l'² = "
                         f"{mpmath.nstr(l2sq, 6)} < 0 (needs r'² + (rρ/r')² <= r² + ρ² + l²)")
    return r2, rho2, mpmath.sqrt(l2sq) * (1 if l >= 0 else -1)


def revolute11_shell(r, rho, l) -> tuple:
    """Inner and outer radius of the (1,1) hinge's output set |B − A| ∈ [inner, outer]."""
    return mpmath.sqrt((r - rho) ** 2 + l * l), mpmath.sqrt((r + rho) ** 2 + l * l)


def revolute11(truth: JointGeometry, data, delta, family: str = "exact") -> Counterexample:
    """Revolute (1,1): an alternative hinge line L' at distance r' from A and ρ' from B, per sample."""
    with mpmath.workdps(DPS + GUARD):
        r, rho, l = revolute11_invariants(truth)
        r2, rho2, l2 = revolute11_family(r, rho, l, delta, family)
        alt = _canonical_revolute11(r2, rho2, l2)
        a, b = alt.parent_markers[0], alt.child_markers[0]
        poses = []
        for i, (A, B) in enumerate(data):
            w = B[0] - A[0]
            D = _norm(w)
            c = (r2 * r2 + rho2 * rho2 + l2 * l2 - D * D) / (2 * r2 * rho2)
            if abs(c) > 1 + mpf(10) ** (-DPS):
                lo, hi = revolute11_shell(r2, rho2, l2)
                raise ConstructionError(i, f"|AB| = {mpmath.nstr(D, 8)} is outside the alternative's shell "
                                           f"[{mpmath.nstr(lo, 8)}, {mpmath.nstr(hi, 8)}]")
            c = max(min(c, mpf(1)), mpf(-1))
            s = mpmath.sqrt(1 - c * c)
            motion = rz(c, s)
            v = motion * b - a                         # B − A in the parent frame
            R = rotation_between(v, w)
            parent = Frame(R, A[0] - R * a)
            poses.append(Pose(parent, child_pose(alt, parent, motion)))
        cx = Counterexample("revolute", 1, 1, truth, alt, list(data), poses, f"revolute11 ({family} family)", mpf(delta))
        if family == "paper":
            lo, _ = revolute11_shell(r2, rho2, l2)
            cx.notes.append(f"the paper's family reproduces exactly the samples with |AB| >= {mpmath.nstr(lo, 12)} "
                            "(its Delta); the exact family reproduces every sample")
        return cx


def spherical21_invariants(g: JointGeometry) -> tuple:
    """(L, d, r, ρ): |A1A2|, the centre's height along A1A2 from A1, its distance to the A1A2 line,
    and |B − J|."""
    a1, a2 = g.parent_markers[:2]
    L = _norm(a2 - a1)
    ez = (a2 - a1) / L
    u = g.parent_joint.t - a1
    d = _dot(u, ez)
    r = _norm(u - d * ez)
    return L, d, r, g.marker_distances()["B1"]


def _canonical_spherical21(L, d, r, rho) -> JointGeometry:
    return JointGeometry("spherical", [vec([0, 0, 0]), vec([0, 0, L])], [vec([rho, 0, 0])],
                         Frame(mpmath.eye(3), vec([r, 0, d])), Frame.identity())


def _axis_frame(A1, A2, B) -> tuple:
    """Columns x̂, ŷ, ẑ with ẑ along A1A2 and B in the x–z half-plane; returns (F, R_B, z_B)."""
    ez = A2 - A1
    ez = ez / _norm(ez)
    u = B - A1
    zb = _dot(u, ez)
    hvec = u - zb * ez
    R = _norm(hvec)
    if R < mpf(10) ** (-DPS // 2) * (1 + _norm(u)):
        e = mpmath.matrix([1, 0, 0]) if abs(ez[0]) < mpf("0.9") else mpmath.matrix([0, 1, 0])
        hvec = e - _dot(e, ez) * ez
    ex = hvec / _norm(hvec)
    ey = _cross(ez, ex)
    F = mpmath.matrix(3, 3)
    for k in range(3):
        F[k, 0], F[k, 1], F[k, 2] = ex[k], ey[k], ez[k]
    return F, R, zb


def spherical21_admissible(R, h, r2, rho2) -> bool:
    """Whether a sample at distance R from the A1A2 line and height h above the circle's plane can be
    reproduced by a centre circle of radius r2 and a radius rho2."""
    return (R - r2) ** 2 + h * h <= rho2 * rho2 <= (R + r2) ** 2 + h * h


def spherical21(truth: JointGeometry, data, delta) -> Counterexample:
    """Spherical (2,1): r' = r − δ, ρ' = ρ + δ, centre J' on the circle Γ' with |BJ'| = ρ', per sample."""
    with mpmath.workdps(DPS + GUARD):
        L, d, r, rho = spherical21_invariants(truth)
        delta = mpf(delta)
        r2, rho2 = r - delta, rho + delta
        if r2 <= 0 or rho2 <= 0:
            raise ValueError(f"delta = {mpmath.nstr(delta, 6)} must keep r' = r − δ and ρ' = ρ + δ positive")
        alt = _canonical_spherical21(L, d, r2, rho2)
        poses = []
        for i, (A, B) in enumerate(data):
            F, R, zb = _axis_frame(A[0], A[1], B[0])
            h = zb - d
            c = (R * R + r2 * r2 + h * h - rho2 * rho2) / (2 * R * r2) if R > 0 else mpf(2)
            if abs(c) > 1 + mpf(10) ** (-DPS):
                raise ConstructionError(i, f"the circle of radius r' = {mpmath.nstr(r2, 8)} does not meet the sphere "
                                           f"of radius ρ' = {mpmath.nstr(rho2, 8)} about B (B at {mpmath.nstr(R, 8)} "
                                           "from the A1A2 line)")
            c = max(min(c, mpf(1)), mpf(-1))
            s = mpmath.sqrt(1 - c * c)
            parent = Frame(F * rz(c, s), A[0])
            J = parent.apply(alt.parent_joint.t)
            Rc = rotation_between(mpmath.matrix([1, 0, 0]), B[0] - J)
            poses.append(Pose(parent, Frame(Rc, J)))
        cx = Counterexample("spherical", 2, 1, truth, alt, list(data), poses, "spherical21 (r - delta, rho + delta)", delta)
        cx.notes.append("reproduces every sample with (R - r')^2 + h^2 <= rho'^2 <= (R + r')^2 + h^2; all of S when "
                        "rho + delta <= r - delta, else those with R >= rho - r + 2 delta (ERRATA E7)")
        return cx


def spherical11(truth: JointGeometry, data, delta) -> Counterexample:
    """Spherical (1,1): J' with |AJ'| = r − δ and |BJ'| = ρ + δ, per sample (needs |r' − ρ'| ≤ |AB| ≤ r' + ρ')."""
    with mpmath.workdps(DPS + GUARD):
        dist = truth.marker_distances()
        delta = mpf(delta)
        r2, rho2 = dist["A1"] - delta, dist["B1"] + delta
        if r2 <= 0 or rho2 <= 0:
            raise ValueError(f"delta = {mpmath.nstr(delta, 6)} must keep r' and ρ' positive")
        alt = JointGeometry("spherical", [vec([0, 0, 0])], [vec([rho2, 0, 0])], Frame(mpmath.eye(3), vec([r2, 0, 0])),
                            Frame.identity())
        poses = []
        for i, (A, B) in enumerate(data):
            w = B[0] - A[0]
            D = _norm(w)
            c = (r2 * r2 + D * D - rho2 * rho2) / (2 * r2 * D)
            if abs(c) > 1 + mpf(10) ** (-DPS):
                raise ConstructionError(i, f"|AB| = {mpmath.nstr(D, 8)} is outside [|r' − ρ'|, r' + ρ'] = "
                                           f"[{mpmath.nstr(abs(r2 - rho2), 8)}, {mpmath.nstr(r2 + rho2, 8)}]")
            c = max(min(c, mpf(1)), mpf(-1))
            Rw = rotation_between(mpmath.matrix([1, 0, 0]), w)    # x̂ along AB
            J = A[0] + Rw * vec([r2 * c, r2 * mpmath.sqrt(1 - c * c), 0])
            parent = Frame(rotation_between(mpmath.matrix([1, 0, 0]), J - A[0]), A[0])
            poses.append(Pose(parent, Frame(rotation_between(mpmath.matrix([1, 0, 0]), B[0] - J), J)))
        return Counterexample("spherical", 1, 1, truth, alt, list(data), poses, "spherical11 (r - delta, rho + delta)",
                              delta, ["reproduces every sample with |r' - rho'| <= |AB| <= r' + rho'"])


def _pose_from_markers(local, world) -> Frame:
    """A rigid pose putting the body-fixed points ``local`` on the measured ``world`` points."""
    if len(local) == 1:
        return Frame(mpmath.eye(3), world[0] - local[0])
    R1 = rotation_between(local[1] - local[0], world[1] - world[0])
    if len(local) >= 3:   # then turn about the first edge so the third marker lands too
        e = world[1] - world[0]
        e = e / _norm(e)
        u, v = R1 * (local[2] - local[0]), world[2] - world[0]
        u, v = u - _dot(u, e) * e, v - _dot(v, e) * e
        ang = mpmath.atan2(_dot(_cross(u, v), e), _dot(u, v))
        c, s = mpmath.cos(ang), mpmath.sin(ang)
        K = mpmath.matrix([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
        R1 = (mpmath.eye(3) + s * K + (1 - c) * K * K) * R1
    return Frame(R1, world[0] - R1 * local[0])


def free_parent(truth: JointGeometry, data, delta) -> Counterexample:
    """p = 0: move the joint by δ on the child (away from B1); the unobserved parent follows it."""
    if truth.parent_markers:
        raise ValueError("free_parent needs a parent without markers (p = 0)")
    if not truth.child_markers:
        raise ValueError("(0,0): no marker defines any joint quantity (vacuous)")
    with mpmath.workdps(DPS + GUARD):
        delta = mpf(delta)
        cj = truth.child_joint
        e = cj.t - truth.child_markers[0]
        if truth.joint == "revolute":
            ax = cj.R * mpmath.matrix([0, 0, 1])
            e = e - _dot(e, ax) * ax
        if _norm(e) == 0:
            e = mpmath.matrix([1, 0, 0])
        moved = Frame(cj.R, cj.t + delta * e / _norm(e))
        alt = replace(truth, child_joint=moved)
        poses = []
        for A, B in data:
            child = _pose_from_markers(truth.child_markers, B)
            parent = child * alt.child_joint * alt.parent_joint.inverse()
            poses.append(Pose(parent, child))
        return Counterexample(truth.joint, 0, len(truth.child_markers), truth, alt, list(data), poses,
                              "free parent (no parent marker)", delta,
                              ["the parent carries no marker, so every joint position on the child reproduces the data"])


def construct(truth: JointGeometry, data, delta, family: str = "exact") -> Counterexample:
    """The counterexample for the case of ``truth`` (revolute or spherical, not locally identifiable)."""
    p, q = len(truth.parent_markers), len(truth.child_markers)
    key = f"{truth.joint}({p},{q})"
    if p == 0 and q == 0:
        raise ValueError(f"{key}: no marker defines any joint quantity (vacuous)")
    if p == 0:
        return free_parent(truth, data, delta)
    if q == 0:
        return swap(free_parent(truth.swapped(), [(B, A) for A, B in data], delta))
    if (p, q) == (1, 1):
        return revolute11(truth, data, delta, family) if truth.joint == "revolute" else spherical11(truth, data, delta)
    if truth.joint == "spherical" and (p, q) == (2, 1):
        return spherical21(truth, data, delta)
    if truth.joint == "spherical" and (p, q) == (1, 2):
        return swap(spherical21(truth.swapped(), [(B, A) for A, B in data], delta))
    raise ValueError(f"{key} is locally identifiable: there is no continuous counterexample")


# -- random true configurations (witnesses and tests) --------------------------------------------------
def random_geometry(joint: str, p: int, q: int, rng) -> JointGeometry:
    """A random joint with p parent and q child markers (``rng``: a ``random.Random``); lengths ~ 10–100."""
    u = lambda lo, hi: mpf(rng.randint(int(lo * 64), int(hi * 64))) / 64  # noqa: E731
    pt = lambda: vec([u(-80, 80), u(-80, 80), u(-80, 80)])  # noqa: E731
    frame = lambda: Frame(quaternion_rotation([u(-1, 1) for _ in range(4)]) if joint == "revolute"  # noqa: E731
                          else mpmath.eye(3), pt())
    return JointGeometry(joint, [pt() for _ in range(p)], [pt() for _ in range(q)], frame(), frame())


def random_motion(joint: str, rng) -> mpmath.matrix:
    """A random joint rotation: about z (revolute) or any (spherical)."""
    if joint == "revolute":
        t = mpf(rng.randint(-4096, 4096)) / 1024
        return rz((1 - t * t) / (1 + t * t), 2 * t / (1 + t * t))
    return quaternion_rotation([mpf(rng.randint(-1024, 1024)) / 1024 for _ in range(4)])


def simulate(g: JointGeometry, n: int, rng) -> tuple:
    """n samples of ``g`` with random parent poses and joint motions: (data, true poses)."""
    poses, data = [], []
    for _ in range(n):
        parent = Frame(quaternion_rotation([mpf(rng.randint(-1024, 1024)) / 1024 for _ in range(4)]),
                       vec([mpf(rng.randint(-4096, 4096)) / 16 for _ in range(3)]))
        pose = Pose(parent, child_pose(g, parent, random_motion(g.joint, rng)))
        poses.append(pose)
        data.append(markers_world(g, pose))
    return data, poses


def witness(joint: str, p: int, q: int, seed: int = 0, n_samples: int = 12, family: str = "exact") -> Counterexample:
    """A deterministic counterexample for a case: a random rational truth, ``n_samples`` exact samples,
    the largest δ ∈ {r/8, r/16, …} (r: the first marker's distance) that the construction admits."""
    rng = random.Random(f"identcheck.counterexamples:{joint}:{p}:{q}:{seed}")
    with mpmath.workdps(DPS + GUARD):
        g = random_geometry(joint, p, q, rng)
        data, poses = simulate(g, n_samples, rng)
        dist = g.marker_distances()
        delta = (dist.get("A1") or dist["B1"]) / 8
        for _ in range(40):
            try:
                cx = construct(g, data, delta, family)
                break
            except (ConstructionError, ValueError) as exc:
                if "locally identifiable" in str(exc) or "vacuous" in str(exc):
                    raise
                delta /= 2
        else:
            raise RuntimeError(f"{joint}({p},{q}): no delta found for the witness")
        cx.truth_poses = poses
        return cx
