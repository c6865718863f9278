#!/usr/bin/env python3
"""Self-check of a heldout-effects dataset.

    python benchmarks/heldout_effects/check.py DIR

For every trial (from its own truth.json spec):
  1. noise-free, effect-free regeneration: every marker's distance to the hip centre / knee
     hinge axis is constant and equal to the truth value (<= 1e-6 mm), both against the
     generator's own joint geometry and against a joint centre / axis estimated from the
     markers alone (Kabsch cluster poses + SCoRE centre + SARA axis);
  2. each effect's recorded magnitude_mm == max 3-D displacement it produces in isolation
     (noise-free) within 1 %, and == its sampled target where it has one;
     its `where` matches the frames / markers that actually move;
  3. the TRC parses back (own reader) to the full regeneration within the 4-decimal rounding,
     header and marker names agree with the model TOML; index entry == truth entry.
v2 datasets (`generator.py --version 2`) also get, per trial (see check_v2_trial):
  - gaps: the NaN samples of the rigid rebuild are exactly the truth gaps, the full rebuild's
    and the TRC's empty cells are those gaps relabelled by an active marker_swap; gap rules
    (1-6 gaps, 5-150 frames, one marker each, >= 70 % visible, <= 1 pelvis marker missing);
  - the distances as in 1 on the visible samples, and against joints estimated from the
    markers alone with virtual markers (hip: sphere fit of the thigh markers in the pelvis
    frame; knee: circle fit of the shank markers in a thigh frame made of the thigh markers and
    that hip centre), which also works for 2-marker segments;
  - magnitude / `where` checks for the new shapes (fast_ramp, *_in_gap, heavy_tailed,
    other_joint), layout landmarks, the sit_to_stand motion, noise level and time-lag exactness.
Sweep datasets (`--sweep`, index "sweep": true) get the v2 checks with the sweep ranges, and per
trial (check_sweep_trial): one effect, its stream, frames / noise / size in range, the size
consistent with the effect's parameters, and the truth spec rebuilt identically from its stream.
"""
import json
import os
import sys
import time
import tomllib

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import generator as G  # noqa: E402

TOL_DIST = 1e-6
failures = []


def fail(stem, msg):
    failures.append(f"{stem}: {msg}")


# ----------------------------------------------------------------------------- tiny TRC reader
def read_trc(path):
    with open(path) as fh:
        lines = fh.read().split("\n")
    assert lines[0].split("\t")[0] == "PathFileType" and lines[0].split("\t")[1] == "4"
    keys = lines[1].split("\t")
    vals = lines[2].split("\t")
    hdr = dict(zip(keys, vals))
    cols = lines[3].split("\t")
    assert cols[0] == "Frame#" and cols[1] == "Time"
    names = [c for c in cols[2:] if c != ""]
    sub = lines[4].split("\t")
    assert sub[2:5] == ["X1", "Y1", "Z1"]
    assert lines[5].strip() == ""
    rows = [ln.split("\t") for ln in lines[6:] if ln.strip()]
    bad = sum(1 for r in rows for v in r if v.strip().lower() in ("nan", "-nan", "inf", "-inf"))
    if bad:
        raise ValueError(f"{path}: {bad} fields spelled nan/inf (missing samples must be empty)")
    arr = np.array([[float(v) if v != "" else np.nan for v in r] for r in rows], dtype=float)
    frames, times = arr[:, 0], arr[:, 1]
    X = arr[:, 2:].reshape(len(rows), -1, 3)
    return hdr, names, frames, times, X


# ----------------------------------------------------------------------------- independent joints
def kabsch(P):
    """P (N,M,3) -> R (N,3,3), p (N,3) with P[t] = R[t] P[0] + p[t]."""
    P0 = P[0]
    c0 = P0.mean(0)
    c = P.mean(1)
    H = np.einsum("mi,nmj->nij", P0 - c0, P - c[:, None])
    U, S, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))
    D = np.zeros((len(P), 3, 3)); D[:, 0, 0] = 1; D[:, 1, 1] = 1; D[:, 2, 2] = d
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)
    p = c - np.einsum("nij,j->ni", R, c0)
    return R, p


def score_centre(Rp, pp, Rc, pc):
    A = np.concatenate([Rp, -Rc], axis=2).reshape(-1, 6)
    b = (pc - pp).reshape(-1)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    return np.einsum("nij,j->ni", Rp, x[:3]) + pp


def sara_axis(Rp, pp, Rc, pc):
    A = (Rp - Rc).reshape(-1, 3)
    b = (pc - pp).reshape(-1)
    x = np.linalg.lstsq(A, b, rcond=1e-9)[0]
    Rrel = np.einsum("nji,njk->nik", Rp, Rc)
    rv = Rotation.from_matrix(Rrel).as_rotvec()
    k = int(np.argmax(np.linalg.norm(rv, axis=1)))
    a = rv[k] / np.linalg.norm(rv[k])
    return np.einsum("nij,j->ni", Rp, x) + pp, np.einsum("nij,j->ni", Rp, a)


def line_dist(X, p, d):
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    v = X - p
    return np.linalg.norm(v - np.sum(v * d, 1, keepdims=True) * d, axis=1)


# ----------------------------------------------------------------------------- v2 checks
V2 = {"trials": 0, "est_frames_min": None, "est_fallback": 0, "est_kabsch_score_sara": 0,
      "min_visible": 1.0, "n_gaps": [], "swap_in_gap": 0, "noise_ratio": [], "s2s_cycles": [],
      "heavy_events": [], "other_joint": 0, "close_to_axis_mm": []}
# sweep mode (README "Sweep mode"): size name and log-uniform range per effect; extra_dof's is
# 0.05-1 x v2's upper amplitude for the dof (12 deg varus_valgus, 15 deg axial_rotation / ball)
SWEEP = {"on": False, "seed": None, "rebuilt": 0}
SWEEP_RANGES = {"soft_tissue": ("target_mm", 0.3, 15.0), "marker_slip": ("target_mm", 0.3, 15.0),
                "marker_swap": ("span_frames", 2, 400), "joint_translation": ("target_mm", 0.3, 12.0),
                "extra_dof": ("amplitude_deg", 0.05, 1.0), "time_offset": ("lag_frames", 0.05, 4.0),
                "outliers": ("target_mm", 1.0, 60.0), "spatial_distortion": ("strength_mm_at_1500", 0.3, 12.0)}
