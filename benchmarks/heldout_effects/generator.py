#!/usr/bin/env python3
"""heldout-effects v1/v2: independent synthetic right-lower-limb trials with known effects.

World: Y up, lab X/Z horizontal, mm, 100 Hz.  Segment frames: x anterior, y proximal
(along the bone, pointing up), z lateral (right).  Everything is a closed-form function of
continuous time, so a delayed segment is simply re-evaluated at t - d.

Only numpy / scipy / stdlib.  `build_spec` draws every random choice of a trial into a
JSON-serialisable dict; `simulate(spec, active=..., noise=...)` turns it into marker
trajectories with any subset of the effects switched on and noise on/off.

`--version 2` (see README.md, "v2") adds occlusion gaps (NaN / empty TRC cells), a
`sit_to_stand` motion, an anatomical marker layout, noise up to 1.5 mm and new effect
shapes.  Every v2 draw comes from its own random stream ([seed, index, 7919, 2]); the
v1 code paths and streams are unchanged, so v1 output is byte-for-byte what it was.

`--version 2 --sweep EFFECT[,EFFECT...]|all` (README "Sweep mode") writes N single-effect trials
per effect for detection-limit curves: each trial draws its own world, 500-3000 frames, noise
(sigma 0.3-1.5 mm) and the effect's size over a range reaching far below detectability
(SWEEP_SIZES), from its own stream [seed, effect index, trial, 4242].  Without --sweep nothing
changes.
"""
import argparse
import json
import math
import os

import numpy as np
from scipy.signal import lfilter

GENERATOR = "heldout-effects v1"
GENERATOR_V2 = "heldout-effects v2"
RATE = 100.0
EFFECTS = ["soft_tissue", "marker_slip", "marker_swap", "joint_translation",
           "extra_dof", "time_offset", "outliers", "spatial_distortion"]
SEGMENTS = ["pelvis", "thigh", "shank"]
D2R = math.pi / 180.0


# ----------------------------------------------------------------------------- math helpers
def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def rodrigues(axis, ang):
    """Rotation matrices (N,3,3) about a fixed unit axis by angles ang (N,) [rad]."""
    a = unit(axis)
    ang = np.asarray(ang, float)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3)[None] + s * K[None] + (1 - c) * (K @ K)[None]


def rot_small(rng, max_deg):
    ax = unit(rng.normal(size=3))
    return rodrigues(ax, np.array([rng.uniform(0, max_deg) * D2R]))[0]


def skew(r):
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


def sinsum(t, comps):
    """sum a*sin(2 pi f t + phi) for comps = [[a, f, phi], ...]."""
    out = np.zeros_like(t, dtype=float)
    for a, f, p in comps:
        out += a * np.sin(2 * np.pi * f * t + p)
    return out


def rand_comps(rng, k, fmin, fmax, amp=1.0):
    return [[float(amp * rng.uniform(0.3, 1.0)), float(rng.uniform(fmin, fmax)),
             float(rng.uniform(0, 2 * np.pi))] for _ in range(k)]


def loguniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def pgauss(p, mu, w):
    d = (p - mu + 0.5) % 1.0 - 0.5
    return np.exp(-0.5 * (d / w) ** 2)


# ----------------------------------------------------------------------------- geometry
def dist_to_line(x, p, d):
    d = unit(d)
    v = np.asarray(x, float) - p
    return float(np.linalg.norm(v - (v @ d) * d))


def draw_joint_geometry(rng):
    """Segment lengths, ASIS width, hip centre, knee centre / hinge axis and the shank's
    misalignment: the rigid-joint part of a subject (shared by both marker layouts)."""
    g = {}
    Lt = rng.uniform(370, 470)
    Ls = rng.uniform(350, 440)
    w = rng.uniform(200, 260)                    # inter-ASIS width
    g["thigh_length"], g["shank_length"], g["asis_width"] = Lt, Ls, w
    # hip centre in pelvis frame (origin mid-ASIS)
    hip = np.array([-rng.uniform(20, 35), -rng.uniform(65, 90), w / 2 - rng.uniform(25, 40)])
    # knee centre in thigh frame (origin hip centre), hinge axis ~ z tilted <= 10 deg
    knee = np.array([rng.uniform(-8, 8), -Lt, rng.uniform(-8, 8)])
    tilt = rng.uniform(0, 10) * D2R
    az = rng.uniform(0, 2 * np.pi)
    axis = unit([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)])
    Rs0 = rot_small(rng, 5.0)                   # shank frame misalignment w.r.t. hinge basis
    g["hip_centre_in_pelvis"] = hip
    g["knee_centre_in_thigh"] = knee
    g["knee_axis_in_thigh"] = axis
    g["shank_R0"] = Rs0
    return g


def draw_pelvis_markers(rng, w):
    """RASI, LASI and SACR (+RILC) or RPSI (+LPSI) in the pelvis frame (origin mid-ASIS)."""
    pel = {}
    jit = lambda: rng.normal(0, 6, 3)
    pel["RASI"] = np.array([0, 0, w / 2]) + jit()
    pel["LASI"] = np.array([0, 0, -w / 2]) + jit()
    dpost = rng.uniform(140, 180)
    if rng.random() < 0.5:
        pel["SACR"] = np.array([-dpost, rng.uniform(20, 45), 0]) + jit()
        if rng.random() < 0.4:
            pel["RILC"] = np.array([-rng.uniform(50, 80), rng.uniform(50, 80), w / 2 + rng.uniform(0, 20)]) + jit()
    else:
        pel["RPSI"] = np.array([-dpost, rng.uniform(20, 45), rng.uniform(40, 55)]) + jit()
        pel["LPSI"] = np.array([-dpost, rng.uniform(20, 45), -rng.uniform(40, 55)]) + jit()
        if rng.random() < 0.4:
            del pel["LPSI"]
    if len(pel) > 4:
        pel.pop(list(pel)[-1])
    return pel


def make_geometry(rng):
    """v1 subject: joint geometry, pelvis markers and RTH1..4 / RSH1..4 clusters off the bone line."""
    g = draw_joint_geometry(rng)
    Ls, w = g["shank_length"], g["asis_width"]
    knee, axis, Rs0 = g["knee_centre_in_thigh"], g["knee_axis_in_thigh"], g["shank_R0"]
    # ---- markers
    pel = draw_pelvis_markers(rng, w)

    def limb_markers(prefix, n, p0, p1, axis_pt, axis_dir, frac_lo, frac_hi, other_pt=None):
        out = {}
        lng = unit(p1 - p0)
        lat = unit(np.cross(np.array([1.0, 0, 0]), lng))  # ~ +z for a bone pointing down
        if lat[2] < 0:
            lat = -lat
        ant = unit(np.cross(lng, lat))
        if ant[0] < 0:
            ant = -ant
        fracs = np.sort(rng.uniform(frac_lo, frac_hi, n))
        i = 0
        tries = 0
        while len(out) < n:
            tries += 1
            f = fracs[i] if tries < 50 else rng.uniform(frac_lo, frac_hi)
            psi = rng.uniform(-40, 140) * D2R
            rad = rng.uniform(40, 80)
            m = p0 + f * (p1 - p0) + rad * (math.cos(psi) * lat + math.sin(psi) * ant)
            ok = dist_to_line(m, axis_pt, axis_dir) >= 30 and np.linalg.norm(m - axis_pt) >= 30
            if other_pt is not None:
                ok = ok and np.linalg.norm(m - other_pt) >= 30
            ok = ok and all(np.linalg.norm(m - q) >= 40 for q in out.values())
            if ok:
                out[f"{prefix}{len(out) + 1}"] = m
                i = min(i + 1, n - 1)
            if tries > 5000:
                raise RuntimeError("marker placement failed")
        return out

    nt = int(rng.integers(3, 5))
    ns = int(rng.integers(3, 5))
    thigh = limb_markers("RTH", nt, np.zeros(3), knee, knee, axis, 0.15, 0.88, other_pt=np.zeros(3))
    # shank frame: origin at knee centre (on axis); axis direction in shank frame = Rs0^T a
    ax_s = Rs0.T @ axis
    ankle = np.array([0, -Ls, 0.0])
    shank = limb_markers("RSH", ns, np.zeros(3), ankle, np.zeros(3), ax_s, 0.10, 0.90)
    g["markers"] = {"pelvis": pel, "thigh": thigh, "shank": shank}
    return g


def bone_basis(lng):
    """Unit (lateral, anterior) directions perpendicular to a bone's long axis `lng`
    (as v1's cluster placement: lateral ~ +z, anterior ~ +x)."""
    lat = unit(np.cross(np.array([1.0, 0, 0]), lng))
    if lat[2] < 0:
        lat = -lat
    ant = unit(np.cross(lng, lat))
    if ant[0] < 0:
        ant = -ant
    return lat, ant


def perp_jitter(rng, d, max_mm):
    """A random vector perpendicular to unit `d`, of length uniform in [0, max_mm]."""
    v = rng.normal(size=3)
    v = unit(v - (v @ d) * d)
    return v * rng.uniform(0, max_mm)


def make_geometry_anatomical(rng):
    """v2 "anatomical" subject: v1 joint geometry and pelvis, but thigh / shank markers at
    anatomical landmarks instead of clusters (2-4 markers per segment):

    thigh: RTHI (lateral mid-thigh, 50-80 mm off the bone line), RKNE (lateral femoral
    epicondyle: 45-55 mm lateral of the knee centre along the hinge axis, <= 4 mm off the axis),
    optional RKNM (medial epicondyle, 40-55 mm medial, <= 4 mm off the axis) and 0-1 extra
    marker (RGT, greater trochanter, or RTHA, anterior thigh);
    shank: RTIB (lateral mid-shank), RANK (lateral malleolus, 30-40 mm lateral of the shank's
    distal end), optional RMED (medial malleolus) and optional RTT (tibial tuberosity).
    """
    g = draw_joint_geometry(rng)
    Ls, w = g["shank_length"], g["asis_width"]
    knee, axis = g["knee_centre_in_thigh"], g["knee_axis_in_thigh"]
    pel = draw_pelvis_markers(rng, w)
    # ---- thigh (origin: hip centre; bone line hip -> knee centre)
    lng = unit(knee)
    lat, ant = bone_basis(lng)
    thigh = {}
    psi = rng.uniform(-20, 20) * D2R
    thigh["RTHI"] = rng.uniform(0.40, 0.65) * knee + rng.uniform(50, 80) * (math.cos(psi) * lat + math.sin(psi) * ant)
    thigh["RKNE"] = knee + rng.uniform(45, 55) * axis + perp_jitter(rng, axis, 4.0)
    if rng.random() < 0.5:
        thigh["RKNM"] = knee - rng.uniform(40, 55) * axis + perp_jitter(rng, axis, 4.0)
    u = rng.random()
    if u < 0.25:        # greater trochanter: lateral, a little distal of the hip centre
        thigh["RGT"] = rng.uniform(0.12, 0.2) * knee + rng.uniform(60, 80) * lat + rng.uniform(-10, 10) * ant
    elif u < 0.5:       # anterior thigh
        psi = rng.uniform(70, 110) * D2R
        thigh["RTHA"] = rng.uniform(0.25, 0.55) * knee + rng.uniform(55, 75) * (math.cos(psi) * lat + math.sin(psi) * ant)
    # ---- shank (origin: knee centre on the axis; bone line along -y to the ankle)
    ankle = np.array([0, -Ls, 0.0])
    lat, ant = bone_basis(unit(ankle))
    shank = {}
    psi = rng.uniform(-20, 20) * D2R
    shank["RTIB"] = rng.uniform(0.40, 0.65) * ankle + rng.uniform(45, 70) * (math.cos(psi) * lat + math.sin(psi) * ant)
    shank["RANK"] = ankle + rng.uniform(30, 40) * lat + perp_jitter(rng, lat, 5.0)
    if rng.random() < 0.5:
        shank["RMED"] = ankle - rng.uniform(30, 40) * lat + perp_jitter(rng, lat, 5.0)
    if rng.random() < 0.5:
        shank["RTT"] = np.array([rng.uniform(30, 45), -rng.uniform(35, 60), rng.uniform(0, 15)])
    # sanity: markers of a segment >= 30 mm apart (true by construction; guard anyway)
    for seg in (thigh, shank):
        pts = list(seg.values())
        assert all(np.linalg.norm(p - q) >= 30 for i, p in enumerate(pts) for q in pts[i + 1:])
    g["markers"] = {"pelvis": pel, "thigh": thigh, "shank": shank}
    return g


