#!/usr/bin/env python3
"""heldout v1 -- independent synthetic lower-limb motion-capture trials.

    python benchmarks/heldout/generator.py --out DIR --n 240 --seed 7

Writes DIR/index.json and, per trial, trial_XXXX.trc / .toml / .truth.json.
See README.md in this folder for the simulated world.  Only numpy, scipy and the
standard library are used.  Everything is reproducible from --seed: trial i draws
from independent random streams SeedSequence(seed, spawn_key=(i, k)), one per
concern (geometry, motion, soft tissue, measurement noise, gaps), so a trial can be
rebuilt with the noise switched off (see build_trial(level=...)).
"""
import argparse
import json
import os
import time

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator
from scipy.ndimage import gaussian_filter1d
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

GENERATOR = "heldout v1"
FS = 100.0
NOISES = ("white", "ar1", "soft_tissue")
MARKERSETS = ("full", "2+2", "minimal")
MOTIONS = ("functional", "gait")
CATEGORIES = [(ms, mo, no) for no in NOISES for ms in MARKERSETS for mo in MOTIONS]
STREAMS = ("geom", "motion", "sta", "noise", "gaps")
MIN_JOINT_CLEARANCE = 30.0   # mm, marker to joint centre / hinge axis
MIN_MARKER_SEPARATION = 40.0  # mm, between markers of one segment


# ----------------------------------------------------------------------------- helpers
def streams(seed, index):
    return {nm: np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, k)))
            for k, nm in enumerate(STREAMS)}


def smooth_noise(rng, n, cutoff_hz):
    """Zero-mean, unit-std, low-pass (Gaussian) noise of length n."""
    sig = FS / (2 * np.pi * cutoff_hz)
    pad = int(4 * sig) + 1
    x = gaussian_filter1d(rng.standard_normal(n + 2 * pad), sig)[pad:pad + n]
    x = x - x.mean()
    return x / x.std()


def tilted_axis(rng, max_deg):
    """Unit vector within max_deg of +z (uniform over the cap's projected disc)."""
    tau = np.radians(max_deg) * np.sqrt(rng.uniform())
    beta = rng.uniform(0, 2 * np.pi)
    n = np.array([np.sin(tau) * np.cos(beta), np.sin(tau) * np.sin(beta), np.cos(tau)])
    return n, float(np.degrees(tau))


def dist_to_line(m, a, n):
    v = np.asarray(m, float) - a
    return float(np.linalg.norm(v - (v @ n) * n))


def dist_to_point(m, c):
    return float(np.linalg.norm(np.asarray(m, float) - c))


def _ok(pts, clearance_fns):
    for p in pts:
        if any(f(p) < MIN_JOINT_CLEARANCE for f in clearance_fns):
            return False
    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            if np.linalg.norm(pts[i] - pts[j]) < MIN_MARKER_SEPARATION:
                return False
    if len(pts) >= 3:  # not (nearly) collinear
        sv = np.linalg.svd(pts - pts.mean(0), compute_uv=False)
        if sv[1] < 15.0:
            return False
    return True


def limb_markers(rng, count, length, clearance_fns, f_range, r_range, az_range):
    """Skin markers around the bone line (the segment's -y axis), spread along it.
    Azimuth 0 = lateral (+z), +90 deg = anterior (+x)."""
    lo, hi = f_range
    edges = np.linspace(lo, hi, count + 1)
    for _ in range(10000):
        f = np.array([rng.uniform(edges[k], edges[k + 1]) for k in range(count)])
        az = np.radians(rng.uniform(*az_range, size=count))
        r = rng.uniform(*r_range, size=count)
        pts = np.column_stack([r * np.sin(az), -f * length, r * np.cos(az)])
        if _ok(pts, clearance_fns):
            return pts
    raise RuntimeError("could not place markers")


PELVIS_CANDIDATES = {
    "RASI": lambda g: [g.uniform(-8, 8), g.uniform(-6, 6), g.uniform(105, 130)],
    "LASI": lambda g: [g.uniform(-8, 8), g.uniform(-6, 6), -g.uniform(105, 130)],
    "RPSI": lambda g: [-g.uniform(140, 175), g.uniform(15, 35), g.uniform(35, 50)],
    "LPSI": lambda g: [-g.uniform(140, 175), g.uniform(15, 35), -g.uniform(35, 50)],
    "SACR": lambda g: [-g.uniform(150, 190), g.uniform(5, 25), g.uniform(-6, 6)],
    "RICR": lambda g: [-g.uniform(40, 70), g.uniform(60, 85), g.uniform(125, 150)],
}


