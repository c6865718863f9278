#!/usr/bin/env python3
"""heldout_still: independent generator of low-excitation lower-limb marker trials.

Chain: pelvis (root) -> hip_r (spherical) -> thigh_r -> knee_r (revolute) -> shank_r
[-> ankle_r (revolute) -> foot_r].  Motions: static / tiny / small / moving (control).
See README.md beside this file for the full spec and output layout.

    python generator.py --out DIR --n N --seed S [--check]
    python generator.py --out DIR --check          # re-check an existing DIR

Trial k depends only on (seed, k): everything it draws comes from
numpy.random.default_rng([seed, k]); its categories come from k alone (a balanced cycle of 24).
Uses numpy and scipy only; never imports the library under test.
"""
import argparse
import json
import sys
import tomllib
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

RATE = 100.0
MIN_CLEAR = 30.0  # mm: every marker at least this far from its joint centres / hinge axes
MOTIONS = ("static", "tiny", "small", "moving")
MARKERSETS = ("full", "sparse", "mixed")
NOISES = ("white", "ar1")
JOINTS = {"hip_r": ("spherical", "pelvis", "thigh_r"),
          "knee_r": ("revolute", "thigh_r", "shank_r"),
          "ankle_r": ("revolute", "shank_r", "foot_r")}
NAMES = {"pelvis": ["LASI", "RASI", "LPSI", "RPSI", "SACR"], "thigh_r": ["RGT", "RTH1", "RTH2", "RTH3"],
         "shank_r": ["RTB1", "RTB2", "RTB3"], "foot_r": ["RHEE", "RTOE", "RMT5"]}
Z = np.array([0.0, 0.0, 1.0])


