"""Command-line interface: parse, make one :mod:`identcheck.api` call, render it with
:mod:`identcheck.report`, exit with the code of docs/contract.md.

0 success, 1 negative answer (not identifiable / derivation mismatch / certificate rejected / gap not
explained), 2 bad input (message on stderr naming the file, marker or option), 3 internal error (never
expected: the message asks for a report). Progress and warnings go to stderr, results to stdout.
"""
from __future__ import annotations

import argparse
import contextlib
import ctypes
import ctypes.util
import logging
import math
import os
import re
import sys
import tempfile
import threading
import traceback
import warnings

import identcheck
from identcheck import api
from identcheck.errors import DegenerateError, IdentifiabilityWarning, InputError
from identcheck.plan import capture
from identcheck.report import json_out, text

log = logging.getLogger("identcheck")


class _EffectNames:
    """The effect names of :data:`identcheck.effects.registry.NAMES`, read when argparse checks or prints them:
    the registry imports every effect module (and SciPy with them), which the other verbs do not need."""

    def _names(self) -> tuple:
        from identcheck.effects.registry import NAMES

        return NAMES

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __iter__(self):
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


EFFECT_NAMES = _EffectNames()


_STDERR_LOCK = threading.Lock()


def _progress(verb: str):
    """A progress callback printing ``identcheck VERB: message`` on stderr, one whole line per call even when
    worker threads report at once (``print`` writes the text and its newline separately: two draws of a bootstrap
    running in parallel had run into one line)."""
    def say(msg) -> None:
        with _STDERR_LOCK:
            sys.stderr.write(f"identcheck {verb}: {msg}\n")
            sys.stderr.flush()
    return say


def _print_json(result) -> None:
    print(json_out.dumps(result))


def _cmd_derive(a) -> int:
    res = api.derive(a.out, regenerate=a.regenerate)
    if a.json:
        _print_json(res)
    else:
        print(text.derive_text(res))
    return 0 if res.ok else 1


def _cmd_rank(a) -> int:
    cert = api.rank(a.joint, a.p, a.q, samples=a.samples, seed=a.seed, progress=_progress("rank"))
    if a.save:
        json_out.write(a.save, cert.sealed(), indent=2)
        log.info("certificate saved to %s", a.save)
    if a.json:
        _print_json(cert.sealed())
    else:
        print(text.rank_text(cert))
    return 0 if cert.full_rank else 1


def _cmd_verify(a) -> int:
    res = api.verify(a.certificate, progress=_progress("verify"))
    if a.json:
        _print_json(res)
    else:
        print(text.verify_text(res))
    return 0 if res.ok else 1


def _cmd_table(a) -> int:
    res = api.table(seed=a.seed, joints=tuple(a.joint) if a.joint else None, progress=_progress("table"))
    if a.save:
        json_out.write(a.save, res, indent=1)
        log.info("table saved to %s", a.save)
    if a.json:
        _print_json(res)
    else:
        print(text.table_text(res))
    return 0


def _cmd_simulate(a) -> int:
    sim = api.simulate(a.model, a.out, seed=a.seed, effect=a.effect, n_frames=a.frames, rate_hz=a.rate,
                       rom_deg=a.rom_deg, noise_mm=a.noise_mm, occlusion=a.occlusion, n_axes=a.n_axes)
    if a.truth:
        sim.save_truth(a.truth)
    log.info("wrote %s (%d frames, %d markers)", a.out, sim.trial.n_frames, sim.trial.n_markers)
    doc = text.simulate_summary(sim, a.out)
    if "effect" in doc:
        log.info("injected effect %s at %s", doc["effect"]["name"], json_out.dumps(doc["effect"]["where"], indent=None))
    if a.json:
        _print_json(doc)
    return 0


def _cmd_identify(a) -> int:
    frames = [int(f) for f in a.frames.split(",")] if a.frames else None
    res = api.identify(a.model, a.trial, joints=a.joint, frames=frames, precision=a.precision)
    if a.json:
        _print_json(res)
    else:
        print(text.identify_text(res))
    return 0 if res.unique else 1


def _cmd_fit(a) -> int:
    res = api.fit(a.model, a.trial, progress=_progress("fit"), frames=a.frames, export_markers=a.export_markers,
                  report=a.report, export_osim=a.export_osim)
    if a.export_osim:
        log.info("OpenSim model written to %s", a.export_osim)
    if a.report:
        log.info("report written to %s", a.report)
    for w in res.warnings:
        print(f"identcheck fit: warning: {w['message']}", file=sys.stderr)
    if a.json:
        _print_json(res)
    else:
        print(text.fit_text(res))
    return 0 if res.ok else 1


def _cmd_plan(a) -> int:
    res = api.plan(a.model, seed=a.seed, motion=not a.fast, robust=not a.fast, fewest=a.fewest, witness=a.witness,
                   progress=_progress("plan"), noise_mm=a.noise_mm, practical_motion=a.motion or "functional",
                   frames=capture.FRAMES if a.frames is None else a.frames,
                   max_seconds=a.max_seconds)
    if a.figure:
        from identcheck.report.plan_figure import draw

        draw(res, a.figure, title=a.model)
        log.info("figure written to %s", a.figure)
    if a.json:
        _print_json(res)
    else:
        print(text.plan_text(res))
    return 0 if res.all_identifiable else 1