def pelvis_markers(rng, count, hip_centre):
    names_all = list(PELVIS_CANDIDATES)
    for _ in range(10000):
        names = [names_all[k] for k in sorted(rng.choice(len(names_all), count, replace=False))]
        pts = np.array([PELVIS_CANDIDATES[nm](rng) for nm in names], float)
        if _ok(pts, [lambda p: dist_to_point(p, hip_centre)]):
            return names, pts
    raise RuntimeError("could not place pelvis markers")


# ----------------------------------------------------------------------------- geometry
def make_geometry(rng, markerset):
    g = {}
    # pelvis frame: origin mid-way between the two ASIS landmarks, x anterior,
    # y superior, z to the right (ISB-like).  Right hip centre:
    g["hip_centre"] = np.array([-rng.uniform(20, 40), -rng.uniform(60, 90), rng.uniform(70, 95)])
    g["thigh_length"] = rng.uniform(370, 470)
    g["shank_length"] = rng.uniform(350, 440)
    # thigh frame: origin at hip centre, axes parallel to the pelvis frame at zero hip
    # angles; bone line along -y.  Knee hinge: point near the distal end, axis ~ +z.
    g["knee_point"] = np.array([rng.uniform(-10, 10), -g["thigh_length"], rng.uniform(-8, 8)])
    g["knee_axis"], g["knee_tilt_deg"] = tilted_axis(rng, 10.0)
    # shank frame: origin at knee_point, parallel to the thigh frame at zero knee angle.
    g["ankle_point"] = np.array([rng.uniform(-10, 10), -g["shank_length"], rng.uniform(-6, 6)])
    g["ankle_axis"], g["ankle_tilt_deg"] = tilted_axis(rng, 20.0)
    g["has_foot"] = bool(markerset == "full" and rng.uniform() < 0.5)

    if markerset == "full":
        counts = dict(pelvis=int(rng.integers(3, 5)), thigh=int(rng.integers(3, 5)),
                      shank=int(rng.integers(3, 5)), foot=3)
    elif markerset == "2+2":
        counts = dict(pelvis=2, thigh=2, shank=3)
    else:
        counts = dict(pelvis=3, thigh=1, shank=1)
    if not g["has_foot"]:
        counts.pop("foot", None)

    hc, kp, ka = g["hip_centre"], g["knee_point"], g["knee_axis"]
    ap, aa = g["ankle_point"], g["ankle_axis"]
    seg = {}
    names, pts = pelvis_markers(rng, counts["pelvis"], hc)
    seg["pelvis"] = (names, pts)
    pts = limb_markers(rng, counts["thigh"], g["thigh_length"],
                       [lambda p: dist_to_point(p, np.zeros(3)), lambda p: dist_to_line(p, kp, ka)],
                       (0.15, 0.85), (40, 80), (-60, 120))
    seg["thigh"] = ([f"RTH{k + 1}" for k in range(len(pts))], pts)
    sh_clear = [lambda p: dist_to_line(p, np.zeros(3), ka)]
    if g["has_foot"]:
        sh_clear.append(lambda p: dist_to_line(p, ap, aa))
    pts = limb_markers(rng, counts["shank"], g["shank_length"], sh_clear,
                       (0.15, 0.85), (40, 70), (-60, 150))
    seg["shank"] = ([f"RSH{k + 1}" for k in range(len(pts))], pts)
    if g["has_foot"]:
        # foot frame: origin at ankle_point, parallel to the shank frame at zero ankle angle
        for _ in range(10000):
            pts = np.array([
                [-rng.uniform(40, 65), -rng.uniform(25, 50), rng.uniform(-10, 10)],   # heel
                [rng.uniform(130, 175), -rng.uniform(35, 60), rng.uniform(-15, 15)],  # toe
                [rng.uniform(60, 95), -rng.uniform(35, 55), rng.uniform(30, 45)],     # 5th MT head
            ])
            if _ok(pts, [lambda p: dist_to_line(p, np.zeros(3), aa)]):
                break
        seg["foot"] = (["RHEE", "RTOE", "RMT5"], pts)
    g["segments"] = seg
    return g


