"""Regenerate examples/real_diagnose_report.md and examples/real_diagnose_*.png: `identcheck diagnose` on measured trials.

For every measured recording paired with a model as in ``examples/real_fit_report.py``, runs
:func:`identcheck.diagnose.workflow.diagnose` (the function behind ``identcheck diagnose``) when the
model's markers are all in the trial (a segment with one or two markers is posed through its joints, as in
``fit``), and records the InputError of the others. Writes one short table per recording, the effects found
in order, and a reading of the numbers; the figures of the most telling recording go to
``examples/real_diagnose_*.png``.

    PYTHONPATH=. python3 examples/real_diagnose_report.py        # a few minutes

Trials: /work/shared/data/real (see its README.md); override with IDENTCHECK_REAL_DATA. Long
trials are cropped to their first ``MAX_FRAMES`` frames (the report says which); IDENTCHECK_FULL=1
runs every trial whole (much slower).
"""
from __future__ import annotations

import os

# The fits are many small dense solves: BLAS threads cost more than they save (about 4x the wall
# time on a busy 2-core machine). Must be set before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import datetime as _dt  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from identcheck.report import diagnose_figures as figures  # noqa: E402
from identcheck.bundle.chain import information  # noqa: E402
from identcheck.bundle.hypothesis import joint_angles  # noqa: E402
from identcheck.diagnose.workflow import diagnose  # noqa: E402
from identcheck.errors import DegenerateError, InputError  # noqa: E402
from identcheck.io.model import Model  # noqa: E402
from identcheck.trial import Trial  # noqa: E402

sys.path.insert(0, str(HERE))
# the same recordings and (trial, model file, role) pairs as the fitting report
from real_fit_report import DATA, HIP, KNEE, RUNS, STATIC, WALK1, WALK2  # noqa: E402

OUT_MD = HERE / "real_diagnose_report.md"
FIG_PREFIX = "real_diagnose_"
FULL = os.environ.get("IDENTCHECK_FULL", "") not in ("", "0")

# first frames kept per trial (None: all). The hip crop keeps frame 731/732 (see the report);
# walking2's pelvis and right thigh are complete only in frames 387-881, so it is not cropped.
MAX_FRAMES = {HIP: 1000, KNEE: 600, STATIC: 300, WALK1: None, WALK2: None}

DESCRIBE = {
    HIP: "hip functional trial (Qualisys, 100 Hz): thigh swung in flexion/extension and ab/adduction, still after 13.5 s",
    KNEE: "knee functional trial (Qualisys, 100 Hz): 5-6 flexion-extension cycles, 18-128 deg",
    STATIC: "static anatomical pose of the same subject (Qualisys, 100 Hz): nothing moves",
    WALK1: "one overground stride (OpenSim example, 60 Hz)",
    WALK2: "treadmill walking (Vicon Nexus, 250 Hz), with gaps",
}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------ running
def accepts(model: Model, trial: Trial) -> list[str]:
    """Why diagnose cannot use this pair (empty: it can): a marker of the model missing from the trial. Segments with
    one or two markers are diagnosed like the others (posed through their joints)."""
    return [f"marker {m!r} is not in the trial" for m in model.markers if m not in trial.labels]


def crop(trial: Trial, n: int | None) -> Trial:
    if FULL or n is None or trial.n_frames <= n:
        return trial
    return trial.replace(xyz=trial.xyz[:n])


def run_one(model: Model, trial: Trial, tag: str) -> dict:
    t0 = time.perf_counter()
    out = {"diag": None, "error": None, "traceback": None, "warnings": []}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            out["diag"] = diagnose(model, trial, progress=lambda m: log(f"  [{tag}] {m}"))
        except (InputError, DegenerateError) as exc:    # the data cannot answer: a clear refusal, not a crash
            out["error"] = f"{type(exc).__name__}: {exc}" if isinstance(exc, DegenerateError) else str(exc)
        except Exception as exc:      # a crash is a finding for the report, not a reason to stop it
            out["error"] = f"{type(exc).__name__}: {exc}"
            out["traceback"] = traceback.format_exc()
            log(out["traceback"])
    out["warnings"] = sorted({f"{w.category.__name__}: {w.message}" for w in caught})
    out["seconds"] = time.perf_counter() - t0
    return out


