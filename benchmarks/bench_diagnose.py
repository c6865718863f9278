"""Speed of `identcheck diagnose` end to end, and of its core fit against scipy's sparse least squares.

Three sections, all on ``examples/diagnose_leg.toml`` (nine markers, ball hip, hinge knee) simulated at
100 Hz with 0.5 mm noise (``identcheck.simulate.rigid.simulate``, seed 1, no gaps):

1. **diagnose, end to end** (the issue's row): a 15 s trial (1500 frames) without an effect and with
   each of the eight named effects hidden in it (``inject_effect(sim, name, seed=1)``), diagnosed by
   ``identcheck.diagnose.workflow.diagnose(model, trial)``: noise floor, rigid fit, candidate search.
   Wall time is the median of ``--repeats`` runs (a row whose first run exceeds ``--repeat-limit-s``
   is timed once: it is far off the target either way); the CPU time of the process (all threads) is
   kept alongside, since the machine may be shared. PASS/FAIL is against 5 s per row; the script does
   not fail on it.
2. **The core fit against the obvious alternative**: the rigid whole-chain least-squares problem
   (root pose and joint angles per frame, marker positions, joint centres and hinge axes as constants)
   solved by ``identcheck.bundle.chain.fit_chain`` (Levenberg-Marquardt, Schur complement over the
   frames) and by ``scipy.optimize.least_squares(method="trf", jac_sparsity=..., x_scale="jac")``
   with finite-difference Jacobians, from the same ``initial_state``. The scipy parametrisation
   (:class:`ScipyChain`) is this script's own: rotation vectors composed on the left of the starting
   rotations (root and ball joints, per frame), hinge-angle and translation increments, constant
   increments, the hinge rest rotation composed on the left and the hinge axis moved in its tangent
   plane; predictions come from ``chain.forward``. Per-frame unknowns touch only their frame's
   residuals, so the sparsity pattern has one dense block of constant columns and a block diagonal
   of per-frame columns; the finite differences need (per-frame unknowns per frame + constants)
   evaluations per Jacobian whatever the number of frames. scipy runs twice: with its default
   tolerances (1e-8) and with ``ftol = xtol = gtol = 1e-10`` (``fit_chain`` stops when the cost falls
   by less than 1e-10 of itself). A scipy run over ``--scipy-cap-s`` is stopped and reported "> cap".
3. **fit_chain alone vs frames**: median time, iterations, time per iteration and the log-log slope of
   time per iteration against frames (1 = linear).

Optionally (``--profile NAME``) one row of section 1 is run once more under cProfile: the top
functions by cumulative time and the time per stage go into the JSON.

Results: a printed table and ``benchmarks/results.json["diagnose"]`` (``"diagnose_quick"`` for
``--quick``, which never overwrites the full run).

    PYTHONPATH=. python3 benchmarks/bench_diagnose.py            # full run (long: see the README)
    PYTHONPATH=. python3 benchmarks/bench_diagnose.py --quick    # 200 frames, two effects, seconds
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import ctypes
import datetime
import math
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
from identcheck.skeleton import Skeleton  # noqa: E402
from identcheck.bundle.chain import REL_TOL, fit_chain, initial_state  # noqa: E402
from identcheck.bundle.model import State, Terms, forward, tangents  # noqa: E402
from identcheck.diagnose.workflow import diagnose  # noqa: E402
from identcheck.effects.registry import NAMES as EFFECTS, inject_effect  # noqa: E402
from identcheck.io.model import Model  # noqa: E402
from identcheck.simulate.rigid import simulate  # noqa: E402
from identcheck.io.jsonable import plain  # noqa: E402

KEY = "diagnose"
RESULTS = ROOT / "benchmarks" / "results.json"
MODEL = "examples/diagnose_leg.toml"
RATE_HZ = 100.0
NOISE_MM = 0.5
SIM_SEED = 1
EFFECT_SEED = 1
TARGET_S = 5.0
BLAS_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

FULL = {"frames": 1500, "repeats": 3, "effects": (None,) + EFFECTS, "scipy_frames": (300, 1000, 1500),
        "fit_frames": (300, 1000, 1500, 3000), "profile": "auto"}
QUICK = {"frames": 200, "repeats": 1, "effects": (None, "marker_slip", "outliers"), "scipy_frames": (100,),
         "fit_frames": (100, 200), "profile": None}
SCIPY_TOLS = {"default": 1e-8, "tight": REL_TOL}
"""scipy's default ftol/xtol/gtol, and fit_chain's own stopping rule (relative fall of the cost)."""


# ---------------------------------------------------------------------- trials
_MODEL = None
_SIMS: dict = {}


def model() -> Model:
    global _MODEL
    if _MODEL is None:
        _MODEL = Model.from_toml(ROOT / MODEL)
    return _MODEL


def rigid(frames: int):
    """The rigid simulated trial of `frames` frames (cached)."""
    if frames not in _SIMS:
        _SIMS[frames] = simulate(model(), n_frames=frames, rate_hz=RATE_HZ, noise_mm=NOISE_MM, seed=SIM_SEED)
    return _SIMS[frames]


def trial(frames: int, effect: str | None):
    sim = rigid(frames)
    return sim if effect is None else inject_effect(sim, effect, seed=EFFECT_SEED)


def _median(xs):
    return float(statistics.median(xs))


# ---------------------------------------------------------------------- BLAS threads
def _openblas_handles() -> list:
    """(path, set, get) for every OpenBLAS loaded in this process (numpy's and scipy's bundled ones)."""
    paths = []
    try:
        with open("/proc/self/maps") as fh:
            for line in fh:
                p = line.split()[-1]
                if "openblas" in Path(p).name and ".so" in p and p not in paths:
                    paths.append(p)
    except OSError:      # not Linux: leave the threads alone
        return []
    out = []
    for p in paths:
        lib = ctypes.CDLL(p)
        for name in ("scipy_openblas_{}_num_threads64_", "scipy_openblas_{}_num_threads", "openblas_{}_num_threads64_",
                     "openblas_{}_num_threads"):
            try:
                out.append((Path(p).name, getattr(lib, name.format("set")), getattr(lib, name.format("get"))))
                break
            except AttributeError:
                continue
    return out


def blas_threads() -> dict:
    return {name: int(get()) for name, _, get in _openblas_handles()}


@contextlib.contextmanager
def pinned_blas(n: int | None):
    """Run with `n` BLAS threads in every loaded OpenBLAS (None: leave them as they are)."""
    handles = _openblas_handles() if n is not None else []
    before = [int(get()) for _, _, get in handles]
    for _, set_, _ in handles:
        set_(ctypes.c_int(n))
    try:
        yield
    finally:
        for (_, set_, _), b in zip(handles, before):
            set_(ctypes.c_int(b))


# ---------------------------------------------------------------------- 1. diagnose end to end
def _run_diagnose(sim, repeats: int, repeat_limit: float):
    walls, cpus, diag = [], [], None
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        d = diagnose(model(), sim.trial)
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
        diag = diag or d
        if walls[0] > repeat_limit:
            break
    return walls, cpus, diag


def diagnose_row(frames: int, effect: str | None, repeats: int, repeat_limit: float,
                 default_threads: dict | None = None) -> dict:
    """Median time of `repeats` diagnoses of one trial (in the current BLAS setting), what they found, and
    with `default_threads` ({library: threads} as found at start) one more run with those threads."""
    sim = trial(frames, effect)
    walls, cpus, diag = _run_diagnose(sim, repeats, repeat_limit)
    injected = sim.settings.get("effect")
    found = [s.name for s in diag.steps]
    wall = _median(walls)
    row = {"effect": effect or "none", "frames": frames,
           "injected_where": None if injected is None else injected["where"],
           "wall_s": wall, "cpu_s": _median(cpus), "all_wall_s": walls, "all_cpu_s": cpus, "repeats": len(walls),
           "blas_threads": blas_threads(),
           "effects_found": found, "where_found": [plain(s.where) for s in diag.steps],
           "found_injected": (found == []) if effect is None else (effect in found),
           "gap_before_mm": diag.gap_before, "gap_after_mm": diag.gap_after, "noise_floor_mm": diag.noise_floor,
           "noise_sigma_mm": float(diag.ctx.noise.sigma_mm), "pass": wall < TARGET_S}
    if default_threads:
        n = max(default_threads.values())
        with pinned_blas(n):
            w2, c2, d2 = _run_diagnose(sim, 1, 0.0)
        found2 = [s.name for s in d2.steps]
        row["default_threads"] = {"blas_threads": n, "wall_s": w2[0], "cpu_s": c2[0], "effects_found": found2,
                                  "same_result": found2 == found and abs(d2.gap_after - diag.gap_after) < 1e-6,
                                  "gap_after_mm": d2.gap_after, "pass": w2[0] < TARGET_S}
    return row




# ---------------------------------------------------------------------- profile of one row
STAGES = {  # stage -> (file suffix, function names); cumulative times, summed
    "start: noise floor + rigid fit": ("diagnose/workflow.py", ("start",)),
    "  noise floor": ("estimate/noise.py", ("noise_floor",)),
    "consistency test": ("bundle/hypothesis.py", ("consistency",)),
    "propose (all effects)": ("effects/", ("propose",)),
    "apply = refit (all effects)": ("effects/", ("apply",)),
    "identifiability check (undetermined)": ("diagnose/workflow.py", ("undetermined",)),
    "polish adopted": ("bundle/hypothesis.py", ("polish",)),
    "standard-error guard (worst_sd)": ("diagnose/workflow.py", ("worst_sd",)),
    "evidence for figures": ("effects/", ("evidence",)),
    "fit_chain (all calls)": ("bundle/chain.py", ("fit_chain",)),
    "  _normal (normal equations)": ("bundle/chain.py", ("_normal",)),
    "  _jacobians": ("bundle/jacobian.py", ("jacobian_blocks",)),
    "  Jacobian blocks formed (the fit's within _normal)": ("bundle/jacobian.py", ("block",)),
}


def profile_row(frames: int, effect: str | None, top: int = 10) -> dict:
    sim = trial(frames, effect)
    prof = cProfile.Profile()
    t = time.perf_counter()
    prof.enable()
    diagnose(model(), sim.trial)
    prof.disable()
    wall = time.perf_counter() - t
    st = pstats.Stats(prof)
    st.sort_stats("cumulative")
    rows = []
    for fn in st.fcn_list[:top]:
        cc, nc, tt, ct, _ = st.stats[fn]
        rows.append({"function": _fname(fn), "ncalls": nc, "tottime_s": tt, "cumtime_s": ct})
    stages = {name: sum(v[3] for fn, v in st.stats.items()
                        if suffix in fn[0].replace(os.sep, "/") and fn[2] in names)
              for name, (suffix, names) in STAGES.items()}
    per_effect = {}
    for fn, v in st.stats.items():
        path = fn[0].replace(os.sep, "/")
        if "diagnose/effects/" in path and fn[2] == "apply":
            per_effect[Path(path).stem] = v[3]
    return {"effect": effect or "none", "frames": frames, "wall_s_profiled": wall, "top_cumulative": rows,
            "stages_s": stages, "apply_s_per_effect": dict(sorted(per_effect.items(), key=lambda kv: -kv[1]))}


def _fname(fn) -> str:
    path, line, name = fn
    if path == "~":
        return name
    p = Path(path)
    try:
        p = p.relative_to(ROOT)
    except ValueError:
        p = Path(*p.parts[-2:])
    return f"{p}:{line}({name})"


# ---------------------------------------------------------------------- 2. scipy least_squares
class _Deadline(Exception):
    pass


class ScipyChain:
    """The rigid whole-chain problem as a parameter vector for ``scipy.optimize.least_squares``.

    ``x = [per-frame block (F, k) row by row, constants (P,)]``, all zero at the starting state:
    per frame the root's rotation vector (on the left of the start's rotation, world frame) and
    translation increment, then per joint in chain order a ball joint's rotation vector (on the left
    of the start's relative rotation) or a hinge-angle increment; constants: marker-position
    increments (3M), then per joint the centre increments in parent and child (6) and for a hinge
    the rest rotation's rotation vector (on the left) and the axis step in its tangent plane (5).
    """

    def __init__(self, chain: Skeleton, start: State, data: np.ndarray):
        self.chain, self.s0 = chain, start
        self.F, self.k, self.M = start.root_R.shape[0], chain.frame_dof(), chain.n_markers
        self.P = 3 * self.M + sum(6 + (5 if chain.types[j] == "revolute" else 0) for j in chain.joints)
        self.tangents = {j: tangents(start.axis[j]) for j in chain.joints if chain.types[j] == "revolute"}
        self.seen = np.all(np.isfinite(data), axis=2)                  # (F, M)
        self.mask = np.repeat(self.seen[..., None], 3, axis=2)          # (F, M, 3)
        self.y = np.where(self.mask, data, 0.0)[self.mask]
        self.terms = Terms()
        self.deadline = math.inf
        self.nfev = 0

    @property
    def n(self) -> int:
        return self.F * self.k + self.P

    def state(self, x: np.ndarray) -> State:
        c, s0, F, k, M = self.chain, self.s0, self.F, self.k, self.M
        q, p = x[:F * k].reshape(F, k), x[F * k:]
        exp = lambda w: Rotation.from_rotvec(w).as_matrix()  # noqa: E731
        s = State(s0.local + p[:3 * M].reshape(M, 3), {}, {}, {}, {}, exp(q[:, :3]) @ s0.root_R,
                  s0.root_t + q[:, 3:6], {}, {})
        col, o = 6, 3 * M
        for j in c.joints:
            s.c_parent[j] = s0.c_parent[j] + p[o:o + 3]
            s.c_child[j] = s0.c_child[j] + p[o + 3:o + 6]
            o += 6
            if c.types[j] == "spherical":
                s.rel_R[j] = exp(q[:, col:col + 3]) @ s0.rel_R[j]
                col += 3
            else:
                s.theta[j] = s0.theta[j] + q[:, col]
                col += 1
                s.rest[j] = exp(p[o:o + 3]) @ s0.rest[j]
                b1, b2 = self.tangents[j]
                a = s0.axis[j] + p[o + 3] * b1 + p[o + 4] * b2
                s.axis[j] = a / np.linalg.norm(a)
                o += 5
        return s

    def residuals(self, x: np.ndarray) -> np.ndarray:
        self.nfev += 1
        if time.perf_counter() > self.deadline:
            raise _Deadline
        pred = forward(self.chain, self.terms, self.state(x))[3]
        return pred[self.mask] - self.y

    def sparsity(self):
        """Residual rows of frame f depend on that frame's k columns and on every constant column."""
        F, k, P = self.F, self.k, self.P
        frame = np.broadcast_to(np.arange(F)[:, None, None], self.mask.shape)[self.mask]   # frame of each row
        n = frame.size
        rows = np.concatenate([np.repeat(np.arange(n), k), np.repeat(np.arange(n), P)])
        cols = np.concatenate([(frame[:, None] * k + np.arange(k)).ravel(), np.tile(F * k + np.arange(P), n)])
        return coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, self.n)).tocsr()

    def solve(self, tol: float, cap_s: float) -> dict:
        self.nfev = 0
        t = time.perf_counter()
        self.deadline = t + cap_s
        try:
            res = least_squares(self.residuals, np.zeros(self.n), method="trf", jac_sparsity=self.sparsity(),
                                x_scale="jac", ftol=tol, xtol=tol, gtol=tol)
        except _Deadline:
            return {"capped": True, "wall_s": None, "cap_s": cap_s, "nfev_before_cap": self.nfev, "tol": tol}
        finally:
            self.deadline = math.inf
        wall = time.perf_counter() - t
        rss = float(np.sum(res.fun ** 2))
        check = self.state(res.x)
        pred = forward(self.chain, self.terms, check)[3]
        return {"capped": False, "wall_s": wall, "rss": rss,
                "rss_forward": float(np.sum((pred[self.mask] - self.y) ** 2)),
                "nfev": int(res.nfev), "njev": int(res.njev or 0), "status": int(res.status),
                "converged": bool(res.status > 0), "message": res.message, "tol": tol,
                "evals_per_jacobian": self.k + self.P}