ANAT_THIGH = {"RTHI", "RKNE", "RKNM", "RGT", "RTHA"}
ANAT_SHANK = {"RTIB", "RANK", "RMED", "RTT"}


def sphere_fit_common(Y):
    """Common centre c of points Y[i] (n_i,3) lying on spheres about c (linear least squares)."""
    y0 = np.concatenate(Y).mean(0)
    rows, rhs = [], []
    for i, y in enumerate(Y):
        u = y - y0
        e = np.zeros((len(u), len(Y))); e[:, i] = 1
        rows.append(np.hstack([2 * u, e])); rhs.append(np.sum(u * u, 1))
    x = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    return y0 + x[:3]


def circle_axis(Z):
    """Common axis (point, unit direction) of points Z[i] (n_i,3) moving on circles about it."""
    Zc = np.concatenate([z - z.mean(0) for z in Z])
    n = np.linalg.svd(Zc, full_matrices=False)[2][-1]
    e1 = np.linalg.svd(np.eye(3) - np.outer(n, n))[0][:, 0]
    e2 = np.cross(n, e1)
    cs = []
    for z in Z:
        zb = z.mean(0)
        q = (z - zb) @ np.stack([e1, e2], 1)
        A = np.hstack([2 * q, np.ones((len(q), 1))])
        c2 = np.linalg.lstsq(A, np.sum(q * q, 1), rcond=None)[0]
        cs.append(zb + c2[0] * e1 + c2[1] * e2)
    return np.mean(cs, 0), n


def v2_estimated_joint_error(stem, spec, X0, names, segs, hd, kd):
    """Worst |distance - truth| against joints estimated from the markers alone (v2).

    Frames where every marker is visible are used (the gap-free rebuild if fewer than 50).
    Virtual-marker method for any layout: pelvis pose (Kabsch), hip centre = common sphere
    centre of the thigh markers in the pelvis frame, thigh frame = Kabsch of the thigh markers
    plus that hip centre, knee axis = common circle axis of the shank markers in the thigh
    frame.  When every segment has >= 3 markers, also v1's Kabsch + SCoRE + SARA."""
    sel = ~np.isnan(X0).any(axis=(1, 2))
    P = X0[sel]
    if sel.sum() < 50:
        V2["est_fallback"] += 1
        P, _, _, _ = G.simulate(spec, [], noise=False, gaps=False)
    V2["est_frames_min"] = len(P) if V2["est_frames_min"] is None else min(V2["est_frames_min"], len(P))
    idx = {m: i for i, m in enumerate(names)}
    Rp, pp = kabsch(P[:, segs["pelvis"]])
    Y = [np.einsum("nji,nj->ni", Rp, P[:, j] - pp) for j in segs["thigh"]]
    hc = pp + np.einsum("nij,j->ni", Rp, sphere_fit_common(Y))
    Rt, pt = kabsch(np.concatenate([P[:, segs["thigh"]], hc[:, None]], axis=1))
    Z = [np.einsum("nji,nj->ni", Rt, P[:, j] - pt) for j in segs["shank"]]
    kl, kdl = circle_axis(Z)
    kp, kdir = pt + np.einsum("nij,j->ni", Rt, kl), np.einsum("nij,j->ni", Rt, kdl)
    err = 0.0
    for m, v in hd.items():
        err = max(err, np.abs(np.linalg.norm(P[:, idx[m]] - hc, axis=1) - v).max())
    for m, v in kd.items():
        err = max(err, np.abs(line_dist(P[:, idx[m]], kp, kdir) - v).max())
    if all(len(segs[s]) >= 3 for s in G.SEGMENTS):
        V2["est_kabsch_score_sara"] += 1
        poses = {s: kabsch(P[:, segs[s]]) for s in G.SEGMENTS}
        hc2 = score_centre(*poses["pelvis"], *poses["thigh"])
        kp2, kd2 = sara_axis(*poses["thigh"], *poses["shank"])
        for m, v in hd.items():
            err = max(err, np.abs(np.linalg.norm(P[:, idx[m]] - hc2, axis=1) - v).max())
        for m, v in kd.items():
            err = max(err, np.abs(line_dist(P[:, idx[m]], kp2, kd2) - v).max())
    return err


def gap_mask(N, names, gaps):
    """(N,M) True at gapped samples, from the truth gap list (the check's own version)."""
    miss = np.zeros((N, len(names)), bool)
    for gp in gaps:
        miss[gp["frames"][0]:gp["frames"][1] + 1, names.index(gp["marker"])] = True
    return miss


def swapped(miss, names, e):
    """A (N,M) mask seen through marker_swap `e`'s labels."""
    out = miss.copy()
    i, j = names.index(e["markers"][0]), names.index(e["markers"][1])
    s0, s1 = e["frames"][0], e["frames"][1] + 1
    out[s0:s1, i], out[s0:s1, j] = miss[s0:s1, j], miss[s0:s1, i]
    return out


def occlusion_rules(stem, miss, names, pelvis, what):
    """>= 70 % visible per marker and <= 1 pelvis marker missing per frame."""
    vis = 1 - miss.mean(0)
    V2["min_visible"] = min(V2["min_visible"], float(vis.min()))
    if (vis < 0.70).any():
        fail(stem, f"{what}: {names[int(np.argmin(vis))]} visible in only {vis.min():.1%} of frames")
    pc = [names.index(m) for m in pelvis]
    if miss[:, pc].sum(1).max(initial=0) > 1:
        fail(stem, f"{what}: two pelvis markers missing at one frame")


def nanmask(X):
    """(N,M) NaN mask; fails loudly if a sample is NaN on some axes only."""
    m = np.isnan(X)
    if not np.array_equal(m.any(2), m.all(2)):
        raise AssertionError("partially NaN sample")
    return m.any(2)


