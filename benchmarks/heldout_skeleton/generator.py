"""Held-out random-skeleton trial generator for identcheck (written independently of the package).

Usage:  python benchmarks/heldout_skeleton/generator.py --out DIR --n N --seed S [--frames F] [--check]

For each trial k it writes DIR/trial_%04d.trc (OpenSim/Cortex TRC, mm, 100 Hz, missing samples as
empty cells), DIR/trial_%04d.truth.json (the true skeleton and motion) and DIR/trial_%04d.toml (the
true model in identcheck's model format), plus DIR/index.json listing every trial with its
categories and parameters.  Only numpy and scipy (Rotation) are used; output is deterministic for a
given seed, and trial k depends only on (seed, k), not on N.

What is drawn (categories recorded in index.json):
- 3 to 15 segments; tree shapes chain, star, human (hub with limbs of 1-3 segments) or random
  (Pruefer sequence); the root is a random node.
- Segment lengths 60-450 mm; 1 to 6 markers per segment, mostly 3-4; 2 trials in every 10 have one
  or two segments with only 1 or 2 markers ("sparse_segment").  Marker names never reveal the
  segment (numbered "M07", anatomical-looking "RTIB3", or mixed) and TRC columns are shuffled.
- Joints: spherical or revolute (p = 0.4; hinge axis random in the parent frame).  A joint centre
  lies near an end of the parent segment and at the child's frame origin, never at a marker.
- Motion: every joint DOF follows its own smooth profile, a sum of 2-4 sinusoids at 0.1-1.5 Hz with
  random phases, scaled to a peak-to-peak range of 15-60 deg per spherical DOF (all 3 DOF), 20-100
  deg for a hinge.  1 trial in 10 has one spherical joint whose third DOF spans < 3 deg
  ("weak_third_dof").  Root: "still" (< 4 mm, < 1.5 deg), "slow" (0.05-0.3 Hz, 50-400 mm,
  5-40 deg) or, in 2 trials in 10, "gait" (all profiles harmonics 1-2 of one stride frequency).
- Noise: white Gaussian, sigma 0.3-1.5 mm per coordinate, or AR(1) (phi 0.6-0.95) with the same
  marginal sigma.  3 trials in 10: soft-tissue artefact, each marker displaced on its segment by a
  smooth (linear + quadratic) function of the nearest joint's angles, amplitude 1-6 mm.
- 4 trials in 10: occlusion gaps of 5-80 frames on 1-4 markers.
- 1 trial in 10: one extra marker attached to nothing rigid ("handheld" object moving freely, or
  "drifting" on a segment), listed under unattached_markers and absent from the TOML model.
Frames 600-2000 unless --frames is given.  --check re-reads every file written, checks rigid
distances within segments and joint-centre consistency against the noise, and prints one line per
trial (exit status 1 if any trial fails).  See README.md for the file conventions.
"""
import argparse
import json
import math
import os
import sys
import tomllib

import numpy as np
from scipy.spatial.transform import Rotation

RATE = 100.0
# Category flags, stratified in blocks of 10 trials (exact share per block of 10).
FLAG_P = {"sparse_segment": 0.2, "soft_tissue": 0.3, "occlusion": 0.4, "unattached_marker": 0.1,
          "weak_third_dof": 0.1, "gait": 0.2, "ar1_noise": 0.5}
SYL = ["ASI", "PSI", "THI", "KNE", "TIB", "ANK", "HEE", "TOE", "SHO", "ELB", "WRA", "WRB", "FIN",
       "UPA", "FRA", "HEA", "CLA", "STR", "TRO", "EPI", "MAL", "MET", "ACR", "SCA", "ILI", "GT",
       "FLE", "MLE", "SPH", "TTU", "PAT", "CAL"]


def block_flags(seed, k):
    b, slot = divmod(k, 10)
    return {name: bool(np.random.default_rng([seed, 1_000_003, b, i]).permutation(10)[slot] < round(p * 10))
            for i, (name, p) in enumerate(FLAG_P.items())}


def rnd(x, d=3):
    return [round(float(v), d) for v in np.asarray(x).ravel()] if np.ndim(x) else round(float(x), d)


def unit(v):
    return np.asarray(v, float) / np.linalg.norm(v)