def lm_fit(frames: int, repeats: int) -> dict:
    m = model()
    chain = Skeleton.from_model(m)
    data = rigid(frames).trial.select(m.markers).as_array()
    start = initial_state(chain, data)
    walls, fit = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        fit = fit_chain(chain, data, start)
        walls.append(time.perf_counter() - t)
    return {"frames": frames, "wall_s": _median(walls), "all_wall_s": walls, "iterations": fit.iterations,
            "s_per_iteration": _median(walls) / max(fit.iterations, 1), "rss": fit.rss, "gap_mm": fit.gap,
            "converged": fit.converged, "_chain": chain, "_data": data, "_start": start}


def scipy_row(lm: dict, cap_s: float, tols: dict) -> dict:
    prob = ScipyChain(lm["_chain"], lm["_start"], lm["_data"])
    row = {"frames": lm["frames"], "unknowns": prob.n, "residuals": int(prob.mask.sum()),
           "lm": {k: v for k, v in lm.items() if not k.startswith("_")}, "scipy": {}}
    for name, tol in tols.items():
        r = prob.solve(tol, cap_s)
        if not r["capped"]:
            r["rel_rss_diff"] = (r["rss"] - lm["rss"]) / lm["rss"]
            r["time_ratio_vs_lm"] = r["wall_s"] / lm["wall_s"]
        row["scipy"][name] = r
    return row