def check_v2_swap(stem, spec, e, w, X0, X1, moved, names, seg_of):
    """marker_swap in v2: moved samples are exactly the two labels' samples in the span that are
    visible in both rebuilds; the gaps follow the markers; `*_in_gap` starts inside that gap."""
    N = spec["n_frames"]
    a, b = w["markers"]; s0, s1 = w["frames"]
    ia, ib = names.index(a), names.index(b)
    m0, m1 = nanmask(X0), nanmask(X1)
    exp = np.zeros_like(moved)
    both = ~m0 & ~m1
    exp[s0:s1 + 1, [ia, ib]] = both[s0:s1 + 1][:, [ia, ib]]
    if not np.array_equal(moved, exp) or not exp.any():
        fail(stem, "marker_swap: moved samples are not the visible samples of the span")
    if w["frame_numbers"] != [s0 + 1, s1 + 1] or [seg_of[m] for m in w["markers"]] != w["segments"] \
            or not (2 if SWEEP["on"] else 50) <= s1 - s0 + 1 <= 400 or e["frames"] != w["frames"] or e["markers"] != w["markers"]:
        fail(stem, "marker_swap where / span")
    if not np.array_equal(m1, swapped(m0, names, e)):
        fail(stem, "marker_swap: the gaps do not follow the swapped markers")
    sh = e["shape"]
    if sh.endswith("_in_gap"):
        V2["swap_in_gap"] += 1
        gp = w.get("gap", {})
        if {"marker": gp.get("marker"), "frames": gp.get("frames")} not in spec["gaps"] or gp["marker"] != a \
                or not gp["frames"][0] < s0 <= gp["frames"][1] or gp.get("frame_numbers") != [f + 1 for f in gp["frames"]]:
            fail(stem, "marker_swap in_gap: the span does not start inside a gap of its first marker")
    elif "gap" in w or (sh.endswith("_at_start") != (s0 == 0)) or (sh.endswith("_at_end") != (s1 == N - 1)):
        fail(stem, "marker_swap shape / span")
    if sh.split("_in_gap")[0].split("_at_")[0] != ("same_segment" if seg_of[a] == seg_of[b] else "neighbour_segments"):
        fail(stem, "marker_swap kind")


def check_v2_effect(stem, spec, e, w, X0, X1, D, moved, names, seg_of):
    """v2 extras per effect: gaps unchanged, ranges, and the new shapes' definitions."""
    nm, sh = e["name"], e["shape"]
    if nm != "marker_swap" and not np.array_equal(nanmask(X0), nanmask(X1)):
        fail(stem, f"{nm} changes the gaps")
    rng_ = {"soft_tissue": (2, 15), "marker_slip": (4, 15), "joint_translation": (3, 12), "outliers": (5, 60)}
    if SWEEP["on"]:
        rng_ = {k: SWEEP_RANGES[k][1:] for k in rng_}
    if nm in rng_ and not rng_[nm][0] - 1e-9 <= e["target_peak_mm"] <= rng_[nm][1] + 1e-9:
        fail(stem, f"{nm} target out of range")
    if nm == "marker_slip":
        j = names.index(w["marker"])
        f0, f1 = w["frames"]
        if np.isnan(D[max(0, f0 - 1):f1 + 2, j]).any():
            fail(stem, "marker_slip: the slip is not visible")
        lo, hi = {"step": (0, 0), "fast_ramp": (0.05, 0.15)}.get(sh, (0.2, 1.0))
        if not lo <= e["drift_s"] <= hi or (sh == "fast_ramp" and not 4 <= f1 - f0 <= 16):
            fail(stem, f"marker_slip {sh}: duration {e['drift_s']} s, frames {f0}-{f1}")
    elif nm == "outliers":
        ok = ~nanmask(X0)
        cells = [(names.index(s_["marker"]), f) for s_ in w["samples"] for f in s_["frames"]]
        if not all(ok[f, j] for j, f in cells):
            fail(stem, "outliers on a gapped sample")
        if sh == "heavy_tailed":
            V2["heavy_events"].append(len(e["events"]))
            mags = np.array([D[f, j] for j, f in cells])
            if not 30 <= len(e["events"]) <= 200 or any(ev["length"] != 1 for ev in e["events"]) \
                    or len(set(cells)) != len(cells) or not 1.5 <= e["nu"] <= 3.0 \
                    or mags.min() < 1.0 - 1e-6 or abs(mags.max() - e["target_peak_mm"]) > 1e-6 * e["target_peak_mm"]:
                fail(stem, "outliers heavy_tailed: definition")
    elif nm == "soft_tissue" and sh.startswith("other_joint"):
        V2["other_joint"] += 1
        part = e["parts"][0]
        s = part["segment"]
        exp_drivers = {"thigh": ["knee"], "shank": ["hip_flex"]}[s]
        if len(e["parts"]) != 1 or part["drivers"] != exp_drivers or w.get("drivers") != exp_drivers \
                or sh != "other_joint_" + s or (s == "shank" and len(w["markers"]) != 1) \
                or (s == "thigh" and len(w["markers"]) not in (1, len(spec["_geom"]["markers"]["thigh"]))):
            fail(stem, "soft_tissue other_joint: definition")
        # |offset|^2 must be an exact quadratic form in (sin d, 1 - cos d) of the driver alone
        ang = G.eval_motion(spec["motion"], np.arange(spec["n_frames"]) / G.RATE)
        d = ang[exp_drivers[0]] - part["ref_angles"][exp_drivers[0]]
        sn, cs = np.sin(d), 1 - np.cos(d)
        F = np.stack([sn * sn, sn * cs, cs * cs], 1)
        for m in w["markers"]:
            y = D[:, names.index(m)] ** 2
            k = ~np.isnan(y)
            coef = np.linalg.lstsq(F[k], y[k], rcond=None)[0]
            if np.abs(F[k] @ coef - y[k]).max() > 1e-6 * max(1.0, y[k].max()):
                fail(stem, f"soft_tissue other_joint: {m} is not driven by {exp_drivers[0]} alone")