# ----------------------------------------------------------------------------------- skeleton
def tree_edges(rng, n, shape):
    if shape == "chain":
        return [(i, i + 1) for i in range(n - 1)]
    if shape == "star":
        return [(0, i) for i in range(1, n)]
    if shape == "human":                      # hub (trunk) with limbs of 1-3 segments
        edges, nxt = [], 1
        while nxt < n:
            prev = 0
            for _ in range(min(int(rng.integers(1, 4)), n - nxt)):
                edges.append((prev, nxt))
                prev, nxt = nxt, nxt + 1
        return edges
    seq = rng.integers(0, n, n - 2)           # random labelled tree (Pruefer sequence)
    deg = np.ones(n, int)
    np.add.at(deg, seq, 1)
    edges = []
    for s in seq:
        leaf = int(np.flatnonzero(deg == 1)[0])
        edges.append((leaf, int(s)))
        deg[leaf] -= 1
        deg[s] -= 1
    u, v = np.flatnonzero(deg == 1)
    return edges + [(int(u), int(v))]


def marker_names(rng, m):
    style, names, nums = str(rng.choice(["numbered", "anatomical", "mixed"])), [], iter(rng.permutation(np.arange(1, m + 30)))
    while len(names) < m:
        if style == "numbered" or (style == "mixed" and rng.random() < 0.5):
            nm = "M%02d" % next(nums)
        else:
            nm = str(rng.choice(["L", "R", "C", ""])) + str(rng.choice(SYL)) + \
                 (str(rng.integers(1, 10)) if rng.random() < 0.4 else "")
        if nm not in names:
            names.append(nm)
    return style, names


def build_skeleton(rng, flags):
    n = int(rng.integers(3, 16))
    shape = str(rng.choice(["chain", "star", "human", "random"]))
    edges = tree_edges(rng, n, shape)
    segs = ["S%02d" % v for v in rng.permutation(n) + 1]
    nb = {i: [b for a, b in edges if a == i] + [a for a, b in edges if b == i] for i in range(n)}
    root = int(rng.integers(n))
    order, parent = [root], {root: None}
    for s in order:                           # breadth-first orientation from the root
        for c in nb[s]:
            if c not in parent:
                parent[c] = s
                order.append(c)
    geo = {}
    for i in order:
        L = float(rng.uniform(60, 450))       # frame: long axis z; non-root origin = proximal joint
        r, (zlo, zhi) = max(20.0, float(rng.uniform(0.12, 0.3)) * L), ((-L / 2, L / 2) if parent[i] is None else (-L, 0.0))
        geo[i] = dict(L=L, r=r, zlo=zlo, zhi=zhi, centres=[] if parent[i] is None else [np.zeros(3)])
    types = {c: ("revolute" if rng.random() < 0.4 else "spherical") for c in order[1:]}
    weak = order[1:][int(rng.integers(n - 1))] if flags["weak_third_dof"] else None
    types.update({weak: "spherical"} if weak is not None else {})
    joints = []
    for j, c in enumerate(order[1:]):
        p, g = parent[c], geo[parent[c]]
        for _ in range(100):                  # centre near an end of the parent, off other centres
            if parent[p] is None:             # root: either end; other segments: mostly distal
                end = "lo" if rng.random() < 0.5 else "hi"
            else:
                end = "hi" if rng.random() < 0.3 else "lo"
            z = g["zlo"] + g["L"] * rng.uniform(0, 0.12) if end == "lo" else g["zhi"] - g["L"] * rng.uniform(0, 0.12)
            rad = g["r"] * (rng.uniform(0.5, 1.0) if (end == "hi" and parent[p] is not None) else rng.uniform(0, 0.6))
            a = rng.uniform(0, 2 * np.pi)
            cen = np.round([rad * np.cos(a), rad * np.sin(a), z], 3)
            if all(np.linalg.norm(cen - q) > 15 for q in g["centres"]):
                break
        g["centres"].append(cen)
        R0 = Rotation.from_rotvec(unit(rng.normal(size=3)) * np.deg2rad(rng.uniform(10, 120)))
        axis = np.round(unit(rng.normal(size=3)), 6) if types[c] == "revolute" else None
        joints.append(dict(name="J%02d" % (j + 1), parent=p, child=c, type=types[c], centre=cen,
                           axis=axis, R0=Rotation.from_quat(np.round(R0.as_quat(), 9))))
    # markers per segment
    counts = {i: int(rng.choice([3, 4, 5, 6], p=[0.45, 0.4, 0.1, 0.05])) for i in order}
    sparse = {}
    if flags["sparse_segment"]:
        for i in rng.permutation(n)[:int(rng.integers(1, 3))]:
            counts[int(i)] = sparse[segs[int(i)]] = int(rng.choice([1, 2]))
    style, names = marker_names(rng, sum(counts.values()) + 1)
    local, seg_markers = {}, {}
    for i in order:
        g, seg_markers[segs[i]] = geo[i], []
        for _ in range(counts[i]):
            for _ in range(200):
                z = rng.uniform(g["zlo"] + 0.08 * g["L"], g["zhi"] - 0.08 * g["L"])
                a, rad = rng.uniform(0, 2 * np.pi), g["r"] * rng.uniform(0.9, 1.4)
                pos = np.round([rad * np.cos(a), rad * np.sin(a), z], 3)
                if all(np.linalg.norm(pos - q) >= min(25, 0.3 * g["L"]) for q in g["centres"]) and \
                   all(np.linalg.norm(pos - local[m]) >= 10 for m in seg_markers[segs[i]]):
                    break
            local[names[len(local)]] = pos
            seg_markers[segs[i]].append(names[len(local) - 1])
    return dict(n=n, shape=shape, segs=segs, root=root, order=order, parent=parent, geo=geo,
                joints=joints, local=local, seg_markers=seg_markers, sparse=sparse, weak=weak,
                name_style=style, spare_name=names[-1])