def joints_of(g):
    js = [("hip", "spherical", "pelvis", "thigh"), ("knee", "revolute", "thigh", "shank")]
    if g["has_foot"]:
        js.append(("ankle", "revolute", "shank", "foot"))
    return js


def truth_distances(g):
    seg = g["segments"]
    out = {}
    d = {}
    for nm, p in zip(*seg["pelvis"]):
        d[nm] = dist_to_point(p, g["hip_centre"])
    for nm, p in zip(*seg["thigh"]):
        d[nm] = dist_to_point(p, np.zeros(3))
    out["hip"] = d
    d = {}
    for nm, p in zip(*seg["thigh"]):
        d[nm] = dist_to_line(p, g["knee_point"], g["knee_axis"])
    for nm, p in zip(*seg["shank"]):
        d[nm] = dist_to_line(p, np.zeros(3), g["knee_axis"])
    out["knee"] = d
    if g["has_foot"]:
        d = {}
        for nm, p in zip(*seg["shank"]):
            d[nm] = dist_to_line(p, g["ankle_point"], g["ankle_axis"])
        for nm, p in zip(*seg["foot"]):
            d[nm] = dist_to_line(p, np.zeros(3), g["ankle_axis"])
        out["ankle"] = d
    return out


# ----------------------------------------------------------------------------- motion
def _window_weights(rng, n, k_blocks, n_types, taper_s=0.6):
    """Smooth partition of unity over n frames: k blocks, each assigned a type."""
    cuts = np.sort(rng.uniform(0.1, 0.9, k_blocks - 1)) * n
    edges = np.concatenate([[0], cuts, [n]]).astype(int)
    types = rng.permutation(np.resize(rng.permutation(n_types), k_blocks))
    w = np.zeros((n, n_types))
    for b in range(k_blocks):
        w[edges[b]:edges[b + 1], types[b]] = 1.0
    w = gaussian_filter1d(w, taper_s * FS / 2, axis=0, mode="nearest")
    return w / w.sum(1, keepdims=True), [int(t) for t in types]


def _irregular_phase(rng, n, f0, spread, cutoff=0.08):
    f = f0 * np.exp(spread * smooth_noise(rng, n, cutoff))
    return 2 * np.pi * np.cumsum(f) / FS + rng.uniform(0, 2 * np.pi)


def functional_motion(rng, n, leg_mm):
    t = np.arange(n) / FS
    info = {}
    A_f, A_a, A_r = rng.uniform(30, 45), rng.uniform(15, 30), rng.uniform(10, 20)
    f0 = rng.uniform(0.25, 0.55)
    ph = _irregular_phase(rng, n, f0, 0.35)
    k_blocks = int(rng.integers(3, 6))
    w, types = _window_weights(rng, n, k_blocks, 5)
    circ_sign = rng.choice([-1.0, 1.0])
    c1, c2, c3 = rng.uniform(0, 2 * np.pi, 3)
    s, c = np.sin(ph), np.cos(ph)
    # unit patterns (flex, abd, rot) per type: flex/ext, abd/add, rotation, circumduction, mixed
    pat = np.zeros((n, 5, 3))
    pat[:, 0] = np.column_stack([s, 0.15 * np.sin(ph + c1), 0.1 * np.sin(ph + c2)])
    pat[:, 1] = np.column_stack([0.15 * np.sin(ph + c3), s, 0.1 * np.sin(ph + c1)])
    pat[:, 2] = np.column_stack([0.2 * np.sin(ph + c2), 0.15 * np.sin(ph + c3), s])
    pat[:, 3] = np.column_stack([c, circ_sign * s, 0.3 * np.sin(2 * ph + c1)])
    pat[:, 4] = np.column_stack([s, 0.7 * np.sin(2 * ph + c2), 0.7 * np.sin(ph + c3)])
    hip = np.einsum("nk,nkd->nd", w, pat) * np.array([A_f, A_a, A_r])
    hip += np.column_stack([rng.uniform(1, 2.5) * smooth_noise(rng, n, 0.3) for _ in range(3)])
    k_lo, k_hi = rng.uniform(5, 10), rng.uniform(70, 90)
    phk = _irregular_phase(rng, n, rng.uniform(0.15, 0.45), 0.35)
    knee = k_lo + (k_hi - k_lo) * (0.5 - 0.5 * np.cos(phk))
    A_an = rng.uniform(15, 20)
    ankle = A_an * np.sin(_irregular_phase(rng, n, rng.uniform(0.2, 0.6), 0.35))
    # pelvis: standing, swaying a little
    psi0 = rng.uniform(0, 2 * np.pi)
    # pelvis height: leg length (ASIS level to ankle axis, straight) + ankle height
    p0 = np.array([rng.uniform(-300, 300), leg_mm + rng.uniform(100, 140), rng.uniform(-300, 300)])
    sway_mm = rng.uniform(2, 6, 3)
    sway_deg = rng.uniform(1, 3, 3)
    pp = p0 + np.column_stack([sway_mm[k] * smooth_noise(rng, n, 0.3) for k in range(3)])
    ang = np.column_stack([sway_deg[k] * smooth_noise(rng, n, 0.3) for k in range(3)])
    Rp = Rotation.from_euler("YZX", np.column_stack([np.degrees(psi0) + ang[:, 0], ang[:, 1], ang[:, 2]]),
                             degrees=True).as_matrix()
    info.update(pelvis_height_mm=p0[1], hip_flex_amp_deg=A_f, hip_abd_amp_deg=A_a, hip_rot_amp_deg=A_r,
                base_freq_hz=f0, blocks=k_blocks,
                block_types=[["flexext", "abdadd", "rotation", "circumduction", "mixed"][k] for k in types],
                knee_range_deg=[k_lo, k_hi], ankle_amp_deg=A_an,
                pelvis_sway_mm=sway_mm.tolist(), pelvis_sway_deg=sway_deg.tolist())
    return dict(hip=hip, knee=knee, ankle=ankle, Rp=Rp, pp=pp), info


