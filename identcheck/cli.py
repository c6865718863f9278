"""Command-line interface: parse, make one library call, print, exit (codes of CONTRACT.md).

0 success, 1 negative answer (not identifiable / derivation mismatch / certificate rejected),
2 bad input (message on stderr naming the file, marker or option).
"""
from __future__ import annotations

import os

# the solvers make many small dense solves: several BLAS threads per solve only fight each other
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

from identcheck.effects.inject import EFFECTS  # noqa: E402
from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError  # noqa: E402
from identcheck.report import json_out  # noqa: E402

log = logging.getLogger("identcheck")

NOT_YET: dict = {}


def _print_json(obj) -> None:
    from identcheck.report.json_out import dumps
    print(dumps(obj))


def _cmd_derive(a) -> int:
    from identcheck.derive.result import derive_and_write

    res = derive_and_write(a.out)
    rep = res.to_dict()
    if a.json:
        _print_json(rep)
    else:
        for d in rep["derivations"]:
            print(f"{d['title']}: {'ok' if d['ok'] else 'MISMATCH'}")
            for c in d["checks"]:
                flag = "agrees" if c["agrees"] else (f"erratum {c['erratum']}" if c["ok"] else "DISAGREES (unrecorded)")
                print(f"  {c['name']:<24} {c['where']:<16} {flag}")
        print(f"written to {a.out}")
    return 0 if rep["ok"] else 1


def _cmd_rank(a) -> int:
    from identcheck.certify import exact_rank as certify

    cert = certify.rank(a.joint, a.p, a.q, n_samples=a.samples, seed=a.seed)
    if a.save:
        json_out.write(a.save, cert, indent=2)
        log.info("certificate saved to %s", a.save)
    if a.json:
        _print_json(cert.to_dict())
    else:
        print(f"{cert.joint} ({cert.p},{cert.q}): unknowns {', '.join(cert.unknowns)}")
        print(f"exact rank {cert.rank} of {len(cert.unknowns)} (float cross-check: {cert.numeric_rank})")
        print(cert.statement)
    return 0 if cert.full_rank else 1


def _cmd_verify(a) -> int:
    from identcheck.certify.verify import verify

    res = verify(a.certificate)
    fmt, problems = res.format, res.problems
    if a.json:
        _print_json(res)
    else:
        print(f"certificate verified ({fmt}): recomputed from scratch" if not problems else "certificate REJECTED:")
        for p in problems:
            print("  - " + p)
    return 0 if not problems else 1


def _cmd_table(a) -> int:
    from identcheck.certify.table import table

    doc = table(seed=a.seed, joints=tuple(a.joint) if a.joint else None)
    if a.save:
        json_out.write(a.save, doc, indent=1)
        log.info("table saved to %s", a.save)
    if a.json:
        _print_json(doc)
        return 0
    print(f"{'joint':<10} {'p,q':<4} {'identifiable':<13} {'local':<6} {'candidates':<11} {'min N':<6} "
          f"{'local N':<8} certificate")
    for r in doc.cases:
        c = r["certificate"]
        how = c["kind"] + (f" <- {c['follows_from']} ({c['rule']})" if c["kind"] == "remark1" else "")
        ident = ("yes" if r["identifiable"] else "no") if r["identifiable_decided"] else "undecided"
        print(f"{r['joint']:<10} {r['p']},{r['q']:<2} {ident:<13} {'yes' if r['local'] else 'no':<6} "
              f"{'-' if r['candidates'] is None else r['candidates']!s:<11} "
              f"{'-' if r['min_samples'] is None else r['min_samples']!s:<6} "
              f"{'-' if r['local_min_samples'] is None else r['local_min_samples']!s:<8} {how}")
    print("identifiable: generic data give one joint; local: finitely many (candidates, mirror images counted); "
          "min N: samples for the stated verdict; local N: samples for local identifiability (Jacobian engine).")
    return 0


