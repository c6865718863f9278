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
    arr = np.array(rows, dtype=float)
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
    X0, _, jg, _ = G.simulate(spec, [], noise=False)
    hd = truth["joints"]["hip"]["marker_distances"]
    kd = truth["joints"]["knee"]["marker_distances"]
    poses = {s: kabsch(X0[:, segs[s]]) for s in G.SEGMENTS}
    hc_est = score_centre(*poses["pelvis"], *poses["thigh"])
    kp_est, kdir_est = sara_axis(*poses["thigh"], *poses["shank"])
    err_gen = err_est = 0.0
    for m, v in hd.items():
        x = X0[:, idx[m]]
        err_gen = max(err_gen, np.abs(np.linalg.norm(x - jg["hip_centre"], axis=1) - v).max())
        err_est = max(err_est, np.abs(np.linalg.norm(x - hc_est, axis=1) - v).max())
    for m, v in kd.items():
        x = X0[:, idx[m]]
        err_gen = max(err_gen, np.abs(line_dist(x, jg["knee_point"], jg["knee_dir"]) - v).max())
        err_est = max(err_est, np.abs(line_dist(x, kp_est, kdir_est) - v).max())
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
        D = np.linalg.norm(X1 - X0, axis=2)
        peak = D.max()
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

    # 3. files
    hdr, tnames, frames, times, Xf = read_trc(os.path.join(d, stem + ".trc"))
    model = tomllib.load(open(os.path.join(d, stem + ".toml"), "rb"))
    mnames = [m for s in model["segments"] for m in model["segments"][s]["markers"]]
    if model.get("units") != "mm" or set(model["joints"]) != {"hip", "knee"} \
            or model["joints"]["hip"]["type"] != "spherical" or model["joints"]["knee"]["type"] != "revolute":
        fail(stem, "model toml content")
    if tnames != names or sorted(mnames) != sorted(names):
        fail(stem, "marker names differ between TRC / TOML / truth")
    N = spec["n_frames"]
    if int(hdr["NumFrames"]) != N or int(hdr["NumMarkers"]) != len(names) or hdr["Units"] != "mm" \
            or float(hdr["DataRate"]) != 100 or Xf.shape != (N, len(names), 3):
        fail(stem, "TRC header / shape")
    if not (np.array_equal(frames, np.arange(1, N + 1)) and np.allclose(times, np.arange(N) / 100, atol=1e-9)):
        fail(stem, "TRC frame / time columns")
    Xfull, _, _, _ = G.simulate(spec)
    trc_err = np.abs(Xf - Xfull).max()
    if trc_err > 5e-5 + 1e-7:
        fail(stem, f"TRC differs from regeneration by {trc_err:.2e} mm")
    return err_gen, err_est, mag_err, trc_err


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "/tmp/heldout_effects_a"
    t0 = time.time()
    index = json.load(open(os.path.join(d, "index.json")))
    assert index["generator"] == G.GENERATOR
    trials = index["trials"]
    worst = np.zeros(4)
    for entry in trials:
        worst = np.maximum(worst, check_trial(d, entry))
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
    print(f"checked in {time.time() - t0:.1f} s")
    if failures:
        print(f"FAIL ({len(failures)})")
        for f in failures[:40]:
            print("  " + f)
        sys.exit(1)
    print("ALL CHECKS PASSED")


if __name__ == "__main__":
    main()
