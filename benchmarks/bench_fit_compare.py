"""Every fitting method of identcheck.fit side by side: joint-centre / hinge-axis error and run time.

Grids after Ehrig et al. (2006, centre: SCoRE vs others; 2007, axis: SARA vs others): marker
noise, range of motion (ROM) and number of frames, one varied at a time around a default cell
(1 mm, 30°, 200 frames at 100 Hz). Every trial draws a random two-segment geometry (3-4 markers
per segment, 50-150 mm from the joint, in a 35° cone either side of it), moves the parent in the
world (rotation and sway of ``identcheck.simulate.rigid``'s root motion) and the child relative to it:

* spherical: star-arc (swings of ±ROM/2 in four planes through the neutral position), a
  circumduction rosette of radius ROM/2, and axial rotation ±ROM/4 throughout (3 DoF);
* hinge: 1-DoF flexion, two sine cycles of ±ROM/2 about a random axis roughly perpendicular to
  the segments (tilt ~ N(0, 0.15) rad).

Isotropic Gaussian noise of the given sd is added to every marker coordinate. Each method is fed
the markers its case allows (the first two parent markers for S22 and Pham (2,1), the first child
marker for (3,1) and (2,1)); errors are taken in the *true* parent frame: the fitted world
trajectory is mapped through the true parent poses and averaged over frames. Spherical: distance
of that point to the true centre (mm). Hinge: angle between fitted and true axis (degrees, an
axis is a line), and distance of the true joint centre (the point of the true axis between the
two marker clusters) to the fitted axis line (mm).

Results: a printed table, ``benchmarks/results.json["fit_compare"]`` (``"fit_compare_quick"`` for
``--quick``) and ``benchmarks/fit_compare.png``.

Run from the repository root::

    PYTHONPATH=. python3 benchmarks/bench_fit_compare.py            # about 3 min on 2 cores
    PYTHONPATH=. python3 benchmarks/bench_fit_compare.py --quick    # about 15 s
"""
from __future__ import annotations

import argparse
import datetime
import multiprocessing
import os
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