# ------------------------------------------------------------------------------------- motion
def profile(rng, n, ptp, freqs, amps=None):
    """Sum of sinusoids rescaled to peak-to-peak `ptp`; returns (values, description)."""
    t = np.arange(n) / RATE
    freqs = np.asarray(freqs, float)
    amps = rng.uniform(0.3, 1.0, len(freqs)) if amps is None else np.asarray(amps, float)
    ph = rng.uniform(0, 2 * np.pi, len(freqs))
    s = (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t + ph[:, None])).sum(0)
    mid, span = (s.max() + s.min()) / 2, s.max() - s.min()
    off = float(rng.uniform(-0.3, 0.3)) * ptp
    return off + ptp * (s - mid) / span, dict(ptp=rnd(ptp, 4), offset=rnd(off, 4), freqs_hz=rnd(freqs, 5),
                                              amps=rnd(amps, 5), phases_rad=rnd(ph, 5), mid=rnd(mid, 8), span=rnd(span, 8))


def joint_freqs(rng, f0):
    if f0 is not None:
        return [f0, 2 * f0], [1.0, float(rng.uniform(0.2, 0.6))]
    return rng.uniform(0.1, 1.5, int(rng.integers(2, 5))), None


def simulate(rng, sk, flags, n):
    gait = flags["gait"]
    f0 = float(rng.uniform(0.6, 0.75)) if gait else None
    root_mode = "gait" if gait else str(rng.choice(["still", "slow", "slow"]))
    segs, R, P, angles, mot_joints = sk["segs"], {}, {}, {}, []
    # root pose
    tr_ptp = {"still": (0, 4), "slow": (50, 400)}.get(root_mode, (20, 80))
    rot_ptp = {"still": (0, 1.5), "slow": (5, 40)}.get(root_mode, (4, 12))
    tr, rot, desc_t, desc_r = [], [], [], []
    for ax in range(3):
        fr = [f0 * (2 if ax == 2 else 1)] if gait else rng.uniform(0.05, 0.3, 2)   # gait: bob at 2 f0
        v, d = profile(rng, n, rng.uniform(*tr_ptp), fr)
        tr.append(v)
        desc_t.append(d)
        v, d = profile(rng, n, rng.uniform(*rot_ptp), [f0] if gait else rng.uniform(0.05, 0.3, 2))
        rot.append(v)
        desc_r.append(d)
    base_p = np.round(np.array([0, 0, 1000.0]) + rng.uniform(-200, 200, 3), 3)
    Rb = Rotation.from_quat(np.round(Rotation.random(random_state=int(rng.integers(2**31))).as_quat(), 9))
    root = sk["root"]
    P[root] = base_p + np.stack(tr, 1)
    R[root] = Rotation.from_rotvec(np.deg2rad(np.stack(rot, 1))) * Rb
    root_desc = dict(mode=root_mode, base_position_mm=rnd(base_p), base_quat_xyzw=rnd(Rb.as_quat(), 9),
                     translation_mm_xyz=desc_t, rotvec_deg_xyz=desc_r,
                     convention="p(t)=base+[tx,ty,tz](t); R(t)=Rotvec(deg2rad([rx,ry,rz](t)))*R_base")
    for jt in sk["joints"]:
        p, c = jt["parent"], jt["child"]
        if jt["type"] == "revolute":
            fr, am = joint_freqs(rng, f0)
            th, d = profile(rng, n, rng.uniform(20, 100), fr, am)
            angles[c], dofs = th[:, None], [d]
            Rrel = Rotation.from_rotvec(np.deg2rad(th)[:, None] * unit(jt["axis"])[None]) * jt["R0"]
            Q = None
        else:
            Q = Rotation.from_quat(np.round(Rotation.random(random_state=int(rng.integers(2**31))).as_quat(), 9))
            vals, dofs = [], []
            for k in range(3):
                ptp = rng.uniform(0.5, 2.5) if (k == 2 and c == sk["weak"]) else rng.uniform(15, 60)
                fr, am = joint_freqs(rng, f0)
                v, d = profile(rng, n, ptp, fr, am)
                vals.append(v), dofs.append(d)
            angles[c] = np.stack(vals, 1)
            Rrel = Q * Rotation.from_euler("XYZ", angles[c], degrees=True) * Q.inv() * jt["R0"]
        R[c] = R[p] * Rrel
        P[c] = P[p] + R[p].apply(jt["centre"])
        mot_joints.append(dict(name=jt["name"], dofs_deg=dofs, rest_quat_xyzw=rnd(jt["R0"].as_quat(), 9),
                               dof_frame_quat_xyzw=None if Q is None else rnd(Q.as_quat(), 9)))
    motion = dict(rate_hz=RATE, frames=n, gait_f0_hz=f0, root=root_mode, root_motion=root_desc,
                  joints=mot_joints, profile="angle(t)=offset+ptp*(s(t)-mid)/span, s(t)=sum amps*sin(2*pi*f*t+phase), t=(frame-1)/100",
                  revolute="R_child=R_parent*Rotvec(axis_parent*angle)*R_rest",
                  spherical="R_child=R_parent*Q*Euler_intrinsic_XYZ(a1,a2,a3)*Q^-1*R_rest",
                  position="p_child=p_parent+R_parent*centre_parent (child frame origin = joint centre)")
    return R, P, angles, motion


