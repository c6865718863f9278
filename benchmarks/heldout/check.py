#!/usr/bin/env python3
"""Checks a folder written by generator.py.

    python benchmarks/heldout/check.py DIR [--tol 1e-6]

* categories balanced over the 18-cell cross, gaps in about a third of the trials;
* TRC files parse back (own minimal reader): header counts, frame numbering, marker
  names = the model's markers, NaN exactly where the generator put gaps, values equal to
  a fresh regeneration (to the 4 written decimals);
* on a noise-free regeneration (level='rigid'): the joint centre / hinge axis computed via
  the parent and via the child coincide, and every truth marker_distance is constant
  over all frames and equal to the truth value to --tol mm;
* truth distances >= 30 mm; truth marker lists = parent + child markers of the model;
* noise: residual TRC - clean has the stated sigma (and phi for AR(1)); the soft-tissue
  deformation has zero trial mean and the stated peak.
Exit 1 on any failure.
"""
import argparse
import collections
import json
import os
import sys
import time
import tomllib

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import generator as G  # noqa: E402


def read_trc(path):
    with open(path) as f:
        lines = f.read().split("\n")
    assert lines[0].split("\t")[0] == "PathFileType", "line 1"
    keys = lines[1].split("\t")
    vals = lines[2].split("\t")
    hdr = dict(zip(keys, vals))
    names = [x for x in lines[3].split("\t")[2:] if x != ""]
    sub = lines[4].split("\t")
    assert sub[:2] == ["", ""] and len(sub) == 2 + 3 * len(names), "line 5"
    assert lines[5] == "", "line 6 must be empty"
    rows = [ln for ln in lines[6:] if ln != ""]
    ncol = 2 + 3 * len(names)
    data = np.full((len(rows), ncol), np.nan)
    for i, ln in enumerate(rows):
        cells = ln.split("\t")
        assert len(cells) == ncol, f"row {i + 1}: {len(cells)} cells, expected {ncol}"
        for j, c in enumerate(cells):
            if c != "":
                data[i, j] = float(c)
    return hdr, names, data[:, 0], data[:, 1], data[:, 2:].reshape(len(rows), len(names), 3)