# One BLAS thread per worker process: with two workers on two cores, multi-threaded BLAS calls
# (e.g. the SVDs in posed_circle) spin against the other worker and their times grow up to 40x.
# Set before numpy loads; the workers are spawned, so they honour it even when the parent process
# had numpy loaded already (pytest).
BLAS_ENV = {v: "1" for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
for _k, _v in BLAS_ENV.items():
    os.environ.setdefault(_k, _v)

import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
from identcheck.estimate import joint as estimate  # noqa: E402
from identcheck.estimate.obrien import joint_location  # noqa: E402
from identcheck.geometry.poses import segment_poses  # noqa: E402
from identcheck.estimate.score_sara import sara, score  # noqa: E402
from identcheck.estimate.seed001 import fit_centre  # noqa: E402
from identcheck.simulate.rigid import ROOT_HEIGHT_MM, ROOT_ROM_DEG, ROOT_SWAY_MM, smooth_profile  # noqa: E402

KEY = "fit_compare"
RESULTS = ROOT / "benchmarks" / "results.json"
FIGURE = ROOT / "benchmarks" / "fit_compare.png"
RATE_HZ = 100.0
DEFAULT = {"noise": 1.0, "rom": 30.0, "frames": 200}
GRIDS = {"noise": (0.0, 0.5, 1.0, 2.0, 4.0), "rom": (10.0, 20.0, 30.0, 45.0, 60.0),
         "frames": (50, 100, 200, 500, 1000)}
QUICK_GRIDS = {"noise": (0.0, 1.0, 4.0), "rom": (20.0, 60.0), "frames": (50, 200)}
QUICK_SLOW_CELLS = {"noise": (0.0, 4.0)}   # --quick runs S22 and Pham (2,1) only here
UNITS = {"noise": "mm", "rom": "deg", "frames": ""}
MARKER_MM = (50.0, 150.0)      # marker distance from the joint centre
CONE_DEG = 35.0                # half-angle of each cluster's cone about the segment direction
MIN_GAP_MM = 25.0
MIN_SPREAD_MM = 10.0           # second singular value of a cluster (not collinear)
MIN_AXIS_MM = 20.0             # markers at least this far from the hinge axis
AXIS_TILT = 0.15

SPHERICAL = {   # name -> (description, slow)
    "seed001": ("identcheck.estimate.seed001.fit_centre, method='pair' (6 unknowns, Gauss-Markov, bias-corrected)", False),
    "seed001 eq9": ("fit_centre(method='paper', bias_correction=False): seed 001 as printed, eq. 9", False),
    "O'Brien": ("identcheck.estimate.obrien.joint_location (stacked SVD)", False),
    "SCoRE": ("identcheck.estimate.score_sara.score (3x3 mean-rotation route)", False),
    "SCoRE loop": ("this file: per-frame Python loop (Kabsch by np.linalg.svd, 6x6 normal equations)", False),
    "sphere 3,q": ("identcheck.estimate.joint.posed_sphere, all child markers (Gamage-Lasenby style)", False),
    "sphere 3,1": ("estimate.posed_sphere on the first child marker (Pham (3,1))", False),
    "S22": ("estimate.pair_spherical (Pham V-A), first two parent + first two child markers", True),
}
HINGE = {
    "SARA": ("identcheck.estimate.score_sara.sara", False),
    "SARA loop": ("this file: per-frame Python loop (Kabsch, 6x6 normal matrix, its null vector)", False),
    "O'Brien": ("joint_location single-axis solution (axis only when motion == 'single_axis')", False),
    "circle 3,q": ("identcheck.estimate.joint.posed_circle, all child markers", False),
    "circle 3,1": ("estimate.posed_circle on the first child marker", False),
    "Pham 2,1": ("estimate.pair_revolute (Pham III-A, ODR), first two parent markers + first child marker; "
                 "error of the candidate nearest the truth among the equally good ones (ERRATA E1/E2)", True),
}
METHODS = {"spherical": SPHERICAL, "hinge": HINGE}


# ---------------------------------------------------------------------- trials with known truth
def _cluster(rng, direction, k, extra_ok=lambda x: True):
    """k marker positions 50-150 mm from the origin within CONE_DEG of ``direction``."""
    for _ in range(1000):
        v = rng.normal(size=(k, 3))
        v -= (v @ direction)[:, None] * direction
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        ang = np.deg2rad(CONE_DEG) * np.sqrt(rng.uniform(0, 1, (k, 1)))
        dirs = np.cos(ang) * direction + np.sin(ang) * v
        x = rng.uniform(*MARKER_MM, (k, 1)) * dirs
        gaps = np.linalg.norm(x[:, None] - x[None], axis=2) + np.eye(k) * 1e9
        if gaps.min() < MIN_GAP_MM or np.linalg.svd(x - x.mean(0), compute_uv=False)[1] < MIN_SPREAD_MM:
            continue
        if extra_ok(x):
            return x
    raise RuntimeError("cannot place markers")


def make_geometry(kind: str, rng: np.random.Generator) -> dict:
    """Joint at the origin of the parent frame (z towards the parent cluster) and of the child frame
    (equal to the parent frame at rest); the hinge axis roughly perpendicular to z."""
    n_p, n_c = rng.integers(3, 5, 2)
    axis = None
    ok = lambda x: True  # noqa: E731
    if kind == "hinge":
        psi = rng.uniform(0, 2 * np.pi)
        axis = np.array([np.cos(psi), np.sin(psi), rng.normal(0, AXIS_TILT)])
        axis /= np.linalg.norm(axis)
        ok = lambda x: np.linalg.norm(x - np.outer(x @ axis, axis), axis=1).min() >= MIN_AXIS_MM  # noqa: E731
    parent = _cluster(rng, np.array([0.0, 0.0, 1.0]), int(n_p), ok)
    child = _cluster(rng, np.array([0.0, 0.0, -1.0]), int(n_c), ok)
    return {"parent_local": parent, "child_local": child, "axis": axis, "centre": np.zeros(3),
            "R0": Rotation.random(random_state=rng).as_matrix(), "rest": np.deg2rad(rng.uniform(-10, 10, 2)),
            "phase": rng.uniform(0, 2 * np.pi), "hinge_offset": np.deg2rad(rng.uniform(-15, 15))}


def star_arc(n: int, rom_deg: float, phase: float) -> np.ndarray:
    """Relative rotation vectors (n, 3), parent frame: 4 swing planes, a circumduction rosette
    (radius ROM/2), axial rotation ±ROM/4 (3 cycles) throughout."""
    u = np.linspace(0.0, 1.0, n)
    a = np.deg2rad(rom_deg) / 2
    seg = np.minimum((u * 5).astype(int), 4)
    s = u * 5 - seg
    phi = phase + seg * np.pi / 4
    swing = np.where(seg < 4, a * np.sin(2 * np.pi * s), a * np.sin(np.pi * s))
    phi = np.where(seg < 4, phi, phase + 2 * np.pi * s)
    axial = a / 2 * np.sin(2 * np.pi * 3 * u + phase)
    return np.stack([swing * np.cos(phi), swing * np.sin(phi), axial], axis=1)


def make_trial(kind: str, n: int, rom_deg: float, noise_mm: float, geo_seed, noise_seed) -> dict:
    """Noisy markers of both segments (``parent`` (F, m, 3), ``child`` (F, q, 3)), the true parent
    poses (``Rp``, ``tp``: world = Rp @ x + tp) and the geometry (``geo``) of one trial.

    ``geo_seed`` seeds the geometry and the motion (so the same trial index shares them across a
    grid), ``noise_seed`` the noise; both are ``numpy.random.SeedSequence`` entropy.
    """
    rng = np.random.default_rng(np.random.SeedSequence(geo_seed))
    geo = make_geometry(kind, rng)
    t = np.arange(n) / RATE_HZ
    # parent in the world: simulate's root motion (rotation ±ROOT_ROM_DEG/2, sway ±ROOT_SWAY_MM/2)
    Rp = Rotation.from_rotvec(np.deg2rad(ROOT_ROM_DEG) * smooth_profile(rng, t, 3)).as_matrix() @ geo["R0"]
    tp = np.array([0.0, 0.0, ROOT_HEIGHT_MM]) + ROOT_SWAY_MM * smooth_profile(rng, t, 3)
    rest = Rotation.from_rotvec([geo["rest"][0], geo["rest"][1], 0.0]).as_matrix()
    if kind == "spherical":
        Rrel = Rotation.from_rotvec(star_arc(n, rom_deg, geo["phase"])).as_matrix() @ rest
    else:
        u = np.linspace(0.0, 1.0, n)
        theta = geo["hinge_offset"] + np.deg2rad(rom_deg) / 2 * np.sin(2 * np.pi * 2 * u + geo["phase"])
        Rrel = Rotation.from_rotvec(theta[:, None] * geo["axis"]).as_matrix()
    parent = np.einsum("fij,mj->fmi", Rp, geo["parent_local"]) + tp[:, None]
    child = np.einsum("fij,mj->fmi", Rp @ Rrel, geo["child_local"]) + tp[:, None]
    clean = np.concatenate([parent, child], axis=1)
    noise = np.random.default_rng(np.random.SeedSequence(noise_seed)).normal(0.0, noise_mm, clean.shape)
    xyz = clean + noise if noise_mm > 0 else clean.copy()
    m = len(geo["parent_local"])
    return {"parent": xyz[:, :m], "child": xyz[:, m:], "Rp": Rp, "tp": tp, "geo": geo}


# ---------------------------------------------------------------------- the obvious per-frame loop
def _kabsch_loop(points):
    """Per-frame least-squares poses in a Python loop (reference: first frame, centred)."""
    ref = points[0] - points[0].mean(axis=0)
    Rs, ts = [], []
    for p in points:
        c = p.mean(axis=0)
        U, _, Vt = np.linalg.svd((p - c).T @ ref)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
        R = U @ D @ Vt
        Rs.append(R)
        ts.append(c - R @ ref.mean(axis=0))
    return Rs, ts


def normal_equations_loop(parent, child):
    """Σ AᵀA and Σ Aᵀb for A = [R_P, −R_C], b = t_C − t_P, one frame at a time, and the poses."""
    Rp, tp = _kabsch_loop(parent)
    Rc, tc = _kabsch_loop(child)
    N = np.zeros((6, 6))
    rhs = np.zeros(6)
    for a, b, c, d in zip(Rp, tp, Rc, tc):
        A = np.hstack([a, -c])
        N += A.T @ A
        rhs += A.T @ (d - b)
    return N, rhs, (Rp, tp)


def score_loop(parent, child):
    """SCoRE written the obvious way: (centre in the parent frame, parent poses)."""
    N, rhs, poses = normal_equations_loop(parent, child)
    return np.linalg.lstsq(N, rhs, rcond=None)[0][:3], poses


def sara_loop(parent, child):
    """SARA written the obvious way: (point on the axis, axis, both in the parent frame; parent poses)."""
    N, rhs, poses = normal_equations_loop(parent, child)
    w, V = np.linalg.eigh(N)
    axis = V[:3, 0] / np.linalg.norm(V[:3, 0])
    u = V[:, 1:] @ ((V[:, 1:].T @ rhs) / w[1:])              # min-norm, null direction dropped
    return u[:3], axis, poses


def _loop_world(point, poses, direction=False):
    Rs, ts = poses
    return np.array([R @ point + (0 if direction else t) for R, t in zip(Rs, ts)])


# ---------------------------------------------------------------------- the methods
def _posed_world(points, local_point):
    poses = segment_poses(points)
    return poses.to_world(np.asarray(local_point)[None])[:, 0], poses


def run_spherical(name, P, C):
    """Fit one method (the timed part) and return ``finish``, the untimed part: ``finish()`` gives
    (world centre trajectory (F, 3), flagged). ``flagged``: the method itself says the centre is
    poorly determined (``excitation_ok`` False, or not ``unique``); None if it has no such verdict.
    The centre is placed through the parent's poses for every posed method (SCoRE's own
    ``centre_world`` averages the parent's and the child's images)."""
    if name in ("seed001", "seed001 eq9"):
        kw = {} if name == "seed001" else {"method": "paper", "bias_correction": False}
        fit = fit_centre(P, C, warn=False, **kw)
        return lambda: (fit.centre_world(), not fit.excitation_ok)
    if name in ("O'Brien", "SCoRE"):
        fit = joint_location(P, C) if name == "O'Brien" else score(P, C)
        return lambda: (_posed_world(P, fit.centre_parent)[0], not fit.unique)
    if name == "SCoRE loop":
        centre, poses = score_loop(P, C)
        return lambda: (_loop_world(centre, poses), None)
    if name == "S22":
        est = estimate.pair_spherical(P[:, 0], P[:, 1], C[:, 0], C[:, 1], "spherical(2,2)")
    elif name in ("sphere 3,q", "sphere 3,1"):
        est = estimate.posed_sphere(P, C if name == "sphere 3,q" else C[:, :1], "spherical(3,q)")
    else:
        raise KeyError(name)
    return lambda: (est.centre, not (est.excitation_ok and est.unique))


def run_hinge(name, P, C):
    """As :func:`run_spherical`; ``finish()`` gives (candidate hinges, each (point (F, 3),
    direction (F, 3)) in the world, flagged)."""
    if name == "SARA":
        fit = sara(P, C)

        def finish():
            pt, poses = _posed_world(P, fit.point_parent)
            return [(pt, fit.axis_world(poses))], not fit.hinge
        return finish
    if name == "SARA loop":
        point, axis, poses = sara_loop(P, C)
        return lambda: ([(_loop_world(point, poses), _loop_world(axis, poses, direction=True))], None)
    if name == "O'Brien":
        fit = joint_location(P, C)
        if fit.axis_parent is None:
            raise RuntimeError(f"no single axis: {fit.reason}")

        def finish():
            pt, poses = _posed_world(P, fit.centre_parent)
            return [(pt, np.einsum("fij,j->fi", poses.R, fit.axis_parent))], False
        return finish
    if name in ("circle 3,q", "circle 3,1"):
        est = estimate.posed_circle(P, C if name == "circle 3,q" else C[:, :1], "revolute(3,q)")
        return lambda: ([(est.point, est.direction)], not est.excitation_ok)
    if name == "Pham 2,1":    # flagged only for poor excitation: (2,1) is never unique (E1/E2)
        est = estimate.pair_revolute(P[:, 0], P[:, 1], C[:, :1], "revolute(2,1)")
        return lambda: ([(e.point, e.direction) for e in [est] + list(est.alternatives)], not est.excitation_ok)
    raise KeyError(name)


def to_parent(world, Rp, tp, direction=False):
    """World trajectory → true parent frame, averaged over the frames where it is finite."""
    ok = np.all(np.isfinite(world), axis=1)
    local = np.einsum("fji,fj->fi", Rp[ok], world[ok] if direction else world[ok] - tp[ok])
    if not len(local):
        return np.full(3, np.nan)
    if direction:                       # an axis is a line: align signs before averaging
        local *= np.sign(local @ local[0])[:, None]
        m = local.mean(axis=0)
        return m / np.linalg.norm(m)
    return local.mean(axis=0)


def hinge_errors(pt_w, dir_w, tr):
    p = to_parent(pt_w, tr["Rp"], tr["tp"])
    a = to_parent(dir_w, tr["Rp"], tr["tp"], direction=True)
    axis, centre = tr["geo"]["axis"], tr["geo"]["centre"]
    ang = float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, axis)), abs(a @ axis))))   # exact near 0
    w = centre - p
    pos = float(np.linalg.norm(w - (w @ a) * a))
    return ang, pos