# ---------------------------------------------------------------------- tables
def _fmt_s(x, cap=None):
    return f"> {cap:g}" if x is None else f"{x:.2f}"


def table(doc: dict) -> str:
    out = []
    st = doc["settings"]
    out.append(f"1. diagnose end to end: {MODEL}, {st['frames']} frames at {RATE_HZ:g} Hz, noise {NOISE_MM} mm, "
               f"target {TARGET_S:g} s per row")
    dflt = any("default_threads" in r for r in doc["rows"])
    nthr = max(st["blas_threads_used"].values(), default=None)
    head = (f"{'effect':<19} {'wall s':>7} {'n':>2} {'cpu s':>7}  {'found':<26} {'gap before':>10} "
            f"{'gap after':>9} {'floor':>6}  {'5 s':<4}")
    if dflt:
        head += f" | {'default BLAS s':>14} {'5 s':<4} {'same':<4}"
    out += [head, "-" * len(head)]
    for r in doc["rows"]:
        found = ",".join(r["effects_found"]) or "-"
        mark = "" if r["found_injected"] else " (!)"
        line = (f"{r['effect']:<19} {r['wall_s']:>7.2f} {r['repeats']:>2} {r['cpu_s']:>7.2f}  "
                f"{(found + mark):<26} {r['gap_before_mm']:>10.3f} {r['gap_after_mm']:>9.3f} "
                f"{r['noise_floor_mm']:>6.3f}  {'PASS' if r['pass'] else 'FAIL':<4}")
        if "default_threads" in r:
            d = r["default_threads"]
            line += (f" | {d['wall_s']:>14.2f} {'PASS' if d['pass'] else 'FAIL':<4} "
                     f"{'yes' if d['same_result'] else 'NO':<4}")
        out.append(line)
    n_pass = sum(r["pass"] for r in doc["rows"])
    out.append(f"{n_pass}/{len(doc['rows'])} rows under {TARGET_S:g} s with {nthr} BLAS thread(s); wall = median of "
               "the repeats (n); (!) = the injected effect not among those found")
    if dflt:
        n2 = sum(r["default_threads"]["pass"] for r in doc["rows"])
        found_thr = max(st["blas_threads_found"].values(), default=None)
        out.append(f"default BLAS = one run with {found_thr} BLAS threads (as numpy/scipy start, as the CLI runs): "
                   f"{n2}/{len(doc['rows'])} under {TARGET_S:g} s; same = the same effects and gap as pinned")
    out.append("")
    out.append("2. core fit: fit_chain (LM + Schur) vs scipy least_squares(trf, jac_sparsity, x_scale='jac'), "
               "same start")
    names = list(st["scipy_tols"])
    head = f"{'frames':>6} {'unknowns':>8} {'LM s':>7} {'it':>3} {'LM RSS mm2':>13}"
    for n in names:
        head += f" | {'scipy ' + n + ' s':>16} {'nfev':>5} {'rel dRSS':>9} {'x LM':>7}"
    out += [head, "-" * len(head)]
    for r in doc["scipy_compare"]:
        line = (f"{r['frames']:>6} {r['unknowns']:>8} {r['lm']['wall_s']:>7.3f} {r['lm']['iterations']:>3} "
                f"{r['lm']['rss']:>13.6f}")
        for n in names:
            s = r["scipy"][n]
            if s["capped"]:
                line += f" | {'> ' + format(s['cap_s'], 'g'):>16} {'-':>5} {'-':>9} {'-':>7}"
            else:
                line += (f" | {s['wall_s']:>16.2f} {s['nfev']:>5} {s['rel_rss_diff']:>9.1e} "
                         f"{s['time_ratio_vs_lm']:>6.1f}x")
        out.append(line)
    out.append("  " + "; ".join(f"scipy {n}: ftol = xtol = gtol = {t:g}" for n, t in st["scipy_tols"].items())
               + f"; cap {st['scipy_cap_s']:g} s; rel dRSS = (scipy - LM) / LM")
    out.append("")
    out.append("3. fit_chain alone vs frames (rigid trial, from initial_state)")
    head = f"{'frames':>6} {'wall s':>8} {'it':>3} {'s/iter':>8} {'ms/iter per 1000 frames':>24}"
    out += [head, "-" * len(head)]
    for r in doc["fit_scaling"]["rows"]:
        out.append(f"{r['frames']:>6} {r['wall_s']:>8.3f} {r['iterations']:>3} {r['s_per_iteration']:>8.4f} "
                   f"{1e6 * r['s_per_iteration'] / r['frames']:>24.1f}")
    out.append(f"log-log slope of s/iter vs frames: {doc['fit_scaling']['slope_per_iteration']:.2f} "
               f"(total time: {doc['fit_scaling']['slope_total']:.2f}); 1 = linear")
    prof = doc.get("profile")
    if prof:
        out.append("")
        out.append(f"profile of the {prof['effect']!r} row ({prof['frames']} frames, {prof['wall_s_profiled']:.1f} s "
                   "under cProfile): top functions by cumulative time")
        head = f"{'cum s':>8} {'own s':>8} {'calls':>6}  function"
        out += [head, "-" * 60]
        for r in prof["top_cumulative"]:
            out.append(f"{r['cumtime_s']:>8.2f} {r['tottime_s']:>8.2f} {r['ncalls']:>6}  {r['function']}")
        out.append("stages (cumulative s): " + "; ".join(f"{k.strip()} {v:.2f}" for k, v in prof["stages_s"].items()))
        out.append("apply (refit) per effect (s): " + ", ".join(f"{k} {v:.2f}" for k, v in
                                                               prof["apply_s_per_effect"].items()))
    return "\n".join(out)


