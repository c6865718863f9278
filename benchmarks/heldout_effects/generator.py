#!/usr/bin/env python3
"""heldout-effects v1: independent synthetic right-lower-limb trials with known effects.

World: Y up, lab X/Z horizontal, mm, 100 Hz.  Segment frames: x anterior, y proximal
(along the bone, pointing up), z lateral (right).  Everything is a closed-form function of
continuous time, so a delayed segment is simply re-evaluated at t - d.

Only numpy / scipy / stdlib.  `build_spec` draws every random choice of a trial into a
JSON-serialisable dict; `simulate(spec, active=..., noise=...)` turns it into marker
trajectories with any subset of the effects switched on and noise on/off.
"""
import argparse
import json
import math
import os

import numpy as np
from scipy.signal import lfilter

GENERATOR = "heldout-effects v1"
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


def make_geometry(rng):
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
    # ---- markers
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


# ----------------------------------------------------------------------------- motion
def make_motion(rng, kind, g, n_frames, force_treadmill=False):
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
    if e["shape"] == "linear_drift":
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


def simulate(spec, active=None, noise=True):
    """Marker array (N,M,3) in marker_order; active=None -> all effects of the trial."""
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
    A, _, _, _ = simulate(spec, [], noise=False)
    B, _, _, _ = simulate(spec, [name], noise=False)
    return float(np.linalg.norm(B - A, axis=2).max())


def tangentish(rng, n, normal_weight=0.3):
    v = rng.normal(size=3)
    v -= (1 - normal_weight) * (v @ n) * n
    return v


def build_soft_tissue(rng, spec, ang):
    g = spec["_geom"]
    seg_choice = rng.choice(["thigh", "shank", "thigh+shank", "pelvis"], p=[0.45, 0.25, 0.2, 0.1])
    segs = seg_choice.split("+")
    shape = str(rng.choice(["angle_harmonics", "long_axis_slide", "coherent_cluster", "bilinear_bulge"]))
    target = loguniform(rng, 2.0, 15.0)
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
    peak = 0.0
    for e in parts:
        for v in st_offsets(e, ang).values():
            peak = max(peak, float(np.linalg.norm(v, axis=1).max()))
    for e in parts:
        e["scale"] = target / peak
    where = {"segment": segs[0] if len(segs) == 1 else segs, "segments": segs, "markers": all_markers,
             "joint": "hip" if segs == ["pelvis"] else "knee"}
    return {"name": "soft_tissue", "shape": shape + ("_" + "_".join(segs)), "parts": parts,
            "target_peak_mm": target, "where": where}


def build_marker_slip(rng, spec, ang):
    g = spec["_geom"]; N = spec["n_frames"]
    s = str(rng.choice(SEGMENTS, p=[0.2, 0.4, 0.4]))
    m = str(rng.choice(list(g["markers"][s])))
    shape = str(rng.choice(["step", "step", "linear_drift", "smoothstep_drift", "cosine_creep"]))
    drift = 0.0 if shape == "step" else float(rng.uniform(0.2, 1.0))
    f0 = int(rng.integers(int(0.15 * N), int(0.85 * N) - int(drift * RATE) - 2))
    mag = float(rng.uniform(4, 15))
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


def build_joint_translation(rng, spec, ang):
    g = spec["_geom"]
    joint = "knee" if rng.random() < 0.8 else "hip"
    target = loguniform(rng, 3.0, 12.0)
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
    peak = float(np.linalg.norm(jt_offset(e, ang), axis=1).max())
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
        A = float(rng.uniform(lo, hi))
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
    if rng.random() < 0.75:
        d = float(rng.integers(1, 5)); shape += "_integer_lag"
    else:
        d = round(float(rng.uniform(1.0, 4.0)), 2); shape += "_fractional_lag"
    e = {"name": "time_offset", "shape": shape, "markers": mk, "delay_frames": d}
    e["where"] = {"segment": s, "markers": mk, "delay_frames": d, "delay_s": d / RATE}
    return e