def _cmd_simulate(a) -> int:
    from identcheck.api import simulate_file

    sim = simulate_file(a.model, a.out, seed=a.seed, effect=a.effect, n_frames=a.frames, rate_hz=a.rate,
                        rom_deg=a.rom_deg, noise_mm=a.noise_mm, occlusion=a.occlusion, n_axes=a.n_axes)
    if a.truth:
        sim.save_truth(a.truth)
    log.info("wrote %s (%d frames, %d markers)", a.out, sim.trial.n_frames, sim.trial.n_markers)
    effect = sim.settings.get("effect")
    if effect:
        log.info("injected effect %s at %s", effect["name"], json.dumps(_without_long_lists(effect["where"]), sort_keys=True))
    if a.json:
        doc = {"out": str(a.out), "n_frames": sim.trial.n_frames, "markers": list(sim.trial.labels),
               "truth": sim.truth.to_dict(poses=False)}
        if effect:
            doc["effect"] = _without_long_lists(effect)
        _print_json(doc)
    return 0


def _without_long_lists(doc: dict, longest: int = 20) -> dict:
    """`doc` without the keys (at any depth) whose values are lists of more than `longest` items,
    so that per-frame arrays stay out of the printed summary."""
    return {k: _without_long_lists(v, longest) if isinstance(v, dict) else v for k, v in doc.items()
            if not (isinstance(v, list) and len(v) > longest)}


def _cmd_identify(a) -> int:
    from identcheck.identify import identify
    from identcheck.io.model import Model
    from identcheck.trial import Trial

    model = Model.from_toml(a.model)
    trial = Trial.from_file(a.trial)
    frames = [int(f) for f in a.frames.split(",")] if a.frames else None
    rep = identify(model, trial, joints=a.joint, frames=frames, precision=a.precision).to_dict()
    if a.json:
        _print_json(rep)
    else:
        for name, j in rep["joints"].items():
            hinge = j["type"] == "revolute"
            print(f"{name}: {j['case']}, {j['n_samples']} samples -> {j['candidates']} joint(s)"
                  + (f" ({j['parameter_sets']} parameter sets x mirror images)" if hinge else "")
                  + f"; unique: {j['unique']}; largest sample residual {j['rms_residual']:.3g} mm")
            rows = [j["marker_distances"]] + [alt["marker_distances"] for alt in j["alternatives"]]
            markers = list(rows[0])
            what = "distances to the hinge axis (mm): " if hinge else "distances to the centre (mm):     "
            print("   " + what + "  ".join(f"{m:>8}" for m in markers))
            for i, row in enumerate(rows):
                print(f"   joint {i}:" + " " * 26 + "  ".join(f"{row[m]:8.2f}" for m in markers))
    return 0 if all(j["unique"] for j in rep["joints"].values()) else 1


def _cmd_fit(a) -> int:
    from identcheck.fit.workflow import fit_model, report
    from identcheck.estimate.labels import screen
    from identcheck.io.model import Model
    from identcheck.trial import Trial

    model = Model.from_toml(a.model)
    trial = Trial.from_file(a.trial)
    trial, warnings = screen(model, trial)
    for w in warnings:
        print(f"identcheck fit: warning: {w}", file=sys.stderr)
    fitted, points = fit_model(model, trial, progress=lambda msg: print(f"identcheck fit: {msg}", file=sys.stderr))
    rep = report(model, fitted, points)
    rep["warnings"] = warnings
    if a.json:
        _print_json(rep)
    else:
        for name, j in rep["joints"].items():
            head = f"{name}: {j['case']} by {j['estimator'] or '-'}"
            if not j["identifiable"]:
                print(f"{head}: NOT IDENTIFIABLE. {j['excitation']['reason']}")
                continue
            unc = "-" if j["uncertainty_mm"] is None else f"{j['uncertainty_mm']:.3g}"
            print(f"{head}; unique: {j['unique']}; rms residual {j['rms_residual']:.3g} mm; uncertainty {unc} mm")
            what = "distance to the centre" if j["type"] == "spherical" else "distance to the hinge axis"
            rows = [j["marker_distances"]] + [alt["marker_distances"] for alt in j["alternatives"]]
            print(f"   {what} (mm): " + "  ".join(f"{m:>8}" for m in rows[0]))
            for i, row in enumerate(rows):
                print(f"   joint {i}:{' ' * (len(what) - 2)}" + "  ".join(
                    "       -" if row[m] is None else f"{row[m]:8.2f}" for m in rows[0]))
            if not j["excitation"]["ok"]:
                print(f"   excitation: {j['excitation']['reason']}")
    ok = all(j["unique"] and j["identifiable"] for j in rep["joints"].values())
    return 0 if ok else 1