def _periodic_curve(rng, knots_s, knots_v, jitter, lo, hi):
    v = np.array(knots_v, float) + rng.uniform(-jitter, jitter, len(knots_v))
    v[-1] = v[0]
    cs = CubicSpline(knots_s, v, bc_type="periodic")
    grid = cs(np.linspace(0, 1, 1001))
    gmin, gmax = grid.min(), grid.max()
    return lambda s: lo + (hi - lo) * (cs(s) - gmin) / (gmax - gmin)


def gait_motion(rng, n, leg_mm):
    t = np.arange(n) / FS
    info = {}
    T0 = rng.uniform(1.0, 1.2)
    cv = rng.uniform(0.015, 0.04)
    bounds = [-rng.uniform(0, T0)]
    while bounds[-1] < t[-1] + 2 * T0:
        bounds.append(bounds[-1] + T0 * float(np.clip(1 + cv * rng.standard_normal(), 0.85, 1.15)))
    cyc = PchipInterpolator(np.array(bounds), np.arange(len(bounds), dtype=float))(t)
    s = np.mod(cyc, 1.0)
    two_pi_s = 2 * np.pi * cyc

    hip_f = _periodic_curve(rng, [0, .12, .3, .5, .6, .75, .87, 1], [25, 22, 8, -10, -6, 15, 28, 25], 2,
                            -rng.uniform(8, 15), rng.uniform(22, 30))
    A_abd = rng.uniform(5, 8)
    hip_a = _periodic_curve(rng, [0, .15, .45, .7, .85, 1], [0, -5, -2, 6, 3, 0], 1, -A_abd,
                            A_abd * rng.uniform(0.8, 1.0))
    A_r = rng.uniform(5, 10)
    cr1, cr2 = rng.uniform(0, 2 * np.pi, 2)
    knee_f = _periodic_curve(rng, [0, .12, .4, .6, .72, .85, .95, 1], [5, 18, 6, 38, 62, 35, 6, 5], 2,
                             rng.uniform(5, 9), rng.uniform(55, 65))
    ank_f = _periodic_curve(rng, [0, .08, .45, .62, .72, .9, 1], [0, -6, 10, -15, -8, 1, 0], 1.5,
                            -rng.uniform(12, 15), rng.uniform(8, 15))
    var_deg = rng.uniform(0.7, 2.0)

    def vary(x):  # cycle-to-cycle variability: amplitude modulation + small smooth offset
        return x * (1 + 0.05 * smooth_noise(rng, n, 0.5)) + var_deg * smooth_noise(rng, n, 0.5)

    hip = np.column_stack([vary(hip_f(s)), vary(hip_a(s)),
                           vary(A_r * np.sin(two_pi_s + cr1) + 0.3 * A_r * np.sin(2 * two_pi_s + cr2))])
    knee = np.maximum(vary(knee_f(s)), 2.0)
    ankle = vary(ank_f(s))

    # pelvis orientation (deg) and bob/sway (mm) in the heading frame
    tilt0 = rng.uniform(-3, 3)
    A_tilt, A_obl, A_prot = rng.uniform(1, 3), rng.uniform(2, 5), rng.uniform(3, 8)
    ct, co, cr = rng.uniform(0, 2 * np.pi, 3)
    tilt = tilt0 + A_tilt * np.sin(2 * two_pi_s + ct)
    obl = A_obl * np.sin(two_pi_s + co)
    prot = A_prot * np.sin(two_pi_s + cr)
    bob, lat = rng.uniform(10, 25), rng.uniform(10, 25)
    h0 = leg_mm + rng.uniform(80, 110)  # no ground contact modelled
    psi0 = rng.uniform(0, 2 * np.pi)
    v = rng.uniform(1000, 1500)  # mm/s
    mode = "treadmill" if rng.uniform() < 0.5 else "overground"
    if mode == "treadmill":
        yaw = np.full(n, psi0)
        fwd = rng.uniform(10, 30) * smooth_noise(rng, n, 0.2)
        start = np.array([rng.uniform(-300, 300), 0.0, rng.uniform(-300, 300)])
        path = start + fwd[:, None] * np.column_stack([np.cos(yaw), 0 * yaw, -np.sin(yaw)])
        info.update(belt_speed_mm_s=v)
    else:
        walk_len = rng.uniform(5000, 8000)
        Dw, Dt = walk_len / v, rng.uniform(1.2, 2.0)
        ev = np.arange(0, t[-1] + Dw + Dt + 1, Dw + Dt) - rng.uniform(0, Dw)  # walk start times
        k = np.searchsorted(ev, t, side="right") - 1
        tau = t - ev[k]
        in_turn = tau > Dw
        u = np.clip((tau - Dw) / Dt, 0, 1)
        smooth = u * u * (3 - 2 * u)
        yaw = psi0 + np.pi * (k + np.where(in_turn, smooth, 0.0))
        speed = v * np.where(in_turn, 1 - 0.7 * np.sin(np.pi * u), 1.0)
        vel = speed[:, None] * np.column_stack([np.cos(yaw), 0 * yaw, -np.sin(yaw)])
        path = np.cumsum(vel, 0) / FS
        path -= path.mean(0)
        path[:, 1] = 0
        info.update(speed_mm_s=v, walkway_mm=walk_len, turn_s=Dt)
    lat_dir = np.column_stack([np.sin(yaw), 0 * yaw, np.cos(yaw)])
    pp = path + np.array([0, h0, 0]) + (bob * np.cos(2 * two_pi_s))[:, None] * np.array([0, 1, 0]) \
        + (lat * np.sin(two_pi_s + co))[:, None] * lat_dir
    Rp = Rotation.from_euler("YZX", np.column_stack([np.degrees(yaw) + prot, tilt, obl]), degrees=True).as_matrix()
    info.update(mode=mode, pelvis_height_mm=h0, stride_s=T0, stride_cv=cv, hip_abd_amp_deg=A_abd, hip_rot_amp_deg=A_r,
                pelvis_tilt_obl_rot_amp_deg=[A_tilt, A_obl, A_prot], bob_mm=bob, lateral_sway_mm=lat,
                knee_range_deg=[float(knee.min()), float(knee.max())],
                hip_flex_range_deg=[float(hip[:, 0].min()), float(hip[:, 0].max())])
    return dict(hip=hip, knee=knee, ankle=ankle, Rp=Rp, pp=pp), info