# ------------------------------------------------------------------ formatting
def fmt(x, digits: int = 2) -> str:
    if x is None:
        return "-"
    x = float(x)
    if not np.isfinite(x):
        return "-"
    return f"{x:.{digits}f}" if abs(x) < 1e4 else f"{x:.3g}"


def where_text(where: dict) -> str:
    """`where` in one cell: long lists as counts, floats rounded."""
    parts = []
    for k, v in where.items():
        if isinstance(v, (list, tuple)):
            if k == "frames" and len(v) == 2 and all(isinstance(x, (int, np.integer)) for x in v):
                parts.append(f"frames {v[0]}-{v[1]}")
            elif len(v) > 4:
                nums = [x for x in v if isinstance(x, (int, float, np.integer, np.floating))]
                span = f" ({min(nums)}-{max(nums)})" if len(nums) == len(v) else ""
                parts.append(f"{k}: {len(v)}{span}")
            else:
                parts.append(f"{k}: {', '.join(str(x) for x in v)}")
        elif isinstance(v, float):
            parts.append(f"{k} {v:.3g}")
        else:
            parts.append(f"{k} {v}")
    return "; ".join(parts) or "-"


def swap_check(trial: Trial, model: Model, a: str, b: str, span) -> str | None:
    """Model-free check of a swap: median distance of each marker to its segment partners inside and
    outside the span (a real swap shows the two exchanging their distance patterns)."""
    seg = next((s for s, g in model.segments.items() if a in g.markers), None)
    if seg is None or b not in model.segments[seg].markers:
        return None
    partners = [m for m in model.segments[seg].markers if m not in (a, b)]
    if not partners:
        return None
    inside = np.zeros(trial.n_frames, bool)
    inside[span[0]:span[1] + 1] = True
    rows = []
    for m in (a, b):
        d = np.array([np.linalg.norm(trial.marker(m) - trial.marker(p), axis=1) for p in partners])
        rows.append(f"{m}: " + ", ".join(
            f"to {p} {np.nanmedian(d[k, inside]):.0f} in / {np.nanmedian(d[k, ~inside]):.0f} out"
            for k, p in enumerate(partners)))
    return "; ".join(rows) + " mm"


def swap_reference(where: dict, model: Model, trials_full: dict, tname: str) -> dict | None:
    """Which frames of the whole trial carry exchanged labels, judged against the same markers' distances
    to their segment partners in the subject's other recordings (not against the trial itself)."""
    a, b = (list(where.get("markers", [])) + [None, None])[:2]
    span = where.get("frames")
    seg = next((sg for sg, g in model.segments.items() if a in g.markers), None)
    if seg is None or b not in model.segments[seg].markers or not span:
        return None
    partners = [m for m in model.segments[seg].markers if m not in (a, b)]
    refs = [n for n, t in trials_full.items() if n != tname and all(m in t.labels for m in [a, b] + partners)]
    if not partners or not refs:
        return None

    def dists(t: Trial, m: str) -> np.ndarray:         # (F, partners)
        return np.stack([np.linalg.norm(t.marker(m) - t.marker(p), axis=1) for p in partners], axis=1)

    ref_a = np.nanmedian(np.concatenate([dists(trials_full[n], a) for n in refs]), axis=0)
    ref_b = np.nanmedian(np.concatenate([dists(trials_full[n], b) for n in refs]), axis=0)
    t = trials_full[tname]
    da, db = dists(t, a), dists(t, b)
    keep = np.nansum((da - ref_a) ** 2, axis=1) + np.nansum((db - ref_b) ** 2, axis=1)
    swap = np.nansum((db - ref_a) ** 2, axis=1) + np.nansum((da - ref_b) ** 2, axis=1)
    exchanged = swap < keep
    edges = np.flatnonzero(np.diff(np.r_[0, exchanged.astype(int), 0]))
    runs = [(int(s0), int(e0) - 1) for s0, e0 in zip(edges[::2], edges[1::2]) if e0 - s0 >= 3]
    inside = exchanged[span[0]:span[1] + 1]
    return {"markers": (a, b), "partners": partners, "refs": refs, "ref_a": ref_a, "ref_b": ref_b,
            "n_exchanged": int(exchanged.sum()), "n_frames": t.n_frames, "runs": runs, "span": tuple(span),
            "span_exchanged": float(inside.mean()) if inside.size else float("nan")}