def _cmd_plan(a) -> int:
    from identcheck.plan import analysis as plan
    from identcheck.io.model import Model

    model = Model.from_toml(a.model)
    doc = plan.plan_model(model, seed=a.seed, motion=not a.fast, robust=not a.fast, fewest=a.fewest,
                          witness=a.witness, progress=lambda msg: print(f"identcheck plan: {msg}", file=sys.stderr))
    if a.figure:
        from identcheck.report.plan_figure import draw

        draw(doc, a.figure, title=a.model)
        log.info("figure written to %s", a.figure)
    if a.json:
        _print_json(doc)
    else:
        from identcheck.report.text import plan_text

        print(plan_text(doc))
    return 0 if doc.all_identifiable else 1


def _cmd_diagnose(a) -> int:
    from identcheck.diagnose.workflow import diagnose
    from identcheck.io.model import Model
    from identcheck.trial import Trial

    model = Model.from_toml(a.model)
    trial = Trial.from_file(a.trial)
    diag = diagnose(model, trial, progress=lambda msg: print(f"identcheck diagnose: {msg}", file=sys.stderr))
    rep = diag.to_dict()
    if a.plots:
        from identcheck.report.diagnose_figures import write_all
        for path in write_all(diag, a.plots):
            log.info("wrote %s", path)
    if a.json:
        _print_json(rep)
    else:
        print(f"noise: {rep['noise_sigma_mm']:.3g} mm per coordinate (within-segment distances, frame to frame; "
              f"whole-trial scatter {diag.ctx.noise.sigma_scatter_mm:.3g} mm)")
        print(f"gap of the rigid-joint model: {rep['gap_before']:.3g} mm (noise floor {rep['noise_floor_before']:.3g} mm)")
        if not rep["effects"]:
            print("no effect found: the rigid-joint model plus noise explains the trial" if rep["consistent_before"]
                  ["consistent"] else "no named effect earns its parameters; the gap stays unexplained")
        for k, e in enumerate(rep["effects"], 1):
            where = ", ".join(f"{key}={val}" for key, val in e["where"].items() if key != "frames" or len(val) <= 4)
            print(f"{k}. {e['name']:<18} {where}: gap {e['gap_before']:.3g} -> {e['gap_after']:.3g} mm")
        test = rep["consistent_after"]
        print(f"gap after: {rep['gap_after']:.3g} mm, noise floor {rep['noise_floor']:.3g} mm; residual "
              f"{'consistent' if test['consistent'] else 'NOT consistent'} with noise "
              f"(gap²/floor² = {test['ratio']:.3g}, limit {test['limit']:.3g})")
        for name, j in rep["joints"].items():
            unc = "-" if j["uncertainty_mm"] is None else f"{j['uncertainty_mm']:.2g}"
            kind = j["type"] if j["type"] == j["declared_type"] else f"{j['type']} (declared {j['declared_type']})"
            print(f"   {name}: {kind}; rms residual {j['rms_residual']:.3g} mm; uncertainty {unc} mm; "
                  + ", ".join(f"{m} {d:.1f}" for m, d in j["marker_distances"].items()))
    return 0 if rep["consistent_after"]["consistent"] else 1


