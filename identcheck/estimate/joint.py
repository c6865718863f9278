"""One joint from noisy trial data, by the best estimator its markers allow; results as world trajectories.

Every estimator returns a :class:`JointEstimate` whose joint is a world trajectory — the centre
(spherical) or a point and direction of the hinge (revolute) in every frame used — so marker
distances, virtual markers for the next joint down the tree and residuals are computed the same
way whatever the estimator. Which estimator runs depends on the markers (real or virtual) each
link carries, as in the identifiability table:

=====================  ==================================================================
markers (p, q)         estimator
=====================  ==================================================================
spherical ≥3, ≥3       seed 001: two-stage centre with Gauss–Markov covariance
spherical ≥3, 1–2      sphere(s) through the child markers in the posed parent (Pham IV-A)
spherical 2, 2         S22 (Pham V-A)
revolute ≥3, ≥3        SARA axis (= O'Brien's single-axis solution)
revolute ≥3, 1–2       circle(s) of the child markers in the posed parent
revolute 2, 1–2        Pham III-A on each child marker: four joints per marker (E1/E2)
=====================  ==================================================================
(p, q) with p < q swaps the links' roles. Anything else is not identifiable (table row named).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from identcheck.errors import DegenerateError, IdentifiabilityWarning
from identcheck.io.model import virtual_names  # noqa: F401  (re-exported: the estimators' name for it)
from identcheck.solve import revolute21, spherical31
from identcheck.geometry.frames import pair_frame
from identcheck.solve.gamage_lasenby import sphere_centre
from identcheck.solve.minimal import circle
from identcheck.geometry.poses import segment_poses

AXIS_HANDLE_MM = 100.0   # the second virtual marker of a hinge sits this far along the axis
MIN_ROM_DEG = 15.0
MAX_OFF_AXIS_DEG = 10.0   # a hinge whose relative rotation wobbles more than this is flagged
MIN_SECOND_AXIS_DEG = 5.0  # a centre needs rotation about two axes: RMS spread about the second, at least
MIN_TRAVEL_MM = 10.0      # child markers that move less than this in the parent frame are not excited


@dataclass
class JointEstimate:
    """A joint as world trajectories over the frames used (NaN elsewhere), with its quality."""

    kind: str                           # "spherical" | "revolute"
    estimator: str
    case: str                           # e.g. "spherical(3,1)", with the markers used
    centre: np.ndarray | None = None    # (F, 3) spherical centre
    point: np.ndarray | None = None     # (F, 3) a point on the hinge
    direction: np.ndarray | None = None  # (F, 3) unit hinge direction
    rms_residual: float = float("nan")
    uncertainty_mm: float | None = None
    excitation_ok: bool = True
    excitation_reason: str = ""
    unique: bool = True
    alternatives: list = field(default_factory=list)   # other JointEstimates explaining the data as well
    notes: list = field(default_factory=list)
    nothing_beyond: bool = False                       # a multi-candidate case with no marker beyond it to decide
    ranked_out: list = field(default_factory=list)     # candidates a far marker ranked lower (the whole-tree
                                                       # fit still starts from them and reports their Δχ²)

    def distance(self, marker: np.ndarray) -> float:
        """Median over frames of a marker's distance to the centre or the hinge axis."""
        if self.kind == "spherical":
            d = np.linalg.norm(marker - self.centre, axis=1)
        else:
            w = marker - self.point
            d = np.linalg.norm(w - np.sum(w * self.direction, axis=1, keepdims=True) * self.direction, axis=1)
        d = d[np.isfinite(d)]
        return float(np.median(d)) if len(d) else float("nan")

    def virtual_markers(self, name: str) -> dict:
        """World trajectories that sit still on both links: the centre, or two points of the hinge (names from
        :func:`virtual_names`)."""
        if self.kind == "spherical":
            return dict(zip(virtual_names(name, "spherical"), [self.centre]))
        return dict(zip(virtual_names(name, "revolute"), [self.point, self.point + AXIS_HANDLE_MM * self.direction]))