def _cmd_diagnose(a) -> int:
    diag = api.diagnose(a.model, a.trial, progress=_progress("diagnose"), frames=a.frames,
                        export_markers=a.export_markers, report=a.report)
    if a.report:
        log.info("report written to %s", a.report)
    if a.plots:
        from identcheck.report.diagnose_figures import write_all

        for path in write_all(diag, a.plots):
            log.info("wrote %s", path)
    if a.json:
        _print_json(diag)
    else:
        print(text.diagnose_text(diag))
    return 0 if diag.consistent else 1


def _cmd_skeleton(a) -> int:
    res = api.skeleton(a.trial, out=a.out, segments=a.segments, root=a.root, frames=a.frames,
                       export_markers=a.export_markers, progress=_progress("skeleton"))
    for w in res.other.get("warnings", ()):
        print(f"identcheck skeleton: warning: {w}", file=sys.stderr)
    if a.json:
        _print_json(res)
    else:
        print(text.skeleton_text(res))
    return 0 if res.ok else 1


def _cmd_batch(a) -> int:
    from identcheck.batch import summary

    try:
        df = api.batch(a.batch_verb, a.inputs, a.out, model=a.model, frames=a.frames, noise_mm=a.noise_mm,
                       motion=a.motion, seed=0 if a.seed is None else a.seed, fast=a.fast, workers=a.workers,
                       scheduler=a.scheduler, dashboard=a.dashboard, progress=True)
    except KeyboardInterrupt:
        print(f"identcheck batch: interrupted; every job finished so far is saved in {a.out}: the same command "
              "completes the rest", file=sys.stderr)
        return 130
    doc = summary.counts(df, a.out)
    if a.json:
        _print_json(doc)
    else:
        print(text.batch_text(doc))
    return summary.exit_code(df)


def _seed(text: str) -> int:
    """A ``--seed``: a whole number, 0 or more (NumPy's generators take no negative seed), checked by argparse
    so that a bad one is a usage error (exit 2) before any work."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value}: a seed is 0 or more")
    return value


class _Help(argparse.HelpFormatter):
    """Help wrapped to the terminal with its line breaks kept: the epilog's example and exit codes, one per line."""

    def _fill_text(self, text, width, indent):
        import textwrap

        lines = []
        for line in text.splitlines():
            lead = indent + line[:len(line) - len(line.lstrip())]
            if line.lstrip().startswith("identcheck "):        # an example command: one line, to copy as it is
                lines.append(lead + line.strip())
            elif line.strip():
                lines.append(textwrap.fill(" ".join(line.split()), width, initial_indent=lead,
                                           subsequent_indent=lead + ("  " if lead != indent else "")))
            else:
                lines.append("")
        return "\n".join(lines)


def _epilog(example: str, ok: str, no: str | None = None) -> str:
    """A verb's ``--help`` epilog: a one-line example and the exit codes of docs/contract.md (docs/cli.md)."""
    codes = [f"  0  {ok}"] + ([f"  1  {no}"] if no else []) + [
        "  2  bad input or arguments (the message names the file, line, marker, frame or option)",
        "  3  internal error (a bug: the message asks for a report)"]
    return f"example:\n  {example}\nexit codes:\n" + "\n".join(codes) + "\nreference: docs/cli.md"