def geometry_to_json(g):
    out = {}
    for k, v in g.items():
        if k == "markers":
            out[k] = {s: {m: np.asarray(p).tolist() for m, p in d.items()} for s, d in v.items()}
        elif isinstance(v, np.ndarray):
            out[k] = v.tolist()
        else:
            out[k] = float(v)
    return out


def geometry_from_json(j):
    g = {}
    for k, v in j.items():
        if k == "markers":
            g[k] = {s: {m: np.array(p, float) for m, p in d.items()} for s, d in v.items()}
        elif isinstance(v, list):
            g[k] = np.array(v, float)
        else:
            g[k] = v
    return g


def marker_order(g):
    return [(s, m) for s in SEGMENTS for m in g["markers"][s]]


def truth_distances(g):
    hip = g["hip_centre_in_pelvis"]
    k, a, Rs0 = g["knee_centre_in_thigh"], g["knee_axis_in_thigh"], g["shank_R0"]
    hd, kd = {}, {}
    for m, p in g["markers"]["pelvis"].items():
        hd[m] = float(np.linalg.norm(p - hip))
    for m, p in g["markers"]["thigh"].items():
        hd[m] = float(np.linalg.norm(p))
        kd[m] = dist_to_line(p, k, a)
    for m, p in g["markers"]["shank"].items():
        kd[m] = dist_to_line(p, np.zeros(3), Rs0.T @ a)
    return {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh", "marker_distances": hd},
            "knee": {"type": "revolute", "parent": "thigh", "child": "shank", "marker_distances": kd}}


# ----------------------------------------------------------------------------- occlusion gaps (v2)
MIN_VISIBLE = 0.70          # every marker visible in >= 70 % of frames


def gap_missing(N, names, gaps):
    """(N,M) bool: True where a gap (list of {marker, frames:[first,last]}) hides a marker."""
    miss = np.zeros((N, len(names)), bool)
    for gp in gaps:
        miss[gp["frames"][0]:gp["frames"][1] + 1, names.index(gp["marker"])] = True
    return miss


def swap_columns(miss, names, swap):
    """The same mask seen through a marker_swap's labels: inside the swap span the two label
    columns exchange their (physical) markers, gaps included."""
    out = miss.copy()
    if swap is not None:
        i, j = names.index(swap["markers"][0]), names.index(swap["markers"][1])
        s0, s1 = swap["frames"][0], swap["frames"][1] + 1
        out[s0:s1, i], out[s0:s1, j] = miss[s0:s1, j], miss[s0:s1, i]
    return out


def gaps_ok(miss, names, pelvis):
    """The v2 occlusion rules: every marker visible in >= 70 % of the frames and at most one
    pelvis marker missing at any frame."""
    N = miss.shape[0]
    if (miss.sum(0) > (1 - MIN_VISIBLE) * N).any():
        return False
    pc = [names.index(m) for m in pelvis]
    return bool(miss[:, pc].sum(1).max(initial=0) <= 1)


def make_gaps(rng, g, N):
    """1-6 occlusion gaps, each one marker over 5-60 frames (12 %: 61-150), 5 % touching the
    trial's start and 5 % its end; gaps on one marker never touch or overlap; the v2 rules of
    `gaps_ok` hold.  Returned sorted by first frame."""
    names = [m for _, m in marker_order(g)]
    pelvis = list(g["markers"]["pelvis"])
    n_gaps = int(rng.integers(1, 7))
    gaps = []
    miss = np.zeros((N, len(names)), bool)
    tries = 0
    while len(gaps) < n_gaps and tries < 2000:
        tries += 1
        j = int(rng.integers(0, len(names)))
        L = int(rng.integers(61, 151)) if rng.random() < 0.12 else int(rng.integers(5, 61))
        u = rng.random()
        f0 = 0 if u < 0.05 else N - L if u < 0.10 else int(rng.integers(1, N - L))
        f1 = f0 + L - 1
        if miss[max(0, f0 - 1):f1 + 2, j].any():        # keep gaps on one marker apart
            continue
        trial = miss.copy()
        trial[f0:f1 + 1, j] = True
        if not gaps_ok(trial, names, pelvis):
            continue
        miss = trial
        gaps.append({"marker": names[j], "frames": [f0, f1]})
    return sorted(gaps, key=lambda gp: (gp["frames"][0], gp["marker"]))


def visible(spec, active=None):
    """(N,M) bool visibility of the written trial's columns (labels): the gaps, relabelled by
    the trial's marker_swap when that effect is active (active=None: all effects)."""
    names = [m for _, m in marker_order(spec["_geom"])]
    miss = gap_missing(spec["n_frames"], names, spec.get("gaps", []))
    sw = [e for e in spec["effects"] if e["name"] == "marker_swap" and (active is None or "marker_swap" in active)]
    return ~swap_columns(miss, names, sw[0] if sw else None)


# ----------------------------------------------------------------------------- motion
def make_motion(rng, kind, g, n_frames, force_treadmill=False, s2s_cycles=(3, 6)):
    """Draw the parameters of a closed-form motion: "functional", "gait" or (v2) "sit_to_stand"
    (with s2s_cycles = the allowed range of cycles: 3-6 in v2, 1-12 in sweep mode)."""
    m = {"kind": kind}
    leg = g["thigh_length"] + g["shank_length"] + rng.uniform(60, 90)
    pel_h = leg - g["hip_centre_in_pelvis"][1]          # hip centre y is negative
    m["heading_deg"] = float(rng.uniform(-180, 180))
    if kind == "functional":
        def osc(amp_lo, amp_hi, f_lo, f_hi):
            f0 = rng.uniform(f_lo, f_hi)
            pm = [[float(rng.uniform(0.2, 1.0)), float(rng.uniform(0.03, 0.2)), float(rng.uniform(0, 6.3))] for _ in range(3)]
            s = sum(a * f for a, f, _ in pm)
            lim = 0.6 * f0
            if s > lim:
                pm = [[a * lim / s, f, p] for a, f, p in pm]
            return {"amp": float(rng.uniform(amp_lo, amp_hi)), "f0": float(f0), "phi0": float(rng.uniform(0, 6.3)),
                    "pm": pm, "env_depth": float(rng.uniform(0.0, 0.35)), "env_f": float(rng.uniform(0.02, 0.1)),
                    "env_phi": float(rng.uniform(0, 6.3))}
        m["hip_flex"] = osc(30, 45, 0.25, 0.6); m["hip_flex"]["offset"] = float(rng.uniform(-5, 5))
        m["hip_abd"] = osc(15, 30, 0.2, 0.5); m["hip_abd"]["offset"] = float(rng.uniform(-3, 3))
        m["hip_rot"] = osc(10, 20, 0.3, 0.7); m["hip_rot"]["offset"] = float(rng.uniform(-3, 3))
        m["knee"] = osc(0, 0, 0.3, 0.8)
        m["knee"]["kmin"] = float(rng.uniform(5, 10)); m["knee"]["kmax"] = float(rng.uniform(70, 90))
        m["pelvis_pos0"] = [float(rng.uniform(-800, 800)), float(pel_h), float(rng.uniform(-800, 800))]
        m["pelvis_sway"] = [rand_comps(rng, 3, 0.05, 0.5, rng.uniform(3, 15)) for _ in range(3)]
        m["pelvis_rot"] = [rand_comps(rng, 3, 0.05, 0.5, rng.uniform(1, 3)) for _ in range(3)]
        m["treadmill"] = None
    elif kind == "sit_to_stand":
        m.update(make_sit_to_stand(rng, pel_h, n_frames, *s2s_cycles))
        m["treadmill"] = None
    else:
        T = rng.uniform(1.0, 1.2)
        m["stride_s"] = float(T)
        pm = rand_comps(rng, 3, 0.05, 0.3, 1.0)
        s = sum(2 * np.pi * f * a for a, f, _ in pm)
        var = rng.uniform(0.03, 0.06) / T
        m["stride_pm"] = [[a * var / s, f, p] for a, f, p in pm]
        # hip flexion template, rescaled to [hmin, hmax]
        m["hip_h"] = [[1.0, 0.0], [float(rng.uniform(0.05, 0.2)), float(rng.uniform(0, 6.3))],
                      [float(rng.uniform(0.0, 0.08)), float(rng.uniform(0, 6.3))]]
        pp = np.linspace(0, 1, 2001)
        gg = sum(a * np.cos(2 * np.pi * (i + 1) * pp + ph) for i, (a, ph) in enumerate(m["hip_h"]))
        m["hip_gmin"], m["hip_gmax"] = float(gg.min()), float(gg.max())
        m["hip_min"], m["hip_max"] = float(rng.uniform(-15, -8)), float(rng.uniform(22, 30))
        m["knee_base"] = float(rng.uniform(3, 8))
        m["knee_b1"] = [float(rng.uniform(8, 20)), float(rng.uniform(0.11, 0.16)), float(rng.uniform(0.05, 0.07))]
        m["knee_b2"] = [float(rng.uniform(55, 65)), float(rng.uniform(0.69, 0.74)), float(rng.uniform(0.10, 0.13))]
        m["amp_var"] = rand_comps(rng, 2, 0.03, 0.2, rng.uniform(0.02, 0.06))
        m["abd"] = [float(rng.uniform(3, 7)), float(rng.uniform(0, 6.3)), float(rng.uniform(-2, 2))]
        m["rot"] = [float(rng.uniform(3, 8)), float(rng.uniform(0, 6.3)), float(rng.uniform(-3, 3))]
        treadmill = force_treadmill or rng.random() < 0.5
        m["treadmill"] = bool(treadmill)
        m["speed_mm_s"] = 0.0 if treadmill else float(rng.uniform(1000, 1500))
        m["pelvis_pos0"] = [float(rng.uniform(-500, 500)), float(pel_h - rng.uniform(10, 30)), float(rng.uniform(-500, 500))]
        if not treadmill:
            dur = n_frames / RATE
            h = m["heading_deg"] * D2R
            m["pelvis_pos0"][0] -= 0.5 * m["speed_mm_s"] * dur * math.cos(h)
            m["pelvis_pos0"][2] += 0.5 * m["speed_mm_s"] * dur * math.sin(h)
        m["pel_vert"] = [float(rng.uniform(12, 25)), float(rng.uniform(0, 6.3))]
        m["pel_lat"] = [float(rng.uniform(15, 30)), float(rng.uniform(0, 6.3))]
        m["pel_yaw"] = [float(rng.uniform(3, 8)), float(rng.uniform(0, 6.3))]
        m["pel_obl"] = [float(rng.uniform(3, 6)), float(rng.uniform(0, 6.3))]
        m["pel_tilt"] = [float(rng.uniform(1.5, 3)), float(rng.uniform(0, 6.3)), float(rng.uniform(5, 12))]
        m["tread_drift"] = rand_comps(rng, 2, 0.02, 0.15, rng.uniform(10, 40)) if treadmill else []
    return m


