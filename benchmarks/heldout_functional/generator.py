#!/usr/bin/env python3
"""Held-out generator of full-body *functional trials* (see README.md).

A 15-segment body stands nearly still (postural sway) while one or two joints
perform a functional motion (star-arc / circumduction for spherical joints,
flexion cycles for hinges).  Markers carry soft-tissue artefact driven by the
angles of the joints adjacent to their segment, measurement noise (white, plus
AR(1) or low-pass coloured noise in half the trials) and occasional gaps.

Written from the written specification only; it shares no code with the tool
under test.  Only numpy and scipy are used.

    python benchmarks/heldout_functional/generator.py --out DIR --n N --seed S
    python benchmarks/heldout_functional/generator.py --check DIR   # self-check
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np
from scipy.signal import butter, filtfilt, lfilter

RATE_HZ = 100.0

SEGMENTS = [
    "pelvis", "trunk", "head",
    "upperarm_r", "forearm_r", "hand_r", "upperarm_l", "forearm_l", "hand_l",
    "thigh_r", "shank_r", "foot_r", "thigh_l", "shank_l", "foot_l",
]

# (joint, parent, child, type) in topological order (parent before child).
JOINTS = [
    ("lumbar", "pelvis", "trunk", "spherical"),
    ("neck", "trunk", "head", "spherical"),
    ("shoulder_r", "trunk", "upperarm_r", "spherical"),
    ("elbow_r", "upperarm_r", "forearm_r", "revolute"),
    ("wrist_r", "forearm_r", "hand_r", "spherical"),
    ("shoulder_l", "trunk", "upperarm_l", "spherical"),
    ("elbow_l", "upperarm_l", "forearm_l", "revolute"),
    ("wrist_l", "forearm_l", "hand_l", "spherical"),
    ("hip_r", "pelvis", "thigh_r", "spherical"),
    ("knee_r", "thigh_r", "shank_r", "revolute"),
    ("ankle_r", "shank_r", "foot_r", "spherical"),
    ("hip_l", "pelvis", "thigh_l", "spherical"),
    ("knee_l", "thigh_l", "shank_l", "revolute"),
    ("ankle_l", "shank_l", "foot_l", "spherical"),
]
JOINT_BY_NAME = {j[0]: j for j in JOINTS}
PARENT_JOINT = {j[2]: j[0] for j in JOINTS}          # child segment -> joint
CHILD_JOINTS = {s: [j[0] for j in JOINTS if j[1] == s] for s in SEGMENTS}

SEG_CLASS = {
    "pelvis": "core", "trunk": "core", "head": "distal",
    "upperarm_r": "long", "upperarm_l": "long", "forearm_r": "long",
    "forearm_l": "long", "thigh_r": "long", "thigh_l": "long",
    "shank_r": "long", "shank_l": "long",
    "hand_r": "distal", "hand_l": "distal", "foot_r": "distal", "foot_l": "distal",
}

# Amplitudes (deg) of (flexion, abduction, axial rotation) for a moving
# spherical joint.  Hip/shoulder follow the spec; ankle and wrist (not given
# numerically in the spec) use smaller physiological ranges.
SPHERICAL_AMPS = {
    "hip": ((30, 60), (15, 30), (10, 20)),
    "shoulder": ((30, 60), (15, 30), (10, 20)),
    "ankle": ((15, 30), (10, 20), (5, 10)),
    "wrist": ((25, 50), (10, 20), (3, 8)),
}
# Reference amplitude (deg) used to make sway-driven soft-tissue artefact
# "proportionally small": a still joint with peak sway angle a contributes
# target_peak * a / REF.
REF_AMP_DEG = {"spherical": 45.0, "revolute": 75.0}


# --------------------------------------------------------------------------
# rotation helpers (vectorised over frames)
# --------------------------------------------------------------------------
def rot_about(axis, ang):
    """Rotation matrices (F,3,3) about unit vector `axis` by angles `ang` (rad)."""
    axis = np.asarray(axis, float)
    axis = axis / np.linalg.norm(axis)
    ang = np.atleast_1d(np.asarray(ang, float))
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    s = np.sin(ang)[:, None, None]
    c = np.cos(ang)[:, None, None]
    return np.eye(3)[None] + s * K[None] + (1 - c) * (K @ K)[None]


def euler_zxy(fz, ax, ry):
    """R = Rz(fz) Rx(ax) Ry(ry), each an array of angles (rad)."""
    return rot_about([0, 0, 1], fz) @ rot_about([1, 0, 0], ax) @ rot_about([0, 1, 0], ry)


# --------------------------------------------------------------------------
# signal helpers
# --------------------------------------------------------------------------
def sines(rng, t, fmin, fmax, k=3):
    """Sum of k sinusoids with random frequency/phase/weight, zero-ish mean."""
    out = np.zeros_like(t)
    for _ in range(k):
        f = rng.uniform(fmin, fmax)
        out += rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    return out


def norm_peak(x, peak):
    m = np.max(np.abs(x))
    return x * (peak / m) if m > 0 else x


def sway(rng, t, amp):
    """Slow postural sway (0.05-0.5 Hz) with peak |value| == amp."""
    return norm_peak(sines(rng, t, 0.05, 0.5, k=int(rng.integers(2, 4))), amp)


def start_envelope(rng, t):
    """0 during an initial quiet stance, smooth ramp to 1, then 1."""
    t0 = rng.uniform(0.3, 1.5)
    tr = rng.uniform(0.5, 1.2)
    e = np.clip((t - t0) / tr, 0, 1)
    return 0.5 - 0.5 * np.cos(np.pi * e)


def spherical_motion(rng, t, amps_deg):
    """Functional motion (deg) of a moving spherical joint -> (F,3), pattern."""
    F = len(t)
    af, aa, ar = amps_deg
    pattern = str(rng.choice(["star_arc", "circumduction", "sines"], p=[0.4, 0.35, 0.25]))
    flex = np.zeros(F)
    abd = np.zeros(F)
    if pattern == "sines":
        flex = norm_peak(sines(rng, t, 0.2, 1.0, k=int(rng.integers(2, 4))), af)
        abd = norm_peak(sines(rng, t, 0.2, 1.0, k=int(rng.integers(2, 4))), aa)
    else:
        i = 0
        if pattern == "star_arc":
            n_dir = int(rng.choice([4, 6, 8]))
            base = rng.uniform(0, 2 * np.pi)
            # opposite directions consecutively: 0, pi, step, pi+step, ...
            dirs = []
            for k in range(n_dir // 2):
                th = base + k * 2 * np.pi / n_dir
                dirs += [th, th + np.pi]
            dirs = [d + rng.normal(0, 0.1) for d in dirs]
            for th in dirs:
                T = 1.0 / rng.uniform(0.2, 1.0)
                n = int(round(T * RATE_HZ))
                if i >= F:
                    break
                tau = np.arange(n) / RATE_HZ
                prof = (0.5 - 0.5 * np.cos(2 * np.pi * tau / T)) * rng.uniform(0.8, 1.0)
                m = min(n, F - i)
                flex[i:i + m] = af * np.cos(th) * prof[:m]
                abd[i:i + m] = aa * np.sin(th) * prof[:m]
                i += m
        if i < F:  # circumduction for the rest (possibly reversing direction)
            tt = t[i:] - t[i]
            fc = rng.uniform(0.2, 0.6)
            sgn = np.ones_like(tt)
            if rng.random() < 0.5:
                sgn[len(tt) // 2:] = -1.0
            ph = 2 * np.pi * fc * tt * sgn
            # after a star arc, fade the circle in from neutral over 1 s
            ramp = np.clip(tt / 1.0, 0, 1) if i > 0 else np.ones_like(tt)
            flex[i:] = af * np.sin(ph) * ramp
            abd[i:] = aa * np.cos(ph) * ramp
    rot = norm_peak(sines(rng, t, 0.2, 1.0, k=2), ar)
    env = start_envelope(rng, t)
    q = np.stack([flex, abd, rot], 1) * env[:, None]
    return q, pattern


def hinge_motion(rng, t, base_deg, range_deg):
    """Hinge flexion (deg) from base to base+range, smooth."""
    pattern = str(rng.choice(["cycles", "sines"], p=[0.6, 0.4]))
    if pattern == "cycles":
        f = rng.uniform(0.2, 1.0)
        g = 0.5 - 0.5 * np.cos(2 * np.pi * f * t)
        # cycle-to-cycle depth variation
        depth = 1.0 + 0.2 * sines(rng, t, 0.02, 0.1, k=1)
        g = g * depth
    else:
        s = sines(rng, t, 0.2, 1.0, k=int(rng.integers(2, 4)))
        g = s - s.min()
    g = g * start_envelope(rng, t)
    g = g - g.min()
    g = g / g.max()
    return base_deg + range_deg * g, pattern


# --------------------------------------------------------------------------
# body geometry and marker candidates
# --------------------------------------------------------------------------
def draw_dims(rng):
    def v(mid):
        return mid * rng.uniform(0.9, 1.1)
    return {
        "pelvis_width": v(250.0), "thigh": v(425.0), "shank": v(400.0),
        "foot": v(240.0), "trunk": v(475.0), "upperarm": v(300.0),
        "forearm": v(260.0), "hand": v(185.0), "shoulder_half": v(175.0),
        "head": v(230.0), "ankle_height": v(75.0),
    }


def joint_offsets(d, rng):
    """Joint-centre positions in the parent segment frame (x ant, y up, z right)."""
    W = d["pelvis_width"]
    off = {}
    hip = np.array([-0.19 * W, -0.30 * W, 0.36 * W])
    off["hip_r"] = hip
    off["hip_l"] = hip * [1, 1, -1]
    off["lumbar"] = np.array([-0.40 * W, 0.15 * W, 0.0])
    off["neck"] = np.array([5.0, d["trunk"], 0.0])
    sh = np.array([-15.0, d["trunk"] - 50.0, d["shoulder_half"]])
    off["shoulder_r"] = sh
    off["shoulder_l"] = sh * [1, 1, -1]
    for s in "rl":
        off["elbow_" + s] = np.array([0.0, -d["upperarm"], 0.0])
        off["wrist_" + s] = np.array([0.0, -d["forearm"], 0.0])
        off["knee_" + s] = np.array([0.0, -d["thigh"], 0.0])
        off["ankle_" + s] = np.array([0.0, -d["shank"], 0.0])
    for k in off:  # a few mm of individual variation
        off[k] = off[k] + rng.normal(0, 3.0, 3)
    return off


def anatomical_candidates(seg, d, off, rng):
    """List of (type_key, position_in_segment_frame, side or None, near_joint)."""
    W = d["pelvis_width"]
    side = seg[-1] if seg.endswith(("_r", "_l")) else None
    c = []
    if seg == "pelvis":
        for sd, m in (("r", 1), ("l", -1)):
            c.append(("ASIS", [0, 0, m * W / 2], sd, False))
            c.append(("PSIS", [-0.62 * W, 0.10 * W, m * 0.18 * W], sd, False))
            c.append(("ILC", [-0.25 * W, 0.30 * W, m * 0.55 * W], sd, False))
        c.append(("SACR", [-0.70 * W, 0.05 * W, 0], None, False))
    elif seg == "trunk":
        L = d["trunk"]
        nk = off["neck"]
        c.append(("C7", [nk[0] - 70, nk[1] + 5, 0], None, True))
        c.append(("T10", [-100, 0.40 * L, 0], None, False))
        c.append(("CLAV", [65, L - 35, 0], None, False))
        c.append(("STRN", [105, L - 180, 0], None, False))
        for sd, m in (("r", 1), ("l", -1)):
            sh = off["shoulder_" + sd]
            c.append(("ACR", [sh[0] - 5, sh[1] + 45, sh[2] + m * 12], sd, True))
            c.append(("SCAP", [-105, L - 130, m * 95], sd, False))
    elif seg == "head":
        H = d["head"]
        for sd, m in (("r", 1), ("l", -1)):
            c.append(("FHD", [85, 0.62 * H, m * 55], sd, False))
            c.append(("BHD", [-90, 0.57 * H, m * 55], sd, False))
        c.append(("VERT", [0, 0.96 * H, 0], None, False))
    else:
        m = 1.0 if side == "r" else -1.0
        kind = seg[:-2]
        if kind == "thigh":
            L = d["thigh"]
            c.append(("GT", [0, -15, 75], side, True))
            c.append(("LFE", [0, -L, rng.uniform(45, 55)], side, True))
            c.append(("MFE", [0, -L, -rng.uniform(45, 55)], side, True))
        elif kind == "shank":
            L = d["shank"]
            c.append(("FH", [-15, -30, 45], side, True))
            c.append(("TT", [40, -60, 0], side, True))
            c.append(("LMAL", [-8, -L - 5, rng.uniform(30, 40)], side, True))
            c.append(("MMAL", [8, -L + 10, -rng.uniform(30, 40)], side, True))
        elif kind == "foot":
            Lf = d["foot"]
            ah = d["ankle_height"]
            c.append(("HEE", [-0.23 * Lf, -0.6 * ah, 0], side, False))
            c.append(("MT1", [0.58 * Lf, -0.85 * ah, -32], side, False))
            c.append(("MT5", [0.48 * Lf, -0.85 * ah, 38], side, False))
            c.append(("TOE", [0.72 * Lf, -0.7 * ah, 0], side, False))
            c.append(("NAV", [0.28 * Lf, -0.45 * ah, -38], side, False))
        elif kind == "upperarm":
            L = d["upperarm"]
            c.append(("LHE", [0, -L, rng.uniform(35, 45)], side, True))
            c.append(("MHE", [0, -L, -rng.uniform(38, 48)], side, True))
            c.append(("DELT", [15, -0.40 * L, 50], side, False))
        elif kind == "forearm":
            L = d["forearm"]
            c.append(("RS", [10, -L, 32], side, True))
            c.append(("US", [-10, -L, -28], side, True))
            c.append(("OLE", [-30, -15, 0], side, True))
        elif kind == "hand":
            c.append(("MCP2", [25, -80, 15], side, False))
            c.append(("MCP5", [-25, -75, 15], side, False))
            c.append(("HDOR", [0, -45, 25], side, False))
            c.append(("FIN", [0, -0.92 * d["hand"], 0], side, False))
        # right-side coordinates above; mirror z for the left side
        c = [(k, [p[0], p[1], m * p[2]], sd, nj) for (k, p, sd, nj) in c]
    return [(k, np.asarray(p, float) + rng.normal(0, 4.0, 3), sd, nj) for (k, p, sd, nj) in c]


def cluster_position(seg, d, rng):
    """One technical marker position in the segment frame."""
    side = seg[-1] if seg.endswith(("_r", "_l")) else None
    m = -1.0 if side == "l" else 1.0
    kind = seg[:-2] if side else seg
    if kind in ("thigh", "shank", "upperarm", "forearm"):
        L = d[kind]
        y = -rng.uniform(0.2, 0.8) * L
        if kind in ("thigh", "shank"):
            phi = np.radians(rng.uniform(-60, 120))   # lateral .. anterior
        else:
            phi = np.radians(rng.uniform(-120, 60))   # posterior .. lateral
        r = rng.uniform(60, 150)
        return np.array([r * np.sin(phi), y, m * r * np.cos(phi)])
    if kind == "pelvis":
        W = d["pelvis_width"]
        if rng.random() < 0.5:   # sacral cluster
            return np.array([-rng.uniform(150, 230), rng.uniform(-10, 90), rng.uniform(-90, 90)])
        s = rng.choice([-1.0, 1.0])
        return np.array([rng.uniform(-70, 30), rng.uniform(20, 90), s * (W / 2 + rng.uniform(20, 60))])
    if kind == "trunk":
        L = d["trunk"]
        if rng.random() < 0.6:
            return np.array([-rng.uniform(110, 170), rng.uniform(0.3, 0.95) * L, rng.uniform(-110, 110)])
        return np.array([rng.uniform(90, 150), rng.uniform(0.45, 0.9) * L, rng.uniform(-110, 110)])
    if kind == "head":
        v = rng.normal(size=3)
        v[1] = abs(v[1]) + 0.3
        v /= np.linalg.norm(v)
        return np.array([15.0, 0.5 * d["head"], 0.0]) + rng.uniform(95, 120) * v
    if kind == "foot":
        Lf = d["foot"]
        if rng.random() < 0.8:
            x = rng.uniform(0.0, 0.55) * Lf
            y = -15 - 35 * x / (0.55 * Lf) + rng.uniform(0, 25)
            return np.array([x, y, rng.uniform(-40, 45) * m])
        return np.array([rng.uniform(-60, -20), rng.uniform(-45, -15), m * rng.uniform(40, 60)])
    if kind == "hand":
        return np.array([rng.uniform(-35, 35), -rng.uniform(30, 120), m * rng.uniform(20, 45)])
    raise ValueError(seg)


# --------------------------------------------------------------------------
# names
# --------------------------------------------------------------------------
ANAT_NAME_OPTIONS = {
    "ASIS": ["ASI", "ASIS"], "PSIS": ["PSI", "PSIS"], "ILC": ["ILC", "ICR"],
    "SACR": ["SACR", "SAC", "S1"], "C7": ["C7"], "T10": ["T10", "TH10"],
    "CLAV": ["CLAV", "IJ", "JN"], "STRN": ["STRN", "XP", "PX"],
    "ACR": ["ACR", "SHO", "AC"], "SCAP": ["SCAP", "BAK"],
    "FHD": ["FHD", "HF"], "BHD": ["BHD", "HB"], "VERT": ["VERT", "HTOP"],
    "GT": ["GTR", "TROC", "GT"], "LFE": ["KNE", "LFE", "LEPI"],
    "MFE": ["KNEM", "MFE", "MEPI"], "FH": ["FIBH", "FHEAD"],
    "TT": ["TT", "TIBT"], "LMAL": ["ANK", "LMAL", "LM"],
    "MMAL": ["ANKM", "MMAL", "MM"], "HEE": ["HEE", "HEEL", "CAL"],
    "MT1": ["MT1", "MET1", "FM1"], "MT5": ["MT5", "MET5", "FM5"],
    "TOE": ["TOE", "HLX"], "NAV": ["NAV", "TUB"],
    "LHE": ["ELB", "LHE", "LEL"], "MHE": ["MEL", "MHE", "ELBM"],
    "DELT": ["DELT", "DLT"], "RS": ["WRA", "RSP", "RS"],
    "US": ["WRB", "USP", "US"], "OLE": ["OLE", "OLC"],
    "MCP2": ["FIN2", "MH2", "MCP2"], "MCP5": ["MH5", "MCP5"],
    "HDOR": ["HAND", "HDO"], "FIN": ["FIN", "FT3"],
}
CLUSTER_BASES = {
    "pelvis": ["PEL", "SACC", "PV"], "trunk": ["TRK", "BCK", "CHST"],
    "head": ["HD", "HEAD", "CAP"], "thigh": ["THI", "TH", "UL"],
    "shank": ["TIB", "SHK", "LL"], "foot": ["FT", "FOOT", "MF"],
    "upperarm": ["UPA", "ARM", "UA"], "forearm": ["FRM", "FA", "LA"],
    "hand": ["HND", "HN", "MANU"],
}
SIDE_STYLES = [
    lambda s, b: ("R" if s == "r" else "L") + b,
    lambda s, b: ("R_" if s == "r" else "L_") + b,
    lambda s, b: b + ("_R" if s == "r" else "_L"),
    lambda s, b: ("r" if s == "r" else "l") + b,
    lambda s, b: ("R." if s == "r" else "L.") + b,
]
NEUTRAL_STYLES = ["M{:02d}", "Marker{}", "m{:03d}", "P{:02d}", "U{}"]


def assign_names(markers, rng, anatomical):
    """markers: list of dicts (seg, kind, key, side). Adds 'name' (unique)."""
    used = set()

    def unique(n):
        base, k = n, 2
        while n in used:
            n = f"{base}{k}"
            k += 1
        used.add(n)
        return n

    if not anatomical:
        style = NEUTRAL_STYLES[int(rng.integers(len(NEUTRAL_STYLES)))]
        start = int(rng.integers(0, 20))
        nums = rng.permutation(len(markers)) + start + 1
        for mk, n in zip(markers, nums):
            mk["name"] = unique(style.format(int(n)))
        return "neutral:" + style
    side_style = SIDE_STYLES[int(rng.integers(len(SIDE_STYLES)))]
    anat_choice = {k: v[int(rng.integers(len(v)))] for k, v in ANAT_NAME_OPTIONS.items()}
    cl_choice = {k: v[int(rng.integers(len(v)))] for k, v in CLUSTER_BASES.items()}
    p_neutral = rng.uniform(0.0, 0.5)
    neutral_nums = iter(rng.permutation(900) + 10)
    counters = {}
    # shuffle the order in which cluster indices are handed out
    for i in rng.permutation(len(markers)):
        mk = markers[i]
        if mk["kind"] == "anat":
            b = anat_choice[mk["key"]]
            n = side_style(mk["side"], b) if mk["side"] else b
        elif rng.random() < p_neutral:
            n = f"M{next(neutral_nums)}"
        else:
            seg = mk["seg"]
            kind = seg[:-2] if seg.endswith(("_r", "_l")) else seg
            b = cl_choice[kind]
            key = (b, mk["seg"])
            counters[key] = counters.get(key, 0) + 1
            b = f"{b}{counters[key]}"
            n = side_style(seg[-1], b) if seg.endswith(("_r", "_l")) else b
        mk["name"] = unique(n)
    return "anatomical"


# --------------------------------------------------------------------------
# one trial
# --------------------------------------------------------------------------
MOVE_SINGLE = [("hip", 0.25), ("knee", 0.2), ("shoulder", 0.2), ("elbow", 0.15),
               ("ankle", 0.12), ("wrist", 0.08)]
MOVE_PAIR = [(("hip", "knee"), 0.35), (("shoulder", "elbow"), 0.25),
             (("knee", "ankle"), 0.15), ("cross", 0.25)]


def choose_moving(rng):
    side = str(rng.choice(["r", "l"]))
    if rng.random() < 0.6:
        names = [k for k, _ in MOVE_SINGLE]
        p = np.array([w for _, w in MOVE_SINGLE])
        return [f"{names[int(rng.choice(len(names), p=p / p.sum()))]}_{side}"]
    p = np.array([w for _, w in MOVE_PAIR])
    pair = MOVE_PAIR[int(rng.choice(len(MOVE_PAIR), p=p / p.sum()))][0]
    if pair != "cross":
        return [f"{pair[0]}_{side}", f"{pair[1]}_{side}"]
    # two joints on different limbs
    limbs = {"leg": ["hip", "knee", "ankle"], "arm": ["shoulder", "elbow"]}
    a = f"{rng.choice(limbs['leg'] + limbs['arm'])}_{side}"
    other = "l" if side == "r" else "r"
    b = f"{rng.choice(limbs['leg'] + limbs['arm'])}_{other}"
    return [a, b]


def rigid_units(moving):
    parent = {s: s for s in SEGMENTS}

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for j, p, c, _ in JOINTS:
        if j not in moving:
            parent[find(c)] = find(p)
    groups = {}
    for s in SEGMENTS:
        groups.setdefault(find(s), []).append(s)
    return [g for g in groups.values()]


def marker_counts(rng, two_marker_segs):
    mins = {s: (2 if s in two_marker_segs else (4 if s == "pelvis" else 3)) for s in SEGMENTS}
    maxs = {s: (2 if s in two_marker_segs else 6) for s in SEGMENTS}
    lo, hi = sum(mins.values()), sum(maxs.values())
    target = int(np.clip(rng.integers(40, 76), lo, hi))
    counts = dict(mins)
    while sum(counts.values()) < target:
        free = [s for s in SEGMENTS if counts[s] < maxs[s]]
        counts[free[int(rng.integers(len(free)))]] += 1
    return counts


def make_trial(seed, idx):
    rng = np.random.default_rng([seed, idx])
    F = int(rng.integers(600, 2001))
    t = np.arange(F) / RATE_HZ
    d = draw_dims(rng)
    off = joint_offsets(d, rng)
    moving = choose_moving(rng)
    cats = []
    for j in moving:
        tag = j[:-2]
        if tag not in cats:
            cats.append(tag)
    if len(moving) == 2:
        cats.append("two_joints")

    # ---------------- joint angles -------------------------------------
    # Static posture offsets of still joints: a moving ankle is tested with
    # that foot lifted (hip flexed 20-40 deg, knee flexed 30-70 deg).
    posture = {}
    for j in moving:
        if j.startswith("ankle"):
            sd = j[-1]
            # (a moving knee then starts from 20-40 deg instead of 0-10 deg)
            posture[f"knee_{sd}"] = rng.uniform(30, 70) if f"knee_{sd}" not in moving else rng.uniform(20, 40)
            if f"hip_{sd}" not in moving:
                posture[f"hip_{sd}"] = np.array([rng.uniform(20, 40), 0.0, 0.0])
    hinge_axis = {}
    angles = {}      # joint -> (F,3) deg for spherical, (F,) deg for revolute
    neutral = {}     # reference angle used by soft-tissue artefact
    patterns = {}
    for j, p, c, typ in JOINTS:
        kind = j[:-2] if j.endswith(("_r", "_l")) else j
        if typ == "revolute":
            tilt = np.radians(rng.uniform(0, 5))
            az = rng.uniform(0, 2 * np.pi)
            ax = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
            hinge_axis[j] = ax
            base = rng.uniform(0, 10) if kind == "knee" else rng.uniform(5, 20)
            base = float(posture.get(j, base))
            neutral[j] = base
            if j in moving:
                rng_deg = min(rng.uniform(40, 110), 140.0 - base)
                angles[j], patterns[j] = hinge_motion(rng, t, base, rng_deg)
            else:
                angles[j] = base + sway(rng, t, rng.uniform(0.3, 3.0))
                patterns[j] = "sway"
        else:
            neutral[j] = posture.get(j, np.zeros(3))
            if j in moving:
                amps = [rng.uniform(*r) for r in SPHERICAL_AMPS[kind]]
                angles[j], patterns[j] = spherical_motion(rng, t, amps)
            else:
                A = rng.uniform(0.3, 3.0)
                fr = np.array([1.0, rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0)])
                fr = fr[rng.permutation(3)]
                angles[j] = neutral[j] + np.stack([sway(rng, t, A * f) for f in fr], 1)
                patterns[j] = "sway"

    # ---------------- segment poses --------------------------------------
    # lab frame: random heading about vertical, random vertical-axis convention
    heading = rng.uniform(0, 2 * np.pi)
    R_lab = rot_about([0, 1, 0], heading)[0]
    up_axis = str(rng.choice(["Y", "Z"]))
    if up_axis == "Z":  # x_lab=x, y_lab=-z, z_lab=y  (Y-up -> Z-up)
        R_lab = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]) @ R_lab
    lab_origin = np.array([rng.uniform(-1500, 1500), 0.0, rng.uniform(-1500, 1500)])
    if up_axis == "Z":
        lab_origin = np.array([lab_origin[0], -lab_origin[2], 0.0])
    # feet on the floor in the neutral pose, plus a 15-25 mm shoe sole
    pelvis_h = -off["hip_r"][1] + d["thigh"] + d["shank"] + d["ankle_height"] + rng.uniform(15, 25)
    # pelvis sway: up to +-10 mm horizontally (<= 20 mm peak-to-peak), +-4 mm vertically
    root_tr = np.stack([sway(rng, t, rng.uniform(2.0, 10.0)), sway(rng, t, rng.uniform(0.5, 4.0)),
                        sway(rng, t, rng.uniform(2.0, 10.0))], 1)
    root_tr = root_tr - root_tr[0]
    root_ang = np.radians(np.stack([sway(rng, t, rng.uniform(0.3, 3.0)) for _ in range(3)], 1))
    R = {}
    P = {}
    R["pelvis"] = R_lab[None] @ euler_zxy(root_ang[:, 0], root_ang[:, 1], root_ang[:, 2])
    P["pelvis"] = lab_origin[None] + (np.array([0.0, pelvis_h, 0.0])[None] + root_tr) @ R_lab.T
    for j, p, c, typ in JOINTS:
        if typ == "revolute":
            sgn = -1.0 if j.startswith("knee") else 1.0
            Rj = rot_about(hinge_axis[j], sgn * np.radians(angles[j]))
        else:
            a = np.radians(angles[j])
            s = 1.0 if j.endswith("_r") else (-1.0 if j.endswith("_l") else 1.0)
            # flexion about z, abduction about x (lateral for each side), rotation about y
            Rj = euler_zxy(a[:, 0], -s * a[:, 1], s * a[:, 2])
        R[c] = R[p] @ Rj
        P[c] = P[p] + np.einsum("fij,j->fi", R[p], off[j])

    # ---------------- two-marker segments -------------------------------
    two_marker = []
    child_of_moving = {JOINT_BY_NAME[j][2] for j in moving}
    if rng.random() < 0.4:
        # In ~20 % of these trials one 2-marker segment is the child of a
        # moving joint (the hard case); otherwise such children are excluded.
        force_child = rng.random() < 0.2
        elig = [s for s in SEGMENTS if s != "pelvis" and s not in child_of_moving]
        k = int(rng.choice([1, 2], p=[0.6, 0.4]))
        two_marker = [str(s) for s in rng.choice(elig, size=k, replace=False)]
        if force_child:
            two_marker[0] = str(rng.choice(sorted(child_of_moving)))
        cats.append("two_marker_segment")
        if any(s in child_of_moving for s in two_marker):
            cats.append("two_marker_moving_child")
    counts = marker_counts(rng, set(two_marker))

    # ---------------- marker placement ----------------------------------
    markers = []
    for seg in SEGMENTS:
        n = counts[seg]
        cand = anatomical_candidates(seg, d, off, rng)
        n_anat = min(len(cand), int(rng.binomial(n, 0.55)))
        chosen = [cand[i] for i in rng.choice(len(cand), size=n_anat, replace=False)]
        pos_list = []
        min_sep = 18.0 if SEG_CLASS[seg] == "distal" else 25.0
        for key, pos, sd, nj in chosen:
            pos_list.append(pos)
            markers.append(dict(seg=seg, kind="anat", key=key, side=sd, near_joint=nj, local=pos))
        for _ in range(n - n_anat):
            for _try in range(500):
                pos = cluster_position(seg, d, rng)
                if all(np.linalg.norm(pos - q) >= min_sep for q in pos_list):
                    break
            pos_list.append(pos)
            markers.append(dict(seg=seg, kind="cluster", key=None, side=None, near_joint=False, local=pos))

    anatomical_names = bool(rng.random() < 0.5)
    naming = assign_names(markers, rng, anatomical_names)
    cats.append("anatomical_names" if anatomical_names else "neutral_names")

    # ---------------- soft-tissue artefact -------------------------------
    def q_rel(j):
        typ = JOINT_BY_NAME[j][3]
        q = angles[j] - neutral[j]
        return np.radians(q[:, None] if typ == "revolute" else q)

    qrel = {j: q_rel(j) for j, *_ in JOINTS}
    peak_ang = {j: float(np.degrees(np.max(np.abs(qrel[j])))) for j in qrel}
    M = len(markers)
    X = np.empty((F, M, 3))
    sta_peak = {}
    for mi, mk in enumerate(markers):
        seg = mk["seg"]
        adj = ([PARENT_JOINT[seg]] if seg in PARENT_JOINT else []) + CHILD_JOINTS[seg]
        cls = SEG_CLASS[seg]
        if cls == "long":
            target = rng.uniform(8, 15) if mk["near_joint"] else rng.uniform(3, 10)
        else:
            target = rng.uniform(1, 5)
        mov = np.zeros((F, 3))
        still = np.zeros((F, 3))
        nonlinear = rng.random() < 0.5
        for j in adj:
            q = qrel[j]
            dof = q.shape[1]
            raw = q @ rng.normal(size=(3, dof)).T
            if nonlinear:
                raw += (q * np.abs(q)) @ rng.normal(size=(3, dof)).T * rng.uniform(0.5, 2.0)
            pk = np.max(np.linalg.norm(raw, axis=1))
            if pk <= 0:
                continue
            raw = raw / pk
            if j in moving:
                mov += rng.uniform(0.3, 1.0) * raw
            else:
                typ = JOINT_BY_NAME[j][3]
                still += raw * target * peak_ang[j] / REF_AMP_DEG[typ]
        pk = np.max(np.linalg.norm(mov, axis=1))
        if pk > 0:
            mov *= target / pk
        disp = mov + still
        sta_peak[mk["name"]] = float(np.max(np.linalg.norm(disp, axis=1)))
        loc = mk["local"][None] + disp
        X[:, mi] = P[seg] + np.einsum("fij,fj->fi", R[seg], loc)

    # ---------------- measurement noise ----------------------------------
    sigma = float(np.exp(rng.uniform(np.log(0.05), np.log(1.0))))
    nk = str(rng.choice(["white", "ar1", "lowpass"], p=[0.5, 0.25, 0.25]))
    noise_info = {"sigma_mm": round(sigma, 4), "kind": nk}
    if nk == "lowpass":
        order = int(rng.integers(2, 5))
        fc = rng.uniform(4.0, 15.0)
        b, a = butter(order, fc / (RATE_HZ / 2))
        e = filtfilt(b, a, rng.normal(size=(F, M, 3)), axis=0)
        e *= sigma / e.std()
        X += e
        noise_info.update(cutoff_hz=round(fc, 3), order=order,
                          note="white noise low-pass filtered (filtfilt), rescaled to sigma_mm")
        cats.append("lowpass_noise")
    else:
        X += rng.normal(0, sigma, size=(F, M, 3))
        if nk == "ar1":
            phi = rng.uniform(0.8, 0.97)
            sc = sigma * rng.uniform(0.5, 2.0)
            inn = rng.normal(0, sc * math.sqrt(1 - phi ** 2), size=(F, M, 3))
            zi = (phi * rng.normal(0, sc, size=(M, 3)))[None]
            e, _ = lfilter([1.0], [1.0, -phi], inn, axis=0, zi=zi)
            X += e
            noise_info.update(kind="white+ar1", ar1_phi=round(phi, 4), ar1_sigma_mm=round(sc, 4),
                              total_sigma_mm=round(math.sqrt(sigma ** 2 + sc ** 2), 4))
            cats.append("ar1_noise")

    # ---------------- occlusions -----------------------------------------
    gaps = {}
    if rng.random() < 0.3:
        cats.append("occlusion")
        for mi in rng.choice(M, size=int(rng.integers(1, 5)), replace=False):
            for _ in range(int(rng.integers(1, 4))):
                L = int(rng.integers(5, 81))
                s0 = int(rng.integers(1, F - L - 1))
                X[s0:s0 + L, mi] = np.nan
                gaps.setdefault(markers[mi]["name"], []).append([s0, s0 + L - 1])

    # ---------------- truth ----------------------------------------------
    order = rng.permutation(M)          # shuffled column order
    names = [markers[i]["name"] for i in order]
    X = X[:, order]
    seg_markers = {s: [mk["name"] for mk in markers if mk["seg"] == s] for s in SEGMENTS}
    joints_truth = []
    for j, p, c, typ in JOINTS:
        a = angles[j]
        ptp = np.ptp(a, axis=0) if a.ndim == 2 else np.array([np.ptp(a)])
        jt = {
            "name": j, "parent": p, "child": c, "type": typ, "moving": j in moving,
            "range_deg": round(float(ptp.max()), 3),
            "angles_ptp_deg": [round(float(v), 3) for v in ptp],
            "pattern": patterns[j],
            "centre_in_parent_mm": [round(float(v), 3) for v in off[j]],
            "centre_frame0_mm": [round(float(v), 3) for v in P[c][0]],
        }
        if typ == "revolute":
            jt["axis_in_parent"] = [round(float(v), 5) for v in hinge_axis[j]]
            jt["axis_frame0"] = [round(float(v), 5) for v in R[p][0] @ hinge_axis[j]]
        joints_truth.append(jt)
    truth = {
        "generator": "heldout_functional",
        "segments": seg_markers,
        "root": "pelvis",
        "joints": joints_truth,
        "moving_joints": list(moving),
        "units": rigid_units(set(moving)),
        "noise": noise_info,
        "soft_tissue_peak_mm": {k: round(v, 3) for k, v in sta_peak.items()},
        "frames": F,
        "rate_hz": RATE_HZ,
        "categories": cats,
        "gaps": gaps,
        "gaps_note": "0-based frame indices [first, last] inclusive; TRC Frame# = index + 1",
        "naming": naming,
        "lab_up_axis": up_axis,
        "dimensions_mm": {k: round(v, 2) for k, v in d.items()},
        "root_motion": {"translation_ptp_mm": [round(float(v), 3) for v in np.ptp(root_tr, 0)],
                        "rotation_ptp_deg": [round(float(v), 3) for v in np.degrees(np.ptp(root_ang, 0))]},
        "marker_local_mm": {mk["name"]: [round(float(v), 3) for v in mk["local"]] for mk in markers},
        "segment_pose_frame0": {s: {"R": np.round(R[s][0], 6).tolist(),
                                    "origin_mm": [round(float(v), 3) for v in P[s][0]]} for s in SEGMENTS},
    }
    return names, X, truth


# --------------------------------------------------------------------------
# TRC I/O
# --------------------------------------------------------------------------
def write_trc(path, names, X, rate):
    F, M, _ = X.shape
    fname = os.path.basename(path)
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{fname}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.2f}\t{rate:.2f}\t{F}\t{M}\tmm\t{rate:.2f}\t1\t{F}",
        "Frame#\tTime\t" + "\t".join(f"{n}\t\t" for n in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, M + 1)),
        "",
    ]
    data = np.empty((F, 2 + 3 * M))
    data[:, 0] = np.arange(1, F + 1)
    data[:, 1] = np.arange(F) / rate
    data[:, 2:] = X.reshape(F, 3 * M)
    fmt = "%d\t%.5f" + "\t%.3f" * (3 * M)
    lines = [(fmt % tuple(row)).replace("nan", "") for row in data]
    with open(path, "w", newline="\n") as f:
        f.write("\n".join(head) + "\n")
        f.write("\n".join(lines) + "\n")


def read_trc(path):
    """Minimal independent TRC reader -> (names, time, X[F,M,3], header dict)."""
    with open(path) as f:
        lines = f.read().split("\n")
    keys = lines[1].split("\t")
    vals = lines[2].split("\t")
    hdr = dict(zip(keys, vals))
    cols = lines[3].split("\t")
    names = [c for c in cols[2:] if c.strip()]
    M = int(hdr["NumMarkers"])
    rows = []
    for ln in lines[5:]:
        if not ln.strip():
            continue
        parts = ln.split("\t")
        parts += [""] * (2 + 3 * M - len(parts))
        rows.append([float(p) if p.strip() else np.nan for p in parts[:2 + 3 * M]])
    a = np.array(rows)
    return names, a[:, 1], a[:, 2:].reshape(len(a), M, 3), hdr


# --------------------------------------------------------------------------
# driver
# --------------------------------------------------------------------------
def generate(out, n, seed):
    os.makedirs(out, exist_ok=True)
    index = {"generator": "heldout_functional", "seed": seed, "n": n, "trials": []}
    for i in range(n):
        tid = f"trial_{i:04d}"
        names, X, truth = make_trial(seed, i)
        write_trc(os.path.join(out, tid + ".trc"), names, X, RATE_HZ)
        with open(os.path.join(out, tid + ".truth.json"), "w") as f:
            json.dump(truth, f, indent=1)
        index["trials"].append({"id": tid, "trc": tid + ".trc", "truth": tid + ".truth.json",
                                "categories": truth["categories"]})
    with open(os.path.join(out, "index.json"), "w") as f:
        json.dump(index, f, indent=1)
    return index


def check(out):
    """Self-check: read the TRCs back and test basic properties."""
    with open(os.path.join(out, "index.json")) as f:
        index = json.load(f)
    ok = True
    for tr in index["trials"]:
        names, tm, X, hdr = read_trc(os.path.join(out, tr["trc"]))
        with open(os.path.join(out, tr["truth"])) as f:
            truth = json.load(f)
        F, M, _ = X.shape
        seg_of = {m: s for s, ms in truth["segments"].items() for m in ms}
        good = (F == truth["frames"] == int(hdr["NumFrames"]) and M == int(hdr["NumMarkers"])
                and sorted(names) == sorted(seg_of) and len(set(names)) == M
                and np.allclose(np.diff(tm), 1 / truth["rate_hz"]))
        col = {n: i for i, n in enumerate(names)}

        def dists(a, b):
            return np.linalg.norm(X[:, col[a]] - X[:, col[b]], axis=1)
        moving = [jt for jt in truth["joints"] if jt["moving"]]
        near_moving = {jt["parent"] for jt in moving} | {jt["child"] for jt in moving}
        still_sd, moving_seg_sd, unit_sd, across = [], [], [], []
        for s, ms in truth["segments"].items():
            for i in range(len(ms)):
                for j in range(i + 1, len(ms)):
                    sd = float(np.nanstd(dists(ms[i], ms[j])))
                    (moving_seg_sd if s in near_moving else still_sd).append(sd)
        # pairs on different segments of one rigid unit (through still joints)
        for u in truth["units"]:
            for k, s1 in enumerate(u):
                for s2 in u[k + 1:]:
                    for a in truth["segments"][s1][:2]:
                        for b in truth["segments"][s2][:2]:
                            unit_sd.append(float(np.nanstd(dists(a, b))))
        for jt in moving:  # parent-segment vs child-segment pairs
            for a in truth["segments"][jt["parent"]]:
                for b in truth["segments"][jt["child"]]:
                    dd = dists(a, b)
                    across.append(float(np.nanmax(dd) - np.nanmin(dd)))
        nan_frac = float(np.mean(np.isnan(X)))
        ok &= bool(good)
        print(f"{tr['id']}: F={F} M={M} moving={truth['moving_joints']} "
              f"noise={truth['noise']['kind']}:{truth['noise']['sigma_mm']:.2f}mm | distance SD: "
              f"still-seg med/max={np.median(still_sd):.2f}/{max(still_sd):.2f}, "
              f"seg-next-to-moving med/max={np.median(moving_seg_sd):.2f}/{max(moving_seg_sd):.2f}, "
              f"same-unit-across-still-joints med/max={np.median(unit_sd):.2f}/{max(unit_sd):.2f} | "
              f"across-moving-joint PTP med/min={np.median(across):.1f}/{min(across):.1f} | "
              f"nan={nan_frac:.4f} ok={good}")
    return ok


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", help="output directory")
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--check", metavar="DIR", help="read back DIR and print sanity statistics")
    a = ap.parse_args(argv)
    if a.check:
        return 0 if check(a.check) else 1
    if not a.out:
        ap.error("--out is required")
    t0 = time.time()
    generate(a.out, a.n, a.seed)
    print(f"wrote {a.n} trials to {a.out} in {time.time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