class _Version(argparse.Action):
    """``--version``: the installed version, read from the package metadata only when asked (importing
    importlib.metadata for every call cost 14 ms of each verb's start-up)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"identcheck {identcheck.__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``identcheck`` argument parser: one subcommand per verb of docs/contract.md (reference: docs/cli.md)."""
    p = argparse.ArgumentParser(prog="identcheck", formatter_class=_Help, epilog=(
        "example:\n  identcheck plan examples/leg.toml && identcheck fit examples/leg.toml trial.c3d --json\n"
        "exit codes: 0 success, 1 a negative answer (not identifiable, not determined, gap not explained), "
        "2 bad input, 3 internal error; each verb's --help gives its own. Reference: docs/cli.md"), description=(
        "Can the joint parameters of this skeleton be identified from these markers? "
        "Certified answers, generated solvers."))
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    p.add_argument("--version", action=_Version, nargs=0, help="show the installed version and exit")
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")

    s = sub.add_parser("derive", formatter_class=_Help, epilog=_epilog("identcheck derive --out derivations/out --json", "every derivation agrees with the paper (or a recorded erratum) and the generated code is up to date", "an unrecorded disagreement, or stale generated code or shipped cache (--regenerate rewrites them)"),
                       help="regenerate and check every derivation against the paper")
    s.add_argument("--out", default="derivations/out", help="directory for the rendered Markdown")
    s.add_argument("--regenerate", action="store_true",
                   help="rewrite the solvers' generated code (identcheck/solve/generated/) from these derivations, "
                        "and the derivation cache the package ships (identcheck/derive/seed/) when it is stale")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_derive)

    s = sub.add_parser("rank", formatter_class=_Help, epilog=_epilog("identcheck rank revolute 2 1 --save cert.json", "M has full rank", "M is rank-deficient: the case is not identifiable from these samples"),
                       help="exact generic rank of the sampled M-matrix of a case")
    s.add_argument("joint", help="joint type (revolute | spherical)")
    s.add_argument("p", type=int, help="markers on the parent link")
    s.add_argument("q", type=int, help="markers on the child link")
    s.add_argument("--samples", type=int, default=None, help="rows of M (default: number of unknowns)")
    s.add_argument("--seed", type=_seed, default=0)
    s.add_argument("--save", metavar="FILE", help="also write the certificate to FILE")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_rank)

    s = sub.add_parser("verify", formatter_class=_Help, epilog=_epilog("identcheck verify cert.json", "the certificate holds", "it does not (the message names the row and field)"),
                       help="re-check a saved certificate from scratch (rank, local, counterexample, table)")
    s.add_argument("certificate")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_verify)

    s = sub.add_parser("table", formatter_class=_Help, epilog=_epilog("identcheck table --joint revolute --save table.json", "the table was made"),
                       help="identifiability verdict and certificate for every joint type x markers")
    s.add_argument("--joint", action="append", choices=("revolute", "spherical", "universal", "prismatic"),
                   help="only this joint type (repeatable; default: all)")
    s.add_argument("--seed", type=_seed, default=0, help="seed of the random rational points")
    s.add_argument("--save", metavar="FILE", help="also write the table with its certificates to FILE")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_table)

    s = sub.add_parser("simulate", formatter_class=_Help, epilog=_epilog("identcheck simulate examples/leg.toml --out leg.c3d --noise-mm 0.5 --truth truth.json", "the trial was written"),
                       help="write a synthetic trial (TRC or C3D by extension)")
    s.add_argument("model")
    s.add_argument("--out", required=True)
    s.add_argument("--effect", default=None, choices=EFFECT_NAMES, metavar="NAME",
                   help="inject one named effect (%(choices)s); drawn from --seed")
    s.add_argument("--seed", type=_seed, default=0)
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

    s = sub.add_parser("identify", formatter_class=_Help, epilog=_epilog("identcheck identify examples/knee_21.toml knee.c3d --json", "every joint asked is unique", "some joint admits several joint-parameter sets (revolute (2,1): four), or the data are degenerate"),
                       help="every joint a trial's samples admit (exact-case solvers)")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--joint", action="append", help="joint name (repeatable; default: all)")
    s.add_argument("--frames", help="comma-separated frame indices (default: every fully visible frame)")
    s.add_argument("--precision", type=int, default=None, help="decimal digits (mpmath) instead of float64")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=_cmd_identify)

    s = sub.add_parser("fit", formatter_class=_Help, epilog=_epilog("identcheck fit examples/real/walking2_right_leg.toml examples/real/opensim_walking2.c3d --json", "every joint is identifiable and determined by the trial", "some joint is not (ambiguous or undetermined: see practical)"),
                       help="joint parameters from a recorded trial, with uncertainty and excitation checks")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--json", action="store_true")
    s.add_argument("--export-markers", metavar="OUT.trc|OUT.c3d", default=None,
                   help="also write the markers plus each joint's centre and hinge-axis points as virtual markers")
    s.add_argument("--report", metavar="OUT.html", default=None,
                   help="also write one self-contained HTML page: the skeleton and fitted joints in 3-D, residuals, "
                        "verdicts and intervals (opens offline in a browser)")
    s.add_argument("--export-osim", metavar="OUT.osim", default=None,
                   help="also write the fitted skeleton as an OpenSim model (bodies, ball and pin joints at the "
                        "fitted centres and axes, the markers), for OpenSim's inverse kinematics; needs "
                        "identcheck[osim]")
    s.add_argument("--frames", metavar="START:END", default=None,
                   help="only these frames, in the file's own numbering (TRC Frame#; C3D from the header's first "
                        "frame, 1-based, as Nexus, QTM and Mokka show it), both included; either end may be left "
                        "out")
    s.set_defaults(func=_cmd_fit)

    s = sub.add_parser("plan", formatter_class=_Help, epilog=_epilog("identcheck plan examples/leg.toml --noise-mm 1 --motion functional", "every joint is uniquely identifiable", "some joint is not (suggestions names the markers to add)"),
                       help="check a marker plan before capture: which joints are identifiable, how; "
                                    "the fewest markers to add")
    s.add_argument("model")
    s.add_argument("--json", action="store_true")
    s.add_argument("--figure", metavar="FILE", help="also draw the tree, joints coloured by verdict (PNG, SVG or PDF)")
    s.add_argument("--seed", type=_seed, default=0, help="seed of the random prime and point")
    s.add_argument("--fast", action="store_true", help="skip the per-marker robustness and motion analyses")
    s.add_argument("--max-seconds", type=float, default=None, metavar="S",
                   help="time budget of the robustness and motion analyses together (default 30), separately of "
                        "the search for the fewest markers to add (default 30), of --fewest (default 30) and of "
                        "the --witness searches (default 120); what they leave unchecked is listed under "
                        "'unfinished'")
    s.add_argument("--fewest", action="store_true",
                   help="also report the fewest of the plan's markers that keep every joint locally identifiable")
    s.add_argument("--witness", action="store_true",
                   help="simulate the plan and, for every joint it does not identify, search for a second skeleton "
                        "that reproduces every marker, verified at 50 digits (seconds to a minute)")
    s.add_argument("--noise-mm", type=float, default=None, metavar="SIGMA",
                   help="also predict what a capture with this marker noise would determine (practical verdicts)")
    s.add_argument("--motion", default=None, metavar="NAME|TRIAL",
                   help="the motion of that capture (with --noise-mm): functional (default), flexion or small, or a "
                        "recorded trial")
    s.add_argument("--frames", type=int, default=None, metavar="N",
                   help=f"frames of that capture (with --noise-mm; default {capture.FRAMES})")
    s.set_defaults(func=_cmd_plan)

    s = sub.add_parser("diagnose", formatter_class=_Help, epilog=_epilog("identcheck diagnose examples/diagnose_leg.toml trial.trc --plots figures/", "the residual left is consistent with noise", "a gap stays unexplained"),
                       help="where the rigid-joint model and a trial disagree: name the missing "
                                        "effects, model them, show the gap shrink")
    s.add_argument("model")
    s.add_argument("trial")
    s.add_argument("--json", action="store_true")
    s.add_argument("--plots", metavar="DIR", default=None, help="write the figures into DIR")
    s.add_argument("--export-markers", metavar="OUT.trc|OUT.c3d", default=None,
                   help="also write the markers plus each joint's centre and hinge-axis points (with the adopted "
                        "effects) as virtual markers")
    s.add_argument("--report", metavar="OUT.html", default=None,
                   help="also write one self-contained HTML page: the skeleton in 3-D, residuals, the effects with "
                        "the gap each closed, and the joints (opens offline in a browser)")
    s.add_argument("--frames", metavar="START:END", default=None,
                   help="only these frames, in the file's own numbering (TRC Frame#; C3D from the header's first "
                        "frame, 1-based, as Nexus, QTM and Mokka show it), both included; either end may be left "
                        "out")
    s.set_defaults(func=_cmd_diagnose)

    s = sub.add_parser("skeleton", formatter_class=_Help, epilog=_epilog(
                           "identcheck skeleton trial.c3d --out model.toml --export-markers playback.c3d",
                           "a skeleton the data settle (no joint ambiguous, every group of markers placed, none "
                           "held together beyond the rigidity tolerance or possibly two segments)",
                           "the model was written, but some joint is ambiguous, some group cannot be placed, holds "
                           "markers that wobble beyond the tolerance, or may be two segments"),
                       help="infer the segments, the tree and the joint types from a trial alone and write a model file",
                       description="Group the markers into rigid segments (or take --segments), join them by the "
                                   "minimum spanning tree over pairwise O'Brien joint-fit residuals, type each joint "
                                   "from its motion, and write a model file that fit, plan and diagnose read, with "
                                   "the evidence as comments. Exit 0: a skeleton the data settle; 1: written, but "
                                   "some joint is ambiguous, some group cannot be placed, wobbles beyond the "
                                   "tolerance or may be two segments; 2: bad input (a static trial included). See "
                                   "docs/skeleton.md.")
    s.add_argument("trial", help="the trial (TRC or C3D)")
    s.add_argument("--out", required=True, metavar="MODEL.toml", help="the model file to write")
    s.add_argument("--segments", metavar="FILE", default=None,
                   help='the grouping, when known: a TOML file with [segments] NAME = ["M1", "M2", ...] (or a model '
                        "file); then only the tree and the joint types are inferred")
    s.add_argument("--root", metavar="NAME", default=None,
                   help="the root segment, or one of its markers (default: the tree's centre)")
    s.add_argument("--json", action="store_true")
    s.add_argument("--frames", metavar="START:END", default=None,
                   help="only these frames, in the file's own numbering, both included; either end may be left out")
    s.add_argument("--export-markers", metavar="OUT.trc|OUT.c3d", default=None,
                   help="also write the measured markers beside the articulated model's playback of them (M.model) "
                        "and each joint's virtual markers")
    s.set_defaults(func=_cmd_skeleton)

    s = sub.add_parser("batch", formatter_class=_Help, epilog=_epilog("identcheck batch fit examples/leg.toml trials/ --out results/", "no job failed", "some jobs failed (2: all did); 130: interrupted, rerun to resume"),
                       help="run fit, diagnose or plan over many trials on a Dask cluster (local by "
                                     "default): one JSON per job, a summary table; resumable",
                       description="Run fit, diagnose or plan over many trials on a Dask cluster: one JSON per job "
                                   "(the verb's own --json output) and DIR/summary.csv + .parquet, one row per job x "
                                   "joint. A job already done with the same inputs, settings and version is skipped; "
                                   "a failed job is an error row. Exit 0: no job failed, 1: some did, 2: all did "
                                   "(or bad arguments). See docs/batch.md.")
    s.add_argument("batch_verb", choices=("fit", "diagnose", "plan"), metavar="VERB", help="fit, diagnose or plan")
    s.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="fit/diagnose: MODEL.toml then trials (files, quoted globs, folders), or manifest CSVs "
                        "(trial,model[,frames], paths relative to the CSV); plan: model files, globs, folders")
    s.add_argument("--out", required=True, metavar="DIR", help="one JSON per job and the summary go here (only here)")
    s.add_argument("--model", metavar="FILE", default=None, help="the model of the trials (instead of a first .toml)")
    s.add_argument("--frames", metavar="START:END|N", default=None,
                   help="fit/diagnose: only these frames of every trial (a manifest row's own range comes first); "
                        "plan: frames of the predicted capture (default 1000)")
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per CPU, at most one per job)")
    s.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="run on an existing Dask cluster (tcp://host:8786) instead of a local one; its workers must "
                        "see the inputs at the same paths")
    s.add_argument("--dashboard", metavar="ADDRESS", default=":8787",
                   help="address of the local cluster's dashboard (default :8787; :0 for any free port)")
    s.add_argument("--noise-mm", metavar="SIGMA[,SIGMA...]", default=None,
                   help="plan: sweep these noise levels (practical verdicts)")
    s.add_argument("--motion", metavar="NAME|TRIAL[,...]", default=None,
                   help="plan: with --noise-mm, sweep these motions (functional, flexion, small, or recorded trials)")
    s.add_argument("--seed", type=_seed, default=None, help="plan: seed of the random prime and point (default 0)")
    s.add_argument("--fast", action="store_true", help="plan: skip the per-marker robustness and motion analyses")
    s.add_argument("--json", action="store_true", help="print the counts and the failed jobs as JSON")
    s.set_defaults(func=_cmd_batch)

    for verb in sub.choices.values():       # also after the verb (``fit ... --json -v``), as users type it
        verb.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                          help="log progress to stderr (as before the verb)")
    return p