def make_sit_to_stand(rng, pel_h, n_frames, min_cycles=3, max_cycles=6):
    """v2 motion: 3-6 sit-to-stand cycles of 2.5-4 s that fill the trial (sweep mode: 1-12
    cycles, so that 5-30 s trials can be filled with 2.5-4 s cycles).

    A cycle is: seated pause, rise, standing pause, sit down.  The standing fraction of cycle k
    is s_k(t) = ramp((t - a_k)/r_k) - ramp((t - b_k)/q_k) (quintic smoothstep ramps), and a
    forward-lean bump sin^2(pi u) runs over each rise and each sit.  Every angle and the pelvis
    position blend a seated value with the cycle's standing value through s_k, plus lean
    bumps; the thigh's world pitch goes ~90 -> ~3 deg, the knee ~90 -> ~5 deg, the pelvis rises
    250-350 mm, moves forward 100-200 mm and tilts forward during the rise.
    """
    D = n_frames / RATE
    n_lo, n_hi = max(min_cycles, math.ceil(D / 4.0)), min(max_cycles, math.floor(D / 2.5))
    n = int(rng.integers(n_lo, n_hi + 1))
    T = None
    for _ in range(100):
        Tc = np.clip(D / n * rng.uniform(0.88, 1.12, n), 2.5, 4.0)
        if Tc.sum() <= D:
            T = Tc
            break
    if T is None:
        T = np.full(n, D / n)
    rise = T * rng.uniform(0.24, 0.32, n)
    sit = T * rng.uniform(0.26, 0.34, n)
    stand = T * rng.uniform(0.12, 0.20, n)
    seated = T - rise - sit - stand
    start = -rng.uniform(0.0, 0.5) * seated[0] + np.concatenate([[0.0], np.cumsum(T)[:-1]])
    a = start + seated                      # rise onset
    b = a + rise + stand                    # sit-down onset
    m = {"n_cycles": n, "cycle_s": T.tolist(), "rise_start_s": a.tolist(), "rise_s": rise.tolist(),
         "sit_start_s": b.tolist(), "sit_s": sit.tolist()}
    m["thigh_seat_deg"] = float(rng.uniform(87, 97))           # world pitch of the thigh (flexion +)
    m["thigh_stand_deg"] = rng.uniform(0, 6, n).tolist()
    m["shank_seat_deg"] = float(rng.uniform(-5, 8))             # world pitch of the shank
    m["knee_stand_deg"] = rng.uniform(3, 8, n).tolist()
    m["shank_lean_deg"] = rng.uniform(8, 18, n).tolist()        # shank forward rotation at rise / sit
    m["tilt_seat_deg"] = float(rng.uniform(-3, 5))              # pelvis tilt (Rz; negative = anterior)
    m["tilt_stand_deg"] = rng.uniform(-2, 4, n).tolist()
    m["lean_rise_deg"] = rng.uniform(15, 25, n).tolist()        # forward (anterior) pelvis tilt at rise
    m["lean_sit_deg"] = rng.uniform(8, 18, n).tolist()
    m["lean_skew"] = float(rng.uniform(0.65, 0.9))              # rise lean peaks early (seat-off)
    m["abd_seat_deg"] = float(rng.uniform(-3, 6)); m["abd_stand_deg"] = rng.uniform(-3, 3, n).tolist()
    m["rot_seat_deg"] = float(rng.uniform(-8, 8)); m["rot_stand_deg"] = rng.uniform(-5, 5, n).tolist()
    m["abd_lean_deg"] = rng.uniform(-3, 3, n).tolist()
    m["rise_mm"] = rng.uniform(250, 350, n).tolist()
    m["forward_mm"] = rng.uniform(100, 200, n).tolist()
    m["forward_lean_mm"] = rng.uniform(10, 50, n).tolist()      # transient forward shift at seat-off
    m["pelvis_pos0"] = [float(rng.uniform(-800, 800)), float(pel_h - 300 - rng.uniform(10, 30)),
                        float(rng.uniform(-800, 800))]
    m["pelvis_sway"] = [rand_comps(rng, 2, 0.05, 0.4, rng.uniform(1, 4)) for _ in range(3)]
    m["pelvis_rot"] = [rand_comps(rng, 2, 0.05, 0.4, rng.uniform(0.3, 1)) for _ in range(3)]
    return m


def _smootherstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (10 - 15 * x + 6 * x * x)


def sit_to_stand_phases(m, t):
    """(N,K) arrays: standing fraction s_k, rise lean bump and sit lean bump of each cycle."""
    t = np.asarray(t, float)[:, None]
    a, r = np.asarray(m["rise_start_s"])[None], np.asarray(m["rise_s"])[None]
    b, q = np.asarray(m["sit_start_s"])[None], np.asarray(m["sit_s"])[None]
    ur = np.clip((t - a) / r, 0, 1)
    us = np.clip((t - b) / q, 0, 1)
    s = _smootherstep(ur) - _smootherstep(us)
    lean_r = np.sin(np.pi * ur ** m["lean_skew"]) ** 2
    lean_s = np.sin(np.pi * us ** (1.0 / m["lean_skew"])) ** 2
    return s, lean_r, lean_s


def eval_sit_to_stand(m, t):
    """Angles [deg] and pelvis translation in the heading frame (N,3) of a sit_to_stand motion."""
    s, lr, ls = sit_to_stand_phases(m, t)

    def blend(seat, stand):
        return seat + s @ (np.asarray(stand) - seat)
    thigh = blend(m["thigh_seat_deg"], m["thigh_stand_deg"])
    shank_stand = np.asarray(m["thigh_stand_deg"]) - np.asarray(m["knee_stand_deg"])
    shank = blend(m["shank_seat_deg"], shank_stand) + (lr + ls) @ np.asarray(m["shank_lean_deg"])
    tilt = blend(m["tilt_seat_deg"], m["tilt_stand_deg"]) - lr @ np.asarray(m["lean_rise_deg"]) \
        - ls @ np.asarray(m["lean_sit_deg"])
    out = {"tilt": tilt, "hip_flex": thigh - tilt, "knee": thigh - shank,
           "hip_abd": blend(m["abd_seat_deg"], m["abd_stand_deg"]) + lr @ np.asarray(m["abd_lean_deg"]),
           "hip_rot": blend(m["rot_seat_deg"], m["rot_stand_deg"])}
    fwd = s @ np.asarray(m["forward_mm"]) + lr @ np.asarray(m["forward_lean_mm"])
    up = s @ np.asarray(m["rise_mm"])
    out["loc"] = np.stack([fwd, up, np.zeros_like(fwd)], 1)
    return out


def _osc(o, t):
    ph = 2 * np.pi * o["f0"] * t + o["phi0"]
    for a, f, p in o["pm"]:
        ph = ph + a * np.sin(2 * np.pi * f * t + p)   # d(phase)/dt stays > 0
    env = 1 - o["env_depth"] * (0.5 + 0.5 * np.sin(2 * np.pi * o["env_f"] * t + o["env_phi"]))
    return ph, env


def eval_motion(m, t):
    """Joint angles [rad] and pelvis pose (R (N,3,3), p (N,3)) at times t."""
    t = np.asarray(t, float)
    out = {}
    hd = m["heading_deg"] * D2R
    if m["kind"] == "functional":
        for k in ("hip_flex", "hip_abd", "hip_rot"):
            o = m[k]
            ph, env = _osc(o, t)
            out[k] = (o["offset"] + o["amp"] * env * np.sin(ph)) * D2R
        o = m["knee"]
        ph, env = _osc(o, t)
        out["knee"] = (o["kmin"] + (o["kmax"] - o["kmin"]) * env * (0.5 - 0.5 * np.cos(ph))) * D2R
        pos = np.stack([m["pelvis_pos0"][i] + sinsum(t, m["pelvis_sway"][i]) for i in range(3)], 1)
        yaw = hd + sinsum(t, m["pelvis_rot"][0]) * D2R
        tilt = sinsum(t, m["pelvis_rot"][1]) * D2R
        obl = sinsum(t, m["pelvis_rot"][2]) * D2R
    elif m["kind"] == "sit_to_stand":
        st = eval_sit_to_stand(m, t)
        for k in ANGLES:
            out[k] = st[k] * D2R
        loc = st["loc"] + np.stack([sinsum(t, m["pelvis_sway"][i]) for i in range(3)], 1)
        Rh = rodrigues([0, 1, 0], np.array([hd]))[0]
        pos = np.asarray(m["pelvis_pos0"])[None] + loc @ Rh.T
        yaw = hd + sinsum(t, m["pelvis_rot"][0]) * D2R
        tilt = st["tilt"] * D2R + sinsum(t, m["pelvis_rot"][1]) * D2R
        obl = sinsum(t, m["pelvis_rot"][2]) * D2R
    else:
        p = t / m["stride_s"] + sinsum(t, m["stride_pm"])
        av = 1 + sinsum(t, m["amp_var"])
        gg = sum(a * np.cos(2 * np.pi * (i + 1) * p + ph) for i, (a, ph) in enumerate(m["hip_h"]))
        u = (gg - m["hip_gmin"]) / (m["hip_gmax"] - m["hip_gmin"])
        out["hip_flex"] = (m["hip_min"] + (m["hip_max"] - m["hip_min"]) * u) * av * D2R
        b1, b2 = m["knee_b1"], m["knee_b2"]
        kb = m["knee_base"]
        out["knee"] = (kb + av * (b1[0] * pgauss(p, b1[1], b1[2]) + (b2[0] - kb) * pgauss(p, b2[1], b2[2]))) * D2R
        out["hip_abd"] = (m["abd"][2] + m["abd"][0] * np.sin(2 * np.pi * p + m["abd"][1])) * D2R
        out["hip_rot"] = (m["rot"][2] + m["rot"][0] * np.sin(2 * np.pi * p + m["rot"][1])) * D2R
        fwd = m["speed_mm_s"] * t + (sinsum(t, m["tread_drift"]) if m["tread_drift"] else 0.0)
        lat = m["pel_lat"][0] * np.sin(2 * np.pi * p + m["pel_lat"][1])
        vert = m["pel_vert"][0] * np.cos(4 * np.pi * p + m["pel_vert"][1])
        loc = np.stack([fwd, vert, lat], 1)   # in heading frame: x forward, y up, z right
        Rh = rodrigues([0, 1, 0], np.array([hd]))[0]
        pos = np.asarray(m["pelvis_pos0"])[None] + loc @ Rh.T
        yaw = hd + m["pel_yaw"][0] * D2R * np.sin(2 * np.pi * p + m["pel_yaw"][1])
        obl = m["pel_obl"][0] * D2R * np.sin(4 * np.pi * p + m["pel_obl"][1])
        tilt = (m["pel_tilt"][2] + m["pel_tilt"][0] * np.cos(4 * np.pi * p + m["pel_tilt"][1])) * D2R
    Rp = rodrigues([0, 1, 0], yaw) @ rodrigues([0, 0, 1], tilt) @ rodrigues([1, 0, 0], obl)
    out["pelvis_R"], out["pelvis_p"] = Rp, pos
    return out