def one_trial(job):
    """All methods on one trial: {method: {err..., time_s}}; failures as {"fail": message}."""
    kind, grid, value, trial, slow, seed = job
    cell = {**DEFAULT, grid: value}
    tr = make_trial(kind, int(cell["frames"]), cell["rom"], cell["noise"],
                    geo_seed=[seed, 0 if kind == "spherical" else 1, trial],
                    noise_seed=[seed, 0 if kind == "spherical" else 1, trial, list(GRIDS).index(grid),
                                int(round(1000 * value))])
    P, C = tr["parent"], tr["child"]
    out = {}
    for name, (_, is_slow) in METHODS[kind].items():
        if is_slow and not slow:
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                finish = run_spherical(name, P, C) if kind == "spherical" else run_hinge(name, P, C)
                dt = time.perf_counter() - t0
                res, flagged = finish()
            if kind == "spherical":
                c = to_parent(res, tr["Rp"], tr["tp"])
                err = float(np.linalg.norm(c - tr["geo"]["centre"]))
                if not np.isfinite(err):
                    raise RuntimeError("no finite centre")
                out[name] = {"err_mm": err, "time_s": dt, "flagged": flagged}
            else:
                errs = [hinge_errors(pt, d, tr) for pt, d in res]
                if not all(np.isfinite(e).all() for e in errs):
                    raise RuntimeError("no finite hinge")
                k = int(np.argmin([e[1] for e in errs]))          # nearest candidate (1 unless Pham 2,1)
                out[name] = {"angle_deg": errs[k][0], "pos_mm": errs[k][1], "time_s": dt, "flagged": flagged,
                             "n_candidates": len(errs), "first_is_nearest": k == 0,
                             "first_angle_deg": errs[0][0], "first_pos_mm": errs[0][1]}
        except Exception as exc:  # a method failing is a result, not a crash of the benchmark
            out[name] = {"fail": f"{type(exc).__name__}: {exc}"[:200]}
    return job, out