def _full(F: int, frames: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.full((F, 3), np.nan)
    out[frames] = values
    return out


def _visible(*arrays) -> np.ndarray:
    ok = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        ok &= np.all(np.isfinite(a.reshape(len(a), -1)), axis=1)
    return np.flatnonzero(ok)


def _rom_reason(angles_deg: float, what: str) -> str:
    return (f"small range of motion: {what} spans only {angles_deg:.1f} deg (< {MIN_ROM_DEG:g}); the estimate "
            "is poorly determined. Record a larger movement of the joint.")


def _travel_reason(X: np.ndarray, sigma: float) -> str:
    """Why child markers X (n, q, 3), seen from the parent, move too little to locate a joint ('' if they
    move enough): the joint must be located from their travel, and travel comparable with the noise
    (or a static trial) leaves it undetermined however well a curve fits the scatter."""
    travel = float(max(np.ptp(X[:, i], axis=0).max() for i in range(X.shape[1])))
    if travel < MIN_TRAVEL_MM:
        need = f"< {MIN_TRAVEL_MM:g} mm"
    elif travel < 10.0 * sigma:
        need = f"< 10 times the fit's rms residual, {sigma:.3g} mm"
    else:
        return ""
    return (f"too little motion: the child markers move at most {travel:.3g} mm relative to the parent "
            f"({need}); a static or nearly static trial does not locate the joint. Record the "
            "joint's functional movement.")


# -- posed parent, 1-2 child markers ---------------------------------------------------------------
def posed_sphere(parent: np.ndarray, child: np.ndarray, case: str) -> JointEstimate:
    """Common centre of the spheres traced by the child markers in the parent's frame
    (:func:`~identcheck.solve.gamage_lasenby.sphere_centre`), with the linearised covariance of the
    centre from the geometric residuals."""
    poses = segment_poses(parent)
    local = poses.to_local(child)                                  # (F, q, 3)
    frames = _visible(local)
    if len(frames) < 4:
        raise DegenerateError(f"{case}: only {len(frames)} frames with the parent posed and every child marker "
                              "seen; a sphere needs at least 4")
    X = local[frames]
    q = X.shape[1]
    sph = sphere_centre(X)                                           # common centre of the child markers' spheres
    c, rho = sph.centre, sph.radii
    dist = np.linalg.norm(X - c, axis=2)                            # (n, q)
    res = dist - rho
    sigma = float(np.sqrt(np.mean(res**2)))
    # geometric Jacobian of |x − c| − ρ_i in (c, ρ): covariance of c
    J = np.zeros((len(X) * q, 3 + q))
    for i in range(q):
        J[i * len(X):(i + 1) * len(X), :3] = -(X[:, i] - c) / dist[:, i:i + 1]
        J[i * len(X):(i + 1) * len(X), 3 + i] = -1
    cov = sigma**2 * np.linalg.pinv(J.T @ J)[:3, :3]
    cond = spherical31.conditioning(X[:, 0], noise_mm=max(sigma, 1e-9))
    est = JointEstimate("spherical", "sphere in the parent frame (Pham IV-A, least squares)", case,
                        centre=_full(len(child), frames, poses.to_world(c[None])[frames, 0]),
                        rms_residual=sigma, uncertainty_mm=float(np.sqrt(max(np.linalg.eigvalsh(cov)[-1], 0))))
    why = _travel_reason(X, sigma) or ("" if cond.ok else cond.reason)
    if why:
        est.excitation_ok, est.excitation_reason = False, why
    return est


def _common_axis(X: np.ndarray) -> tuple:
    """Hinge point and direction shared by the circles of several markers, X (n, q, 3) in the parent.

    The direction is the least-variance direction of all markers' positions, each centred on its
    own mean (every marker moves in a plane normal to the hinge); each marker's circle centre in
    its plane then lies on the hinge: the point is their average weighted by radius² (a larger
    circle fixes its centre better), moved onto the line along the direction. A marker whose path
    fixes no circle (:func:`~identcheck.solve.minimal.circle` raises) is left out of the average,
    unless every marker's is.
    """
    centred = (X - X.mean(axis=0)).reshape(-1, 3)
    n = np.linalg.svd(centred, full_matrices=False)[2][2]
    pts, wts, problem = [], [], None
    for i in range(X.shape[1]):
        try:
            c, _, r = circle(X[:, i]) if len(X) >= 3 else (X[:, i].mean(0), None, 0.0)
        except DegenerateError as exc:          # a marker on a straight path fixes no centre: it is left out
            c, r, problem = X[:, i].mean(0), 0.0, exc
        pts.append(c - (c @ n) * n)
        wts.append(r * r)
    wts = np.asarray(wts)
    if problem is not None and not wts.sum() > 0:
        raise problem
    J = np.average(pts, axis=0, weights=wts if wts.sum() > 0 else None)
    return J, n


def posed_circle(parent: np.ndarray, child: np.ndarray, case: str) -> JointEstimate:
    """The hinge as the common axis of the child markers' circles in the parent's frame."""
    poses = segment_poses(parent)
    local = poses.to_local(child)
    frames = _visible(local)
    if len(frames) < 3:
        raise DegenerateError(f"{case}: only {len(frames)} frames with the parent posed and every child marker "
                              "seen; a circle needs at least 3")
    X = local[frames]
    J, n = _common_axis(X)
    w = X - J
    radial = np.linalg.norm(w - (w @ n)[..., None] * n, axis=2)
    planar = (w @ n) - np.median(w @ n, axis=0)
    res = np.concatenate([(radial - np.median(radial, axis=0)).ravel(), planar.ravel()])
    sigma = float(np.sqrt(np.mean(res**2)))
    k = int(np.argmax(np.median(radial, axis=0)))           # the marker farthest from the hinge
    # uncertainty: the spread of the hinge between the two halves of the frames (even / odd), which
    # carries the pose noise of the parent and the conditioning of the direction; the linear
    # least-squares covariance of the centre alone is far too optimistic here
    halves = [_common_axis(X[0::2]), _common_axis(X[1::2])] if len(X) >= 8 else []
    spread = 0.0
    for Jh, nh in halves:
        nh = nh if nh @ n >= 0 else -nh
        ends = X.reshape(-1, 3)
        near = lambda pt, J0, n0: (pt - J0) - ((pt - J0) @ n0)[:, None] * n0  # noqa: E731
        spread = max(spread, float(np.max(np.abs(np.linalg.norm(near(ends, Jh, nh), axis=1)
                                                 - np.linalg.norm(near(ends, J, n), axis=1)))))
    u = w[:, k] - (w[:, k] @ n)[:, None] * n
    e1 = u[0] / np.linalg.norm(u[0])
    ang = np.unwrap(np.arctan2(u @ np.cross(n, e1), u @ e1))
    rom = float(np.degrees(ang.max() - ang.min()))
    pt = poses.to_world(J[None])[:, 0]
    dirw = np.einsum("fij,j->fi", poses.R, n)
    est = JointEstimate("revolute", "circle in the parent frame (least squares)", case,
                        point=_full(len(child), frames, pt[frames]), direction=_full(len(child), frames, dirw[frames]),
                        rms_residual=sigma, uncertainty_mm=spread)
    est.notes.append("uncertainty: largest change of a child marker's distance to the hinge between fits to the even "
                     "and the odd frames (an empirical spread, not a calibrated covariance)")
    why = _travel_reason(X, sigma) or (_rom_reason(rom, "the child marker's angle about the hinge")
                                      if rom < MIN_ROM_DEG else "")
    if why:
        est.excitation_ok, est.excitation_reason = False, why
    return est


# -- two parent markers ------------------------------------------------------------------------------
def _pair_rotation(a1: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """Columns of the frame :func:`pair_frame` uses, per frame: world = a1 + cols @ local."""
    probe = a1[:, None, :] + np.eye(3)[None]
    cols, _ = pair_frame(a1[:, None, :], a2[:, None, :], probe)     # cols[f, j] = R e_j: cols[f] = Rᵀ
    return cols


def _hinge_world(params, theta, a1, rot):
    """World point and direction of a revolute (2,1) joint's hinge in each frame (DH axis z_D)."""
    d, r, alpha, _, _ = params
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    pt = np.stack([r * ct, r * st, np.full_like(theta, d)], axis=1)
    dr = np.stack([st * sa, -ct * sa, np.full_like(theta, ca)], axis=1)
    return a1 + np.einsum("fij,fj->fi", rot, pt), np.einsum("fij,fj->fi", rot, dr)


def scale_of(points) -> float:
    """RMS distance of samples from the frame origin: the problem's length scale."""
    return float(np.sqrt(np.mean(np.asarray(points) ** 2)))


SEED_SAMPLES = 400
"""Samples the revolute (2,1) least squares uses (evenly spread over the trial): its answer only starts the
whole-tree fit, which uses every sample; the ODR problem's cost grows with the samples and its flat valleys
make it the slowest step of ``fit`` on sparse marker sets."""
SEED_NFEV = 100
"""Evaluations per revolute (2,1) least-squares run: enough to leave the closed form's noise-biased roots
for the basin of a minimum; the whole-tree fit converges from there."""


START_FRAMES = 500
"""Frames (evenly spread) a closed form that only starts the whole-tree fit is computed from, and the start's
segment shapes are averaged over (:mod:`identcheck.fit.whole_tree`): on a 1500-frame leg seed 001's centre took a
quarter of ``fit``; the whole-tree fit, from any start in the right basin, uses every frame."""


def start_stride(n_frames: int, most: int = START_FRAMES) -> int:
    """Every how many frames a start uses (`most` of them at most)."""
    return max(1, n_frames // most)


def pair_revolute(a1: np.ndarray, a2: np.ndarray, child: np.ndarray, case: str) -> JointEstimate:
    """Pham III-A on noisy samples (geometric least squares seeded by the closed form): every joint
    that explains the samples as well as the best, never one picked silently."""
    from identcheck.estimate import revolute21 as revolute21_fit

    frames = _visible(a1, a2, child)
    if len(frames) < revolute21.N_UNKNOWNS:
        raise DegenerateError(f"{case}: only {len(frames)} frames with every marker seen; at least 5 are needed")
    local, _ = pair_frame(a1[frames], a2[frames], child[frames, 0])
    if np.ptp(local, axis=0).max() < MIN_TRAVEL_MM:     # the least squares would chase the noise to any size
        raise DegenerateError(f"{case}: {_travel_reason(local[:, None, :], 0.0)}")
    every = start_stride(len(local), SEED_SAMPLES)   # a start for the whole-tree fit: a spread subset will do
    sols = revolute21_fit.fit(local[::every], max_nfev=SEED_NFEV)
    if not sols:
        raise DegenerateError(f"{case}: no revolute joint fits these samples")
    rot = _pair_rotation(a1[frames], a2[frames])
    F = len(child)
    ests = []
    for params, rms, unc in sols:
        pt, dr = _hinge_world(params, revolute21_fit.thetas(params, local), a1[frames], rot)
        ests.append(JointEstimate("revolute", "Pham III-A, geometric least squares (two parent markers)", case,
                                  point=_full(F, frames, pt), direction=_full(F, frames, dr), rms_residual=rms,
                                  uncertainty_mm=unc))
    best = ests[0]
    equal = [e for e in ests[1:] if e.rms_residual <= 1.05 * best.rms_residual + 1e-9]
    best.unique = not equal
    best.alternatives = equal
    why = _travel_reason(local[:, None, :], best.rms_residual)
    if why:
        best.excitation_ok, best.excitation_reason = False, why
    elif not best.uncertainty_mm < 0.5 * scale_of(local):
        best.excitation_ok = False
        best.excitation_reason = (f"the constants are poorly determined (1-sigma {best.uncertainty_mm:.3g} mm): the "
                                  "hinge passes close to the line of the two parent markers, or the motion is too "
                                  "small. Add a third marker on a link or record a larger movement.")
    best.notes.append(f"{1 + len(equal)} joints explain the samples equally well: revolute (2,1) is locally, not "
                      "globally, identifiable (ERRATA E1, E2); a third marker on either link, or a second on the "
                      "child, decides")
    return best


def pair_spherical(a1, a2, b1, b2, case: str) -> JointEstimate:
    """S22 (Pham V-A) with two markers per link."""
    from identcheck.solve.s22 import solve_s22

    res = solve_s22(a1, a2, b1, b2)
    c = res.centres_world
    ok = np.all(np.isfinite(c), axis=1)
    d = np.stack([np.linalg.norm(b1 - c, axis=1) - res.params[2], np.linalg.norm(b2 - c, axis=1) - res.params[3]])
    sigma = float(np.sqrt(np.nanmean(d[:, ok] ** 2)))
    return JointEstimate("spherical", "S22 (Pham V-A)", case, centre=c, rms_residual=sigma,
                         uncertainty_mm=sigma / np.sqrt(max(int(ok.sum()) - 4, 1)),
                         notes=["uncertainty: residual scatter / sqrt(frames), not a calibrated covariance"])


# -- both links posed --------------------------------------------------------------------------------
def _fixed_in(parent: np.ndarray, world_some: np.ndarray, every: int) -> np.ndarray | None:
    """A point fixed in the parent cluster, known in every `every`-th frame (world_some), in every frame: its
    mean position in the parent's frame, carried by the parent's poses (None when no spread frame poses it)."""
    if every == 1:
        return world_some
    poses = segment_poses(parent)
    some = np.full((len(parent), 3), np.nan)
    some[::every] = world_some
    local = poses.body_fixed(some)
    return poses.to_world(local[None])[:, 0] if np.isfinite(local).all() else None


def posed_pair(parent: np.ndarray, child: np.ndarray, kind: str, case: str) -> JointEstimate:
    """Seed 001 (spherical) or SARA (revolute) from two posed clusters."""
    if kind == "spherical":
        from identcheck.estimate.seed001 import fit_centre

        every = start_stride(len(parent))
        with warnings.catch_warnings(record=True) as caught:     # kept as notes: they judge seed 001's own
            warnings.simplefilter("always", IdentifiabilityWarning)  # covariance, which fit no longer reports
            fit = fit_centre(parent[::every], child[::every])
        centre = _fixed_in(parent, fit.parent.to_world(fit.centre_parent[None])[:, 0], every)
        if centre is None:                      # no pose of the parent in the spread frames: take them all
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", IdentifiabilityWarning)
                fit = fit_centre(parent, child)
            centre = fit.parent.to_world(fit.centre_parent[None])[:, 0]
        est = JointEstimate("spherical", "seed 001 two-stage centre with Gauss-Markov covariance", case,
                            centre=centre, rms_residual=float(fit.rms_residual), uncertainty_mm=float(fit.uncertainty_mm),
                            excitation_ok=bool(fit.excitation_ok), excitation_reason=fit.excitation_reason,
                            notes=[f"seed 001: {w.message}" for w in caught])
        second = float(fit.rotation_spread_deg[1])
        if est.excitation_ok and second < MIN_SECOND_AXIS_DEG:
            # the covariance knows only white marker noise; with rotation about essentially one axis, skin
            # motion shifts the centre along that axis by far more than it says (gait: tens of mm)
            est.excitation_ok = False
            est.excitation_reason = (f"{fit.excitation_reason}; but the rotation about the second axis spreads only "
                                     f"{second:.2g} deg RMS (< {MIN_SECOND_AXIS_DEG:g}): the centre is weakly "
                                     "determined along the main rotation axis, where soft-tissue motion (not in the "
                                     "covariance) moves it. Record a functional movement (star arc, circumduction).")
        return est
    from identcheck.estimate.obrien import HINGE_TOL_DEG, joint_location

    fit = joint_location(parent, child, hinge=True)
    spread = fit.spread_deg                      # ascending: off-axis wobble, then the flexion, ...
    pp = segment_poses(parent)           # the same body frame joint_location used (same default)
    point = pp.to_world(fit.centre_parent[None])[:, 0]
    est = JointEstimate("revolute", "O'Brien et al. single-axis solution (= SARA)", case, point=point,
                        rms_residual=float(fit.rms_residual), uncertainty_mm=float(fit.uncertainty_mm))
    if fit.axis_parent is None:
        est.direction = np.full_like(point, np.nan)
        est.excitation_ok = False
        est.excitation_reason = f"no single hinge axis: {fit.reason}"
        return est
    est.direction = np.einsum("fij,j->fi", pp.R, fit.axis_parent)
    est.notes.append(f"off-axis rotation spread {spread[0]:.2g} deg, flexion spread {spread[1]:.3g} deg")
    if spread[0] > MAX_OFF_AXIS_DEG:
        est.excitation_ok = False
        est.excitation_reason = (f"the relative rotation is not about one axis: it wobbles {spread[0]:.3g} deg off "
                                 f"the best hinge (> {MAX_OFF_AXIS_DEG:g}): soft-tissue motion of the clusters, or "
                                 "the joint is not a hinge (see `identcheck diagnose`)")
    elif spread[1] < max(HINGE_TOL_DEG, MIN_ROM_DEG / 2):
        est.excitation_ok = False
        est.excitation_reason = (f"small range of motion: the rotation about the hinge has a spread of only "
                                 f"{spread[1]:.3g} deg; record a larger flexion-extension")
    return est