ANGLES = ["hip_flex", "hip_abd", "hip_rot", "knee"]


# ----------------------------------------------------------------------------- effect features
def st_features(e, ang):
    """soft tissue: feature matrix F (N,K) of angle deviations from the reference posture."""
    d = {k: ang[k] - e["ref_angles"][k] for k in e["drivers"]}
    cols = []
    sh = e["shape"]
    if sh == "angle_harmonics":
        for k in e["drivers"]:
            for h in e["harmonics"]:
                cols += [np.sin(h * d[k]), 1 - np.cos(h * d[k])]
    elif sh == "long_axis_slide":
        for k in e["drivers"]:
            cols += [d[k], np.sin(2 * d[k])]
    elif sh == "coherent_cluster":
        for k in e["drivers"]:
            cols += [d[k], d[k] ** 2]
    elif sh == "bilinear_bulge":
        ks = e["drivers"]
        for i in range(len(ks)):
            for j in range(i, len(ks)):
                cols.append(d[ks[i]] * d[ks[j]])
    elif sh == "other_joint":                       # v2: driven by the other joint's angle only
        for k in e["drivers"]:
            cols += [np.sin(d[k]), 1 - np.cos(d[k])]
    return np.stack(cols, 1)


def st_offsets(e, ang):
    F = st_features(e, ang)
    return {m: e["scale"] * (F @ np.asarray(C)) for m, C in e["coef"].items()}


def jt_features(e, ang):
    sh = e["shape"]
    if e["joint"] == "knee":
        th = ang["knee"]
        if sh == "rollback":
            return np.stack([np.sin(th), 1 - np.cos(th)], 1)
        if sh == "condyle_posterior_shift":
            sig = lambda x: 1 / (1 + np.exp(-x))
            tm, w = e["theta_mid"], e["width"]
            return np.stack([sig((th - tm) / w) - sig(-tm / w), np.sin(th) ** 2], 1)
        if sh == "polycentric_arc":
            k = e["kappa"]
            return np.stack([np.cos(k * th) - 1, np.sin(k * th)], 1)
    else:
        f, a = ang["hip_flex"], ang["hip_abd"]
        return np.stack([1 - np.cos(f), np.sin(a), np.sin(f) * np.sin(a)], 1)
    raise ValueError(sh)


def jt_offset(e, ang):
    return e["scale"] * (jt_features(e, ang) @ np.asarray(e["coef"]))


def slip_profile(e, t):
    ts = (e["frame"] - 0.5) / RATE
    if e["shape"] == "step":
        return (t >= ts).astype(float)
    s = np.clip((t - ts) / e["drift_s"], 0, 1)
    if e["shape"] in ("linear_drift", "fast_ramp"):        # fast_ramp (v2): 0.05-0.15 s
        return s
    if e["shape"] == "smoothstep_drift":
        return s * s * (3 - 2 * s)
    if e["shape"] == "cosine_creep":
        return 0.5 - 0.5 * np.cos(np.pi * s)
    raise ValueError(e["shape"])


def distortion(e, X):
    """X (...,3) world positions -> displacement (...,3)."""
    c = np.asarray(e["centre_mm"])
    v = X - c
    r = np.linalg.norm(v, axis=-1, keepdims=True)
    sh = e["shape"]
    if sh == "radial_lens":
        return e["k"] * r * v
    if sh == "shear_plus_radial":
        S = np.asarray(e["shear"])
        return e["k"] * r * v + v @ S.T
    if sh == "single_axis_scale":
        ax = np.asarray(e["axis"])
        return e["eps"] * (v @ ax)[..., None] * ax
    if sh == "smooth_warp":
        out = np.zeros_like(X)
        for a, kv, ph in e["modes"]:
            kv = np.asarray(kv)
            out += (np.sin(v @ kv + ph) - np.sin(ph))[..., None] * np.asarray(a)
        return e["scale"] * out
    raise ValueError(sh)


# ----------------------------------------------------------------------------- simulation
def kinematics(spec, t, active):
    """World marker positions (N,M,3) + joint geometry, effects in `active` that act on
    the body (soft_tissue, marker_slip, joint_translation, extra_dof) applied."""
    g = spec["_geom"]
    eff = {e["name"]: e for e in spec["effects"] if e["name"] in active}
    ang = eval_motion(spec["motion"], t)
    N = len(t)
    Rp, pp = ang["pelvis_R"], ang["pelvis_p"]
    hip = g["hip_centre_in_pelvis"]
    Rhip = rodrigues([0, 0, 1], ang["hip_flex"]) @ rodrigues([1, 0, 0], -ang["hip_abd"]) @ rodrigues([0, 1, 0], ang["hip_rot"])
    Rt = Rp @ Rhip
    hip_c = pp + np.einsum("nij,j->ni", Rp, hip)
    ot = hip_c.copy()
    jt = eff.get("joint_translation")
    if jt is not None and jt["joint"] == "hip":
        ot = ot + np.einsum("nij,nj->ni", Rp, jt_offset(jt, ang))
    a, k, Rs0 = g["knee_axis_in_thigh"], g["knee_centre_in_thigh"], g["shank_R0"]
    Q = rodrigues(a, -ang["knee"])
    ed = eff.get("extra_dof")
    if ed is not None:
        b = np.asarray(ed["b_axis"]); c = np.asarray(ed["c_axis"])
        if ed["dof"] in ("varus_valgus", "ball"):
            Q = Q @ rodrigues(b, ed["vv_scale"] * sinsum(t, ed["vv_comps"]) * D2R)
        if ed["dof"] in ("axial_rotation", "ball"):
            Q = Q @ rodrigues(c, ed["ax_scale"] * sinsum(t, ed["ax_comps"]) * D2R)
    Rs = Rt @ Q @ Rs0
    kc = k.copy()
    knee_pt = ot + np.einsum("nij,j->ni", Rt, kc)
    os_ = knee_pt.copy()
    if jt is not None and jt["joint"] == "knee":
        os_ = os_ + np.einsum("nij,nj->ni", Rt, jt_offset(jt, ang))
    poses = {"pelvis": (Rp, pp), "thigh": (Rt, ot), "shank": (Rs, os_)}
    st = eff.get("soft_tissue")
    st_off = {}
    if st is not None:
        for seg_e in st["parts"]:
            st_off.update(st_offsets(seg_e, ang))
    sl = eff.get("marker_slip")
    order = marker_order(g)
    X = np.empty((N, len(order), 3))
    for j, (s, m) in enumerate(order):
        loc = np.broadcast_to(g["markers"][s][m], (N, 3)).copy()
        if m in st_off:
            loc += st_off[m]
        if sl is not None and sl["marker"] == m:
            loc += slip_profile(sl, t)[:, None] * np.asarray(sl["offset_local"])[None]
        R, o = poses[s]
        X[:, j] = o + np.einsum("nij,nj->ni", R, loc)
    geom = {"hip_centre": hip_c, "knee_point": knee_pt, "knee_dir": np.einsum("nij,j->ni", Rt, a)}
    return X, geom, ang


def simulate(spec, active=None, noise=True, gaps=True):
    """Marker array (N,M,3) in marker_order; active=None -> all effects of the trial.

    v2 occlusion gaps (spec["gaps"]) hide the physical marker: its samples are NaN.  They are
    applied after time_offset and before marker_swap, so inside a swap span a gap follows its
    marker to the other label.  gaps=False returns the trajectories without the gaps."""
    if "_geom" not in spec:
        spec["_geom"] = geometry_from_json(spec["geometry"])
    if active is None:
        active = [e["name"] for e in spec["effects"]]
    active = set(active)
    eff = {e["name"]: e for e in spec["effects"] if e["name"] in active}
    N = spec["n_frames"]
    t = np.arange(N) / RATE
    X, geom, ang = kinematics(spec, t, active)
    names = [m for _, m in marker_order(spec["_geom"])]
    if "time_offset" in eff:
        e = eff["time_offset"]
        Xd, _, _ = kinematics(spec, t - e["delay_frames"] / RATE, active)
        for m in e["markers"]:
            j = names.index(m)
            X[:, j] = Xd[:, j]
    if gaps and spec.get("gaps"):
        X[gap_missing(N, names, spec["gaps"])] = np.nan
    if "marker_swap" in eff:
        e = eff["marker_swap"]
        i, j = names.index(e["markers"][0]), names.index(e["markers"][1])
        s0, s1 = e["frames"][0], e["frames"][1] + 1
        tmp = X[s0:s1, i].copy()
        X[s0:s1, i] = X[s0:s1, j]
        X[s0:s1, j] = tmp
    if "spatial_distortion" in eff:
        X = X + distortion(eff["spatial_distortion"], X)
    if noise:
        nz = spec["noise"]
        rng = np.random.default_rng(nz["seed"])
        w = rng.normal(size=(N, len(names), 3))
        if nz["model"] == "white":
            X = X + nz["sigma_mm"] * w
        else:
            phi = nz["phi"]
            e0 = w.copy()
            e0[1:] *= math.sqrt(1 - phi * phi)
            ar = lfilter([1.0], [1.0, -phi], e0, axis=0)   # stationary start: e[0] ~ N(0,1)
            X = X + nz["sigma_mm"] * ar
    if "outliers" in eff:
        for ev in eff["outliers"]["events"]:
            j = names.index(ev["marker"])
            X[ev["frame"]:ev["frame"] + ev["length"], j] += np.asarray(ev["vector_mm"])
    return X, names, geom, ang