def design(k):
    """Categories of trial k: a fixed cycle of 24 = 4 motions x 3 marker sets x 2 noise models.
    Trials 0-11 hold every motion x markerset pair once (6 white, 6 AR(1)); 12-23 repeat them
    with the other noise model."""
    c = k % 24
    m, s = c % 4, (c // 4) % 3
    return MOTIONS[m], MARKERSETS[s], NOISES[(m // 2 + s + c // 12) % 2]


def unit(v):
    return v / np.linalg.norm(v)


def dist_line(x, p, a):
    """Distance of point(s) x to the line through p with unit direction a (broadcasts)."""
    d = x - p
    return np.linalg.norm(d - np.sum(d * a, -1, keepdims=True) * a, axis=-1)


def tilted(rng, base, max_deg):
    """Unit vector at an angle uniform in [0, max_deg] from base, random azimuth."""
    perp = unit(np.cross(base, rng.normal(size=3)))
    ang = np.radians(rng.uniform(0, max_deg))
    return unit(np.cos(ang) * base + np.sin(ang) * perp)


def place(rng, start, end, frac, phi_c, phi_w, clear):
    """Marker at fraction `frac` (range) along the bone line start->end, 40-90 mm from it at an
    azimuth phi_c +- phi_w deg (0 = lateral +z side, 90 = d x lateral); rejection-sampled until
    at least MIN_CLEAR from every ('pt', c) / ('line', p, a) in `clear`."""
    d = unit(end - start)
    e1 = unit(Z - (Z @ d) * d)
    e2 = np.cross(d, e1)
    for _ in range(10000):
        phi = np.radians(phi_c + rng.uniform(-phi_w, phi_w))
        x = start + rng.uniform(*frac) * (end - start) + rng.uniform(40, 90) * (np.cos(phi) * e1 + np.sin(phi) * e2)
        if all((np.linalg.norm(x - c[1]) if c[0] == "pt" else dist_line(x, c[1], c[2])) >= MIN_CLEAR for c in clear):
            return x
    raise RuntimeError("marker placement failed")


def draw_subject(rng):
    """Segment frames: x anterior, y superior, z right (lateral), as the lab at zero angles.
    pelvis: origin mid-ASIS.  thigh: origin hip centre, knee centre at (0,-Lt,0).
    shank: origin knee centre, ankle centre (0,-Ls,0).  foot: origin ankle centre."""
    W, Lt, Ls, Lf = rng.uniform(200, 280), rng.uniform(380, 460), rng.uniform(360, 440), rng.uniform(180, 230)
    D = rng.uniform(130, 170)                       # ASIS-PSIS depth
    hip = np.array([-0.19 * W, -0.30 * W, 0.36 * W]) + rng.uniform(-8, 8, 3)   # Bell-like
    knee_c, knee_a = np.array([0.0, -Lt, 0.0]), tilted(rng, Z, 10)
    ankle_c, ankle_a = np.array([0.0, -Ls, 0.0]), tilted(rng, Z, 10)
    o = np.zeros(3)
    loc = {}
    for n, p in zip(NAMES["pelvis"], ([0, 0, -W / 2], [0, 0, W / 2], [-D, 15, -45], [-D, 15, 45], [-D - 15, 40, 0])):
        loc[n] = np.array(p, float) + rng.uniform(-10, 10, 3)
    ck, ca = ("line", knee_c, knee_a), ("line", ankle_c, ankle_a)
    for n, f, w in (("RGT", (0.03, 0.10), 30), ("RTH1", (0.15, 0.38), 90),
                    ("RTH2", (0.38, 0.62), 90), ("RTH3", (0.62, 0.85), 90)):
        loc[n] = place(rng, o, knee_c, f, 0, w, [("pt", o), ck])
    for n, f in (("RTB1", (0.12, 0.35)), ("RTB2", (0.35, 0.60)), ("RTB3", (0.60, 0.85))):
        loc[n] = place(rng, o, ankle_c, f, 0, 90, [("line", o, knee_a), ca])
    alpha = np.radians(rng.uniform(15, 30))                       # foot bone line slopes down
    toe = Lf * np.array([np.cos(alpha), -np.sin(alpha), 0.0])
    for n, f, pc, pw in (("RHEE", (-0.30, -0.15), 90, 45), ("RTOE", (0.85, 1.0), -90, 45),
                         ("RMT5", (0.60, 0.80), 0, 30)):
        loc[n] = place(rng, o, toe, f, pc, pw, [("line", o, ankle_a)])
    return dict(W=W, Lt=Lt, Ls=Ls, Lf=Lf, hip=hip, knee_c=knee_c, knee_a=knee_a,
                ankle_c=ankle_c, ankle_a=ankle_a, loc=loc)


def select(rng, markerset, has_foot, loc):
    """Markers per segment for the marker set.  Pelvis subsets are redrawn until their
    smallest in-plane spread (2nd singular value of centred coordinates) is >= 20 mm."""
    while True:
        npel = int(rng.integers(3, 5)) if markerset == "full" else 3
        pel = sorted(rng.choice(5, npel, replace=False))
        P = np.array([loc[NAMES["pelvis"][i]] for i in pel])
        if np.linalg.svd(P - P.mean(0), compute_uv=False)[1] >= 20:
            break
    pick = lambda seg, n: [NAMES[seg][i] for i in sorted(rng.choice(len(NAMES[seg]), n, replace=False))]
    segs = {"pelvis": [NAMES["pelvis"][i] for i in pel]}
    if markerset == "full":
        segs.update(thigh_r=["RTH1", "RTH2", "RTH3"], shank_r=list(NAMES["shank_r"]))
    elif markerset == "sparse":
        segs.update(thigh_r=pick("thigh_r", 1), shank_r=pick("shank_r", 1))
    else:
        segs.update(thigh_r=pick("thigh_r", int(rng.integers(1, 3))), shank_r=pick("shank_r", int(rng.integers(2, 4))))
    if has_foot:
        segs["foot_r"] = list(NAMES["foot_r"]) if markerset == "full" else pick("foot_r", 2)
    return segs


def profile(rng, t):
    """Smooth random profile in [0, 1] (min 0, max 1): sum of 2-3 sinusoids, 0.1-1 Hz."""
    n = int(rng.integers(2, 4))
    f, a, ph = rng.uniform(0.1, 1.0, n), rng.uniform(0.3, 1.0, n), rng.uniform(0, 2 * np.pi, n)
    u = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + ph[:, None])).sum(0)
    return (u - u.min()) / (u.max() - u.min())


def sway(rng, t, std):
    """Zero-mean low-frequency signal (3 sinusoids, 0.05-0.5 Hz) with exactly this std."""
    f, a, ph = rng.uniform(0.05, 0.5, 3), rng.uniform(0.3, 1.0, 3), rng.uniform(0, 2 * np.pi, 3)
    u = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + ph[:, None])).sum(0)
    u -= u.mean()
    return u * std / u.std()