def check_layout(stem, spec, geom):
    """Marker layout: v1 clusters or the anatomical landmarks with their offsets."""
    mk = geom["markers"]
    if not 3 <= len(mk["pelvis"]) <= 4 or len(mk["thigh"]) < 2 or len(mk["shank"]) < 2:
        fail(stem, "markers per segment")
    a, k = geom["knee_axis_in_thigh"], geom["knee_centre_in_thigh"]
    if spec["layout"] == "clusters":
        if not (3 <= len(mk["thigh"]) <= 4 and 3 <= len(mk["shank"]) <= 4
                and all(m.startswith("RTH") for m in mk["thigh"]) and all(m.startswith("RSH") for m in mk["shank"])):
            fail(stem, "clusters layout")
        return
    th, sh = set(mk["thigh"]), set(mk["shank"])
    if not ({"RTHI", "RKNE"} <= th <= ANAT_THIGH and len(th & {"RGT", "RTHA"}) <= 1
            and {"RTIB", "RANK"} <= sh <= ANAT_SHANK):
        fail(stem, f"anatomical marker names {sorted(th)} {sorted(sh)}")
        return
    Lt, Ls = geom["thigh_length"], geom["shank_length"]
    for m, side in (("RKNE", 1), ("RKNM", -1)):
        if m in th:
            v = mk["thigh"][m] - k
            along, off = side * v @ a, np.linalg.norm(v - (v @ a) * a)
            V2["close_to_axis_mm"].append(off)
            if not (40 - 1e-9 <= along <= 55 + 1e-9 and off <= 4 + 1e-9):
                fail(stem, f"{m}: {along:.1f} mm along / {off:.1f} mm off the knee axis")
    lng = k / np.linalg.norm(k)
    v = mk["thigh"]["RTHI"]
    off = np.linalg.norm(v - (v @ lng) * lng)
    if not 50 - 1e-9 <= off <= 80 + 1e-9 or v[2] <= 0:
        fail(stem, f"RTHI {off:.1f} mm off the thigh line")
    ank = np.array([0, -Ls, 0.0])
    for m, side in (("RANK", 1), ("RMED", -1)):
        if m in sh:
            v = mk["shank"][m] - ank
            if not 30 - 1e-9 <= side * v[2] <= 40 + 1e-9 or np.linalg.norm(v[:2]) > 5 + 1e-9:
                fail(stem, f"{m}: {v.round(1)} from the shank's distal end")
    v = mk["shank"]["RTIB"]
    if not 45 - 1e-9 <= np.hypot(v[0], v[2]) <= 70 + 1e-9 or v[2] <= 0 or not 0.4 * Ls <= -v[1] <= 0.65 * Ls:
        fail(stem, "RTIB placement")
    if Lt <= 0:
        fail(stem, "thigh length")


def check_motion(stem, spec):
    """Closed form in t (a 1-frame lag re-evaluated equals the shifted trial), continuity, and
    for sit_to_stand the cycle structure and the seated / standing postures."""
    m = spec["motion"]; N = spec["n_frames"]
    t = np.arange(N) / G.RATE
    A = G.eval_motion(m, t)
    B = G.eval_motion(m, t - 1 / G.RATE)
    for kk in G.ANGLES + ["pelvis_p"]:
        if np.abs(B[kk][1:] - A[kk][:-1]).max() > 1e-9:
            fail(stem, f"motion {kk} is not a function of continuous time")
        step = np.abs(np.diff(A[kk], axis=0)).max()
        if step > (0.1 if kk != "pelvis_p" else 25.0):
            fail(stem, f"motion {kk} jumps by {step:.3g} per frame")
    if m["kind"] != "sit_to_stand":
        return
    n = m["n_cycles"]
    T = np.array(m["cycle_s"]); a = np.array(m["rise_start_s"]); r = np.array(m["rise_s"])
    b = np.array(m["sit_start_s"]); q = np.array(m["sit_s"])
    V2["s2s_cycles"].append(n)
    ends = b + q
    n_lo, n_hi = (1, 12) if SWEEP["on"] else (3, 6)
    if not (n_lo <= n <= n_hi and len(T) == n and (T >= 2.5 - 1e-9).all() and (T <= 4 + 1e-9).all()
            and (b > a + r).all() and (a[1:] > ends[:-1]).all() and a[0] > 0 and ends[-1] <= N / G.RATE + 1e-9):
        fail(stem, "sit_to_stand cycle structure")
        return
    seat_t = np.concatenate([[a[0] / 2], (ends[:-1] + a[1:]) / 2])           # mid seated pauses
    stand_t = (a + r + b) / 2                                                  # mid standing pauses
    S, U = G.eval_motion(m, seat_t), G.eval_motion(m, stand_t)
    deg = 180 / np.pi
    hf_s, hf_u = S["hip_flex"] * deg, U["hip_flex"] * deg
    kn_s, kn_u = S["knee"] * deg, U["knee"] * deg
    if not ((hf_s > 75).all() and (hf_s < 105).all() and (np.abs(hf_u) < 12).all()
            and (kn_s > 75).all() and (kn_s < 105).all() and (kn_u > 0).all() and (kn_u < 12).all()):
        fail(stem, f"sit_to_stand postures: hip {hf_s.round(0)} -> {hf_u.round(0)}, knee {kn_s.round(0)} -> {kn_u.round(0)}")
    h = m["heading_deg"] * np.pi / 180
    fwd_dir = np.array([np.cos(h), 0, -np.sin(h)])
    d = U["pelvis_p"] - S["pelvis_p"]
    up, fwd = d[:, 1], d @ fwd_dir
    if not ((up > 230).all() and (up < 370).all() and (fwd > 80).all() and (fwd < 220).all()):
        fail(stem, f"sit_to_stand pelvis rise {up.round(0)} / forward {fwd.round(0)} mm")
    tilt = np.degrees(np.arcsin(A["pelvis_R"][:, 1, 0]))      # Rz tilt: negative = anterior
    for k in range(n):
        f_seat = int(round(seat_t[k] * G.RATE)); rise = (t >= a[k]) & (t <= a[k] + r[k])
        if rise.any() and f_seat < N and not tilt[rise].min() < tilt[f_seat] - 5:
            fail(stem, "sit_to_stand: the pelvis does not tilt forward during the rise")