# ----------------------------------------------------------------------------- effect builders
def peak_disp(spec, name):
    """Realised peak 3-D displacement of one effect alone, noise-free, vs the rigid trial,
    over the samples visible in both (NaN-aware; identical to a plain max without gaps)."""
    A, _, _, _ = simulate(spec, [], noise=False)
    B, _, _, _ = simulate(spec, [name], noise=False)
    return float(np.nanmax(np.linalg.norm(B - A, axis=2)))


def tangentish(rng, n, normal_weight=0.3):
    v = rng.normal(size=3)
    v -= (1 - normal_weight) * (v @ n) * n
    return v


def is_v2(spec):
    return spec.get("version", 1) == 2


# sweep mode: per effect, the size parameter's name and its log-uniform range.  extra_dof's
# range is a fraction of v2's upper amplitude for its dof (12 deg varus_valgus, 15 deg axial);
# marker_swap's span is an integer number of frames.
SWEEP_SIZES = {
    "soft_tissue": ("target_mm", 0.3, 15.0),
    "marker_slip": ("target_mm", 0.3, 15.0),
    "marker_swap": ("span_frames", 2.0, 400.0),
    "joint_translation": ("target_mm", 0.3, 12.0),
    "extra_dof": ("amplitude_deg", 0.05, 1.0),
    "time_offset": ("lag_frames", 0.05, 4.0),
    "outliers": ("target_mm", 1.0, 60.0),
    "spatial_distortion": ("strength_mm_at_1500", 0.3, 12.0),
}


def sweep_size(spec, default, scale=1.0, integer=False, digits=None):
    """An effect's size parameter: `default` (the v1 / v2 draw, already taken) unless `spec` is a
    sweep trial.  Then it is log-uniform over SWEEP_SIZES[effect] (times `scale`) at the trial's
    own quantile spec["sweep"]["size_u"]: floor(lo * ((hi + 1) / lo) ** u) for an integer size,
    else lo * (hi / lo) ** u (rounded to `digits`).  The value is noted in spec["_size"]."""
    sw = spec.get("sweep")
    if sw is None:
        return default
    name, lo, hi = SWEEP_SIZES[sw["effect"]]
    lo, hi = scale * lo, scale * hi
    u = sw["size_u"]
    if integer:
        v = int(min(hi, math.floor(lo * ((hi + 1) / lo) ** u)))
    else:
        v = lo * (hi / lo) ** u
        v = float(round(v, digits) if digits is not None else v)
    spec["_size"] = {"name": name, "value": float(v), "range": [lo, hi]}
    return v


def marker_index(spec):
    return {m: j for j, (_, m) in enumerate(marker_order(spec["_geom"]))}


def st_peak(spec, parts, ang):
    """Peak soft-tissue offset over the samples where each marker is visible (all in v1)."""
    vis, idx = visible(spec, active=[]), marker_index(spec)
    peak = 0.0
    for e in parts:
        for m, v in st_offsets(e, ang).items():
            peak = max(peak, float(np.linalg.norm(v, axis=1)[vis[:, idx[m]]].max()))
    return peak


def build_soft_tissue(rng, spec, ang):
    """soft_tissue: see README.  v2 adds the shape `other_joint` (build_st_other_joint)."""
    g = spec["_geom"]
    seg_choice = rng.choice(["thigh", "shank", "thigh+shank", "pelvis"], p=[0.45, 0.25, 0.2, 0.1])
    segs = seg_choice.split("+")
    shapes = ["angle_harmonics", "long_axis_slide", "coherent_cluster", "bilinear_bulge"]
    shape = str(rng.choice(shapes + (["other_joint"] if is_v2(spec) else [])))
    target = sweep_size(spec, loguniform(rng, 2.0, 15.0))
    if shape == "other_joint":
        return build_st_other_joint(rng, spec, ang, target)
    parts = []
    all_markers = []
    for s in segs:
        mk = list(g["markers"][s])
        if shape == "angle_harmonics" and rng.random() < 0.5 and len(mk) > 1:
            mk = sorted(rng.choice(mk, int(rng.integers(1, len(mk))), replace=False).tolist())
        drivers = {"thigh": ["knee", "hip_flex", "hip_abd"], "shank": ["knee", "hip_rot"],
                   "pelvis": ["hip_flex", "hip_abd"]}[s]
        drivers = drivers[:int(rng.integers(1, len(drivers) + 1))]
        if shape == "bilinear_bulge" and len(drivers) == 1:
            drivers = {"thigh": ["knee", "hip_flex"], "shank": ["knee", "hip_rot"], "pelvis": ["hip_flex", "hip_abd"]}[s]
        ref = {k: float(np.median(ang[k])) for k in ANGLES}
        e = {"segment": s, "shape": shape, "drivers": drivers, "ref_angles": ref, "coef": {}, "scale": 1.0}
        if shape == "angle_harmonics":
            e["harmonics"] = sorted(rng.choice([1, 2, 3], int(rng.integers(1, 3)), replace=False).tolist())
        pts = g["markers"][s]
        cen = np.mean([pts[m] for m in pts], 0)
        if s == "thigh":
            lng = unit(-g["knee_centre_in_thigh"]); jpt = g["knee_centre_in_thigh"]
        elif s == "shank":
            lng = np.array([0, 1.0, 0]); jpt = np.zeros(3)
        else:
            lng = np.array([0, 1.0, 0]); jpt = g["hip_centre_in_pelvis"]
        K = st_features(e, ang).shape[1]
        if shape == "coherent_cluster":
            Cc = rng.normal(size=(K, 3))
            W = rng.normal(size=(K, 3)) * 0.01 * rng.uniform(0, 1)
        for m in mk:
            p = pts[m]
            n = p - cen; n = unit(n) if np.linalg.norm(n) > 1e-9 else lng
            if shape == "angle_harmonics":
                C = np.stack([tangentish(rng, unit(p - jpt)) * rng.uniform(0.2, 1) for _ in range(K)])
            elif shape == "long_axis_slide":
                wgt = math.exp(-np.linalg.norm(p - jpt) / 150.0) + 0.15
                C = np.outer(rng.normal(size=K), lng) * wgt + 0.1 * rng.normal(size=(K, 3)) * wgt
            elif shape == "coherent_cluster":
                C = Cc - W @ skew(p - cen).T
            else:
                C = np.stack([tangentish(rng, unit(p - jpt), 0.6) for _ in range(K)])
            e["coef"][m] = C.tolist()
        parts.append(e)
        all_markers += mk
    # scale all parts jointly to the target peak
    peak = st_peak(spec, parts, ang)
    for e in parts:
        e["scale"] = target / peak
    where = {"segment": segs[0] if len(segs) == 1 else segs, "segments": segs, "markers": all_markers,
             "joint": "hip" if segs == ["pelvis"] else "knee"}
    return {"name": "soft_tissue", "shape": shape + ("_" + "_".join(segs)), "parts": parts,
            "target_peak_mm": target, "where": where}


def build_st_other_joint(rng, spec, ang, target):
    """v2 soft_tissue `other_joint`: a thigh marker or the whole thigh cluster driven by the
    KNEE angle only, or one shank marker driven by the HIP flexion angle only.  Offsets are
    C @ [sin d, 1 - cos d] of that angle's deviation d from the median posture; a whole cluster
    moves with one common C (a rigid translation of the cluster)."""
    g = spec["_geom"]
    if rng.random() < 0.5:
        s, drivers = "thigh", ["knee"]
        mk = list(g["markers"]["thigh"])
        cluster = bool(rng.random() < 0.5)
        if not cluster:
            mk = [str(rng.choice(mk))]
        jpt = g["knee_centre_in_thigh"]
    else:
        s, drivers, cluster = "shank", ["hip_flex"], False
        mk = [str(rng.choice(list(g["markers"]["shank"])))]
        jpt = np.zeros(3)
    ref = {k: float(np.median(ang[k])) for k in ANGLES}
    e = {"segment": s, "shape": "other_joint", "drivers": drivers, "ref_angles": ref, "coef": {},
         "scale": 1.0, "cluster": cluster}
    Cc = rng.normal(size=(2, 3))
    for m in mk:
        p = g["markers"][s][m]
        C = Cc if cluster else np.stack([tangentish(rng, unit(p - jpt)) * rng.uniform(0.3, 1) for _ in range(2)])
        e["coef"][m] = C.tolist()
    e["scale"] = target / st_peak(spec, [e], ang)
    where = {"segment": s, "segments": [s], "markers": mk, "joint": "knee", "drivers": drivers}
    return {"name": "soft_tissue", "shape": "other_joint_" + s, "parts": [e],
            "target_peak_mm": target, "where": where}


def build_marker_slip(rng, spec, ang):
    """marker_slip: see README.  v2 adds `fast_ramp` (a linear ramp over 0.05-0.15 s) and puts
    the onset where the marker is visible from the frame before onset to the one after the end."""
    g = spec["_geom"]; N = spec["n_frames"]
    s = str(rng.choice(SEGMENTS, p=[0.2, 0.4, 0.4]))
    m = str(rng.choice(list(g["markers"][s])))
    shapes = ["step", "step", "linear_drift", "smoothstep_drift", "cosine_creep"]
    shape = str(rng.choice(shapes + (["fast_ramp"] if is_v2(spec) else [])))
    if shape == "fast_ramp":
        drift = float(rng.uniform(0.05, 0.15))
    else:
        drift = 0.0 if shape == "step" else float(rng.uniform(0.2, 1.0))
    if is_v2(spec):
        vis = visible(spec, active=[])[:, marker_index(spec)[m]]
        w = int(math.ceil(drift * RATE)) + 2
        cands = [f for f in range(int(0.15 * N), int(0.85 * N) - int(drift * RATE) - 2)
                 if vis[f - 1:f + w].all()]
        if not cands:
            raise RuntimeError("no visible slip onset")
        f0 = int(cands[int(rng.integers(0, len(cands)))])
    else:
        f0 = int(rng.integers(int(0.15 * N), int(0.85 * N) - int(drift * RATE) - 2))
    mag = sweep_size(spec, float(rng.uniform(4, 15)))
    dirn = unit(rng.normal(size=3))
    if rng.random() < 0.5:       # along the skin: suppress the component normal to the skin
        cen = np.mean(list(g["markers"][s].values()), 0)
        n = unit(g["markers"][s][m] - cen)
        dirn = unit(dirn - 0.9 * (dirn @ n) * n)
    e = {"name": "marker_slip", "shape": shape, "marker": m, "segment": s, "frame": f0,
         "drift_s": drift, "offset_local": (mag * dirn).tolist(), "target_peak_mm": mag}
    tt = np.arange(N) / RATE
    prof = slip_profile(e, tt)
    f_end = int(np.argmax(prof >= 1.0))
    e["where"] = {"marker": m, "markers": [m], "segment": s, "frame": f0, "frame_number": f0 + 1,
                  "frames": [f0, f_end], "frame_numbers": [f0 + 1, f_end + 1]}
    return e