# ----------------------------------------------------------------------------- kinematics
def segment_poses(g, mot):
    """World rotation (N,3,3) and origin (N,3) of every segment."""
    Rp, pp = mot["Rp"], mot["pp"]
    hip = mot["hip"]
    Rh = Rotation.from_euler("ZXY", np.column_stack([hip[:, 0], -hip[:, 1], hip[:, 2]]),
                             degrees=True).as_matrix()
    Rt = Rp @ Rh
    pt = pp + Rp @ g["hip_centre"]
    Rk = Rotation.from_rotvec(-np.radians(mot["knee"])[:, None] * g["knee_axis"]).as_matrix()
    Rs = Rt @ Rk
    ps = pt + Rt @ g["knee_point"]
    poses = {"pelvis": (Rp, pp), "thigh": (Rt, pt), "shank": (Rs, ps)}
    if g["has_foot"]:
        Ra = Rotation.from_rotvec(np.radians(mot["ankle"])[:, None] * g["ankle_axis"]).as_matrix()
        poses["foot"] = (Rs @ Ra, ps + Rs @ g["ankle_point"])
    return poses


def adjacent_angles(g, mot):
    """Radians of the joint angles adjacent to each segment (for soft tissue)."""
    hip = np.radians(mot["hip"])
    knee = np.radians(mot["knee"])[:, None]
    ankle = np.radians(mot["ankle"])[:, None]
    adj = {"pelvis": hip, "thigh": np.hstack([hip, knee]),
           "shank": np.hstack([knee, ankle]) if g["has_foot"] else knee}
    if g["has_foot"]:
        adj["foot"] = ankle
    return adj