def check_sweep_trial(stem, truth, entry, spec):
    """Sweep mode: one effect drawn from its own stream, frames / noise / size in their ranges,
    the size consistent with the effect's parameters, and the spec rebuilt from the stream."""
    sw = spec.get("sweep")
    if not sw:
        fail(stem, "sweep dataset, but the spec has no sweep record")
        return
    nm = sw["effect"]
    if entry["category"]["kind"] != "single" or len(spec["effects"]) != 1 or spec["effects"][0]["name"] != nm \
            or sw["effect_index"] != G.EFFECTS.index(nm):
        fail(stem, "sweep: not a single trial of its effect")
        return
    key = [SWEEP["seed"], G.EFFECTS.index(nm), sw["trial_index"], 4242] + ([sw["attempt"]] if sw["attempt"] else [])
    if sw["stream"] != key:
        fail(stem, f"sweep stream {sw['stream']} != {key}")
    N, nz, p = spec["n_frames"], spec["noise"], entry["params"]
    if not 500 <= N <= 3000 or p.get("frames") != N:
        fail(stem, f"sweep frames {N} / params.frames {p.get('frames')}")
    if p.get("noise") != {"kind": nz["model"], "sigma_mm": nz["sigma_mm"], "phi": nz.get("phi"),
                          "model": nz["model"], "seed": nz["seed"]}:
        fail(stem, "sweep params.noise")
    e, rec = spec["effects"][0], entry["effects"][0]
    size = rec.get("size")
    sname, lo, hi = SWEEP_RANGES[nm]
    if size is None or size != e.get("size") or size["name"] != sname:
        fail(stem, "sweep: effect size missing or named wrongly")
        return
    v, u = size["value"], sw["size_u"]
    if nm == "extra_dof":
        f = size["fraction"]
        amps = {"varus_valgus": e.get("vv_peak_deg"), "axial_rotation": e.get("ax_peak_deg")}
        top = 15.0 if e["dof"] != "varus_valgus" else 12.0
        ok = abs(f - lo * (hi / lo) ** u) <= 1e-9 and lo - 1e-12 <= f <= hi + 1e-12 \
            and abs(v - top * f) <= 1e-9 * top and size["range"] == [lo * top, hi * top] \
            and all((a is None) == (d not in e["dof"] and e["dof"] != "ball") for d, a in amps.items()) \
            and all(a is None or abs(a - {"varus_valgus": 12.0, "axial_rotation": 15.0}[d] * f) <= 1e-9 * 15
                    for d, a in amps.items())
    elif nm == "marker_swap":
        ok = v == int(v) and lo <= v <= hi and v == e["frames"][1] - e["frames"][0] + 1 \
            and v == min(hi, np.floor(lo * ((hi + 1) / lo) ** u))
    else:
        ok = lo - 1e-9 <= v <= hi + 1e-9 and abs(v - lo * (hi / lo) ** u) <= (5e-5 if nm == "time_offset" else 1e-9 * v)
        field = {"target_mm": "target_peak_mm", "lag_frames": "delay_frames", "strength_mm_at_1500": "mm_at_1500"}[sname]
        ok = ok and e[field] == v
        if nm == "time_offset":
            ok = ok and e["shape"].endswith("_fractional_lag") and rec["where"]["delay_frames"] == v
        if nm == "spatial_distortion" and e["shape"] == "smooth_warp":
            ok = ok and abs(e["target_peak_mm"] - 0.6 * v) <= 1e-9 * v
    if not ok:
        fail(stem, f"sweep: size {size} inconsistent with {nm} / its quantile {u}")
    # the spec rebuilds identically from its stream
    again = json.loads(json.dumps(G.spec_json(G.build_spec_sweep(SWEEP["seed"], sw["trial_index"], nm))))
    if again != {k: v for k, v in truth["spec"].items() if not k.startswith("_")}:
        fail(stem, "sweep: the spec does not rebuild from its stream")
    else:
        SWEEP["rebuilt"] += 1


def summarise_sweep(index, trials):
    """Per swept effect: trial count, size and magnitude ranges, lengths, noise, worlds."""
    from collections import Counter
    names, n = index["effects"], index["n_per_effect"]
    if [t["effects"][0]["name"] for t in trials] != [x for x in names for _ in range(n)] \
            or len({t["stem"] for t in trials}) != len(trials):
        fail("index", "sweep: trials are not n_per_effect single trials per listed effect, in order, with unique stems")
    print(f"sweep: {n} trials per effect; spec rebuilt from its stream for {SWEEP['rebuilt']} of {len(trials)}")
    for nm in names:
        ts = [t for t in trials if t["effects"][0]["name"] == nm]
        sz = [t["effects"][0]["size"]["value"] for t in ts]
        mg = [t["effects"][0]["magnitude_mm"] for t in ts]
        fr = [t["params"]["frames"] for t in ts]
        sg = [t["params"]["noise"]["sigma_mm"] for t in ts]
        print(f"  {nm:19s} {ts[0]['effects'][0]['size']['name']:>19s} {min(sz):8.3f}-{max(sz):8.3f}  "
              f"magnitude {min(mg):8.3f}-{max(mg):8.3f} mm  frames {min(fr)}-{max(fr)}  sigma {min(sg):.2f}-{max(sg):.2f}  "
              f"noise {dict(Counter(t['params']['noise']['kind'] for t in ts))}  "
              f"motion {dict(Counter(t['category']['motion'] for t in ts))}")