def build_marker_swap(rng, spec, ang):
    """marker_swap: see README (v2: build_marker_swap_v2)."""
    if is_v2(spec):
        return build_marker_swap_v2(rng, spec, ang)
    g = spec["_geom"]; N = spec["n_frames"]
    if rng.random() < 0.55:
        s = str(rng.choice(SEGMENTS))
        a, b = rng.choice(list(g["markers"][s]), 2, replace=False).tolist()
        segs = [s, s]; kind = "same_segment"
    else:
        s1, s2 = [("pelvis", "thigh"), ("thigh", "shank")][int(rng.integers(0, 2))]
        a = str(rng.choice(list(g["markers"][s1]))); b = str(rng.choice(list(g["markers"][s2])))
        segs = [s1, s2]; kind = "neighbour_segments"
    L = int(rng.integers(50, 401))
    u = rng.random()
    if u < 0.1:
        s0 = 0
    elif u < 0.2:
        s0 = N - L
    else:
        s0 = int(rng.integers(1, N - L))
    e = {"name": "marker_swap", "shape": kind + ("_at_start" if s0 == 0 else "_at_end" if s0 == N - L else ""),
         "markers": [a, b], "frames": [s0, s0 + L - 1]}
    e["where"] = {"markers": [a, b], "segments": segs, "frames": [s0, s0 + L - 1],
                  "frame_numbers": [s0 + 1, s0 + L]}
    return e


NEIGHBOURS = {"pelvis": ["thigh"], "thigh": ["pelvis", "shank"], "shank": ["thigh"]}


def build_marker_swap_v2(rng, spec, ang):
    """v2 marker_swap.  When the trial has gaps, half the swaps are `*_in_gap`: the span starts
    strictly inside an occlusion gap of one of the two markers (the gapped marker is listed
    first; `where.gap` names that gap).  Gaps belong to the physical marker, so after the swap
    the gapped label reappears early carrying the other marker, and the other label goes
    missing until the gap ends.  Every swap keeps the occlusion rules in the label view and
    is visible on at least one sample."""
    g = spec["_geom"]; N = spec["n_frames"]
    order = marker_order(g)
    names = [m for _, m in order]
    seg_of = {m: s for s, m in order}
    pelvis = list(g["markers"]["pelvis"])
    miss = gap_missing(N, names, spec["gaps"])
    L_sweep = sweep_size(spec, None, integer=True)   # sweep mode: the span length is given
    want_gap = bool(spec["gaps"]) and rng.random() < 0.5
    for attempt in range(1000):
        in_gap = want_gap and attempt < 500
        if in_gap:
            gp = spec["gaps"][int(rng.integers(0, len(spec["gaps"])))]
            a, (g0, g1) = gp["marker"], gp["frames"]
            sa = seg_of[a]
            sb = sa if rng.random() < 0.55 else str(rng.choice(NEIGHBOURS[sa]))
            b = str(rng.choice([m for m in g["markers"][sb] if m != a]))
            kind = "same_segment" if sa == sb else "neighbour_segments"
            s0 = int(rng.integers(g0 + 1, g1 + 1))
            if N - s0 < (50 if L_sweep is None else L_sweep):
                continue
            L = int(rng.integers(50, min(400, N - s0) + 1)) if L_sweep is None else L_sweep
        else:
            if rng.random() < 0.55:
                sa = sb = str(rng.choice(SEGMENTS))
                a, b = rng.choice(list(g["markers"][sa]), 2, replace=False).tolist()
                kind = "same_segment"
            else:
                sa, sb = [("pelvis", "thigh"), ("thigh", "shank")][int(rng.integers(0, 2))]
                a = str(rng.choice(list(g["markers"][sa]))); b = str(rng.choice(list(g["markers"][sb])))
                kind = "neighbour_segments"
            L = int(rng.integers(50, 401)) if L_sweep is None else L_sweep
            u = rng.random()
            s0 = 0 if u < 0.1 else N - L if u < 0.2 else int(rng.integers(1, N - L))
        span = [s0, s0 + L - 1]
        lab = swap_columns(miss, names, {"markers": [a, b], "frames": span})
        if not gaps_ok(lab, names, pelvis):
            continue
        both = (~miss & ~lab)[s0:s0 + L][:, [names.index(a), names.index(b)]]
        if not both.any():
            continue
        suffix = "_in_gap" if in_gap else "_at_start" if s0 == 0 else "_at_end" if s0 == N - L else ""
        e = {"name": "marker_swap", "shape": kind + suffix, "markers": [a, b], "frames": span}
        e["where"] = {"markers": [a, b], "segments": [sa, sb], "frames": span,
                      "frame_numbers": [s0 + 1, s0 + L]}
        if in_gap:
            e["where"]["gap"] = {"marker": a, "frames": [g0, g1], "frame_numbers": [g0 + 1, g1 + 1]}
        return e
    raise RuntimeError("no admissible marker swap")


def build_joint_translation(rng, spec, ang):
    g = spec["_geom"]
    joint = "knee" if rng.random() < 0.8 else "hip"
    target = sweep_size(spec, loguniform(rng, 3.0, 12.0))
    a = g["knee_axis_in_thigh"]
    b = unit(np.array([1.0, 0, 0]) - a[0] * a)      # anterior, perpendicular to hinge
    c = np.cross(a, b)                               # ~ proximal/distal in the sagittal plane
    if c[1] < 0:
        c = -c
    if joint == "knee":
        shape = str(rng.choice(["rollback", "condyle_posterior_shift", "polycentric_arc"]))
        e = {"name": "joint_translation", "joint": "knee", "shape": shape}
        if shape == "rollback":
            C = np.stack([-b * rng.uniform(0.5, 1) + c * rng.uniform(-0.3, 0.3) + a * rng.uniform(-0.15, 0.15),
                          -b * rng.uniform(-0.3, 1) + c * rng.uniform(-0.5, 0.5)])
        elif shape == "condyle_posterior_shift":
            e["theta_mid"] = float(rng.uniform(20, 50) * D2R); e["width"] = float(rng.uniform(8, 20) * D2R)
            C = np.stack([-b, c * rng.uniform(0.1, 0.4)])
        else:
            e["kappa"] = float(rng.uniform(0.4, 1.0))
            phi = rng.uniform(0, 2 * np.pi)
            e1 = math.cos(phi) * b + math.sin(phi) * c
            e2 = np.cross(a, e1)
            C = np.stack([e1, e2])
    else:
        e = {"name": "joint_translation", "joint": "hip", "shape": "hip_pistoning"}
        C = rng.normal(size=(3, 3))
    e["coef"] = C.tolist(); e["scale"] = 1.0
    off = np.linalg.norm(jt_offset(e, ang), axis=1)
    if is_v2(spec):     # peak over frames where a moved (thigh / shank) marker is visible
        moved = [j for j, (s, _) in enumerate(marker_order(g)) if s == "shank" or (joint == "hip" and s == "thigh")]
        off = off[visible(spec, active=[])[:, moved].any(1)]
    peak = float(off.max())
    e["scale"] = target / peak
    e["target_peak_mm"] = target
    e["where"] = {"joint": joint}
    return e


def build_extra_dof(rng, spec, ang):
    g = spec["_geom"]; N = spec["n_frames"]
    a = g["knee_axis_in_thigh"]
    b = unit(np.array([1.0, 0, 0]) - a[0] * a)
    c = np.cross(a, b)
    dof = str(rng.choice(["varus_valgus", "axial_rotation", "ball"]))
    t = np.arange(N) / RATE
    e = {"name": "extra_dof", "dof": dof, "b_axis": b.tolist(), "c_axis": c.tolist()}
    spectrum = str(rng.choice(["slow", "broadband"]))
    fhi = 0.4 if spectrum == "slow" else 1.5

    def prof(lo, hi):
        comps = rand_comps(rng, int(rng.integers(3, 8)), 0.03, fhi)
        A = sweep_size(spec, float(rng.uniform(lo, hi)), scale=hi)   # sweep: 0.05-1 x hi
        return comps, A / float(np.abs(sinsum(t, comps)).max()), A
    if dof in ("varus_valgus", "ball"):
        e["vv_comps"], e["vv_scale"], e["vv_peak_deg"] = prof(4, 12)
    if dof in ("axial_rotation", "ball"):
        e["ax_comps"], e["ax_scale"], e["ax_peak_deg"] = prof(5, 15)
    e["shape"] = f"{dof}_{spectrum}_random"
    e["where"] = {"joint": "knee", "dof": dof}
    return e


def build_time_offset(rng, spec, ang):
    g = spec["_geom"]
    s = str(rng.choice(SEGMENTS, p=[0.2, 0.4, 0.4]))
    if rng.random() < 0.2:
        mk = [str(rng.choice(list(g["markers"][s])))]; shape = "single_marker"
    else:
        mk = list(g["markers"][s]); shape = "whole_segment"
    if "sweep" in spec:        # sweep mode: fractional lag, log-uniform 0.05-4 frames
        d = sweep_size(spec, None, digits=4); shape += "_fractional_lag"
    elif rng.random() < 0.75:
        d = float(rng.integers(1, 5)); shape += "_integer_lag"
    else:
        d = round(float(rng.uniform(1.0, 4.0)), 2); shape += "_fractional_lag"
    e = {"name": "time_offset", "shape": shape, "markers": mk, "delay_frames": d}
    e["where"] = {"segment": s, "markers": mk, "delay_frames": d, "delay_s": d / RATE}
    return e


def outlier_cells_ok(spec):
    """(N,M) bool: samples an outlier may hit (v2): visible in the rigid trial and in the
    written trial (relabelled by a marker_swap built before), so every outlier shows."""
    return visible(spec, active=[]) & visible(spec)