def swap_reference_text(x: dict) -> str:
    a, b = x["markers"]
    runs = ", ".join(f"{s0}-{e0}" for s0, e0 in x["runs"][:6]) + (" ..." if len(x["runs"]) > 6 else "")
    named = (f"so the span diagnose names ({x['span'][0]}-{x['span'][1]}) holds the wrong labels"
             if x["span_exchanged"] > 0.9 else
             f"so the span diagnose names ({x['span'][0]}-{x['span'][1]}, {100 * x['span_exchanged']:.0f} % of it "
             "exchanged by this reference) is the complementary, correctly labelled part: diagnose judges "
             "labels against the median geometry of the frames it is given, so it names the minority span")
    return (f"Against the subject's other recordings ({', '.join(f'`{n}`' for n in x['refs'])}), where {a} is "
            + "/".join(f"{v:.0f}" for v in x["ref_a"]) + f" mm and {b} "
            + "/".join(f"{v:.0f}" for v in x["ref_b"]) + f" mm from {'/'.join(x['partners'])}: in the whole "
            f"{x['n_frames']}-frame trial the labels are exchanged in {x['n_exchanged']} frames (runs {runs}), "
            + named + ".")


# ------------------------------------------------------------------ the report
def main() -> int:
    t_start = time.perf_counter()
    trials_full = {t: Trial.from_file(DATA / t) for t in dict.fromkeys(t for t, _, _ in RUNS)}
    trials = {t: crop(tr, MAX_FRAMES.get(t)) for t, tr in trials_full.items()}
    results, refused = [], []
    for tname, mname, role in RUNS:
        model = Model.from_toml(HERE / mname)
        trial = trials[tname]
        why = accepts(model, trial)
        tag = f"{mname} x {tname}"
        if why:
            # confirm with diagnose itself (it refuses before any fitting) and keep its message
            r = run_one(model, trial, tag)
            msg = r["error"] or ("diagnose accepted it although " + "; ".join(why))
            refused.append((tname, mname, role, msg))
            log(f"refused: {tag}: {msg.splitlines()[0]}")
            continue
        log(f"diagnose {tag} ({trial.n_frames} of {trials_full[tname].n_frames} frames)")
        r = run_one(model, trial, tag)
        r.update(trial=tname, model=mname, role=role, modelobj=model, trialobj=trial)
        if r["diag"] is not None:
            d = r["diag"]
            r["json"] = d.to_dict()
            r["info_finite"] = bool(np.isfinite(information(d.after.fit, d.after.data, d.after.weights)).all())
            r["rom_deg"] = {jn: np.degrees(np.ptp(a, axis=0)).tolist() for jn, a in joint_angles(d.before).items()}
            r["swaps"] = [swap_reference(s.where, model, trials_full, tname) for s in d.steps
                          if s.name == "marker_swap"]
            log(f"  done in {r['seconds']:.0f} s: gap {d.gap_before:.3g} -> {d.gap_after:.3g} mm, floor "
                f"{d.noise_floor:.3g} mm, effects {[s.name for s in d.steps]}")
        else:
            log(f"  FAILED in {r['seconds']:.0f} s: {r['error']}")
        results.append(r)

    ok = [r for r in results if r["diag"] is not None]
    # the most telling recording: the largest share of the gap closed by the named effects
    best = max(ok, key=lambda r: r["diag"].gap_before / max(r["diag"].gap_after, 1e-9), default=None)
    figs = []
    for old in HERE.glob(f"{FIG_PREFIX}*.png"):      # figures of an earlier run may name other effects
        old.unlink()
    if best is not None:
        with tempfile.TemporaryDirectory() as tmp:
            for p in figures.write_all(best["diag"], tmp):
                dest = HERE / f"{FIG_PREFIX}{Path(p).name}"
                shutil.copyfile(p, dest)
                figs.append(dest.name)
        log(f"figures of {best['model']} x {best['trial']}: {', '.join(figs)}")

    L: list[str] = []
    w = L.append
    stamp = _dt.datetime.now().replace(microsecond=0).isoformat()
    total = time.perf_counter() - t_start
    w("# `identcheck diagnose` on measured trials")
    w("")
    w(f"Generated by `PYTHONPATH=. python3 examples/real_diagnose_report.py` ({stamp}, {total:.0f} s); "
      "do not edit by hand.")
    w("")
    w("Each recording in `/work/shared/data/real` (see its README) is paired with the models of "
      "`examples/real_fit_report.py`. `diagnose` fits the rigid-joint model (rigid segments, the declared "
      "joints), compares its gap (RMS 3-D marker error) with the noise floor (what measurement noise "
      "alone would leave, estimated from within-segment distances, frame to frame), and while the gap is "
      "larger, adopts the named effect that explains most of it. There is no ground truth for these "
      "subjects: the effects are what the data support, to be read with the anatomy in mind.")
    w("")
    cropped = [(t, trials[t].n_frames, trials_full[t].n_frames) for t in trials
               if trials[t].n_frames < trials_full[t].n_frames]
    if cropped:
        w("To keep the run short, long trials are cut to their first frames: "
          + "; ".join(f"`{t}` frames 0-{n - 1} of {m}" for t, n, m in cropped)
          + " (`IDENTCHECK_FULL=1` runs them whole).")
        w("")

    w("## Summary")
    w("")
    w("σ: noise per coordinate from frame-to-frame changes of within-segment distances; σ scatter: the "
      "same from their whole-trial scatter. Gaps and floors: RMS 3-D distance, mm. consistent: the final "
      "residual passes diagnose's test that it is noise (gap²/floor² against its limit).")
    w("")
    w("| recording | model | frames | σ (mm) | σ scatter (mm) | gap before | floor | effects | gap after | "
      "floor after | gap²/floor² (limit) | consistent | time (s) |")
    w("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        if r["diag"] is None:
            w(f"| `{r['trial']}` | `{r['model']}` | {r['trialobj'].n_frames} | - | - | - | - | **failed**: "
              f"{r['error'].splitlines()[0]} | - | - | - | - | {r['seconds']:.0f} |")
            continue
        d, j = r["diag"], r["json"]
        t = j["consistent_after"]
        w(f"| `{r['trial']}` | `{r['model']}` | {r['trialobj'].n_frames} | {fmt(d.ctx.noise.sigma_mm, 3)} | "
          f"{fmt(d.ctx.noise.sigma_scatter_mm, 3)} | {fmt(d.gap_before)} | {fmt(j['noise_floor_before'], 3)} | "
          f"{', '.join(s.name for s in d.steps) or 'none'} | {fmt(d.gap_after)} | {fmt(d.noise_floor, 3)} | "
          f"{fmt(t['ratio'], 1)} ({fmt(t['limit'], 2)}) | {'yes' if t['consistent'] else '**no**'} | "
          f"{r['seconds']:.0f} |")
    w("")

    for tname in dict.fromkeys(r["trial"] for r in results):
        w(f"## `{tname}`")
        w("")
        full = trials_full[tname]
        w(f"{DESCRIBE.get(tname, '')}; {full.n_frames} frames at {full.rate_hz:g} Hz"
          + (f", first {trials[tname].n_frames} used" if trials[tname].n_frames < full.n_frames else "") + ".")
        w("")
        for r in (r for r in results if r["trial"] == tname):
            section(w, r, figs if r is best else None)

    if refused:
        w("## Pairs diagnose cannot use")
        w("")
        w("diagnose needs every marker of the model in the trial. Its InputError, verbatim:")
        w("")
        w("| recording | model | role | InputError |")
        w("|---|---|---|---|")
        for tname, mname, role, msg in refused:
            msg = " ".join(msg.split())
            w(f"| `{tname}` | `{mname}` | {role} | {msg} |")
        w("")

    w("## Reading the numbers")
    w("")
    for line in reading(results):
        w(f"- {line}")
    w("")
    bugs = problems(results)
    if bugs:
        w("## Problems of diagnose on these trials")
        w("")
        for line in bugs:
            w(f"- {line}")
        w("")
    OUT_MD.write_text("\n".join(L))
    log(f"wrote {OUT_MD} ({total:.0f} s)")
    return 0


def section(w, r, figs) -> None:
    d = r["diag"]
    w(f"### `{r['model']}` ({r['role']})")
    w("")
    if d is None:
        w(f"**diagnose failed** after {r['seconds']:.0f} s: `{r['error']}`")
        if r["traceback"]:
            w("")
            w("```")
            w(r["traceback"].rstrip())
            w("```")
        w("")
        return
    j = r["json"]
    nz = d.ctx.noise
    w("| quantity | value |")
    w("|---|---|")
    w(f"| noise σ, frame to frame | {nz.sigma_mm:.3f} mm (relative s.e. {nz.rel_se:.2f}, {nz.n_pairs} pairs) |")
    w(f"| noise σ, whole-trial scatter | {nz.sigma_scatter_mm:.3f} mm ({nz.sigma_scatter_mm / nz.sigma_mm:.1f} x) |")
    w(f"| gap before (rigid-joint model) | {d.gap_before:.3f} mm |")
    w(f"| noise floor (before / after) | {j['noise_floor_before']:.3f} / {d.noise_floor:.3f} mm |")
    w(f"| gap after the effects | {d.gap_after:.3f} mm |")
    t0, t1 = j["consistent_before"], j["consistent_after"]
    w(f"| residual consistent with noise | before: {'yes' if t0['consistent'] else 'no'} "
      f"(gap²/floor² {t0['ratio']:.1f}, limit {t0['limit']:.2f}); after: "
      f"{'**yes**' if t1['consistent'] else '**no**'} ({t1['ratio']:.1f}, limit {t1['limit']:.2f}) |")
    w(f"| run time | {r['seconds']:.0f} s |")
    w("")
    if d.steps:
        w("| # | effect | where | gap before → after (mm) | score |")
        w("|---|---|---|---|---|")
        for k, s in enumerate(d.steps, 1):
            w(f"| {k} | `{s.name}` | {where_text(s.where)} | {s.gap_before:.3f} → {s.gap_after:.3f} | {s.score:.3g} |")
        w("")
        for name, where, gain in d.dropped:
            w(f"Dropped on the way: `{name}` ({where_text(where)}), adopted before later effects that explain what "
              f"it did (it gains {gain:.0f} given them).")
            w("")
    else:
        w("No effect adopted.")
        w("")
    w("| joint | type (declared) | rms residual (mm) | uncertainty (mm) | excitation |")
    w("|---|---|---|---|---|")
    for name, jt in j["joints"].items():
        kind = jt["type"] if jt["type"] == jt["declared_type"] else f"**{jt['type']}** ({jt['declared_type']})"
        ex = jt["excitation"]
        w(f"| {name} | {kind} | {fmt(jt['rms_residual'])} | {fmt(jt['uncertainty_mm'])} | "
          f"{'ok' if ex['ok'] else ex['reason']} |")
    w("")
    for s in d.steps:
        if s.name == "marker_swap" and len(s.where.get("markers", [])) == 2 and "frames" in s.where:
            txt = swap_check(r["trialobj"], r["modelobj"], *s.where["markers"], s.where["frames"])
            if txt:
                w(f"Model-free check of the swap (median distances to the segment's other markers, inside / "
                  f"outside frames {s.where['frames'][0]}-{s.where['frames'][1]}): {txt}.")
                w("")
    for x in r.get("swaps", []):
        if x:
            w(swap_reference_text(x))
            w("")
    if r["warnings"]:
        w("Warnings during the run: " + "; ".join(f"`{x}`" for x in r["warnings"]) + ".")
        w("")
    if figs:
        w("Figures of this run (residual per marker and frame before/after, gap per step, evidence of each "
          "effect):")
        w("")
        for f in figs:
            w(f"![{f}]({f})")
        w("")


def _tissue_note(markers: list, segment: str, static: bool) -> str:
    if static:
        return ""
    if "thigh" in segment:
        note = "expected: thigh skin and muscle slide over the femur with the joint angles"
        if any(m.endswith("GT") for m in markers):
            note += " (the greater-trochanter marker is known for the largest skin artefact of the leg)"
        return note
    if "pelvis" in segment:
        return "plausible: the skin over the iliac spines moves with hip flexion"
    if "shank" in segment:
        return "plausible: shank skin moves less than thigh skin, but it moves"
    return ""


def reading(results) -> list[str]:
    """Statements drawn from this run's numbers."""
    out = []
    for r in results:
        d = r["diag"]
        head = f"`{r['trial']}` with `{r['model']}`"
        if d is None:
            if r["traceback"]:
                out.append(f"{head}: **diagnose crashed** ({r['error'].splitlines()[0]}); see the trace above.")
            else:
                out.append(f"{head}: refused with a clear input error: {r['error'].splitlines()[0]}")
            continue
        j = r["json"]
        nz = d.ctx.noise
        names = [s.name for s in d.steps]
        rom = max((max(v) for v in r["rom_deg"].values()), default=0.0)
        static = rom < 2.0
        parts = []
        ratio = nz.sigma_scatter_mm / max(nz.sigma_mm, 1e-12)
        if ratio > 3:
            parts.append(f"the whole-trial scatter of within-segment distances ({nz.sigma_scatter_mm:.2f} mm) is "
                         f"{ratio:.0f} times the frame-to-frame noise ({nz.sigma_mm:.3f} mm)"
                         + (" (the label swap below inflates it)" if "marker_swap" in names else "")
                         + ": the segments deform slowly (skin moving under the markers) and/or the trajectories "
                         "were low-pass filtered, which hides noise from the frame-to-frame estimate; either way "
                         f"the noise floor ({d.noise_floor:.3f} mm) is far below anything a model of rigid bones "
                         "with a few named effects can reach")
        else:
            parts.append(f"frame-to-frame noise ({nz.sigma_mm:.3f} mm) and whole-trial scatter "
                         f"({nz.sigma_scatter_mm:.3f} mm) agree within {ratio:.1f}x: the within-segment distances "
                         "hardly drift over the trial")
        if static:
            parts.append(f"nothing moves (largest joint-angle range {rom:.1f} deg) and the rigid model already "
                         f"fits to {d.gap_before:.2f} mm; the effects adopted here ("
                         + ", ".join(names) + f") each remove less than 0.1 mm: with σ = {nz.sigma_mm:.3f} mm "
                         "diagnose's score finds sub-0.1-mm drift significant and gives it the name of the closest "
                         "effect. With no joint motion there is no soft tissue in the biomechanical sense: on a "
                         "static trial these names are false positives, and the 0.1 mm scale is the message")
        elif d.steps:
            closed = 1 - d.gap_after / d.gap_before if d.gap_before > 0 else 0.0
            parts.append(f"the effects close {100 * closed:.0f} % of the gap ({d.gap_before:.2f} → "
                         f"{d.gap_after:.2f} mm), the first one {d.steps[0].name} "
                         f"({where_text(d.steps[0].where)}, {d.steps[0].gap_before:.2f} → "
                         f"{d.steps[0].gap_after:.2f} mm)")
        for s in d.steps:
            if static:
                break
            if s.name == "soft_tissue":
                note = _tissue_note(s.where.get("markers", []), str(s.where.get("segment", "")), static)
                parts.append(f"soft tissue on {', '.join(s.where.get('markers', []))} ({s.where.get('segment')}, "
                             f"driven by {s.where.get('joint')})" + (f" is {note}" if note else ""))
        if "marker_swap" in names:
            s = d.steps[names.index("marker_swap")]
            parts.append(f"the label swap of {', '.join(s.where.get('markers', []))} "
                         f"({where_text({'frames': s.where.get('frames', [])})}) is a genuine labelling error in "
                         "the recording, visible without any model in the distances to the other thigh markers "
                         "(see the checks above); it dominates the rigid-model gap")
        if "extra_dof" in names and not static:
            s = d.steps[names.index("extra_dof")]
            parts.append(f"{s.where.get('joint')} declared {s.where.get('declared')} fits better as "
                         f"{s.where.get('needs')}: a real knee rotates a few degrees off its flexion axis (axial "
                         "rotation, ab/adduction), and skin motion adds apparent rotation, so a strict hinge "
                         "leaves residual; once re-declared, the excitation check applies the ball-joint rule "
                         "(two axes of 15 deg), which a knee never meets")
        for jn in dict.fromkeys(s.where.get("joint") for s in d.steps if s.name == "joint_translation"):
            n = sum(1 for s in d.steps if s.name == "joint_translation" and s.where.get("joint") == jn)
            kind = d.ctx.model.joints[jn].type if jn in d.ctx.model.joints else ""
            twice = f" (adopted {n} times in a row at the same joint)" if n > 1 else ""
            if static:
                continue
            if kind == "spherical":
                parts.append(f"joint_translation at {jn}{twice}: a hip centre does not move in the pelvis by "
                             "millimetres, so this is skin motion of the thigh markers that follows the hip "
                             "angles, seen through the joint")
            else:
                parts.append(f"joint_translation at {jn}{twice}: the knee's centre does move with flexion "
                             "(rolling and gliding), and skin motion follows the same angles; markers alone "
                             "cannot tell the two apart")
        if "spatial_distortion" in names and not static:
            s = d.steps[names.index("spatial_distortion")]
            amp = s.where.get("amplitude_mm")
            parts.append("spatial_distortion was adopted" + (f" with an amplitude of {amp:.0f} mm" if amp else "")
                         + ": a calibrated capture volume is not distorted by tens of mm over a leg's length, so "
                         "this term most likely absorbs slow non-rigid motion of several markers at once that "
                         "the single-marker soft-tissue terms leave; read it as 'smooth residual', not as a "
                         "camera problem")
        if "time_offset" in names:
            parts.append("a time offset between segments is unlikely in a synchronised camera system; it more "
                         "likely stands for skin markers lagging the bone")
        if not d.steps:
            if not r["info_finite"]:
                parts.append(f"no effect was adopted although the gap ({d.gap_before:.2f} mm) is "
                             f"{d.gap_before / d.noise_floor:.0f} times the floor: the fit's information matrix "
                             "is not finite on this trial (it has frames in which a segment has no visible "
                             "marker), so diagnose's identifiability check counts every direction as undetermined "
                             "and refuses every candidate, and the joints' `uncertainty_mm` is NaN. This is a "
                             "defect of diagnose on trials with gaps, not a property of the data")
            else:
                parts.append(f"no named effect earns its parameters (gap {d.gap_before:.2f} mm)")
        t1 = j["consistent_after"]
        if t1["consistent"]:
            parts.append("the final residual is consistent with noise")
        else:
            parts.append(f"the final residual is **not** consistent with noise (gap²/floor² {t1['ratio']:.1f}, limit "
                         f"{t1['limit']:.2f}"
                         + (", after the maximum of 4 effects" if len(d.steps) >= 4 else "") + ")")
        bad = [n for n, jt in j["joints"].items() if not jt["excitation"]["ok"]]
        if bad and not static:
            parts.append("excitation flagged for " + ", ".join(bad) + " (" + "; ".join(
                j["joints"][n]["excitation"]["reason"] for n in bad) + ")")
        out.append(f"{head}: " + "; ".join(parts) + ".")
    ok = [r for r in results if r["diag"] is not None]
    if ok:
        n_no = sum(not r["json"]["consistent_after"]["consistent"] for r in ok)
        tissue = sorted({m for r in ok for s in r["diag"].steps if s.name == "soft_tissue"
                         for m in s.where.get("markers", [])})
        out.append(f"Overall: the final residual is consistent with noise in {len(ok) - n_no} of {len(ok)} runs. "
                   "On these recordings the frame-to-frame noise is tiny (Qualisys/Vicon trajectories are "
                   "usually smoothed), while skin markers move by millimetres: the rigid-joint model plus four "
                   "named effects closes much of the gap but never reaches a floor set by sub-0.1-mm noise. "
                   "Markers named for soft tissue: " + ", ".join(tissue) + ". Treat the ranking of the first "
                   "effect as the useful output, and the later ones as an account of smooth residual.")
    return out


def problems(results) -> list[str]:
    """What went wrong in diagnose itself on these trials."""
    out = []
    for r in results:
        if r["diag"] is None and r["traceback"]:
            where = ""
            if r["traceback"]:
                frames = [ln.strip() for ln in r["traceback"].splitlines() if ln.strip().startswith("File ")]
                where = f" at {frames[-2] if len(frames) > 1 else frames[-1]}" if frames else ""
            out.append(f"`{r['model']}` x `{r['trial']}`: crash, `{r['error']}`{where} (the CLI prints a "
                       "traceback for it).")
        elif r["diag"] is not None and not r["info_finite"]:
            out.append(f"`{r['model']}` x `{r['trial']}`: the information matrix of the final fit is not finite, "
                       "so `undetermined()` refuses every effect and `uncertainty_mm` is NaN.")
        for wmsg in r["warnings"]:
            if "Mean of empty slice" in wmsg:
                out.append(f"`{r['model']}` x `{r['trial']}`: `{wmsg}` (joint_translation's detector on frames "
                           "where a segment is not visible).")
    return out


if __name__ == "__main__":
    sys.exit(main())