def markers_world(rng, sk, R, P, angles, flags, n):
    segs, geo, sta, X, sta_on = sk["segs"], sk["geo"], {}, {}, flags["soft_tissue"]
    for i in sk["order"]:
        # joints adjacent to segment i with their centres in i's frame
        adj = [(jt["child"], jt["centre"]) for jt in sk["joints"] if jt["parent"] == i]
        if sk["parent"][i] is not None:
            adj.append((i, np.zeros(3)))
        for m in sk["seg_markers"][segs[i]]:
            loc = np.broadcast_to(sk["local"][m], (n, 3)).copy()
            if sta_on:
                jc = min(adj, key=lambda a: np.linalg.norm(sk["local"][m] - a[1]))[0]
                u = (angles[jc] - angles[jc].mean(0)) / 30.0     # smooth: linear + quadratic in angles
                d = u @ rng.normal(size=(u.shape[1], 3)) + (u**2 - (u**2).mean(0)) @ rng.normal(size=(u.shape[1], 3))
                amp = float(rng.uniform(1, 6))
                loc += d * amp / np.linalg.norm(d, axis=1).max()
                sta[m] = dict(amplitude_mm=rnd(amp), joint=next(j["name"] for j in sk["joints"] if j["child"] == jc))
            X[m] = P[i] + R[i].apply(loc)
    unatt = {}
    if flags["unattached_marker"]:
        m = sk["spare_name"]
        kind = str(rng.choice(["handheld", "drifting"]))
        if kind == "handheld":
            c = np.mean([P[i].mean(0) for i in sk["order"]], axis=0) + rng.uniform(-300, 300, 3)
            X[m] = c + np.stack([profile(rng, n, rng.uniform(100, 500), rng.uniform(0.1, 1.0, 3))[0]
                                 for _ in range(3)], 1)
            unatt[m] = dict(kind=kind)
        else:
            i = sk["order"][int(rng.integers(sk["n"]))]
            g, D = geo[i], float(rng.uniform(20, 80))
            start = np.array([g["r"] * 1.2, 0.0, (g["zlo"] + g["zhi"]) / 2])
            X[m] = P[i] + R[i].apply(start + np.linspace(0, 1, n)[:, None] * unit(rng.normal(size=3)) * D)
            unatt[m] = dict(kind=kind, near_segment=segs[i], drift_mm=rnd(D))
    # measurement noise
    names, sigma, phi = list(X), float(rng.uniform(0.3, 1.5)), None
    w = rng.normal(size=(n, len(names), 3)) * sigma
    if flags["ar1_noise"]:                    # stationary AR(1) with marginal sigma
        phi = float(rng.uniform(0.6, 0.95))
        for t in range(1, n):
            w[t] = phi * w[t - 1] + math.sqrt(1 - phi**2) * w[t]
    for j, m in enumerate(names):
        X[m] = X[m] + w[:, j]
    # occlusions
    gaps = []
    if flags["occlusion"]:
        for m in rng.permutation(names)[:int(rng.integers(1, 5))]:
            for _ in range(int(rng.integers(1, 4))):
                ln = int(rng.integers(5, 81))
                s = int(rng.integers(0, n - ln))
                X[str(m)][s:s + ln] = np.nan
                gaps.append(dict(marker=str(m), start=s, stop=s + ln))
    noise = dict(model="ar1" if phi else "white", sigma_mm=rnd(sigma, 4), phi=None if phi is None else rnd(phi, 4),
                 soft_tissue=sta if sta_on else None, occlusions=gaps)
    return X, unatt, noise