# ---------------------------------------------------------------------- checks before any work
FILE_OUTPUTS = {"rank": ("save",), "table": ("save",), "simulate": ("out", "truth"), "plan": ("figure",),
                "fit": ("export_markers", "report", "export_osim"), "diagnose": ("export_markers", "report"), "skeleton": ("out", "export_markers")}
DIR_OUTPUTS = {"derive": ("out",), "diagnose": ("plots",), "batch": ("out",)}
NEEDS_MATPLOTLIB = {"plan": "figure", "diagnose": "plots"}
TRIAL_SUFFIXES = (".c3d", ".trc")
FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
JSON_OUTPUTS = {"rank": ("save",), "table": ("save",), "simulate": ("truth",)}
DEGENERATE_KEYS = {"fit": {"joints": {}, "noise": None, "warnings": []},
                   "diagnose": {"noise_floor": None, "gap_before": None, "gap_after": None, "effects": [],
                                "joints": {}, "noise": None, "warnings": []}}
"""The keys the contract requires of a verb's JSON, with what degenerate data give them (nothing measured: null,
nothing named, no joint judged), beside ``ok`` false and the ``degenerate`` message: a reader of the contract's keys
finds every one of them."""
MAX_RANK_SAMPLES = 675              # identcheck.certify.exact_rank.distinct_tangents() (no SymPy import here)
PRECISION_DIGITS = (15, 1000)
MAX_SIMULATED_FRAMES = 1_000_000     # a million frames of a body model is already gigabytes
RATE_HZ = (0.01, 1e6)               # a simulated capture's rate: its times print (6 decimals) and rise frame by frame