def diameter_deg(R):
    """Peak-to-peak of a rotation trajectory: the largest rotation angle between any two frames."""
    M = R.as_matrix().reshape(len(R), 9)
    i, j = np.unravel_index(np.argmin(M @ M.T), (len(R), len(R)))   # trace(Ri^T Rj) is least
    return float(np.degrees((R[i].inv() * R[j]).magnitude()))       # accurate even near 0


def joint_motion(rng, motion, t, g):
    """Relative rotations (scipy Rotation arrays) of hip, knee, ankle."""
    one = lambda: profile(rng, t) - 0.5
    base = rng.uniform([-5, -5, -10], [15, 5, 10])      # hip flexion, adduction, rotation (deg)
    kb, ab = rng.uniform(2, 20), rng.uniform(-5, 10)    # knee flexion, ankle dorsiflexion (deg)
    zero = np.zeros_like(t)
    if motion == "static":
        hip_amp, k_v, a_v, shapes = np.zeros(3), zero, zero, [zero] * 3
    else:
        shapes = [one(), one(), one()]
        if motion == "moving":
            hip_amp = rng.uniform([30, 10, 10], [60, 25, 25])
            k_v, a_v = rng.uniform(40, 90) * (one() + 0.5), rng.uniform(20, 40) * one()
        else:
            lo, hi = (0.5, 3.0) if motion == "tiny" else (3.0, 8.0)
            hip_target, kp, ap = rng.uniform(lo, hi, 3)
            k_v, a_v = kp * (one() + 0.5), ap * one()
            w = rng.uniform(0.3, 1.0, 3)
            s = hip_target                                  # scale so the hip diameter hits target
            for _ in range(50):
                d = diameter_deg(Rotation.from_euler("ZXY", (base + s * w * np.stack(shapes, 1)), degrees=True))
                s *= hip_target / d
                if abs(d - hip_target) < 1e-10:
                    break
            hip_amp = s * w
    hip = Rotation.from_euler("ZXY", base + hip_amp * np.stack(shapes, 1), degrees=True)
    knee = Rotation.from_rotvec(-np.radians(kb + k_v)[:, None] * g["knee_a"])     # flexion: shank back
    ankle = Rotation.from_rotvec(np.radians(ab + a_v)[:, None] * g["ankle_a"])    # dorsiflexion: toe up
    return hip, knee, ankle