# ------------------------------------------------------------------------------------ writers
def write_trc(path, X, order, n):
    lines = ["PathFileType\t4\t(X/Y/Z)\t%s" % os.path.basename(path),
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             "%.2f\t%.2f\t%d\t%d\tmm\t%.2f\t1\t%d" % (RATE, RATE, n, len(order), RATE, n),
             "Frame#\tTime\t" + "".join("%s\t\t\t" % m for m in order),
             "\t\t" + "\t".join("X%d\tY%d\tZ%d" % (k, k, k) for k in range(1, len(order) + 1)), ""]
    A = np.concatenate([X[m] for m in order], axis=1)
    for t in range(n):
        cells = ["" if np.isnan(v) else "%.4f" % v for v in A[t]]
        lines.append("%d\t%.3f\t%s" % (t + 1, t / RATE, "\t".join(cells)))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_toml(path, sk):
    segs, out = sk["segs"], ['# True model written by benchmarks/heldout_skeleton/generator.py', 'units = "mm"', ""]
    for i in sk["order"]:
        g, ms = sk["geo"][i], sk["seg_markers"][segs[i]]
        out += ["[segments.%s]" % segs[i], "markers = %s" % json.dumps(ms),
                "length_mm = %.3f" % g["L"], "", "[segments.%s.positions]" % segs[i]]
        out += ["%s = %s" % (m, rnd(sk["local"][m])) for m in ms] + [""]
    for jt in sk["joints"]:
        out += ["[joints.%s]" % jt["name"], 'type = "%s"' % jt["type"], 'parent = "%s"' % segs[jt["parent"]],
                'child = "%s"' % segs[jt["child"]], "centre_parent = %s" % rnd(jt["centre"])]
        if jt["axis"] is not None:
            out.append("axis = %s" % rnd(jt["axis"], 6))
        out.append("")
    with open(path, "w") as f:
        f.write("\n".join(out))