MAX_WORKERS_PER_CPU = 4
"""``batch --workers`` above this many per CPU is refused: a local cluster of that many processes only shares the
CPUs, each with its own copy of the libraries (memory), and a typo of 200 had started 200."""


def preflight(a) -> list:
    """Everything that can be checked about the arguments before the work starts, so that a bad output
    path, a missing optional package or a swapped argument costs nothing and loses no result: the
    problems, each naming the option and the path (empty: go)."""
    problems = []
    outputs = [(o, _unwritable_file) for o in FILE_OUTPUTS.get(a.verb, ())] + \
              [(o, _unwritable_dir) for o in DIR_OUTPUTS.get(a.verb, ())]
    for opt, check in outputs:
        path = getattr(a, opt, None)
        why = check(path) if path else ""
        if why:
            problems.append(f"--{opt.replace('_', '-')} {path}: {why}")
    opt = NEEDS_MATPLOTLIB.get(a.verb)
    if opt and getattr(a, opt, None):
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            problems.append(f"--{opt} draws with matplotlib, which is not installed: pip install 'identcheck[plots]'")
    model, trial = getattr(a, "model", None), getattr(a, "trial", None)
    if model and trial and str(model).lower().endswith(TRIAL_SUFFIXES) and str(trial).lower().endswith(".toml"):
        problems.append(f"the model and the trial are swapped: {a.verb} takes MODEL.toml first, then the trial "
                        f"(identcheck {a.verb} {trial} {model})")
    elif model and str(model).lower().endswith(TRIAL_SUFFIXES):
        problems.append(f"{model} is a trial; {a.verb} takes the model file (TOML) first")
    out = getattr(a, "export_markers", None)
    if out and not str(out).lower().endswith(TRIAL_SUFFIXES):
        problems.append(f"--export-markers {out}: give a .trc or .c3d file name")
    for opt in JSON_OUTPUTS.get(a.verb, ()):
        path = getattr(a, opt, None)
        if path and not str(path).lower().endswith(".json"):
            problems.append(f"--{opt} {path}: give a .json file name (it is written as JSON)")
    written = [(opt, getattr(a, opt)) for opt in FILE_OUTPUTS.get(a.verb, ()) if getattr(a, opt, None)]
    for i, (opt, path) in enumerate(written):
        for other, path2 in written[i + 1:]:
            if same_file(path, path2):
                problems.append(f"--{opt.replace('_', '-')} and --{other.replace('_', '-')} are the same file "
                                f"({getattr(a, opt)}): one would overwrite the other")
    figure = getattr(a, "figure", None)
    if figure and not str(figure).lower().endswith(FIGURE_SUFFIXES):
        kinds = [suffix.lstrip(".").upper() for suffix in FIGURE_SUFFIXES]
        problems.append(f"--figure {figure}: give a {', '.join(kinds[:-1])} or {kinds[-1]} file name")
    page = getattr(a, "report", None)
    if page and not str(page).lower().endswith((".html", ".htm")):
        problems.append(f"--report {page}: give an .html file name")
    osim = getattr(a, "export_osim", None)
    if osim:
        from identcheck.fit.osim import opensim_missing

        if not str(osim).lower().endswith(".osim"):
            problems.append(f"--export-osim {osim}: give an .osim file name")
        if opensim_missing():
            problems.append(f"--export-osim {osim}: {opensim_missing()}")
    for opt in FILE_OUTPUTS.get(a.verb, ()):
        path = getattr(a, opt, None)
        if path and any(same_file(path, src) for src in _input_files(a)):
            problems.append(f"--{opt.replace('_', '-')} {path}: is an input file (or a link to one); it would be "
                            "overwritten")
    if a.verb == "rank" and a.samples is not None and not 1 <= a.samples <= MAX_RANK_SAMPLES:
        problems.append(f"--samples {a.samples}: between 1 and {MAX_RANK_SAMPLES} (the samples' half-angle tangents "
                        "are distinct, drawn from that many rationals)")
    if a.verb == "identify":
        lo, hi = PRECISION_DIGITS
        if a.precision is not None and not lo <= a.precision <= hi:
            problems.append(f"--precision {a.precision}: decimal digits between {lo} and {hi}")
        if a.frames:
            try:
                listed = [int(f) for f in a.frames.split(",")]
            except ValueError:
                listed = None
            if listed is None or any(f < 0 for f in listed):
                problems.append(f"--frames {a.frames}: comma-separated frame indices, 0 or more")
            elif len(set(listed)) < len(listed):
                again = sorted({f for f in listed if listed.count(f) > 1})
                problems.append(f"--frames {a.frames}: frame(s) {', '.join(map(str, again))} listed twice; a frame "
                                "repeated adds no sample (each frame is one sample of the joint)")
    if a.verb in ("fit", "diagnose", "skeleton", "batch") and a.frames is not None and not str(a.frames).strip():
        problems.append("--frames is empty: give START:END in the file's frame numbers (either end may be left out, "
                        "e.g. 100: or :500), or leave the option out for every frame")
    if a.verb == "plan" and a.max_seconds is not None and not 0 < a.max_seconds <= 86400:
        problems.append(f"--max-seconds {a.max_seconds}: a positive number of seconds, at most a day")
    if a.verb == "plan" and a.noise_mm is not None:
        from identcheck.fit.predict import MAX_NOISE_MM

        if not 0 < a.noise_mm <= MAX_NOISE_MM:
            problems.append(f"--noise-mm {a.noise_mm}: a positive noise level in mm, at most {MAX_NOISE_MM:g} (no "
                            "capture system's markers are a metre off; typical systems 0.1-2 mm)")
        if a.frames is not None and capture.frames_problem(a.frames):
            problems.append(f"--frames {capture.frames_problem(a.frames)}")
        if a.motion is not None:
            from identcheck.fit.predict import motion_problem

            if motion_problem(a.motion):
                problems.append(motion_problem(a.motion))
    elif a.verb == "plan":
        given = [f"--{o} {getattr(a, o)}" for o in ("motion", "frames") if getattr(a, o) is not None]
        if given:
            verb = "describes" if len(given) == 1 else "describe"
            problems.append(f"{' and '.join(given)} {verb} the capture that --noise-mm predicts; without --noise-mm "
                            "nothing uses them (add --noise-mm SIGMA)")
    if a.verb == "batch":
        from identcheck.batch import extra

        if extra.problem():
            problems.append(extra.problem())
        folders = [i for i in a.inputs if os.path.isdir(i) and same_file(i, a.out)]
        if folders:
            problems.append(f"--out {a.out}: is an input folder ({folders[0]}); the jobs' JSONs and the summary would "
                            "lie among the trials: give the batch a folder of its own")
        if a.dashboard is not None and _bad_address(a.dashboard):
            problems.append(f"--dashboard {a.dashboard}: {_bad_address(a.dashboard)}")
        if a.workers is not None and a.workers < 1:
            problems.append(f"--workers {a.workers}: 1 or more")
        elif a.workers is not None and a.workers > MAX_WORKERS_PER_CPU * (os.cpu_count() or 1):
            problems.append(f"--workers {a.workers}: at most {MAX_WORKERS_PER_CPU} per CPU ("
                            f"{MAX_WORKERS_PER_CPU * (os.cpu_count() or 1)} on this machine): each worker is a process "
                            "with its own copy of the numerical libraries, and more than the CPUs only share them")
        plan_only = [opt for opt, given in (("--noise-mm", a.noise_mm is not None), ("--motion", a.motion is not None),
                                            ("--seed", a.seed is not None), ("--fast", a.fast)) if given]
        if plan_only and a.batch_verb != "plan":
            one = len(plan_only) == 1
            problems.append(f"{', '.join(plan_only)}: {'an option' if one else 'options'} of batch plan only; batch "
                            f"{a.batch_verb} would ignore {'it' if one else 'them'} (drop {'it' if one else 'them'}, "
                            "or run batch plan on the model)")
        if a.workers is not None and a.scheduler:
            problems.append("--workers sizes the local cluster; with --scheduler the cluster's own workers run the "
                            "jobs: give one of them")
    if a.verb == "skeleton":
        problems += _skeleton_problems(a)
    if a.verb == "simulate":
        for opt, ok, allowed in (
                ("frames", 2 <= a.frames <= MAX_SIMULATED_FRAMES, f"2 to {MAX_SIMULATED_FRAMES:,} frames"),
                ("rate", RATE_HZ[0] <= a.rate <= RATE_HZ[1], f"{RATE_HZ[0]:g} to {RATE_HZ[1]:g} Hz"),
                ("noise_mm", 0 <= a.noise_mm < math.inf, "0 or more mm, finite"),
                ("occlusion", 0 <= a.occlusion < 1, "a fraction of frames from 0 up to (not including) 1"),
                ("rom_deg", 0 <= a.rom_deg <= 360, "0 to 360 degrees")):
            if not ok:
                problems.append(f"--{opt.replace('_', '-')} {getattr(a, opt)}: out of range ({allowed})")
    return problems