def check_v2_trial(stem, truth, entry, spec, X0, Xfull, Xf, names, seg_of):
    """Per-trial v2 checks: category, gaps, gap-free rebuild, label view, noise, layout, motion."""
    V2["trials"] += 1
    geom = spec["_geom"]; N = spec["n_frames"]
    cat = entry["category"]
    if cat.get("gaps") != bool(spec["gaps"]) or cat.get("layout") != spec["layout"] \
            or cat["motion"] != spec["motion"]["kind"] or spec["motion"]["kind"] not in ("functional", "gait", "sit_to_stand"):
        fail(stem, "v2 category")
    # gap list
    gaps = spec["gaps"]
    if truth.get("gaps") != gaps or entry["params"].get("gaps") != gaps:
        fail(stem, "truth / index gap lists differ from the spec's")
    pelvis = list(geom["markers"]["pelvis"])
    if gaps:
        V2["n_gaps"].append(len(gaps))
        if not 1 <= len(gaps) <= 6:
            fail(stem, f"{len(gaps)} gaps")
        for gp in gaps:
            f0, f1 = gp["frames"]
            if gp["marker"] not in names or not 0 <= f0 <= f1 < N or not 5 <= f1 - f0 + 1 <= 150:
                fail(stem, f"gap {gp}")
        for i, g1 in enumerate(gaps):
            for g2 in gaps[i + 1:]:
                if g1["marker"] == g2["marker"] and g1["frames"][0] <= g2["frames"][1] + 1 and g2["frames"][0] <= g1["frames"][1] + 1:
                    fail(stem, f"gaps {g1} and {g2} touch")
    miss = gap_mask(N, names, gaps)
    if not np.array_equal(nanmask(X0), miss):
        fail(stem, "rigid rebuild: NaN samples != truth gaps")
    occlusion_rules(stem, miss, names, pelvis, "gaps")
    Xng, _, _, _ = G.simulate(spec, [], noise=False, gaps=False)
    if np.isnan(Xng).any() or not np.array_equal(Xng[~miss], X0[~miss]):
        fail(stem, "gap-free rebuild differs from the gapped one on visible samples")
    # label view (written trial)
    sw = [e for e in spec["effects"] if e["name"] == "marker_swap"]
    lab = swapped(miss, names, sw[0]) if sw else miss
    if not np.array_equal(nanmask(Xfull), lab) or not np.array_equal(np.isnan(Xf).any(2), lab):
        fail(stem, "full rebuild / TRC: empty samples != gaps relabelled by the swap")
    occlusion_rules(stem, lab, names, pelvis, "TRC labels")
    # noise level (outlier samples excluded)
    nz = spec["noise"]
    if not 0.3 <= nz["sigma_mm"] <= 1.5 or (nz["model"] == "ar1" and not 0.6 <= nz["phi"] <= 0.9) \
            or nz["model"] not in ("white", "ar1"):
        fail(stem, "noise parameters")
    Xc, _, _, _ = G.simulate(spec, None, noise=False)
    res = Xfull - Xc
    for e in spec["effects"]:
        if e["name"] == "outliers":
            for ev in e["events"]:
                res[ev["frame"]:ev["frame"] + ev["length"], names.index(ev["marker"])] = np.nan
    ratio = np.nanstd(res) / nz["sigma_mm"]
    V2["noise_ratio"].append(ratio)
    if not 0.85 < ratio < 1.15:
        fail(stem, f"noise std / sigma = {ratio:.3f}")
    check_layout(stem, spec, geom)
    check_motion(stem, spec)
    if SWEEP["on"]:
        check_sweep_trial(stem, truth, entry, spec)
    elif "sweep" in spec:
        fail(stem, "sweep spec in a non-sweep dataset")