def _not_yet(verb):
    def run(a) -> int:
        print(f"identcheck {verb}: {NOT_YET[verb]} is not available yet", file=sys.stderr)
        return 2
    return run


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="identcheck", description=(
        "Can the joint parameters of this skeleton be identified from these markers? "
        "Certified answers, generated solvers."))
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")

    s = sub.add_parser("derive", help="regenerate and check every derivation against the paper")
    s.add_argument("--out", default="derivations/out", help="directory for the rendered Markdown")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_derive)

    s = sub.add_parser("rank", help="exact generic rank of the sampled M-matrix of a case")
    s.add_argument("joint", help="joint type (revolute | spherical)")
    s.add_argument("p", type=int, help="markers on the parent link")
    s.add_argument("q", type=int, help="markers on the child link")
    s.add_argument("--samples", type=int, default=None, help="rows of M (default: number of unknowns)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--save", metavar="FILE", help="also write the certificate to FILE")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_rank)

    s = sub.add_parser("verify", help="re-check a saved certificate from scratch (rank, local, counterexample, table)")
    s.add_argument("certificate")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_verify)

    s = sub.add_parser("table", help="identifiability verdict and certificate for every joint type x markers")
    s.add_argument("--joint", action="append", choices=("revolute", "spherical", "universal", "prismatic"),
                   help="only this joint type (repeatable; default: all)")
    s.add_argument("--seed", type=int, default=0, help="seed of the random rational points")
    s.add_argument("--save", metavar="FILE", help="also write the table with its certificates to FILE")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_table)

    s = sub.add_parser("simulate", help="write a synthetic trial (TRC or C3D by extension)")
    s.add_argument("model")
    s.add_argument("--out", required=True)
    s.add_argument("--effect", default=None, choices=EFFECTS, metavar="NAME",
                   help=f"inject one named effect ({', '.join(EFFECTS)}); drawn from --seed")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--frames", type=int, default=200)
    s.add_argument("--rate", type=float, default=100.0, help="Hz")
    s.add_argument("--rom-deg", type=float, default=60.0, help="range of motion of each exercised angle")
    s.add_argument("--noise-mm", type=float, default=0.0, help="Gaussian marker noise (std per axis)")
    s.add_argument("--n-axes", type=int, default=None, choices=(1, 2, 3),
                   help="rotation axes each spherical joint exercises (default 3; 1 = flexion only)")
    s.add_argument("--occlusion", type=float, default=0.0, help="fraction of frames with marker gaps")
    s.add_argument("--truth", metavar="FILE", help="also write the true parameters as JSON")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_simulate)

    s = sub.add_parser("identify", help="every joint a trial's samples admit (exact-case solvers)")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--joint", action="append", help="joint name (repeatable; default: all)")
    s.add_argument("--frames", help="comma-separated frame indices (default: every fully visible frame)")
    s.add_argument("--precision", type=int, default=None, help="decimal digits (mpmath) instead of float64")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_identify)

    s = sub.add_parser("fit", help="joint parameters from a recorded trial, with uncertainty and excitation checks")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_fit)

    s = sub.add_parser("plan", help="check a marker plan before capture: which joints are identifiable, how; "
                                    "the fewest markers to add")
    s.add_argument("model")
    s.add_argument("--json", action="store_true")
    s.add_argument("--figure", metavar="FILE", help="also draw the tree, joints coloured by verdict (PNG/SVG)")
    s.add_argument("--seed", type=int, default=0, help="seed of the random prime and point")
    s.add_argument("--fast", action="store_true", help="skip the per-marker robustness and motion analyses")
    s.add_argument("--fewest", action="store_true",
                   help="also report the fewest of the plan's markers that keep every joint locally identifiable")
    s.add_argument("--witness", action="store_true",
                   help="simulate the plan and, for every joint it does not identify, search for a second skeleton "
                        "that reproduces every marker, verified at 50 digits (seconds to a minute)")
    s.set_defaults(func=_cmd_plan)

    s = sub.add_parser("diagnose", help="where the rigid-joint model and a trial disagree: name the missing "
                                        "effects, model them, show the gap shrink")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--json", action="store_true")
    s.add_argument("--plots", metavar="DIR", default=None, help="write the figures into DIR")
    s.set_defaults(func=_cmd_diagnose)

    for verb in NOT_YET:
        s = sub.add_parser(verb, help=f"{NOT_YET[verb]} (not available yet)")
        s.add_argument("args", nargs="*")
        s.add_argument("--json", action="store_true")
        s.add_argument("--plots", default=None)
        s.set_defaults(func=_not_yet(verb))
    return p


def main(argv=None) -> int:
    """Run the CLI in-process; returns the exit code (tests call this)."""
    parser = build_parser()
    try:
        a = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) and 2
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, stream=sys.stderr,
                        format="identcheck: %(message)s")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", IdentifiabilityWarning)
            warnings.showwarning = _show_warning
            return a.func(a)
    except InputError as exc:
        print(f"identcheck {a.verb}: {exc}", file=sys.stderr)
        return 2
    except DegenerateError as exc:
        print(f"identcheck {a.verb}: degenerate data: {exc}", file=sys.stderr)
        return 1


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one readable stderr line, not a source location."""
    print(f"identcheck: warning: {message}", file=sys.stderr)


def run() -> None:
    """Console-script entry point. A reader that closes the pipe early (``| head``) ends the output quietly."""
    try:
        sys.exit(main())
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)       # keep Python from failing again on flushing stdout
        os.dup2(devnull, sys.stdout.fileno())
        sys.exit(0)