def _warm_up():
    """First calls (imports, code generation of the (2,1) solver) outside any timing: every method
    once on a short, noise-free, well-conditioned trial."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kind, methods in METHODS.items():
            tr = make_trial(kind, 12, 30.0, 0.0, [1], [1])
            for name in methods:
                (run_spherical if kind == "spherical" else run_hinge)(name, tr["parent"], tr["child"])()


# ---------------------------------------------------------------------- summaries
def _stats(values):
    v = np.asarray(values, dtype=float)
    if not len(v):
        return {"mean": None, "p95": None, "median": None, "max": None}
    return {"mean": float(v.mean()), "p95": float(np.percentile(v, 95)), "median": float(np.median(v)),
            "max": float(v.max())}


def summarise(kind, results, grids):
    """Per grid, per value, per method: error statistics, failures and median run time."""
    out = {}
    for grid, values in grids.items():
        rows = []
        for value in values:
            cell = [r for (k, g, v, *_), r in results if k == kind and g == grid and v == value]
            row = {"value": value, "methods": {}}
            for name in METHODS[kind]:
                rs = [r[name] for r in cell if name in r]
                ok = [r for r in rs if "fail" not in r]
                m = {"n": len(rs), "n_fail": len(rs) - len(ok),
                     "fail_messages": sorted({r["fail"] for r in rs if "fail" in r})[:3],
                     "median_time_s": float(np.median([r["time_s"] for r in ok])) if ok else None,
                     "flagged": (float(np.mean([bool(r["flagged"]) for r in ok]))
                                 if ok and ok[0]["flagged"] is not None else None)}
                if kind == "spherical":
                    m["err_mm"] = _stats([r["err_mm"] for r in ok])
                else:
                    m["angle_deg"] = _stats([r["angle_deg"] for r in ok])
                    m["pos_mm"] = _stats([r["pos_mm"] for r in ok])
                    if name == "Pham 2,1" and ok:
                        m["mean_candidates"] = float(np.mean([r["n_candidates"] for r in ok]))
                        m["first_is_nearest"] = float(np.mean([r["first_is_nearest"] for r in ok]))
                        m["first_angle_deg"] = _stats([r["first_angle_deg"] for r in ok])
                        m["first_pos_mm"] = _stats([r["first_pos_mm"] for r in ok])
                row["methods"][name] = m
            rows.append(row)
        out[grid] = rows
    return out


def timing(kind, results):
    """Median run time per trial of each method over all trials, and at each frame count of the
    frames grid, with ratios to the fastest method."""
    def med(sel, name):
        ts = [r[name]["time_s"] for (k, g, v, *_), r in results
              if k == kind and sel(g, v) and name in r and "fail" not in r[name]]
        return float(np.median(ts)) if ts else None
    out = {"all_trials": {}, "by_frames": {}}
    for label, sel in [("all_trials", lambda g, v: True)] + [
            (str(n), (lambda n: lambda g, v: g == "frames" and v == n)(n)) for n in GRIDS["frames"]]:
        t = {name: med(sel, name) for name in METHODS[kind]}
        if not any(x is not None for x in t.values()):
            continue
        fastest = min(x for x in t.values() if x is not None)
        entry = {name: {"median_s": x, "ratio_to_fastest": None if x is None else x / fastest}
                 for name, x in t.items()}
        if label == "all_trials":
            out["all_trials"] = entry
        else:
            out["by_frames"][label] = entry
    return out


def run(trials: int, slow_trials: int, grids: dict, seed: int, workers: int, slow_cells=None) -> dict:
    """Every cell of every grid, ``trials`` trials each (the slow methods: the first ``slow_trials``,
    and only in the cells of ``slow_cells``, {grid: values}; default every cell)."""
    t0 = time.perf_counter()
    slow_cells = grids if slow_cells is None else slow_cells
    jobs = [(kind, grid, value, k, k < slow_trials and value in slow_cells.get(grid, ()), seed)
            for kind in METHODS for grid, values in grids.items() for value in values for k in range(trials)]
    # slow jobs first so that the workers finish together
    jobs.sort(key=lambda j: -j[4] * (DEFAULT["frames"] if j[1] != "frames" else j[2]))
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers, initializer=_warm_up,
                                 mp_context=multiprocessing.get_context("spawn")) as pool:
            results = list(pool.map(one_trial, jobs, chunksize=1))
    else:
        _warm_up()
        results = [one_trial(j) for j in jobs]
    results = [((k, g, v, t), r) for (k, g, v, t, _, _), r in results]
    return {kind: {"grids": summarise(kind, results, grids), "timing": timing(kind, results)}
            for kind in METHODS} | {"total_s": time.perf_counter() - t0}


# ---------------------------------------------------------------------- output
def _grid_order(grids) -> list:
    """noise, rom, frames (a JSON round trip sorts the keys)."""
    return [g for g in GRIDS if g in grids]


def _cellstr(m, key):
    s = m.get(key) or {}
    if s.get("mean") is None:
        return "fail" if m["n"] else "-"
    txt = f"{s['mean']:.3g}/{s['p95']:.3g}"
    return txt + (f" ({m['n_fail']}F)" if m["n_fail"] else "")


def table(res: dict) -> str:
    lines = []
    for kind, metrics in (("spherical", (("err_mm", "centre error mm"),)),
                          ("hinge", (("angle_deg", "axis angle error deg"), ("pos_mm", "axis position error mm")))):
        names = list(METHODS[kind])
        w = max(14, max(len(n) for n in names) + 1)
        for key, title in metrics:
            lines.append(f"\n{kind}: {title}, mean/p95 over trials ((nF) = n trials failed)")
            head = f"{'grid':>12} | " + " ".join(f"{n:>{w}}" for n in names)
            lines += [head, "-" * len(head)]
            for grid in _grid_order(res[kind]["grids"]):
                for row in res[kind]["grids"][grid]:
                    label = f"{grid} {row['value']:g}{UNITS[grid]}"
                    lines.append(f"{label:>12} | " + " ".join(f"{_cellstr(row['methods'][n], key):>{w}}"
                                                           for n in names))
        lines.append(f"\n{kind}: median run time per trial, ms (ratio to the fastest method)")
        head = f"{'frames':>12} | " + " ".join(f"{n:>{w}}" for n in names)
        lines += [head, "-" * len(head)]
        tm = res[kind]["timing"]
        for label, entry in list(tm["by_frames"].items()) + [("all trials", tm["all_trials"])]:
            cells = []
            for n in names:
                e = entry.get(n, {})
                cells.append("-" if e.get("median_s") is None
                             else f"{1e3 * e['median_s']:.3g} ({e['ratio_to_fastest']:.3g}x)")
            lines.append(f"{label:>12} | " + " ".join(f"{c:>{w}}" for c in cells))
        lines.append(f"\n{kind}: % of trials the method itself flags (excitation_ok False / not unique / "
                     "not single-axis; '-' = no verdict)")
        lines += [head.replace("frames", "  grid", 1), "-" * len(head)]
        for grid in _grid_order(res[kind]["grids"]):
            for row in res[kind]["grids"][grid]:
                label = f"{grid} {row['value']:g}{UNITS[grid]}"
                cells = ["-" if row["methods"][n]["flagged"] is None else f"{100 * row['methods'][n]['flagged']:.0f}"
                         for n in names]
                lines.append(f"{label:>12} | " + " ".join(f"{c:>{w}}" for c in cells))
        ph = [(row["value"], row["methods"].get("Pham 2,1", {})) for row in res[kind]["grids"].get("noise", [])] \
            if kind == "hinge" else []
        for value, m in ph:
            if m.get("first_is_nearest") is not None:
                lines.append(f"  Pham 2,1 at noise {value:g} mm: {m['mean_candidates']:.2f} equally good joints on "
                             f"average; best-RMS one is the nearest in {100 * m['first_is_nearest']:.0f}% of trials "
                             f"(its errors {m['first_angle_deg']['mean']:.3g} deg / {m['first_pos_mm']['mean']:.3g} mm)")
    return "\n".join(lines)


def figure(res: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("spherical", "err_mm", "centre error (mm)"), ("hinge", "angle_deg", "axis angle error (deg)"),
              ("hinge", "pos_mm", "axis position error (mm)")]
    grids = _grid_order(res["spherical"]["grids"])
    fig, axes = plt.subplots(len(panels), len(grids), figsize=(5 * len(grids), 4 * len(panels)), squeeze=False)
    for i, (kind, key, ylabel) in enumerate(panels):
        for j, grid in enumerate(grids):
            ax = axes[i, j]
            rows = [r for r in res[kind]["grids"][grid] if not (grid == "noise" and r["value"] == 0)]
            x = np.array([r["value"] for r in rows], float)
            for k, name in enumerate(METHODS[kind]):
                y = np.array([np.nan if (r["methods"][name].get(key) or {}).get("mean") is None
                              else r["methods"][name][key]["mean"] for r in rows])
                label = name + (" (trials with an axis only)" if (kind, name) == ("hinge", "O'Brien") else "")
                if np.isfinite(y).any():
                    ax.plot(x, y, marker="os^vD<>p"[k % 8], ls="--" if "loop" in name else "-",
                            lw=0.8 if "loop" in name else 1.5, ms=4, label=label)
            ax.set(yscale="log", xlabel=f"{grid} ({UNITS[grid] or 'count'})", ylabel=f"mean {ylabel}",
                   title=f"{kind}: {ylabel} vs {grid}" + (" (0 mm: exact, not drawn)" if grid == "noise" else ""))
            if grid == "frames":
                ax.set_xscale("log")
            ax.grid(True, which="both", alpha=0.3)
            if grid == "noise" or len(grids) == 1:
                ax.legend(fontsize=7)
    fig.suptitle("identcheck.fit methods side by side (mean over trials; other parameters at "
                 f"{DEFAULT['noise']:g} mm, {DEFAULT['rom']:g} deg, {DEFAULT['frames']} frames)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20, help="trials per cell (default 20)")
    ap.add_argument("--slow-trials", type=int, default=5,
                    help="trials per cell for the slow methods S22 and Pham 2,1 (default 5)")
    ap.add_argument("--seed", type=int, default=0, help="seed of every trial's SeedSequence (default 0)")
    ap.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    ap.add_argument("--quick", action="store_true",
                    help="3 trials, grids noise 0/1/4, rom 20/60, frames 50/200 (the slow methods: 1 trial at "
                         "noise 0 and 4 only); stored under fit_compare_quick")
    ap.add_argument("--out", type=Path, default=None, help="JSON to update (default benchmarks/results.json)")
    ap.add_argument("--figure", type=Path, default=None,
                    help="figure path (default: benchmarks/fit_compare.png for a full run, OUT with .png when "
                         "--out is given, none for --quick)")
    ap.add_argument("--replot", action="store_true",
                    help="only print the table and draw the figure from the stored key (no trials)")
    args = ap.parse_args(argv)
    grids, slow_cells = GRIDS, None
    if args.quick:
        args.trials, args.slow_trials, grids = min(args.trials, 3), min(args.slow_trials, 1), QUICK_GRIDS
        slow_cells = QUICK_SLOW_CELLS
    key = KEY + ("_quick" if args.quick else "")
    out = args.out or RESULTS
    if args.replot:
        import json
        doc = json.loads(Path(out).read_text())[key]
        print(table(doc))
        fig = args.figure or (FIGURE if out == RESULTS and not args.quick else Path(out).with_suffix(".png"))
        figure(doc, fig)
        print(f"drew {fig}")
        return 0
    load_before = [round(x, 2) for x in os.getloadavg()]
    res = run(args.trials, min(args.slow_trials, args.trials), grids, args.seed, args.workers, slow_cells)
    print(table(res))
    print(f"\ntotal {res['total_s']:.1f} s")
    doc = {"description": __doc__.split("\n\n")[0], "date": datetime.datetime.now().isoformat(timespec="seconds"),
           "total_s": res["total_s"], "spherical": res["spherical"], "hinge": res["hinge"],
           "settings": {
               "seed": args.seed, "trials": args.trials, "slow_trials": min(args.slow_trials, args.trials),
               "quick": args.quick, "workers": args.workers, "rate_hz": RATE_HZ, "defaults": DEFAULT,
               "grids": {g: list(v) for g, v in grids.items()},
               "methods": {k: {n: d for n, (d, _) in m.items()} for k, m in METHODS.items()},
               "slow_methods": [n for m in METHODS.values() for n, (_, s) in m.items() if s],
               "slow_cells": {g: list(v) for g, v in (slow_cells or grids).items()},
               "generation": {
                   "function": "benchmarks/bench_fit_compare.py:make_trial(kind, frames, rom, noise, geo_seed, "
                               "noise_seed)",
                   "geo_seed": "[seed, 0 spherical | 1 hinge, trial]  (geometry and motion; shared across grids)",
                   "noise_seed": "[seed, kind, trial, grid index (noise, rom, frames), round(1000 * value)]",
                   "markers_mm_from_joint": MARKER_MM, "cone_deg": CONE_DEG, "markers_per_segment": [3, 4],
                   "min_gap_mm": MIN_GAP_MM, "min_axis_distance_mm": MIN_AXIS_MM, "axis_tilt_sd_rad": AXIS_TILT,
                   "parent_motion": f"simulate root motion: rotation {ROOT_ROM_DEG} deg and sway {ROOT_SWAY_MM} mm "
                                    "peak-to-peak per axis (sums of sinusoids 0.2-2 Hz)",
                   "spherical_motion": "star-arc: 4 planes x one sine cycle of ±ROM/2, circumduction rosette "
                                       "radius ROM/2, axial ±ROM/4 (3 cycles); rest offset ±10 deg",
                   "hinge_motion": "2 sine cycles of ±ROM/2 about the axis, offset ±15 deg"},
               "errors": {"spherical": "|mean_f Rp_f^T (c_f - tp_f) - c_true| (true parent poses), mm",
                          "hinge_angle": "angle between mean fitted axis (true parent frame) and true axis, deg",
                          "hinge_position": "distance of the true joint centre to the fitted axis line, mm"}},
           "machine": machine_info(loadavg_before=load_before,
                                   blas_threads={k: os.environ.get(k) for k in BLAS_ENV})}
    write_json(out, key, doc)
    if args.figure is not None:
        fig = args.figure
    elif out != RESULTS:
        fig = out.with_suffix(".png")
    else:
        fig = None if args.quick else FIGURE      # a quick run never overwrites the full run's figure
    if fig is not None:
        figure(res, fig)
    print(f"wrote {out} (key {key!r})" + (f" and {fig}" if fig is not None else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