# ----------------------------------------------------------------------------- per trial
def check_trial(d, entry):
    stem = entry["stem"]
    truth = json.load(open(os.path.join(d, stem + ".truth.json")))
    for k in ("stem", "effects", "category", "params"):
        if truth[k] != entry[k]:
            fail(stem, f"index and truth differ in {k}")
    spec = truth["spec"]
    geom = G.geometry_from_json(spec["geometry"])
    spec["_geom"] = geom
    order = G.marker_order(geom)
    names = [m for _, m in order]
    seg_of = dict((m, s) for s, m in order)
    idx = {m: i for i, m in enumerate(names)}
    segs = {s: [idx[m] for m in geom["markers"][s]] for s in G.SEGMENTS}

    # 1. rigid reference geometry
    v2 = spec.get("version", 1) == 2
    X0, _, jg, _ = G.simulate(spec, [], noise=False)
    hd = truth["joints"]["hip"]["marker_distances"]
    kd = truth["joints"]["knee"]["marker_distances"]
    err_gen = err_est = 0.0
    for m, v in hd.items():      # NaN-aware: v2 gaps leave NaN samples (none in v1)
        x = X0[:, idx[m]]
        err_gen = max(err_gen, np.nanmax(np.abs(np.linalg.norm(x - jg["hip_centre"], axis=1) - v)))
    for m, v in kd.items():
        x = X0[:, idx[m]]
        err_gen = max(err_gen, np.nanmax(np.abs(line_dist(x, jg["knee_point"], jg["knee_dir"]) - v)))
    if v2:
        err_est = v2_estimated_joint_error(stem, spec, X0, names, segs, hd, kd)
    else:
        poses = {s: kabsch(X0[:, segs[s]]) for s in G.SEGMENTS}
        hc_est = score_centre(*poses["pelvis"], *poses["thigh"])
        kp_est, kdir_est = sara_axis(*poses["thigh"], *poses["shank"])
        for m, v in hd.items():
            err_est = max(err_est, np.abs(np.linalg.norm(X0[:, idx[m]] - hc_est, axis=1) - v).max())
        for m, v in kd.items():
            err_est = max(err_est, np.abs(line_dist(X0[:, idx[m]], kp_est, kdir_est) - v).max())
    if set(hd) != set(geom["markers"]["pelvis"]) | set(geom["markers"]["thigh"]):
        fail(stem, "hip marker_distances keys")
    if set(kd) != set(geom["markers"]["thigh"]) | set(geom["markers"]["shank"]):
        fail(stem, "knee marker_distances keys")
    if err_gen > TOL_DIST:
        fail(stem, f"truth distance not constant vs generator joints: {err_gen:.2e} mm")
    if err_est > TOL_DIST:
        fail(stem, f"truth distance vs marker-estimated joints: {err_est:.2e} mm")

    # 2. effects: magnitude and where
    mag_err = 0.0
    for e_rec, e in zip(truth["effects"], spec["effects"]):
        X1, _, _, _ = G.simulate(spec, [e["name"]], noise=False)
        D = np.linalg.norm(X1 - X0, axis=2)          # NaN where a gap hides either sample
        peak = np.nanmax(D)
        rel = abs(peak - e_rec["magnitude_mm"]) / max(peak, 1e-12)
        mag_err = max(mag_err, rel)
        if rel > 0.01:
            fail(stem, f"{e['name']}: recorded {e_rec['magnitude_mm']:.4f} vs actual {peak:.4f}")
        if "target_peak_mm" in e and abs(peak - e["target_peak_mm"]) > 0.01 * e["target_peak_mm"]:
            fail(stem, f"{e['name']}: target {e['target_peak_mm']:.4f} vs actual {peak:.4f}")
        w = e_rec["where"]
        moved = D > 1e-9
        mk_moved = sorted(names[j] for j in np.where(moved.any(0))[0])
        fr_moved = np.where(moved.any(1))[0]
        nm = e["name"]
        if nm == "marker_slip":
            if mk_moved != [w["marker"]] or fr_moved[0] != w["frame"] or w["frame_number"] != w["frame"] + 1:
                fail(stem, "marker_slip where mismatch")
            prof = D[:, idx[w["marker"]]]
            if not (prof[w["frames"][1]] >= 0.99999 * peak and (w["frames"][1] == w["frame"] or prof[w["frames"][1] - 1] < peak)):
                fail(stem, "marker_slip drift end mismatch")
            if seg_of[w["marker"]] != w["segment"]:
                fail(stem, "marker_slip segment")
        elif nm == "marker_swap" and v2:
            check_v2_swap(stem, spec, e, w, X0, X1, moved, names, seg_of)
        elif nm == "marker_swap":
            if mk_moved != sorted(w["markers"]) or fr_moved[0] != w["frames"][0] or fr_moved[-1] != w["frames"][1] \
                    or len(fr_moved) != w["frames"][1] - w["frames"][0] + 1 or w["frame_numbers"] != [w["frames"][0] + 1, w["frames"][1] + 1]:
                fail(stem, "marker_swap where mismatch")
            if [seg_of[m] for m in w["markers"]] != w["segments"]:
                fail(stem, "marker_swap segments")
        elif nm == "outliers":
            cells = sorted((names[j], int(f)) for f, j in zip(*np.where(moved)))
            rec = sorted((s["marker"], f) for s in w["samples"] for f in s["frames"])
            if cells != rec or sorted({f for _, f in rec}) != w["frames"]:
                fail(stem, "outliers where mismatch")
        elif nm in ("time_offset", "soft_tissue"):
            if mk_moved != sorted(w["markers"]):
                fail(stem, f"{nm} where markers mismatch {mk_moved} vs {w['markers']}")
            if nm == "time_offset" and any(seg_of[m] != w["segment"] for m in w["markers"]):
                fail(stem, "time_offset segment")
        elif nm == "joint_translation":
            moved_segs = {seg_of[m] for m in mk_moved}
            exp = {"shank"} if w["joint"] == "knee" else {"thigh", "shank"}
            if moved_segs != exp:
                fail(stem, "joint_translation moves the wrong segments")
        elif nm == "extra_dof":
            if {seg_of[m] for m in mk_moved} != {"shank"}:
                fail(stem, "extra_dof moves the wrong segments")
        if v2:
            check_v2_effect(stem, spec, e, w, X0, X1, D, moved, names, seg_of)

    # 3. files
    hdr, tnames, frames, times, Xf = read_trc(os.path.join(d, stem + ".trc"))
    model = tomllib.load(open(os.path.join(d, stem + ".toml"), "rb"))
    mnames = [m for s in model["segments"] for m in model["segments"][s]["markers"]]
    if model.get("units") != "mm" or set(model["joints"]) != {"hip", "knee"} \
            or model["joints"]["hip"]["type"] != "spherical" or model["joints"]["knee"]["type"] != "revolute":
        fail(stem, "model toml content")
    if tnames != names or sorted(mnames) != sorted(names):
        fail(stem, "marker names differ between TRC / TOML / truth")
    if v2 and any(model["segments"].get(s, {}).get("markers") != list(geom["markers"][s]) for s in G.SEGMENTS):
        fail(stem, "model toml segment markers differ from the truth geometry")
    N = spec["n_frames"]
    if int(hdr["NumFrames"]) != N or int(hdr["NumMarkers"]) != len(names) or hdr["Units"] != "mm" \
            or float(hdr["DataRate"]) != 100 or Xf.shape != (N, len(names), 3):
        fail(stem, "TRC header / shape")
    if not (np.array_equal(frames, np.arange(1, N + 1)) and np.allclose(times, np.arange(N) / 100, atol=1e-9)):
        fail(stem, "TRC frame / time columns")
    Xfull, _, _, _ = G.simulate(spec)
    if Xf.shape == Xfull.shape and not np.array_equal(np.isnan(Xf), np.isnan(Xfull)):
        fail(stem, "TRC empty cells differ from the regeneration's NaN samples")
    trc_err = np.nanmax(np.abs(Xf - Xfull)) if Xf.shape == Xfull.shape else np.inf
    if trc_err > 5e-5 + 1e-7:
        fail(stem, f"TRC differs from regeneration by {trc_err:.2e} mm")
    if v2:
        check_v2_trial(stem, truth, entry, spec, X0, Xfull, Xf, names, seg_of)
    return err_gen, err_est, mag_err, trc_err