def simulate(seed, k):
    """Everything about trial k, noise-free and noisy, deterministic in (seed, k)."""
    rng = np.random.default_rng([seed, k])
    motion, markerset, noise_model = design(k)
    has_foot = markerset != "sparse" and bool(rng.random() < 0.5)
    g = draw_subject(rng)
    segs = select(rng, markerset, has_foot, g["loc"])
    n = int(rng.integers(300, 1501))
    t = np.arange(n) / RATE
    sigma = float(rng.uniform(0.2, 1.5))
    phi = float(rng.uniform(0.5, 0.9)) if noise_model == "ar1" else None
    # root: random heading and place, plus whole-body low-frequency sway
    s_t, s_r = rng.uniform(1, 5), rng.uniform(0.3, 1.5)
    trans = np.stack([sway(rng, t, s_t), sway(rng, t, 0.3 * s_t), sway(rng, t, s_t)], 1)
    rotv = np.radians(np.stack([sway(rng, t, s_r) for _ in range(3)], 1))
    p0 = np.array([rng.uniform(-500, 500), g["Lt"] + g["Ls"] + 80 + 0.30 * g["W"], rng.uniform(-500, 500)])
    R_p = Rotation.from_euler("y", rng.uniform(0, 360), degrees=True) * Rotation.from_rotvec(rotv)
    o_p = p0 + trans
    hip, knee, ankle = joint_motion(rng, motion, t, g)
    R = {"pelvis": R_p, "thigh_r": R_p * hip}
    R["shank_r"], R["foot_r"] = R["thigh_r"] * knee, R["thigh_r"] * knee * ankle
    O = {"pelvis": o_p, "thigh_r": o_p + R_p.apply(g["hip"])}
    O["shank_r"] = O["thigh_r"] + R["thigh_r"].apply(g["knee_c"])
    O["foot_r"] = O["shank_r"] + R["shank_r"].apply(g["ankle_c"])
    names = [m for s in segs for m in segs[s]]
    seg_of = {m: s for s in segs for m in segs[s]}
    clean = np.stack([O[seg_of[m]] + R[seg_of[m]].apply(g["loc"][m]) for m in names], 1)   # (n, M, 3)
    w = rng.normal(size=clean.shape)
    if noise_model == "white":
        e = sigma * w
    else:                                     # stationary AR(1), marginal std sigma
        e = np.empty_like(w)
        e[0] = sigma * w[0]
        for i in range(1, n):
            e[i] = phi * e[i - 1] + sigma * np.sqrt(1 - phi ** 2) * w[i]
    joints = {j: v for j, v in JOINTS.items() if v[2] in segs}
    # exact distances from the local geometry; and global centres / axes for --check
    local = {"hip_r": {"pelvis": lambda x: np.linalg.norm(x - g["hip"]), "thigh_r": np.linalg.norm},
             "knee_r": {"thigh_r": lambda x: dist_line(x, g["knee_c"], g["knee_a"]),
                        "shank_r": lambda x: dist_line(x, 0.0, g["knee_a"])},
             "ankle_r": {"shank_r": lambda x: dist_line(x, g["ankle_c"], g["ankle_a"]),
                         "foot_r": lambda x: dist_line(x, 0.0, g["ankle_a"])}}
    dists = {j: {m: float(local[j][s](g["loc"][m])) for s in (p, c) for m in segs[s]}
             for j, (_, p, c) in joints.items()}
    glob = {"hip_r": (O["thigh_r"], None), "knee_r": (O["shank_r"], R["thigh_r"].apply(g["knee_a"])),
            "ankle_r": (O["foot_r"], R["shank_r"].apply(g["ankle_a"]))}
    p2p = {j: diameter_deg(R[p].inv() * R[c]) for j, (_, p, c) in joints.items()}
    truth = {"seed": seed, "index": k, "markerset": markerset, "motion": motion,
             "noise": {"model": noise_model, "sigma_mm": sigma, "phi": phi}, "frames": n, "rate_hz": RATE,
             "has_foot": has_foot, "segments": segs,
             "joints": {j: {"type": ty, "parent": p, "child": c} for j, (ty, p, c) in joints.items()},
             "marker_distances": dists, "peak_to_peak_deg": p2p,
             "sway": {"translation_std_mm": [s_t, 0.3 * s_t, s_t], "rotation_std_deg": s_r}}
    return dict(truth=truth, names=names, clean=clean, noisy=clean + e, glob=glob, R=R)