def build_outliers(rng, spec, ang):
    g = spec["_geom"]; N = spec["n_frames"]
    names = [m for _, m in marker_order(g)]
    peak = loguniform(rng, 5.0, 60.0)
    style = str(rng.choice(["isolated_spikes", "short_bursts", "axis_jumps", "mixed"]))
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


def build_spatial_distortion(rng, spec, ang):
    X, _, _, _ = simulate(spec, [], noise=False)
    mean = X.reshape(-1, 3).mean(0)
    c = np.array([mean[0] + rng.uniform(-400, 400), rng.uniform(600, 1200), mean[2] + rng.uniform(-400, 400)])
    shape = str(rng.choice(["radial_lens", "shear_plus_radial", "single_axis_scale", "smooth_warp"]))
    A = float(rng.uniform(4, 12))
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
        e["scale"] = e["target_peak_mm"] / float(np.linalg.norm(distortion(e, X), axis=-1).max())
    e["where"] = {"volume": "capture volume", "centre_mm": c.tolist()}
    return e


BUILDERS = {"soft_tissue": build_soft_tissue, "marker_slip": build_marker_slip,
            "marker_swap": build_marker_swap, "joint_translation": build_joint_translation,
            "extra_dof": build_extra_dof, "time_offset": build_time_offset,
            "outliers": build_outliers, "spatial_distortion": build_spatial_distortion}


# ----------------------------------------------------------------------------- trial assembly
def build_spec(seed, index, kind, names):
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
        lines.append(f"{f + 1}\t{f / RATE:.4f}\t" + "\t".join(f"{v:.4f}" for v in flat[f]))
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
    m = spec["motion"]; g = spec["_geom"]
    params = {"n_frames": spec["n_frames"], "rate_hz": RATE,
              "thigh_length_mm": g["thigh_length"], "shank_length_mm": g["shank_length"],
              "knee_axis_tilt_deg": float(math.degrees(math.acos(abs(g["knee_axis_in_thigh"][2])))),
              "markers_per_segment": {s: len(g["markers"][s]) for s in SEGMENTS},
              "motion": m["kind"], "treadmill": m["treadmill"],
              "speed_mm_s": m.get("speed_mm_s"),
              "noise": {k: v for k, v in spec["noise"].items()},
              "effect_params": [{k: v for k, v in e.items()
                                 if k not in ("where", "coef", "parts", "events", "modes", "vv_comps", "ax_comps")}
                                for e in spec["effects"]]}
    effects = [{"name": e["name"], "where": e["where"], "magnitude_mm": e["magnitude_mm"], "shape": e["shape"]}
               for e in spec["effects"]]
    return {"stem": stem, "effects": effects,
            "category": {"motion": m["kind"], "noise": spec["noise"]["model"], "kind": kind},
            "params": params}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--n", type=int, default=120)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    trials = []
    for i, (kind, names) in enumerate(plan_trials(args.n, args.seed)):
        stem = f"trial_{i:04d}"
        spec = build_spec(args.seed, i, kind, names)
        X, mnames, _, _ = simulate(spec)
        write_trc(os.path.join(args.out, stem + ".trc"), X, mnames)
        write_toml(os.path.join(args.out, stem + ".toml"), spec["_geom"])
        entry = trial_entry(stem, kind, spec)
        truth = dict(entry)
        truth["joints"] = truth_distances(spec["_geom"])
        truth["spec"] = spec_json(spec)
        with open(os.path.join(args.out, stem + ".truth.json"), "w") as fh:
            json.dump(truth, fh, indent=1)
        trials.append(entry)
    with open(os.path.join(args.out, "index.json"), "w") as fh:
        json.dump({"generator": GENERATOR, "seed": args.seed, "trials": trials}, fh, indent=1)
    print(f"wrote {len(trials)} trials to {args.out}")


if __name__ == "__main__":
    main()