def summarise_v2(trials):
    """Print the v2 mix (gaps / layout / motion / new shapes) and check its proportions (not in
    sweep mode, whose categories are drawn independently per trial)."""
    from collections import Counter
    n = len(trials)
    cat = lambda k: Counter(t["category"][k] for t in trials)
    gaps, layout, motion = cat("gaps"), cat("layout"), cat("motion")
    kinds = cat("kind")
    print(f"v2: gaps {dict(gaps)}  layout {dict(layout)}  motion {dict(motion)}")
    for k in ("gaps", "layout", "motion") if not SWEEP["on"] else ():
        print(f"    clean trials by {k}: {dict(Counter(t['category'][k] for t in trials if t['category']['kind'] == 'clean'))}")
    ng = Counter(V2["n_gaps"])
    print(f"    gaps per gapped trial: {dict(sorted(ng.items()))}; min visible fraction (any marker, any view): "
          f"{V2['min_visible']:.3f}")
    lens = []
    for t in trials:
        lens += [gp["frames"][1] - gp["frames"][0] + 1 for gp in t["params"].get("gaps", [])]
    if lens:
        print(f"    gap lengths: {min(lens)}-{max(lens)} frames, median {np.median(lens):.0f}, "
              f"{sum(x > 60 for x in lens)} of {len(lens)} longer than 60")
    mps = Counter((t["category"]["layout"], t["params"]["markers_per_segment"]["thigh"],
                   t["params"]["markers_per_segment"]["shank"]) for t in trials)
    print(f"    (layout, thigh markers, shank markers): {dict(sorted(mps.items()))}")
    if V2["close_to_axis_mm"]:
        print(f"    epicondyle markers off the knee axis: {min(V2['close_to_axis_mm']):.2f}-{max(V2['close_to_axis_mm']):.2f} mm")
    print(f"    sit_to_stand cycles: {dict(sorted(Counter(V2['s2s_cycles']).items()))}")
    sig = [t["params"]["noise"]["sigma_mm"] for t in trials]
    print(f"    noise sigma {min(sig):.2f}-{max(sig):.2f} mm; measured std / sigma "
          f"{min(V2['noise_ratio']):.3f}-{max(V2['noise_ratio']):.3f}")
    print(f"    new shapes: marker_swap in_gap {V2['swap_in_gap']}, heavy_tailed outliers {len(V2['heavy_events'])} "
          f"({min(V2['heavy_events'], default=0)}-{max(V2['heavy_events'], default=0)} events), "
          f"soft_tissue other_joint {V2['other_joint']}, marker_slip fast_ramp "
          f"{sum(e['shape'] == 'fast_ramp' for t in trials for e in t['effects'])}")
    print(f"    marker-estimated joints: virtual-marker fit on {V2['trials']} trials (>= {V2['est_frames_min']} "
          f"fully visible frames; {V2['est_fallback']} gap-free fallbacks), plus Kabsch/SCoRE/SARA on "
          f"{V2['est_kabsch_score_sara']}")
    if SWEEP["on"]:
        return
    if kinds != Counter({"clean": round(0.12 * n), "pair": round(0.18 * n),
                         "single": n - round(0.12 * n) - round(0.18 * n)}):
        fail("index", f"mix {dict(kinds)}")
    n_s2s = round(n / 3)
    exp = {"gaps": round(0.6 * n), "anatomical": round(0.5 * n), "sit_to_stand": n_s2s,
           "functional": round((n - n_s2s) / 2)}
    got = {"gaps": gaps[True], "anatomical": layout["anatomical"], "sit_to_stand": motion["sit_to_stand"],
           "functional": motion["functional"]}
    if got != exp:
        fail("index", f"v2 category counts {got}, expected {exp}")


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "/tmp/heldout_effects_a"
    t0 = time.time()
    index = json.load(open(os.path.join(d, "index.json")))
    assert index["generator"] in (G.GENERATOR, G.GENERATOR_V2)
    version = 2 if index["generator"] == G.GENERATOR_V2 else 1
    assert index.get("version", 1) == version
    SWEEP["on"], SWEEP["seed"] = bool(index.get("sweep")), index["seed"]
    assert not SWEEP["on"] or version == 2
    trials = index["trials"]
    worst = np.zeros(4)
    for entry in trials:
        worst = np.maximum(worst, check_trial(d, entry))
        sv = json.load(open(os.path.join(d, entry["stem"] + ".truth.json")))["spec"].get("version", 1)
        if sv != version:
            fail(entry["stem"], f"spec version {sv} in a v{version} dataset")
    # mix summary
    from collections import Counter
    kinds = Counter(t["category"]["kind"] for t in trials)
    motion = Counter(t["category"]["motion"] for t in trials)
    noise = Counter(t["category"]["noise"] for t in trials)
    single = Counter(t["effects"][0]["name"] for t in trials if t["category"]["kind"] == "single")
    anyeff = Counter(e["name"] for t in trials for e in t["effects"])
    for t in trials:
        k = t["category"]["kind"]
        if len(t["effects"]) != {"clean": 0, "single": 1, "pair": 2}[k] or \
                len({e["name"] for e in t["effects"]}) != len(t["effects"]) or \
                any(e["name"] not in G.EFFECTS for e in t["effects"]):
            fail(t["stem"], "category / effects inconsistent")
    print(f"trials: {len(trials)}  kinds: {dict(kinds)}  motion: {dict(motion)}  noise: {dict(noise)}")
    print(f"single-effect counts: {dict(sorted(single.items()))}")
    print(f"all-effect counts:    {dict(sorted(anyeff.items()))}")
    print("magnitude_mm per effect (min / median / max) and shapes:")
    for nm in G.EFFECTS:
        mags = [e["magnitude_mm"] for t in trials for e in t["effects"] if e["name"] == nm]
        shapes = sorted({e["shape"] for t in trials for e in t["effects"] if e["name"] == nm})
        if mags:
            print(f"  {nm:19s} {min(mags):7.2f} {np.median(mags):7.2f} {max(mags):8.2f}   {', '.join(shapes)}")
    print(f"worst |distance - truth|, generator joints: {worst[0]:.2e} mm; marker-estimated joints: {worst[1]:.2e} mm")
    print(f"worst relative magnitude error: {worst[2]:.2e};  worst TRC vs regeneration: {worst[3]:.2e} mm")
    if version == 2:
        summarise_v2(trials)
    if SWEEP["on"]:
        summarise_sweep(index, trials)
    print(f"checked in {time.time() - t0:.1f} s")
    if failures:
        print(f"FAIL ({len(failures)})")
        for f in failures[:40]:
            print("  " + f)
        sys.exit(1)
    print("ALL CHECKS PASSED")


if __name__ == "__main__":
    main()