def write_trc(path, names, X):
    n, M = X.shape[:2]
    head = [f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{RATE:.2f}\t{RATE:.2f}\t{n}\t{M}\tmm\t{RATE:.2f}\t1\t{n}",
            "Frame#\tTime\t" + "".join(f"{m}\t\t\t" for m in names),
            "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, M + 1)), ""]
    data = np.column_stack([np.arange(1, n + 1), np.arange(n) / RATE, X.reshape(n, 3 * M)])
    with open(path, "w", newline="\n") as fh:
        fh.write("\n".join(head) + "\n")
        np.savetxt(fh, data, fmt=["%d", "%.5f"] + ["%.4f"] * (3 * M), delimiter="\t")


def write_toml(path, truth):
    out = ["# heldout_still model: segments, markers and joints only (no geometry)", 'units = "mm"', ""]
    for s, ms in truth["segments"].items():
        out += [f"[segments.{s}]", "markers = [" + ", ".join(f'"{m}"' for m in ms) + "]", ""]
    for j, v in truth["joints"].items():
        out += [f"[joints.{j}]", f'type = "{v["type"]}"', f'parent = "{v["parent"]}"', f'child = "{v["child"]}"', ""]
    path.write_text("\n".join(out))


def generate(out, n, seed):
    out.mkdir(parents=True, exist_ok=True)
    index = {"generator": "heldout_still", "seed": seed, "n": n, "rate_hz": RATE, "trials": []}
    for k in range(n):
        sim, stem = simulate(seed, k), f"trial_{k:04d}"
        tr = sim["truth"]
        write_trc(out / f"{stem}.trc", sim["names"], sim["noisy"])
        write_toml(out / f"{stem}.toml", tr)
        (out / f"{stem}.truth.json").write_text(json.dumps(tr, indent=1))
        index["trials"].append({"id": stem, "index": k, "motion": tr["motion"], "markerset": tr["markerset"],
                                "noise_model": tr["noise"]["model"], "sigma_mm": tr["noise"]["sigma_mm"],
                                "frames": tr["frames"], "has_foot": tr["has_foot"],
                                "joints": list(tr["joints"]), "peak_to_peak_deg": tr["peak_to_peak_deg"],
                                "files": {x: f"{stem}.{x}" for x in ("trc", "toml", "truth.json")}})
        print(f"{stem}: {tr['motion']:6s} {tr['markerset']:6s} {tr['noise']['model']:5s} "
              f"{len(sim['names'])} markers, {tr['frames']} frames", file=sys.stderr)
    (out / "index.json").write_text(json.dumps(index, indent=1))


def read_trc(path):
    """Parse an OpenSim TRC v4 file: returns (header dict, marker names, frame#, time, (n, M, 3))."""
    lines = path.read_text().split("\n")
    f0 = lines[0].split("\t")
    assert f0[:3] == ["PathFileType", "4", "(X/Y/Z)"], "bad PathFileType line"
    hdr = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    l3 = lines[3].split("\t")
    assert l3[:2] == ["Frame#", "Time"], "bad Frame#/Time line"
    names = [x for x in l3[2:] if x]
    assert l3[2:] == [x for m in names for x in (m, "", "")] + [""], "marker name line not NAME\\t\\t\\t"
    assert lines[4].split("\t")[2:] == [f"{c}{i}" for i in range(1, len(names) + 1) for c in "XYZ"]
    assert lines[5] == "", "no blank line after header"
    data = np.array([[float(v) for v in ln.split("\t")] for ln in lines[6:] if ln.strip()])
    n, M = int(hdr["NumFrames"]), int(hdr["NumMarkers"])
    assert hdr["Units"] == "mm" and float(hdr["DataRate"]) == RATE and M == len(names), "header values"
    assert data.shape == (n, 2 + 3 * M), f"data shape {data.shape} != ({n}, {2 + 3 * M})"
    return hdr, names, data[:, 0], data[:, 1], data[:, 2:].reshape(n, M, 3)


def check(out):
    """Read back every file and verify it against a regeneration of the same (seed, k)."""
    index, errors = json.loads((out / "index.json").read_text()), []
    for e in index["trials"]:
        stem, k = e["id"], e["index"]
        try:
            tr = json.loads((out / f"{stem}.truth.json").read_text())
            sim = simulate(tr["seed"], k)
            _, names, fr, tm, X = read_trc(out / f"{stem}.trc")
            n = tr["frames"]
            assert np.array_equal(fr, np.arange(1, n + 1)) and np.allclose(tm, np.arange(n) / RATE, atol=1e-6)
            assert names == sim["names"], "TRC marker names differ from the regenerated trial"
            assert np.abs(X - sim["noisy"]).max() <= 5.001e-5, "TRC values differ from the regenerated trial"
            model = tomllib.loads((out / f"{stem}.toml").read_text())
            segs = {s: v["markers"] for s, v in model["segments"].items()}
            assert sorted(m for v in segs.values() for m in v) == sorted(names), "model markers != TRC markers"
            assert set(model["joints"]) == set(tr["marker_distances"]) == set(tr["peak_to_peak_deg"])
            assert not any(set(v) - {"markers"} for v in model["segments"].values()), "geometry leaked into model"
            for j, v in model["joints"].items():
                ty, p, c = JOINTS[j]
                assert (v["type"], v["parent"], v["child"]) == (ty, p, c), f"{j} joint definition"
                want = tr["marker_distances"][j]
                assert sorted(want) == sorted(segs[p] + segs[c]), f"{j}: distance markers != parent+child"
                centre, axis = sim["glob"][j]
                for m, dm in want.items():
                    x = sim["clean"][:, names.index(m)]
                    d = np.linalg.norm(x - centre, axis=1) if axis is None else dist_line(x, centre, axis)
                    assert np.abs(d - dm).max() < 1e-6, f"{j}/{m}: distance {dm} not recomputed ({d.min()}..{d.max()})"
                    assert dm >= MIN_CLEAR, f"{j}/{m}: {dm:.1f} mm < {MIN_CLEAR}"
                p2p = diameter_deg(sim["R"][p].inv() * sim["R"][c])
                assert abs(p2p - tr["peak_to_peak_deg"][j]) < 1e-6, f"{j}: peak-to-peak"
                if tr["motion"] == "static":
                    assert p2p < 1e-6, f"{j}: static trial moves ({p2p} deg)"
            r = (X - sim["clean"]).reshape(n, -1)                 # residual noise sanity check
            sig, ph = tr["noise"]["sigma_mm"], tr["noise"]["phi"] or 0.0
            ratio = r.std() / sig
            rho = np.sum(r[1:] * r[:-1]) / np.sum(r * r)
            assert 0.75 < ratio < 1.25 and abs(rho - ph) < 0.12, \
                f"noise stats: std/sigma {ratio:.2f}, lag-1 {rho:.2f} vs {ph:.2f}"
            print(f"{stem}: ok  (std/sigma {ratio:.2f}, lag-1 {rho:.2f}, p2p "
                  + ", ".join(f"{j} {v:.2f}" for j, v in tr["peak_to_peak_deg"].items()) + ")", file=sys.stderr)
        except Exception as ex:  # report every failing trial, not just the first
            errors.append(f"{stem}: {type(ex).__name__}: {ex}")
    for m in errors:
        print("CHECK FAILED " + m, file=sys.stderr)
    print(f"check: {len(index['trials']) - len(errors)}/{len(index['trials'])} trials ok", file=sys.stderr)
    return not errors


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="output folder")
    ap.add_argument("--n", type=int, help="number of trials to generate (omit with --check to only check)")
    ap.add_argument("--seed", type=int, default=0, help="non-negative integer seed")
    ap.add_argument("--check", action="store_true", help="read back every file in --out and verify it")
    a = ap.parse_args()
    if a.n is None and not a.check:
        ap.error("give --n (generate) and/or --check")
    if a.n is not None:
        if a.n < 1 or a.seed < 0:
            ap.error("--n must be >= 1 and --seed >= 0")
        generate(a.out, a.n, a.seed)
    return 0 if not a.check or check(a.out) else 1


if __name__ == "__main__":
    sys.exit(main())