def soft_tissue(rng, g, mot):
    """Per-marker displacement in its segment frame:
        d(t) = sum_j sum_{k=1,2} c_jk cos(w_jk theta_j(t) + b_jk),  c ~ N(0, I3),
    w ~ U(1, 3) /rad, b ~ U(0, 2pi); then the trial mean is removed (zero mean) and d is
    scaled so that max_t |d(t)| = A_m = A * U(0.6, 1)."""
    A = rng.uniform(2, 10)
    adj = adjacent_angles(g, mot)
    disp, peaks = {}, {}
    for sname, (names, _) in g["segments"].items():
        th = adj[sname]
        for nm in names:
            J = th.shape[1]
            c = rng.standard_normal((J, 2, 3))
            w = rng.uniform(1, 3, (J, 2))
            b = rng.uniform(0, 2 * np.pi, (J, 2))
            d = np.einsum("njk,jkd->nd", np.cos(th[:, :, None] * w + b), c)
            d -= d.mean(0)
            am = A * rng.uniform(0.6, 1.0)
            d *= am / np.linalg.norm(d, axis=1).max()
            disp[nm] = d
            peaks[nm] = am
    return disp, {"amplitude_mm": A, "peak_mm": peaks}


# ----------------------------------------------------------------------------- trial
def build_trial(seed, index, category, gaps=False, level="full"):
    """level: 'rigid' (reference markers only), 'sta' (+ soft tissue), 'full' (+ noise, gaps)."""
    markerset, motion, noise = category
    rs = streams(seed, index)
    g = make_geometry(rs["geom"], markerset)
    n = int(rs["motion"].integers(1000, 2001))
    leg = -g["hip_centre"][1] + g["thigh_length"] + g["shank_length"]
    mot, minfo = (functional_motion if motion == "functional" else gait_motion)(rs["motion"], n, leg)
    poses = segment_poses(g, mot)
    names, seg_of = [], {}
    for sname, (mn, _) in g["segments"].items():
        for nm in mn:
            names.append(nm)
            seg_of[nm] = sname
    local = {nm: p for sname, (mn, pts) in g["segments"].items() for nm, p in zip(mn, pts)}

    disp, sta_info = None, None
    if noise == "soft_tissue" and level in ("sta", "full"):
        disp, sta_info = soft_tissue(rs["sta"], g, mot)
    X = np.empty((n, len(names), 3))
    for j, nm in enumerate(names):
        R, p = poses[seg_of[nm]]
        m = local[nm] if disp is None else local[nm] + disp[nm]
        X[:, j] = p + np.einsum("nij,nj->ni", R, np.broadcast_to(m, (n, 3)))

    noise_info = {"type": noise}
    rn = rs["noise"]
    if noise == "white":
        sigma = rn.uniform(0.3, 1.2)
        noise_info.update(sigma_mm=sigma, model="iid Gaussian per marker coordinate")
        if level == "full":
            X = X + sigma * rn.standard_normal(X.shape)
    elif noise == "ar1":
        phi, sigma = rn.uniform(0.6, 0.95), rn.uniform(0.3, 1.2)
        sig_e = sigma * np.sqrt(1 - phi ** 2)
        noise_info.update(phi=phi, marginal_sigma_mm=sigma, innovation_sigma_mm=sig_e,
                          model="stationary AR(1) per marker and axis: e[t] = phi e[t-1] + w[t]")
        if level == "full":
            e = sig_e * rn.standard_normal(X.shape)
            e[0] = sigma * rn.standard_normal(X.shape[1:])
            X = X + lfilter([1.0], [1.0, -phi], e, axis=0)
    else:
        sigma = rn.uniform(0.3, 0.8)
        noise_info.update(white_sigma_mm=sigma, model="soft-tissue deformation (smooth in adjacent "
                          "joint angles, zero trial mean) + iid Gaussian")
        if sta_info is None:  # still report the amplitude (draws from its own stream)
            _, sta_info = soft_tissue(streams(seed, index)["sta"], g, mot)
        noise_info.update(soft_tissue_amplitude_mm=sta_info["amplitude_mm"],
                          soft_tissue_peak_mm=sta_info["peak_mm"])
        if level == "full":
            X = X + sigma * rn.standard_normal(X.shape)

    gap_list = []
    mask = np.zeros(X.shape[:2], bool)
    if gaps:
        rg = rs["gaps"]
        k = int(rg.integers(1, 4))
        for j in sorted(rg.choice(len(names), k, replace=False)):
            for _ in range(int(rg.integers(1, 3))):
                L = int(rg.integers(5, 41))
                st = int(rg.integers(5, n - L - 5))
                mask[st:st + L, j] = True
                gap_list.append({"marker": names[j], "first_frame": st + 1, "last_frame": st + L})
        if level == "full":
            X[mask] = np.nan
    return dict(names=names, seg_of=seg_of, X=X, n=n, geom=g, motion=mot, motion_info=minfo,
                poses=poses, noise=noise_info, gaps=gap_list, gap_mask=mask, disp=disp)