def _skeleton_problems(a) -> list:
    """``skeleton``'s own checks: a trial first, and a .toml model to write."""
    problems = []
    if str(a.trial).lower().endswith(".toml"):
        problems.append(f"{a.trial} is a TOML file; skeleton takes the trial (.trc or .c3d) and writes the model "
                        f"with --out (identcheck skeleton TRIAL --out MODEL.toml)")
    if a.out and not str(a.out).lower().endswith(".toml"):
        problems.append(f"--out {a.out}: give a .toml file name (the model file to write)")
    return problems           # an output over an input, or over the other output: preflight's own checks


def _bad_address(address: str) -> str:
    """Why `address` is no ``[HOST]:PORT`` a dashboard can listen on ('' when it is): the port a number from 0
    (any free one) to 65535."""
    host, sep, port = address.rpartition(":")
    if not sep or not port.isascii() or not port.isdigit() or not 0 <= int(port) <= 65535:
        return "give [HOST]:PORT with PORT from 0 (any free port) to 65535, e.g. :8787 or 127.0.0.1:0"
    if host and not all(c.isascii() and (c.isalnum() or c in ".-[]:") for c in host):
        return f"{host!r} is no host name or address"
    return ""


def _unwritable_file(path) -> str:
    """Why a file cannot be written at `path` ('' when it can); nothing is left behind. A symbolic link is judged
    where it leads (its target is what is written, :func:`identcheck.io.atomic.replacing`)."""
    path = os.path.realpath(path)
    if os.path.isdir(path):
        return "is a directory; give a file name"
    if os.path.exists(path) and not os.path.isfile(path):
        # a device or a FIFO (/dev/null, /dev/stdout): written into, not beside, so its folder does not matter
        return "" if os.access(path, os.W_OK) else "not writable"
    parent = os.path.dirname(path)
    if not os.path.isdir(parent):
        return f"its directory {parent} does not exist"
    if not os.access(parent, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        return "not writable"
    return _cannot_create_in(parent)


def _cannot_create_in(folder) -> str:
    """Why no file can be created in `folder` ('' when one can), found by creating an empty one there and removing
    it: the permission bits do not say it for every folder (root may write anywhere by them, yet nothing can be
    created in /proc; a read-only mount; a full inode table), and the results are written beside their names
    (:mod:`identcheck.io.atomic`) only after the work."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".tmp-probe-", dir=folder)
    except OSError as exc:
        return f"cannot create a file in {folder} ({exc.strerror or exc})"
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError as exc:
        return f"a file created in {folder} cannot be removed ({exc.strerror or exc}; {probe} is left there)"
    return ""


def same_file(a, b) -> bool:
    """Whether two paths name one file: the same path, a symbolic link to it, or a hard link (same device and
    inode); a path that does not exist yet is compared by where its links lead."""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _input_files(a) -> list:
    """Every file the command reads (model, trial, certificate, segments, a plan's recorded motion, batch inputs)."""
    files = [getattr(a, k, None) for k in ("model", "trial", "certificate", "segments")]
    motion = getattr(a, "motion", None)
    if isinstance(motion, str):
        files += [m for m in motion.split(",") if m.lower().endswith(TRIAL_SUFFIXES)]
    files += list(getattr(a, "inputs", None) or [])
    return [str(f) for f in files if f]


def _unwritable_dir(path) -> str:
    """Why a directory cannot be written (created if missing) at `path` ('' when it can)."""
    if os.path.exists(path) and not os.path.isdir(path):
        return "is a file; give a directory"
    if os.path.isdir(path):
        return _cannot_create_in(path) if os.access(path, os.W_OK) else "not writable"
    parent = os.path.dirname(os.path.abspath(path))
    while parent and not os.path.exists(parent):
        parent = os.path.dirname(parent)
    if not os.path.isdir(parent):
        return f"{parent} is a file, not a directory"
    if not os.access(parent, os.W_OK):
        return f"cannot create it under {parent} (not writable)"
    return _cannot_create_in(parent)


def keep_freed_memory() -> None:
    """Ask the C library's allocator to keep freed memory for reuse: arrays under 32 MiB come from the heap, and
    the heap is not handed back to the system below 1 GiB. By default glibc maps fresh pages for every large
    temporary and unmaps them when it is freed, and the whole-chain fit allocates and drops a few MB per
    iteration: first-touch page faults measured about a third of the time of its normal equations (both legs of
    walking2, 1500 frames: 72 ms → 48 ms). A process-wide setting, so the command line makes it, not the
    library; nothing happens on a C library without ``mallopt``."""
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return
    mallopt(-3, 32 << 20)                # M_MMAP_THRESHOLD
    mallopt(-1, 1 << 30)                 # M_TRIM_THRESHOLD


NEGATIVE_VALUE_OPTIONS = ("--frames",)
"""Options whose value may start with a minus sign (a frame range or index from before the file's first frame)."""


def takes_negative_value(word: str) -> bool:
    """Whether `word` names one of :data:`NEGATIVE_VALUE_OPTIONS`, in full or as the abbreviation argparse accepts
    (``--fra`` for ``--frames``: at least ``--fr``, so that no other option of any verb shares it)."""
    return any(word == opt or (len(word) >= 4 and opt.startswith(word)) for opt in NEGATIVE_VALUE_OPTIONS)


def joined_negative_values(argv: list) -> list:
    """`argv` with ``--frames -5:10`` (or an abbreviation, ``--fra -5:10``) written as ``--frames=-5:10``: argparse
    takes a word starting with '-' and a digit for an option when the parser has options that look like numbers,
    and otherwise answered only "expected one argument"; joined, the value reaches the option's own check, which
    explains (a range is clamped to the file's frames, with a warning)."""
    out, i = [], 0
    while i < len(argv):
        word = str(argv[i])
        if takes_negative_value(word) and i + 1 < len(argv) and re.match(r"-\d", str(argv[i + 1])):
            out.append(f"{word}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def main(argv=None) -> int:
    """Run the CLI in-process; returns the exit code (tests call this)."""
    keep_freed_memory()
    parser = build_parser()
    try:
        a = parser.parse_args(joined_negative_values(sys.argv[1:] if argv is None else list(argv)))
    except SystemExit as exc:
        return int(exc.code or 0) and 2
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, stream=sys.stderr,
                        format="identcheck: %(message)s")
    if sys.stdout is None:      # started with its standard output closed: Python drops every print silently
        print(f"identcheck {a.verb}: standard output is closed, so the answer would be lost; run with it open "
              "(redirect it to a file, or to /dev/null to keep only the exit code)", file=sys.stderr)
        return 2
    problems = preflight(a)
    if problems:
        for msg in problems:
            print(f"identcheck {a.verb}: {msg}", file=sys.stderr)
        return 2
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", IdentifiabilityWarning)
            warnings.showwarning = _show_warning
            with _named_stdout():
                code = a.func(a)
                sys.stdout.flush()      # a full or failing standard output is reported here, not lost at exit
            return code
    except InputError as exc:
        print(f"identcheck {a.verb}: {exc}", file=sys.stderr)
        return 2
    except DegenerateError as exc:
        where = f"{a.trial}: " if getattr(a, "trial", None) and str(a.trial) not in str(exc) else ""
        print(f"identcheck {a.verb}: degenerate data: {where}{exc}", file=sys.stderr)
        if getattr(a, "json", False):   # exit 1 is an answer, and --json promises one document for it
            try:
                with _named_stdout():
                    said = {"warnings": exc.warnings} if getattr(exc, "warnings", None) else {}
                    _print_json({"ok": False, "degenerate": f"{where}{exc}", **DEGENERATE_KEYS.get(a.verb, {}), **said})
                    sys.stdout.flush()
            except BrokenPipeError:     # a reader that stopped early: quiet, as everywhere (run())
                raise
            except OSError as err:      # (the answer could not be written: said, not lost)
                print(f"identcheck {a.verb}: {err.filename or 'standard output'}: {err.strerror or err}",
                      file=sys.stderr)
                return 2
        return 1
    except BrokenPipeError:
        raise
    except KeyboardInterrupt:           # Ctrl-C: the user's stop, not a failure; one line, not a traceback
        print(f"identcheck {a.verb}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:              # the disk is full, a file vanished, a device refused: the machine, not a bug
        where = exc.filename or _outputs(a) or _inputs(a)
        print(f"identcheck {a.verb}: {where}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception:                   # a bug: say so, with the traceback to report (exit 3, docs/contract.md)
        traceback.print_exc(file=sys.stderr)
        print(f"identcheck {a.verb}: internal error (a bug in identcheck {identcheck.__version__}) on "
              f"{_inputs(a)}; please report it with the command line, these inputs and the traceback above",
              file=sys.stderr)
        return 3


class _NamedStream:
    """A text stream whose failed writes name it: an error without a file name (a full disk, a failing device) raised
    while printing the answer had been reported against the command's input files."""

    def __init__(self, stream, name: str):
        self._stream, self._name = stream, name

    def _named(self, call, *args):
        try:
            return call(*args)
        except OSError as exc:
            if exc.filename is None:
                exc.filename = self._name
            raise

    def write(self, text):
        return self._named(self._stream.write, text)

    def flush(self):
        return self._named(self._stream.flush)

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _named_stdout():
    """Standard output as a :class:`_NamedStream` for the verb's run (restored after)."""
    stream = sys.stdout
    sys.stdout = _NamedStream(stream, "standard output")
    try:
        yield
    finally:
        sys.stdout = stream


def _stdout_fails() -> bool:
    """Whether standard output refuses what is pending for it (a full disk, a failing device): an error without a
    file name, raised while printing the answer, is then standard output's, not an input file's."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        return True
    return False


def _outputs(a) -> str:
    """The files and folders the command writes, for a message about a failed write."""
    opts = FILE_OUTPUTS.get(a.verb, ()) + DIR_OUTPUTS.get(a.verb, ())
    return ", ".join(str(getattr(a, o)) for o in opts if getattr(a, o, None))


def _inputs(a) -> str:
    """The input files of the command, for the internal-error message (what to attach to a report)."""
    files = _input_files(a)
    return ", ".join(files) if files else "no input file"


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one readable stderr line, not a source location."""
    print(f"identcheck: warning: {message}", file=sys.stderr)


def run() -> None:
    """Console-script entry point. A reader that closes the pipe early (``| head``) ends the output quietly; what a
    failing standard output still holds (:func:`main` reported it) is dropped, so Python does not fail on it again
    at exit."""
    try:
        code = main()
    except BrokenPipeError:
        code = 0
    if sys.stdout is not None and _stdout_fails():
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    sys.exit(code)