def _slope(xs, ys) -> float:
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


# ---------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help=f"{QUICK['frames']} frames, one repeat, effects {QUICK['effects'][1:]}, scipy at "
                         f"{QUICK['scipy_frames']} frames, fit_chain at {QUICK['fit_frames']}, no run with the "
                         "default BLAS threads; stored under diagnose_quick")
    ap.add_argument("--repeats", type=int, default=None, help="runs per diagnose row (default 3; 1 for --quick)")
    ap.add_argument("--repeat-limit-s", type=float, default=60.0,
                    help="a diagnose row whose first run takes longer than this is timed once (default 60)")
    ap.add_argument("--blas-threads", type=int, default=1,
                    help="BLAS threads for every measurement (default 1, as the tests pin them; 0 = leave as found)")
    ap.add_argument("--default-threads", action=argparse.BooleanOptionalAction, default=None,
                    help="also run each diagnose row once with the BLAS threads as found at start, the way "
                         "`identcheck diagnose` runs (default: on, off for --quick)")
    ap.add_argument("--scipy-cap-s", type=float, default=120.0, help="stop a scipy run after this long (default 120)")
    ap.add_argument("--profile", default=None,
                    help="effect whose diagnose row to run once more under cProfile: a name, 'rigid' (no effect), "
                         "'auto' (the slowest row) or 'none' (default auto, none for --quick)")
    ap.add_argument("--effects", default=None, help="comma-separated effects to run ('none' = the rigid trial)")
    ap.add_argument("--out", type=Path, default=None, help="JSON to update (default benchmarks/results.json)")
    args = ap.parse_args(argv)
    cfg = dict(QUICK if args.quick else FULL)
    if args.repeats is not None:
        cfg["repeats"] = args.repeats
    if args.effects:
        cfg["effects"] = tuple(None if e == "none" else e for e in args.effects.split(","))
    if args.profile is not None:
        cfg["profile"] = None if args.profile == "none" else args.profile
    default_run = (not args.quick) if args.default_threads is None else args.default_threads
    key = KEY + ("_quick" if args.quick else "")
    out = args.out or RESULTS
    model()
    found_threads = blas_threads()                  # as numpy and scipy start: what the CLI runs with
    load_before = [round(x, 2) for x in os.getloadavg()]
    t_all = time.perf_counter()

    with pinned_blas(args.blas_threads or None):
        rows = []
        for eff in cfg["effects"]:
            rows.append(diagnose_row(cfg["frames"], eff, cfg["repeats"], args.repeat_limit_s,
                                     found_threads if default_run else None))
            r = rows[-1]
            extra = (f"; {r['default_threads']['blas_threads']} BLAS threads: {r['default_threads']['wall_s']:.2f} s"
                     if "default_threads" in r else "")
            print(f"  diagnose {r['effect']}: {r['wall_s']:.2f} s ({r['repeats']} run(s)), found "
                  f"{r['effects_found']}{extra}", flush=True)

        sizes = sorted(set(cfg["fit_frames"]) | set(cfg["scipy_frames"]))
        lm = {}
        for f in sizes:
            lm[f] = lm_fit(f, cfg["repeats"])
            print(f"  fit_chain {f} frames: {lm[f]['wall_s']:.3f} s, {lm[f]['iterations']} iterations", flush=True)
        compare = []
        for f in cfg["scipy_frames"]:
            compare.append(scipy_row(lm[f], args.scipy_cap_s, SCIPY_TOLS))
            print(f"  scipy {f} frames: " + ", ".join(
                f"{n} {'capped' if s['capped'] else format(s['wall_s'], '.2f') + ' s'}"
                for n, s in compare[-1]["scipy"].items()), flush=True)
        fit_rows = [{k: v for k, v in lm[f].items() if not k.startswith("_")} for f in cfg["fit_frames"]]
        fr = [r["frames"] for r in fit_rows]
        scaling = {"rows": fit_rows,
                   "slope_per_iteration": _slope(fr, [r["s_per_iteration"] for r in fit_rows]),
                   "slope_total": _slope(fr, [r["wall_s"] for r in fit_rows])}

        profile = None
        if cfg["profile"]:
            name = cfg["profile"]
            if name == "auto":
                name = max(rows, key=lambda r: r["wall_s"])["effect"]
            eff = None if name in ("rigid", "none") else name
            print(f"  profiling the {name} row", flush=True)
            profile = profile_row(cfg["frames"], eff)
        threads_used = blas_threads()

    doc = {"description": __doc__.split("\n\n")[0],
           "date": datetime.datetime.now().isoformat(timespec="seconds"),
           "total_s": time.perf_counter() - t_all,
           "rows": rows, "target_s": TARGET_S, "n_pass": sum(r["pass"] for r in rows),
           "scipy_compare": compare, "fit_scaling": scaling, "profile": profile,
           "settings": {"quick": args.quick, "model": MODEL, "frames": cfg["frames"], "rate_hz": RATE_HZ,
                        "noise_mm": NOISE_MM, "occlusion": 0.0, "sim_seed": SIM_SEED, "effect_seed": EFFECT_SEED,
                        "effects": [e or "none" for e in cfg["effects"]], "repeats": cfg["repeats"],
                        "repeat_limit_s": args.repeat_limit_s, "scipy_frames": list(cfg["scipy_frames"]),
                        "fit_frames": list(cfg["fit_frames"]), "scipy_cap_s": args.scipy_cap_s,
                        "scipy_tols": SCIPY_TOLS, "fit_chain_rel_tol": REL_TOL,
                        "blas_threads_found": found_threads, "blas_threads_used": threads_used,
                        "default_threads_run": default_run,
                        "scipy_call": "least_squares(fun, 0, method='trf', jac_sparsity=S, x_scale='jac', "
                                      "ftol=tol, xtol=tol, gtol=tol) (2-point finite differences, lsmr)",
                        "timing": "time.perf_counter (wall) and time.process_time (CPU, all threads); median of "
                                  "the repeats"},
           "machine": machine_info(loadavg_before=load_before,
                                   blas_env={k: os.environ.get(k) for k in BLAS_ENV})}
    print()
    print(table(doc))
    print(f"\ntotal {doc['total_s']:.1f} s; load average before {load_before}, after "
          f"{[round(x, 2) for x in os.getloadavg()]}")
    write_json(out, key, doc)
    print(f"wrote {out} (key {key!r})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