# ----------------------------------------------------------------------------- writers
def write_trc(path, names, X):
    n, m, _ = X.shape
    head = [f"PathFileType\t4\t(X/Y/Z)\t{os.path.basename(path)}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{FS:.2f}\t{FS:.2f}\t{n}\t{m}\tmm\t{FS:.2f}\t1\t{n}",
            "Frame#\tTime\t" + "\t\t\t".join(names),
            "\t\t" + "\t".join(f"X{j + 1}\tY{j + 1}\tZ{j + 1}" for j in range(m)),
            ""]
    fmt = "%d\t%.5f" + "\t%.4f" * (3 * m)
    data = np.column_stack([np.arange(1, n + 1), np.arange(n) / FS, X.reshape(n, 3 * m)])
    body = "\n".join(fmt % tuple(r) for r in data).replace("\tnan", "\t")
    with open(path, "w", newline="\n") as f:
        f.write("\n".join(head) + "\n" + body + "\n")


def write_toml(path, g):
    lines = ['units = "mm"', ""]
    for sname, (names, _) in g["segments"].items():
        lines += [f"[segments.{sname}]", "markers = [" + ", ".join(f'"{x}"' for x in names) + "]", ""]
    for jn, jt, par, ch in joints_of(g):
        lines += [f"[joints.{jn}]", f'type = "{jt}"', f'parent = "{par}"', f'child = "{ch}"', ""]
    with open(path, "w") as f:
        f.write("\n".join(lines))