def line_dist(X, a, n):
    v = X - a
    return np.linalg.norm(v - np.sum(v * n, -1, keepdims=True) * n, axis=-1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--tol", type=float, default=1e-6)
    a = ap.parse_args()
    t0 = time.time()
    idx = json.load(open(os.path.join(a.dir, "index.json")))
    seed = idx["seed"]
    fails = []

    def fail(msg):
        fails.append(msg)
        if len(fails) <= 30:
            print("FAIL", msg)

    # ---- balance
    cnt = collections.Counter((t["category"]["noise"], t["category"]["markerset"], t["category"]["motion"])
                              for t in idx["trials"])
    print(f"{len(idx['trials'])} trials, {len(cnt)} categories")
    for no in G.NOISES:
        print("  " + no.ljust(12) + "  ".join(f"{ms}/{mo}={cnt[(no, ms, mo)]:2d}"
                                             for ms in G.MARKERSETS for mo in G.MOTIONS))
    if len(cnt) != 18 or max(cnt.values()) - min(cnt.values()) > 1:
        fail("categories not balanced")
    n_gap = sum(t["params"]["has_gaps"] for t in idx["trials"])
    print(f"trials with gaps: {n_gap} ({n_gap / len(idx['trials']):.0%})")
    if not 0.2 <= n_gap / len(idx["trials"]) <= 0.45:
        fail("gap fraction not about a third")

    worst = collections.defaultdict(float)
    ratios = collections.defaultdict(list)
    for i, t in enumerate(idx["trials"]):
        stem = t["stem"]
        cat = (t["category"]["markerset"], t["category"]["motion"], t["category"]["noise"])
        gaps = t["params"]["has_gaps"]
        assert t["params"]["trial_seed"] == [seed, i]
        model = tomllib.load(open(os.path.join(a.dir, stem + ".toml"), "rb"))
        truth = json.load(open(os.path.join(a.dir, stem + ".truth.json")))
        hdr, names, frame, tim, X = read_trc(os.path.join(a.dir, stem + ".trc"))

        seg_markers = {s: v["markers"] for s, v in model["segments"].items()}
        all_m = [m for v in seg_markers.values() for m in v]
        if names != all_m or len(set(all_m)) != len(all_m) or not all(m.isupper() for m in all_m):
            fail(f"{stem}: TRC names {names} vs model {all_m}")
        n = len(frame)
        if int(hdr["NumFrames"]) != n or int(hdr["NumMarkers"]) != len(names) or hdr["Units"] != "mm":
            fail(f"{stem}: header {hdr}")
        if not (np.array_equal(frame, np.arange(1, n + 1)) and np.allclose(tim, np.arange(n) / 100.0)):
            fail(f"{stem}: frame/time columns")
        if not 1000 <= n <= 2000 or n != t["params"]["frames"]:
            fail(f"{stem}: frames {n}")
        ms = t["category"]["markerset"]
        cnts = {s: len(v) for s, v in seg_markers.items()}
        exp = {"full": dict(pelvis=(3, 4), thigh=(3, 4), shank=(3, 4), foot=(3, 3)),
               "2+2": dict(pelvis=(2, 2), thigh=(2, 2), shank=(3, 3)),
               "minimal": dict(pelvis=(3, 3), thigh=(1, 1), shank=(1, 1))}[ms]
        if any(s not in exp or not exp[s][0] <= c <= exp[s][1] for s, c in cnts.items()):
            fail(f"{stem}: marker counts {cnts} for {ms}")

        # ---- regenerate: rigid, and full (must equal the file)
        rig = G.build_trial(seed, i, cat, gaps=gaps, level="rigid")
        full = G.build_trial(seed, i, cat, gaps=gaps, level="full")
        if rig["names"] != names:
            fail(f"{stem}: regenerated names differ")
            continue
        nan = np.isnan(X).any(-1)
        if not np.array_equal(nan, np.isnan(X).all(-1)) or not np.array_equal(nan, rig["gap_mask"]):
            fail(f"{stem}: NaN pattern differs from the gap mask")
        if gaps != bool(nan.any()):
            fail(f"{stem}: has_gaps={gaps} but NaN present={nan.any()}")
        ok = ~nan
        dv = np.abs(X[ok] - full["X"][ok]).max()
        worst["trc_vs_regen"] = max(worst["trc_vs_regen"], dv)
        if dv > 5.1e-5:
            fail(f"{stem}: TRC differs from regeneration by {dv}")

        # ---- rigid geometry: joint via parent == via child; distances constant
        col = {m: j for j, m in enumerate(names)}
        Xr = rig["X"]
        P = rig["poses"]
        g = rig["geom"]
        J = truth["joints"]
        if set(J) != set(model["joints"]):
            fail(f"{stem}: truth joints {set(J)} vs model {set(model['joints'])}")
        for jn, jt in J.items():
            mj = model["joints"][jn]
            if jt["type"] != mj["type"]:
                fail(f"{stem}: {jn} type")
            par, ch = mj["parent"], mj["child"]
            Rp_, pp_ = P[par]
            Rc_, pc_ = P[ch]
            expect = seg_markers[par] + seg_markers[ch]
            if sorted(jt["marker_distances"]) != sorted(expect):
                fail(f"{stem}: {jn} marker list")
            if jt["type"] == "spherical":
                c_par = pp_ + Rp_ @ np.array(jt["centre_parent"])
                c_ch = pc_ + Rc_ @ np.array(jt["centre_child"])
                worst["centre_parent_vs_child"] = max(worst["centre_parent_vs_child"],
                                                      np.abs(c_par - c_ch).max())
                d = {m: np.linalg.norm(Xr[:, col[m]] - c_par, axis=-1) for m in expect}
            else:
                a_par = pp_ + Rp_ @ np.array(jt["axis_point_parent"])
                n_par = Rp_ @ np.array(jt["axis_direction_parent"])
                a_ch = pc_ + Rc_ @ np.array(jt["axis_point_child"])
                n_ch = Rc_ @ np.array(jt["axis_direction_child"])
                worst["axis_parent_vs_child"] = max(worst["axis_parent_vs_child"],
                                                    np.abs(n_par - n_ch).max(),
                                                    line_dist(a_ch, a_par, n_par).max())
                d = {m: line_dist(Xr[:, col[m]], a_par, n_par) for m in expect}
            for m, dm in d.items():
                ref = jt["marker_distances"][m]
                dev = np.abs(dm - ref).max()
                worst["distance_dev_" + t["category"]["noise"]] = max(
                    worst["distance_dev_" + t["category"]["noise"]], dev)
                if dev > a.tol:
                    fail(f"{stem}: {jn}/{m} distance deviates by {dev:.3g} mm")
                if ref < 30.0:
                    fail(f"{stem}: {jn}/{m} truth distance {ref:.1f} < 30 mm")
        # the limb hangs down from the pelvis and the knee stays below the hip
        hip_w = P["thigh"][1]
        knee_w = P["shank"][1]
        if not (knee_w[:, 1] < hip_w[:, 1] - 150).all():
            fail(f"{stem}: knee not below hip")

        # ---- noise model
        no = truth["noise"]
        if no["type"] == "soft_tissue":
            sta = G.build_trial(seed, i, cat, gaps=gaps, level="sta")
            mean_dev = max(np.abs(v.mean(0)).max() for v in sta["disp"].values())
            worst["sta_mean_abs"] = max(worst["sta_mean_abs"], mean_dev)
            for m, v in sta["disp"].items():
                pk = np.linalg.norm(v, axis=1).max()
                if abs(pk - no["soft_tissue_peak_mm"][m]) > 1e-9 or not 2 * 0.6 - 1e-9 <= pk <= 10:
                    fail(f"{stem}: STA peak {m}")
            if mean_dev > 1e-9:
                fail(f"{stem}: STA mean {mean_dev}")
            res = X[ok] - sta["X"][ok]
            ratios["soft_tissue white"].append(res.std() / no["white_sigma_mm"])
            res_r = X[ok] - Xr[ok]
            ratios["soft_tissue total rms/white"].append(np.sqrt((res_r ** 2).mean()) / no["white_sigma_mm"])
        else:
            res = X - Xr  # (n, m, 3) with NaN
            sig = no["sigma_mm"] if no["type"] == "white" else no["marginal_sigma_mm"]
            ratios[no["type"] + " sigma"].append(np.nanstd(res) / sig)
            if no["type"] == "ar1":
                a0, a1 = res[1:].reshape(n - 1, -1), res[:-1].reshape(n - 1, -1)
                okk = ~np.isnan(a0) & ~np.isnan(a1)
                r1 = np.sum(a0[okk] * a1[okk]) / np.sqrt(np.sum(a0[okk] ** 2) * np.sum(a1[okk] ** 2))
                ratios["ar1 lag1 - phi"].append(r1 - no["phi"])
            else:
                a0, a1 = res[1:].ravel(), res[:-1].ravel()
                okk = ~np.isnan(a0) & ~np.isnan(a1)
                ratios["white lag1"].append(np.corrcoef(a0[okk], a1[okk])[0, 1])

    print("worst-case deviations (mm unless noted):")
    for k, v in sorted(worst.items()):
        print(f"  {k:32s} {v:.3g}")
    print("noise statistics over trials (min / median / max):")
    for k, v in sorted(ratios.items()):
        v = np.array(v)
        print(f"  {k:32s} {v.min():+.3f} / {np.median(v):+.3f} / {v.max():+.3f}  (n={len(v)})")
    if "white sigma" in ratios and not 0.9 < np.median(ratios["white sigma"]) < 1.1:
        fail("white sigma off")
    if "ar1 sigma" in ratios and not 0.8 < np.median(ratios["ar1 sigma"]) < 1.2:
        fail("ar1 sigma off")
    if "ar1 lag1 - phi" in ratios and np.abs(ratios["ar1 lag1 - phi"]).max() > 0.05:
        fail("ar1 phi off")
    print(f"checked in {time.time() - t0:.1f} s: " + ("OK" if not fails else f"{len(fails)} FAILURES"))
    sys.exit(1 if fails else 0)


if __name__ == "__main__":
    main()