def build_outliers(rng, spec, ang):
    """outliers: see README.  v2 adds `heavy_tailed` (build_outliers_heavy) and keeps every
    outlier sample visible."""
    g = spec["_geom"]; N = spec["n_frames"]
    names = [m for _, m in marker_order(g)]
    peak = sweep_size(spec, loguniform(rng, 5.0, 60.0))
    styles = ["isolated_spikes", "short_bursts", "axis_jumps", "mixed"]
    style = str(rng.choice(styles + (["heavy_tailed"] if is_v2(spec) else [])))
    if style == "heavy_tailed":
        return build_outliers_heavy(rng, spec, peak)
    ok = outlier_cells_ok(spec) if is_v2(spec) else None
    n_ev = int(rng.integers(3, 26))
    used = set(); events = []
    while len(events) < n_ev:
        m = str(rng.choice(names))
        st = style if style != "mixed" else str(rng.choice(["isolated_spikes", "short_bursts", "axis_jumps"]))
        L = 1 if st != "short_bursts" else int(rng.integers(2, 6))
        f = int(rng.integers(0, N - L))
        cells = {(m, f + i) for i in range(L)}
        if cells & used:
            continue
        if ok is not None and not ok[f:f + L, names.index(m)].all():
            continue
        used |= cells
        if st == "axis_jumps":
            d = np.zeros(3); d[int(rng.integers(0, 3))] = rng.choice([-1, 1])
        else:
            d = unit(rng.normal(size=3))
        mag = peak if not events else peak * rng.uniform(0.4, 1.0)
        events.append({"marker": m, "frame": f, "length": L, "vector_mm": (mag * d).tolist()})
    frames = sorted({f for _, f in used})
    e = {"name": "outliers", "shape": style, "events": events, "target_peak_mm": peak}
    e["where"] = {"markers": sorted({m for m, _ in used}), "frames": frames,
                  "frame_numbers": [f + 1 for f in frames],
                  "samples": [{"marker": ev["marker"], "frames": list(range(ev["frame"], ev["frame"] + ev["length"]))}
                              for ev in events]}
    return e


def outliers_where(events):
    """`where` of an outliers effect from its events (markers, frames, every sample)."""
    used = {(ev["marker"], ev["frame"] + i) for ev in events for i in range(ev["length"])}
    frames = sorted({f for _, f in used})
    return {"markers": sorted({m for m, _ in used}), "frames": frames,
            "frame_numbers": [f + 1 for f in frames],
            "samples": [{"marker": ev["marker"], "frames": list(range(ev["frame"], ev["frame"] + ev["length"]))}
                        for ev in events]}


def build_outliers_heavy(rng, spec, peak):
    """v2 outliers `heavy_tailed`: 30-200 single-sample deviations on distinct visible samples,
    random directions, magnitudes |t| (Student-t, nu 1.5-3) scaled so the largest equals the drawn
    peak (5-60 mm, log-uniform), floored at 1 mm."""
    g = spec["_geom"]
    names = [m for _, m in marker_order(g)]
    nu = float(rng.uniform(1.5, 3.0))
    n_ev = int(rng.integers(30, 201))
    cells = np.argwhere(outlier_cells_ok(spec))
    pick = cells[np.sort(rng.choice(len(cells), n_ev, replace=False))]
    tv = np.abs(rng.standard_t(nu, n_ev))
    mags = np.maximum(peak * tv / tv.max(), 1.0)
    mags[int(np.argmax(tv))] = peak
    events = []
    for (f, j), mag in zip(pick, mags):
        d = unit(rng.normal(size=3))
        events.append({"marker": names[int(j)], "frame": int(f), "length": 1, "vector_mm": (float(mag) * d).tolist()})
    e = {"name": "outliers", "shape": "heavy_tailed", "nu": nu, "events": events, "target_peak_mm": peak}
    e["where"] = outliers_where(events)
    return e


def build_spatial_distortion(rng, spec, ang):
    """spatial_distortion: see README (v2: NaN-aware centre and smooth_warp scaling)."""
    X, _, _, _ = simulate(spec, [], noise=False)
    mean = np.nanmean(X.reshape(-1, 3), 0) if is_v2(spec) else X.reshape(-1, 3).mean(0)
    c = np.array([mean[0] + rng.uniform(-400, 400), rng.uniform(600, 1200), mean[2] + rng.uniform(-400, 400)])
    shape = str(rng.choice(["radial_lens", "shear_plus_radial", "single_axis_scale", "smooth_warp"]))
    A = sweep_size(spec, float(rng.uniform(4, 12)))
    e = {"name": "spatial_distortion", "shape": shape, "centre_mm": c.tolist(), "mm_at_1500": A}
    sgn = float(rng.choice([-1, 1]))
    if shape == "radial_lens":
        e["k"] = sgn * A / 1500.0 ** 2
    elif shape == "shear_plus_radial":
        fr = rng.uniform(0.3, 0.7)
        e["k"] = sgn * (1 - fr) * A / 1500.0 ** 2
        S = np.zeros((3, 3)); i, j = rng.choice(3, 2, replace=False)
        S[i, j] = float(rng.choice([-1, 1])) * fr * A / 1500.0
        e["shear"] = S.tolist(); e["shear_component"] = [int(i), int(j)]
    elif shape == "single_axis_scale":
        ax = np.zeros(3); ax[int(rng.integers(0, 3))] = 1.0
        e["axis"] = ax.tolist(); e["eps"] = sgn * A / 1500.0
    else:
        modes = []
        for _ in range(int(rng.integers(2, 5))):
            lam = rng.uniform(2000, 6000)
            modes.append([unit(rng.normal(size=3)).tolist(), (2 * np.pi / lam * unit(rng.normal(size=3))).tolist(),
                          float(rng.uniform(0, 2 * np.pi))])
        e["modes"] = modes; e["scale"] = 1.0
        e["target_peak_mm"] = A * 0.6
        e["scale"] = e["target_peak_mm"] / float(np.nanmax(np.linalg.norm(distortion(e, X), axis=-1)))
    e["where"] = {"volume": "capture volume", "centre_mm": c.tolist()}
    return e


BUILDERS = {"soft_tissue": build_soft_tissue, "marker_slip": build_marker_slip,
            "marker_swap": build_marker_swap, "joint_translation": build_joint_translation,
            "extra_dof": build_extra_dof, "time_offset": build_time_offset,
            "outliers": build_outliers, "spatial_distortion": build_spatial_distortion}


# ----------------------------------------------------------------------------- trial assembly
def build_spec(seed, index, kind, names, version=1, cats=None):
    """Draw trial `index` of a dataset: v1 (stream [seed, index, 7919]) or v2 (build_spec_v2,
    with `cats` = (motion, layout, has_gaps) from plan_categories_v2)."""
    if version == 2:
        return build_spec_v2(seed, index, kind, names, *cats)
    rng = np.random.default_rng([seed, index, 7919])
    geom = make_geometry(rng)
    N = int(rng.integers(1000, 2001))
    motion_kind = "functional" if rng.random() < 0.5 else "gait"
    motion = make_motion(rng, motion_kind, geom, N, force_treadmill="spatial_distortion" in names)
    nm = "white" if rng.random() < 0.5 else "ar1"
    noise = {"model": nm, "sigma_mm": float(rng.uniform(0.3, 1.0)), "seed": int(rng.integers(0, 2 ** 31))}
    if nm == "ar1":
        noise["phi"] = float(rng.uniform(0.6, 0.9))
    spec = {"n_frames": N, "rate_hz": RATE, "geometry": geometry_to_json(geom), "_geom": geom,
            "motion": motion, "noise": noise, "effects": []}
    ang = eval_motion(motion, np.arange(N) / RATE)
    for nme in names:
        e = BUILDERS[nme](rng, spec, ang)
        spec["effects"].append(e)
    # record the realised peak displacement of every effect, each in isolation, noise-free
    for e in spec["effects"]:
        e["magnitude_mm"] = peak_disp(spec, e["name"])
    return spec


def plan_categories_v2(n, seed):
    """v2 categories per trial, balanced and randomly assigned (own stream [seed, 1234567, 2]):
    motion sit_to_stand round(n/3), the rest split functional / gait; layout anatomical
    round(n/2); occlusion gaps in round(0.6 n) trials.  Returns [(motion, layout, has_gaps)]."""
    rng = np.random.default_rng([seed, 1234567, 2])
    n_s2s = int(round(n / 3)); n_fun = int(round((n - n_s2s) / 2))
    motions = ["sit_to_stand"] * n_s2s + ["functional"] * n_fun + ["gait"] * (n - n_s2s - n_fun)
    n_anat = int(round(0.5 * n)); n_gaps = int(round(0.6 * n))
    layouts = ["anatomical"] * n_anat + ["clusters"] * (n - n_anat)
    gaps = [True] * n_gaps + [False] * (n - n_gaps)
    cols = [[c[i] for i in rng.permutation(n)] for c in (motions, layouts, gaps)]
    return list(zip(*cols))


def build_spec_v2(seed, index, kind, names, motion_kind, layout, has_gaps):
    """Draw a v2 trial from its own stream [seed, index, 7919, 2], given its categories: subject
    (v1 clusters or anatomical layout), 1000-2000 frames, motion, noise (sigma 0.3-1.5 mm),
    occlusion gaps (when has_gaps), then the effects.  A marker_swap is built first (outliers
    avoid the samples it hides); effects are listed in `names` order."""
    rng = np.random.default_rng([seed, index, 7919, 2])
    geom = make_geometry_anatomical(rng) if layout == "anatomical" else make_geometry(rng)
    N = int(rng.integers(1000, 2001))
    motion = make_motion(rng, motion_kind, geom, N, force_treadmill="spatial_distortion" in names)
    nm = "white" if rng.random() < 0.5 else "ar1"
    noise = {"model": nm, "sigma_mm": float(rng.uniform(0.3, 1.5)), "seed": int(rng.integers(0, 2 ** 31))}
    if nm == "ar1":
        noise["phi"] = float(rng.uniform(0.6, 0.9))
    gaps = make_gaps(rng, geom, N) if has_gaps else []
    spec = {"version": 2, "layout": layout, "n_frames": N, "rate_hz": RATE, "geometry": geometry_to_json(geom),
            "_geom": geom, "motion": motion, "noise": noise, "gaps": gaps, "effects": []}
    ang = eval_motion(motion, np.arange(N) / RATE)
    for nme in sorted(names, key=lambda x: x != "marker_swap"):
        spec["effects"].append(BUILDERS[nme](rng, spec, ang))
    spec["effects"].sort(key=lambda e: names.index(e["name"]))
    for e in spec["effects"]:
        e["magnitude_mm"] = peak_disp(spec, e["name"])
    return spec


SWEEP_STREAM = 4242
SWEEP_FRAMES = (500, 3000)
SWEEP_SIGMA_MM = (0.3, 1.5)
SWEEP_CYCLES = (1, 12)          # sit_to_stand cycles allowed in a 5-30 s sweep trial