def make_trial(out, seed, k, frames):
    rng = np.random.default_rng([seed, k])
    flags = block_flags(seed, k)
    n = frames or int(rng.integers(600, 2001))
    sk = build_skeleton(rng, flags)
    R, P, angles, motion = simulate(rng, sk, flags, n)
    X, unatt, noise = markers_world(rng, sk, R, P, angles, flags, n)
    cols = [str(m) for m in rng.permutation(list(X))]
    tid, segs = "trial_%04d" % k, sk["segs"]
    joints = [dict(name=j["name"], parent=segs[j["parent"]], child=segs[j["child"]], type=j["type"],
                   centre_parent_mm=rnd(j["centre"]), axis_parent=None if j["axis"] is None else rnd(j["axis"], 6),
                   centre_child_mm=[0.0, 0.0, 0.0],
                   axis_child=None if j["axis"] is None else rnd(j["R0"].inv().apply(unit(j["axis"])), 6))
              for j in sk["joints"]]
    cats = [sk["shape"]] + [f for f, on in flags.items() if on and f != "weak_third_dof"]
    if sk["weak"] is not None:
        cats.append("weak_third_dof")
    kinds = {j["type"] for j in joints}
    if len(kinds) == 1:
        cats.append("all_" + kinds.pop())
    cats.append("root_" + motion["root"])
    params = dict(frames=n, n_segments=sk["n"], tree=sk["shape"], root=segs[sk["root"]],
                  n_markers=len(cols), n_spherical=sum(j["type"] == "spherical" for j in joints),
                  n_revolute=sum(j["type"] == "revolute" for j in joints), sparse_segments=sk["sparse"],
                  weak_third_dof_joint=next((j["name"] for j in sk["joints"] if j["child"] == sk["weak"]), None),
                  noise_model=noise["model"], sigma_mm=noise["sigma_mm"], phi=noise["phi"],
                  soft_tissue_max_mm=max((v["amplitude_mm"] for v in (noise["soft_tissue"] or {}).values()), default=None),
                  occluded_markers=sorted({g["marker"] for g in noise["occlusions"]}), n_gaps=len(noise["occlusions"]),
                  unattached=unatt, root_motion=motion["root"], gait_f0_hz=motion["gait_f0_hz"],
                  marker_names=sk["name_style"])
    truth = dict(trial=tid, seed=seed, index=k, rate_hz=RATE, frames=n, units="mm",
                 segments={segs[i]: sk["seg_markers"][segs[i]] for i in sk["order"]}, root=segs[sk["root"]],
                 joints=joints, unattached_markers=list(unatt), noise=noise, motion=motion,
                 markers_local_mm={m: rnd(v) for m, v in sk["local"].items()},
                 segment_length_mm={segs[i]: rnd(sk["geo"][i]["L"]) for i in sk["order"]},
                 unattached=unatt, trc_columns=cols, categories=cats)
    write_trc(os.path.join(out, tid + ".trc"), X, cols, n)
    write_toml(os.path.join(out, tid + ".toml"), sk)
    with open(os.path.join(out, tid + ".truth.json"), "w") as f:
        json.dump(truth, f, indent=1)
    return dict(id=tid, trc=tid + ".trc", truth=tid + ".truth.json", model=tid + ".toml",
                categories=cats, params=params)


# -------------------------------------------------------------------------------------- check
def read_trc(path):
    lines = open(path).read().split("\n")
    h0 = lines[0].split("\t")
    assert h0[:3] == ["PathFileType", "4", "(X/Y/Z)"], "bad PathFileType line"
    meta = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    labels = [x for x in lines[3].split("\t")[2:] if x]
    assert lines[3].startswith("Frame#\tTime\t") and lines[4].startswith("\t\tX1\tY1\tZ1") and lines[5] == ""
    rows = [ln.split("\t") for ln in lines[6:] if ln.strip()]
    M = len(labels)
    assert int(meta["NumFrames"]) == len(rows) and int(meta["NumMarkers"]) == M and meta["Units"] == "mm"
    assert float(meta["DataRate"]) == RATE and all(len(r) == 2 + 3 * M for r in rows)
    A = np.array([[float(v) if v else np.nan for v in r[2:]] for r in rows]).reshape(len(rows), M, 3)
    assert [int(r[0]) for r in rows] == list(range(1, len(rows) + 1))
    return {m: A[:, j] for j, m in enumerate(labels)}


def kabsch(Pl, X):
    """Poses (R (n,3,3), t (n,3)) with X ~ R @ Pl + t; Pl (m,3) local, X (n,m,3) world."""
    pc, xc = Pl.mean(0), X.mean(1)
    H = np.einsum("mi,nmj->nij", Pl - pc, X - xc[:, None])
    U, _, Vt = np.linalg.svd(H)
    V, Ut = Vt.transpose(0, 2, 1), U.transpose(0, 2, 1)
    D = np.tile(np.eye(3), (len(X), 1, 1))
    D[:, 2, 2] = np.sign(np.linalg.det(V @ Ut))
    R = V @ D @ Ut
    return R, xc - np.einsum("nij,j->ni", R, pc)