def truth_doc(tr, category):
    g = tr["geom"]
    dist = truth_distances(g)
    joints = {
        "hip": {"type": "spherical", "parent": "pelvis", "child": "thigh",
                "centre_parent": g["hip_centre"].tolist(), "centre_child": [0.0, 0.0, 0.0],
                "marker_distances": dist["hip"]},
        "knee": {"type": "revolute", "parent": "thigh", "child": "shank",
                 "axis_point_parent": g["knee_point"].tolist(), "axis_direction_parent": g["knee_axis"].tolist(),
                 "axis_point_child": [0.0, 0.0, 0.0], "axis_direction_child": g["knee_axis"].tolist(),
                 "axis_tilt_from_mediolateral_deg": g["knee_tilt_deg"],
                 "marker_distances": dist["knee"]},
    }
    if g["has_foot"]:
        joints["ankle"] = {"type": "revolute", "parent": "shank", "child": "foot",
                           "axis_point_parent": g["ankle_point"].tolist(),
                           "axis_direction_parent": g["ankle_axis"].tolist(),
                           "axis_point_child": [0.0, 0.0, 0.0], "axis_direction_child": g["ankle_axis"].tolist(),
                           "axis_tilt_from_mediolateral_deg": g["ankle_tilt_deg"],
                           "marker_distances": dist["ankle"]}
    segs = {s: {"markers_local": {nm: p.tolist() for nm, p in zip(names, pts)}}
            for s, (names, pts) in g["segments"].items()}
    segs["thigh"]["length"] = g["thigh_length"]
    segs["shank"]["length"] = g["shank_length"]
    return {
        "units": "mm",
        "category": dict(zip(("markerset", "motion", "noise"), category)),
        "joints": joints,
        "segments": segs,
        "noise": tr["noise"],
        "gaps": tr["gaps"],
        "frames": tr["n"], "rate_hz": FS,
        "notes": ("Frames: pelvis origin mid-way between the ASIS landmarks, x anterior, y superior, "
                  "z right. thigh origin = hip centre, shank origin = knee axis point, foot origin = "
                  "ankle axis point; each child frame coincides in orientation with its parent at zero "
                  "joint angles. Distances use the markers' reference positions (markers_local; "
                  "for soft_tissue = position at zero deformation = the trial-mean position on the "
                  "segment). Right limb; marker_distances lists parent and child markers."),
    }


# ----------------------------------------------------------------------------- plan / main
def plan(seed, n):
    # round-robin over the 18 categories; the k-th trial of category c gets occlusion gaps
    # when k % 3 == c % 3 (staggered, so about a third of the trials for any n)
    nc = len(CATEGORIES)
    items = [(CATEGORIES[i % nc], (i // nc) % 3 == (i % nc) % 3) for i in range(n)]
    order = np.random.default_rng(seed).permutation(n)
    return [items[k] for k in order]


def params_of(tr, has_gaps, seed, index):
    g = tr["geom"]
    p = {"trial_seed": [seed, index], "frames": tr["n"], "rate_hz": FS, "has_foot": g["has_foot"],
         "markers_per_segment": {s: len(v[0]) for s, v in g["segments"].items()},
         "thigh_length_mm": g["thigh_length"], "shank_length_mm": g["shank_length"],
         "hip_centre_pelvis_mm": g["hip_centre"].tolist(),
         "knee_tilt_deg": g["knee_tilt_deg"],
         "ankle_tilt_deg": g["ankle_tilt_deg"] if g["has_foot"] else None,
         "has_gaps": has_gaps, "gaps": tr["gaps"], "motion": tr["motion_info"]}
    p.update({k: v for k, v in tr["noise"].items() if k not in ("model", "soft_tissue_peak_mm")})
    if "sigma_mm" in p:
        p["sigma"] = p["sigma_mm"]
    if "marginal_sigma_mm" in p:
        p["sigma"] = p["marginal_sigma_mm"]
    if "white_sigma_mm" in p:
        p["sigma"] = p["white_sigma_mm"]
    return p


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--n", type=int, default=240)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    t0 = time.time()
    trials = []
    for i, (cat, has_gaps) in enumerate(plan(a.seed, a.n)):
        stem = f"trial_{i:04d}"
        tr = build_trial(a.seed, i, cat, gaps=has_gaps, level="full")
        write_trc(os.path.join(a.out, stem + ".trc"), tr["names"], tr["X"])
        write_toml(os.path.join(a.out, stem + ".toml"), tr["geom"])
        with open(os.path.join(a.out, stem + ".truth.json"), "w") as f:
            json.dump(truth_doc(tr, cat), f, indent=1)
        trials.append({"stem": stem,
                       "category": dict(zip(("markerset", "motion", "noise"), cat)),
                       "params": params_of(tr, has_gaps, a.seed, i)})
    with open(os.path.join(a.out, "index.json"), "w") as f:
        json.dump({"generator": GENERATOR, "seed": a.seed, "trials": trials}, f, indent=1)
    print(f"wrote {a.n} trials to {a.out} in {time.time() - t0:.1f} s")


if __name__ == "__main__":
    main()