def build_spec_sweep(seed, trial_index, name):
    """Draw sweep trial `trial_index` of effect `name` from its own stream
    [seed, EFFECTS.index(name), trial_index, 4242] (so a trial does not depend on which other
    effects are swept): motion, layout and gaps uniformly at random, the effect's size quantile,
    500-3000 frames (log-uniform), the subject, motion, noise (white / ar1, sigma log-uniform
    0.3-1.5 mm, phi 0.6-0.9), gaps, then the single effect with v2's shapes and its size from
    SWEEP_SIZES.  In the rare case that the effect cannot be placed (RuntimeError: no admissible
    swap / slip onset), the whole trial is redrawn from [seed, e, trial_index, 4242, attempt]."""
    eff_index = EFFECTS.index(name)
    for attempt in range(50):
        key = [seed, eff_index, trial_index, SWEEP_STREAM] + ([attempt] if attempt else [])
        rng = np.random.default_rng(key)
        motion_kind = str(rng.choice(["functional", "gait", "sit_to_stand"]))
        layout = str(rng.choice(["anatomical", "clusters"]))
        has_gaps = bool(rng.random() < 0.5)
        size_u = float(rng.random())
        N = int(min(SWEEP_FRAMES[1], math.floor(loguniform(rng, SWEEP_FRAMES[0], SWEEP_FRAMES[1] + 1))))
        geom = make_geometry_anatomical(rng) if layout == "anatomical" else make_geometry(rng)
        motion = make_motion(rng, motion_kind, geom, N, force_treadmill=name == "spatial_distortion",
                             s2s_cycles=SWEEP_CYCLES)
        nm = "white" if rng.random() < 0.5 else "ar1"
        noise = {"model": nm, "sigma_mm": loguniform(rng, *SWEEP_SIGMA_MM), "seed": int(rng.integers(0, 2 ** 31))}
        if nm == "ar1":
            noise["phi"] = float(rng.uniform(0.6, 0.9))
        gaps = make_gaps(rng, geom, N) if has_gaps else []
        spec = {"version": 2, "sweep": {"effect": name, "effect_index": eff_index, "trial_index": trial_index,
                                        "stream": key, "attempt": attempt, "size_u": size_u},
                "layout": layout, "n_frames": N, "rate_hz": RATE, "geometry": geometry_to_json(geom),
                "_geom": geom, "motion": motion, "noise": noise, "gaps": gaps, "effects": []}
        ang = eval_motion(motion, np.arange(N) / RATE)
        try:
            e = BUILDERS[name](rng, spec, ang)
        except RuntimeError:
            continue
        e["size"] = spec.pop("_size")
        if name == "extra_dof":      # value: the larger amplitude (axial for `ball`)
            e["size"]["value"] = max(e.get("vv_peak_deg", 0.0), e.get("ax_peak_deg", 0.0))
            e["size"]["range"] = [r * (15.0 if e["dof"] != "varus_valgus" else 12.0) for r in SWEEP_SIZES[name][1:]]
            e["size"]["fraction"] = SWEEP_SIZES[name][1] * (SWEEP_SIZES[name][2] / SWEEP_SIZES[name][1]) ** size_u
        spec["effects"].append(e)
        e["magnitude_mm"] = peak_disp(spec, name)
        return spec
    raise RuntimeError(f"sweep trial {name} {trial_index}: no admissible draw")


def spec_json(spec):
    return {k: v for k, v in spec.items() if not k.startswith("_")}


def plan_trials(n, seed):
    rng = np.random.default_rng([seed, 1234567])
    n_clean = int(round(0.12 * n)); n_pair = int(round(0.18 * n)); n_single = n - n_clean - n_pair
    singles = []
    while len(singles) < n_single:
        blk = list(EFFECTS); rng.shuffle(blk); singles += blk
    singles = singles[:n_single]
    pool = []
    while len(pool) < 2 * n_pair:
        blk = list(EFFECTS); rng.shuffle(blk); pool += blk
    pairs = []
    pool = pool[:2 * n_pair]
    for i in range(n_pair):
        a, b = pool[2 * i], pool[2 * i + 1]
        if a == b:                      # re-pair with a later partner
            for j in range(2 * i + 2, len(pool)):
                if pool[j] != a:
                    pool[2 * i + 1], pool[j] = pool[j], pool[2 * i + 1]
                    break
            else:
                pool[2 * i + 1] = str(rng.choice([x for x in EFFECTS if x != a]))
            b = pool[2 * i + 1]
        pairs.append([a, b])
    plan = [("clean", [])] * n_clean + [("single", [s]) for s in singles] + [("pair", p) for p in pairs]
    order = rng.permutation(len(plan))
    return [plan[i] for i in order]


def write_trc(path, X, names):
    """OpenSim TRC, mm, 4 decimals; a missing (NaN) sample is written as empty fields."""
    N, M, _ = X.shape
    stem = os.path.basename(path)
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{stem}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{RATE:g}\t{RATE:g}\t{N}\t{M}\tmm\t{RATE:g}\t1\t{N}",
             "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
             "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(M)),
             ""]
    flat = X.reshape(N, 3 * M)
    for f in range(N):
        lines.append(f"{f + 1}\t{f / RATE:.4f}\t" + "\t".join("" if v != v else f"{v:.4f}" for v in flat[f]))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_toml(path, g):
    out = ['units = "mm"', ""]
    for s in SEGMENTS:
        out += [f"[segments.{s}]", "markers = [" + ", ".join(f'"{m}"' for m in g["markers"][s]) + "]", ""]
    out += ["[joints.hip]", 'type = "spherical"', 'parent = "pelvis"', 'child = "thigh"', "",
            "[joints.knee]", 'type = "revolute"', 'parent = "thigh"', 'child = "shank"', ""]
    with open(path, "w") as fh:
        fh.write("\n".join(out))


def trial_entry(stem, kind, spec):
    """Index entry of a trial (v2 adds category.gaps / category.layout and params.layout / gaps)."""
    m = spec["motion"]; g = spec["_geom"]
    params = {"n_frames": spec["n_frames"], "rate_hz": RATE,
              "thigh_length_mm": g["thigh_length"], "shank_length_mm": g["shank_length"],
              "knee_axis_tilt_deg": float(math.degrees(math.acos(abs(g["knee_axis_in_thigh"][2])))),
              "markers_per_segment": {s: len(g["markers"][s]) for s in SEGMENTS},
              "motion": m["kind"], "treadmill": m["treadmill"],
              "speed_mm_s": m.get("speed_mm_s"),
              "noise": {k: v for k, v in spec["noise"].items()},
              "effect_params": [{k: v for k, v in e.items()
                                 if k not in ("where", "coef", "parts", "events", "modes", "vv_comps", "ax_comps", "size")}
                                for e in spec["effects"]]}
    effects = [{"name": e["name"], "where": e["where"], "magnitude_mm": e["magnitude_mm"], "shape": e["shape"]}
               for e in spec["effects"]]
    for rec, e in zip(effects, spec["effects"]):
        if "size" in e:                                  # sweep mode
            rec["size"] = e["size"]
    category = {"motion": m["kind"], "noise": spec["noise"]["model"], "kind": kind}
    if is_v2(spec):
        category["gaps"] = bool(spec["gaps"])
        category["layout"] = spec["layout"]
        params["layout"] = spec["layout"]
        params["gaps"] = spec["gaps"]
        if m["kind"] == "sit_to_stand":
            params["sit_to_stand_cycles"] = m["n_cycles"]
    if "sweep" in spec:
        nz = spec["noise"]
        params["frames"] = spec["n_frames"]
        params["noise"] = {"kind": nz["model"], "sigma_mm": nz["sigma_mm"], "phi": nz.get("phi"),
                           "model": nz["model"], "seed": nz["seed"]}
    return {"stem": stem, "effects": effects, "category": category, "params": params}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--n", type=int, default=120)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--version", type=int, default=1, choices=[1, 2],
                    help="1: heldout-effects v1 (default, unchanged); 2: v1 plus gaps, sit_to_stand, "
                         "anatomical layout, noise up to 1.5 mm and new effect shapes")
    ap.add_argument("--sweep", default=None, metavar="EFFECT[,EFFECT...]",
                    help="sweep mode (needs --version 2): N single-effect trials per listed effect ('all': all "
                         "eight), each with its size, noise and length drawn over wide ranges (README: Sweep mode)")
    args = ap.parse_args(argv)
    if args.sweep is not None:
        if args.version != 2:
            ap.error("--sweep needs --version 2")
        names = list(EFFECTS) if args.sweep.strip() == "all" else [x.strip() for x in args.sweep.split(",") if x.strip()]
        bad = [x for x in names if x not in EFFECTS]
        if bad or not names or len(set(names)) != len(names):
            ap.error(f"--sweep: unknown or repeated effect(s) {bad or names}; choose from {', '.join(EFFECTS)} or 'all'")
        return main_sweep(args, names)
    os.makedirs(args.out, exist_ok=True)
    trials = []
    cats = plan_categories_v2(args.n, args.seed) if args.version == 2 else [None] * args.n
    for i, (kind, names) in enumerate(plan_trials(args.n, args.seed)):
        stem = f"trial_{i:04d}"
        spec = build_spec(args.seed, i, kind, names, version=args.version, cats=cats[i])
        X, mnames, _, _ = simulate(spec)
        write_trc(os.path.join(args.out, stem + ".trc"), X, mnames)
        write_toml(os.path.join(args.out, stem + ".toml"), spec["_geom"])
        entry = trial_entry(stem, kind, spec)
        truth = dict(entry)
        truth["joints"] = truth_distances(spec["_geom"])
        if args.version == 2:
            truth["gaps"] = spec["gaps"]
        truth["spec"] = spec_json(spec)
        with open(os.path.join(args.out, stem + ".truth.json"), "w") as fh:
            json.dump(truth, fh, indent=1)
        trials.append(entry)
    with open(os.path.join(args.out, "index.json"), "w") as fh:
        if args.version == 2:
            json.dump({"generator": GENERATOR_V2, "version": 2, "seed": args.seed, "trials": trials}, fh, indent=1)
        else:
            json.dump({"generator": GENERATOR, "seed": args.seed, "trials": trials}, fh, indent=1)
    print(f"wrote {len(trials)} trials to {args.out}")


def write_trial(out, stem, kind, spec):
    """Write one v2 trial (TRC, TOML, truth) and return its index entry."""
    X, mnames, _, _ = simulate(spec)
    write_trc(os.path.join(out, stem + ".trc"), X, mnames)
    write_toml(os.path.join(out, stem + ".toml"), spec["_geom"])
    entry = trial_entry(stem, kind, spec)
    truth = dict(entry)
    truth["joints"] = truth_distances(spec["_geom"])
    truth["gaps"] = spec["gaps"]
    truth["spec"] = spec_json(spec)
    with open(os.path.join(out, stem + ".truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1)
    return entry


def main_sweep(args, names):
    """Sweep mode: args.n single-effect trials per effect in `names`, stems numbered across the run."""
    import time
    os.makedirs(args.out, exist_ok=True)
    trials, times = [], []
    for name in names:
        for i in range(args.n):
            t0 = time.time()
            spec = build_spec_sweep(args.seed, i, name)
            trials.append(write_trial(args.out, f"trial_{len(trials):04d}", "single", spec))
            times.append(time.time() - t0)
    with open(os.path.join(args.out, "index.json"), "w") as fh:
        json.dump({"generator": GENERATOR_V2, "version": 2, "seed": args.seed, "sweep": True, "effects": names,
                   "n_per_effect": args.n, "trials": trials}, fh, indent=1)
    print(f"wrote {len(trials)} sweep trials ({args.n} per effect: {', '.join(names)}) to {args.out}; "
          f"{sum(times):.1f} s, {np.mean(times):.2f} s a trial (max {max(times):.2f} s)")


if __name__ == "__main__":
    main()