def check_trial(out, entry):
    truth = json.load(open(os.path.join(out, entry["truth"])))
    model = tomllib.load(open(os.path.join(out, entry["model"]), "rb"))
    X = read_trc(os.path.join(out, entry["trc"]))
    sig, phi = truth["noise"]["sigma_mm"], truth["noise"]["phi"]
    sta = max((v["amplitude_mm"] for v in (truth["noise"]["soft_tissue"] or {}).values()), default=0.0)
    problems, attached = [], [m for ms in truth["segments"].values() for m in ms]
    if sorted(X) != sorted(attached + truth["unattached_markers"]):
        problems.append("TRC labels differ from truth markers")
    mask = {m: np.zeros(truth["frames"], bool) for m in X}
    for g in truth["noise"]["occlusions"]:
        mask[g["marker"]][g["start"]:g["stop"]] = True
    if any((np.isnan(X[m][:, 0]) != mask[m]).any() for m in X):
        problems.append("missing samples differ from truth occlusions")
    loc = {m: np.array(p) for s in model["segments"].values() for m, p in s["positions"].items()}
    if {s: v["markers"] for s, v in model["segments"].items()} != truth["segments"] or \
       any(np.abs(np.array(loc[m]) - truth["markers_local_mm"][m]).max() > 1e-6 for m in loc):
        problems.append("TOML segments/positions differ from truth")
    for j in truth["joints"]:
        mj = model["joints"][j["name"]]
        if (mj["type"], mj["parent"], mj["child"]) != (j["type"], j["parent"], j["child"]) or \
           np.abs(np.array(mj["centre_parent"]) - j["centre_parent_mm"]).max() > 1e-6:
            problems.append("TOML joint %s differs from truth" % j["name"])
    # 1) rigid distances within segments
    errs = []
    for ms in truth["segments"].values():
        for a in range(len(ms)):
            for b in range(a + 1, len(ms)):
                d = np.linalg.norm(X[ms[a]] - X[ms[b]], axis=1)
                errs.append((d - np.linalg.norm(loc[ms[a]] - loc[ms[b]]))[~np.isnan(d)])
    e = np.concatenate(errs) if errs else np.zeros(0)
    rig_rms, rig_max = (float(np.sqrt(np.mean(e**2))), float(np.abs(e).max())) if e.size else (0.0, 0.0)
    rig_tol, rig_mtol = 1.5 * math.sqrt(2) * sig + 2 * sta + 0.05, 6 * math.sqrt(2) * sig + 2 * sta + 0.1
    if rig_rms > rig_tol or rig_max > rig_mtol:
        problems.append("rigid distances rms %.2f max %.2f" % (rig_rms, rig_max))
    # 2) joint centres: posed parent and child agree; the other side's markers keep their distance to it
    poses = {}
    for s, ms in truth["segments"].items():
        if len(ms) >= 3:
            Pl = np.array([loc[m] for m in ms])
            S = np.cov((Pl - Pl.mean(0)).T, bias=True) * len(ms)
            rho = math.sqrt(max(np.trace(S) - np.linalg.eigvalsh(S)[-1], 1e-9))
            W = np.stack([X[m] for m in ms], 1)
            ok = ~np.isnan(W).any(axis=(1, 2))
            R, t = kabsch(Pl, W[ok])
            poses[s] = (ok, R, t, rho, Pl.mean(0))
    worst = {"centre": (0.0, 1.0), "sphere": (0.0, 1.0), "axis": (0.0, 1.0)}

    def note(kind, val, tol, what):
        if val / tol > worst[kind][0] / worst[kind][1]:
            worst[kind] = (val, tol)
        if val > tol:
            problems.append("%s %s %.2f > %.2f" % (kind, what, val, tol))
    for j in truth["joints"]:
        sides = {j["parent"]: np.array(j["centre_parent_mm"]), j["child"]: np.array(j["centre_child_mm"])}
        world = {}
        for s, c in sides.items():
            if s in poses:
                ok, R, t, rho, cen = poses[s]
                lever = 1 + np.linalg.norm(c - cen) / rho
                cw = np.full((len(ok), 3), np.nan)
                cw[ok] = np.einsum("nij,j->ni", R, c) + t
                world[s] = (cw, lever, R, ok, rho)
                other = j["child"] if s == j["parent"] else j["parent"]
                for m in truth["segments"][other]:
                    d = np.linalg.norm(X[m] - cw, axis=1)
                    r = d - np.linalg.norm(loc[m] - sides[other])
                    r = r[~np.isnan(r)]
                    if r.size:
                        note("sphere", float(np.sqrt(np.mean(r**2))), 2 * (sig + sta) * (lever + 1) + 0.3, j["name"] + "/" + m)
        if len(world) == 2:
            (cp, lp, Rp, okp, rp), (cc, lc, Rc, okc, rc) = world[j["parent"]], world[j["child"]]
            g = np.linalg.norm(cp - cc, axis=1)
            g = g[~np.isnan(g)]
            if g.size:
                note("centre", float(np.sqrt(np.mean(g**2))), 2 * (sig + sta) * (lp + lc) + 0.3, j["name"])
            if j["type"] == "revolute":
                both = okp & okc
                ap = np.einsum("nij,j->ni", Rp[both[okp]], j["axis_parent"])
                ac = np.einsum("nij,j->ni", Rc[both[okc]], j["axis_child"])
                ang = np.degrees(np.arccos(np.clip((ap * ac).sum(1), -1, 1)))
                if ang.size:
                    note("axis", float(np.sqrt(np.mean(ang**2))),
                         float(np.degrees(2 * (sig + sta) * (1 / rp + 1 / rc))) + 0.2, j["name"])
    for jm in truth["motion"]["joints"]:      # weak_third_dof: third DOF spans < 3 deg
        if jm["name"] == entry["params"]["weak_third_dof_joint"] and not jm["dofs_deg"][2]["ptp"] < 3:
            problems.append("weak third DOF of %s spans %.1f deg" % (jm["name"], jm["dofs_deg"][2]["ptp"]))
    p, w = entry["params"], {k: "-" if v[0] == 0 else "%.2f(tol %.1f)" % v for k, v in worst.items()}
    print("%s %s segs=%d joints=%dS/%dR markers=%d unattached=%d frames=%d noise=%s sigma=%.2f%s sta=%s "
          "gaps=%d rigid_mm rms=%.2f(tol %.2f) max=%.2f(tol %.1f) centre_mm=%s sphere_mm=%s axis_deg=%s cats=%s%s" % (
              entry["id"], "FAIL" if problems else "OK", p["n_segments"], p["n_spherical"], p["n_revolute"],
              len(attached), len(truth["unattached_markers"]), p["frames"], p["noise_model"], sig,
              "" if phi is None else " phi=%.2f" % phi, "%.1fmm" % sta if sta else "-", p["n_gaps"], rig_rms,
              rig_tol, rig_max, rig_mtol, w["centre"], w["sphere"], w["axis"], ",".join(entry["categories"]),
              "" if not problems else " PROBLEMS: " + "; ".join(problems[:5])))
    return not problems


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--n", type=int, required=True)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--check", action="store_true", help="re-read every file written and check it")
    a = ap.parse_args(argv)
    if a.frames is not None and a.frames < 100:
        ap.error("--frames must be at least 100")
    os.makedirs(a.out, exist_ok=True)
    trials = [make_trial(a.out, a.seed, k, a.frames) for k in range(a.n)]
    with open(os.path.join(a.out, "index.json"), "w") as f:
        json.dump(dict(generator="benchmarks/heldout_skeleton/generator.py", seed=a.seed, n=a.n,
                       frames=a.frames, rate_hz=RATE, units="mm", trials=trials), f, indent=1)
    print("wrote %d trials to %s" % (a.n, a.out), file=sys.stderr)
    if a.check:
        index = json.load(open(os.path.join(a.out, "index.json")))
        ok = []
        for e in index["trials"]:
            try:
                ok.append(check_trial(a.out, e))
            except (AssertionError, KeyError, ValueError, OSError) as exc:
                print("%s FAIL unreadable or inconsistent files: %r" % (e["id"], exc))
                ok.append(False)
        print("check: %d/%d trials OK" % (sum(ok), len(ok)))
        return 0 if all(ok) else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
