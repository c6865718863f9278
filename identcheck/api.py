"""The library's verbs: one function per CLI verb, each taking a model and a trial (objects or file paths)
and returning a frozen result with ``to_dict()`` (the verb's JSON).

The command line (:mod:`identcheck.cli`) parses its arguments, calls exactly one of these, renders the
result with :mod:`identcheck.report` and chooses the exit code; nothing a verb computes lives in the CLI.
So ``identcheck.fit(model, trial)`` and ``identcheck fit MODEL TRIAL --json`` give the same numbers.

Each verb runs with one BLAS thread (``threadpoolctl``): the solvers make many small dense solves, and
several threads per solve only fight each other (a notebook with the default thread count was ~12x
slower). The limit holds inside the call only; the caller's settings are restored after it.

Heavy modules (SymPy, SciPy) are imported by the verbs that need them, when called.
"""
from __future__ import annotations

import functools
import os
import warnings
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from identcheck.errors import DegenerateError, InputError, warning_kind
from identcheck.io.model import Model
from identcheck.plan import capture

if TYPE_CHECKING:  # pragma: no cover
    from identcheck.simulate.rigid import Simulation
    from identcheck.trial import Trial


def _one_blas_thread(verb, with_scipy: bool = True):
    """Run ``verb`` with BLAS (and OpenMP) limited to one thread, restored afterwards.

    threadpoolctl limits the libraries loaded when the call starts, so SciPy (whose wheels bring their own
    BLAS) is imported first. ``with_scipy=False`` is for a verb that runs on NumPy alone (``identify``): it
    spares that import, a third of such a verb's time; a callable decides from the call's arguments (``plan``
    needs SciPy only for its numerical parts).
    """
    @functools.wraps(verb)
    def run(*args, **kwargs):
        if with_scipy(*args, **kwargs) if callable(with_scipy) else with_scipy:
            import scipy.linalg  # noqa: F401  (SciPy's own BLAS is loaded here: limit it too)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):
            return verb(*args, **kwargs)
    return run


def _path_argument(value, what: str, expected: str):
    """`value` when it can name a file (a str or an os.PathLike); else an InputError naming the argument, what it
    expects and what it got: an int had been read as an open file descriptor ("Bad file descriptor"), a list or an
    array had failed deep in pathlib."""
    if isinstance(value, (str, os.PathLike)):
        return value
    shown = " ".join(repr(value).split())
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    raise InputError([f"{what}: expected {expected}, got {type(value).__name__} {shown}"])


def _number_argument(value, what: str, integer: bool = False):
    """`value` when it is a number (an int, for `integer`; not a bool), else an InputError naming the argument."""
    import numbers

    kind = numbers.Integral if integer else numbers.Real
    if isinstance(value, kind) and not isinstance(value, bool):
        return value
    raise InputError([f"{what}: expected {'an integer' if integer else 'a number'}, got {type(value).__name__} "
                      f"{value!r:.60}"])


def load_model(model) -> Model:
    """A :class:`~identcheck.io.model.Model` from a TOML file (a Model is returned as it is).

    Raises
    ------
    InputError
        Every problem of the file at once (unknown marker, joint cycle, ...), naming file and line; an argument that
        is neither a Model nor a path, naming what it got.
    """
    return model if isinstance(model, Model) else Model.from_toml(_model_argument(model))


def _model_argument(model):
    """`model` when it is a Model or can name its file, else the InputError of :func:`_path_argument`: checked before
    a verb reads its trial, so that a bad argument is named before a long file is read."""
    if isinstance(model, Model):
        return model
    return _path_argument(model, "model", "a Model or the path of its .toml file")


def _model_with_joints(model, verb: str) -> Model:
    """The model of `verb` (:func:`load_model`), which must have a joint: a model of segments alone is a valid
    plan (``plan`` says every joint of it is identifiable) but leaves ``fit`` and ``diagnose`` nothing to fit.

    Raises
    ------
    InputError
        The model has no joint, naming its file.
    """
    model = load_model(model)
    if not model.joints:
        raise InputError([f"the model has no joint ({len(model.segments)} segment(s), no [joints.*] table): {verb} "
                          "has nothing to fit; add the joints between the segments, or let `identcheck skeleton` "
                          "infer them from the trial"], source=str(model.source))
    return model


def read_trial(trial) -> Trial:
    """A :class:`~identcheck.trial.Trial` from a C3D or TRC file (a Trial is returned as it is):
    markers in mm, shape ``(n_frames, n_markers, 3)``, NaN where occluded.

    Raises
    ------
    InputError
        Unreadable file, unknown extension, or bad content, naming the file.
    """
    from identcheck.trial import Trial   # here, not at the top: a verb that reads no trial (plan) needs no NumPy

    if isinstance(trial, Trial):
        return trial
    return Trial.from_file(_path_argument(trial, "trial", "a Trial or the path of a .c3d or .trc file (an array: "
                                                           "identcheck.Trial(xyz, labels, rate_hz))"))


@_one_blas_thread
def simulate(model, out=None, seed: int = 0, effect: str | None = None, effect_seed: int | None = None,
             **kw) -> Simulation:
    """Simulate `model`, inject `effect` if given, and write the (noisy) trial to `out` (TRC or C3D by
    extension) if given.

    Parameters
    ----------
    model : Model, str or os.PathLike
        The model, or its TOML file.
    out : str or os.PathLike, optional
        ``.trc`` or ``.c3d`` (any case).
    seed : int
    effect : str, optional
        An effect name of :data:`identcheck.effects.registry.NAMES`, injected before writing.
    effect_seed : int, optional
        Seed of the effect's draw; default ``seed + identcheck.effects.registry.SEED_OFFSET``.
    **kw
        Passed to :func:`identcheck.simulate.rigid.simulate`.

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Bad model, bad arguments, an unknown output extension (checked before simulating),
        or an effect the model cannot carry.
    """
    from identcheck.trial import FORMATS

    out_path = None if out is None else Path(_path_argument(out, "out", "the path of a .trc or .c3d file"))
    if out_path is not None and out_path.suffix.lower() not in FORMATS:
        raise InputError([f"unknown trial file extension {out_path.suffix or '(none)'!r} (expected "
                          f"one of {', '.join(FORMATS)})"], source=str(out_path))
    from identcheck.simulate.rigid import simulate as simulate_model

    model = load_model(model)
    if not model.markers:       # a file of frames and no markers: no reader (this one included) takes it
        raise InputError(["the model lists no markers on any segment: a trial of it would hold no data; add "
                          "markers = [...] to its segments"], source=model.source)
    sim = simulate_model(model, seed=seed, **kw)
    if effect is not None:
        from identcheck.effects.registry import SEED_OFFSET, inject_effect   # the effects load only when used
        sim = inject_effect(sim, effect, seed=seed + SEED_OFFSET if effect_seed is None else effect_seed)
    if out_path is not None:
        sim.trial.to_file(out_path)
    return sim


def simulate_file(model_path, out_path, seed: int = 0, effect: str | None = None,
                  effect_seed: int | None = None, **kw) -> Simulation:
    """:func:`simulate` with the output file required."""
    return simulate(model_path, out_path, seed=seed, effect=effect, effect_seed=effect_seed, **kw)


def _frames(trial, frames: str | None):
    """The trial (read if a path), cut to ``frames`` (``START:END`` in the file's numbering) when given."""
    data = read_trial(trial)
    return data.frames(frames) if frames else data


@_one_blas_thread
def fit(model, trial, progress=None, frames: str | None = None, export_markers=None, report=None,
        export_osim=None):
    """Joint parameters of every joint of `model` from `trial`, with uncertainty and excitation checks.

    First the trial is screened for swapped marker labels (a span where two markers' labels are
    exchanged is left out for those two, with a warning), then every joint is fitted as ``identcheck
    fit`` does; every warning is in the result's ``warnings``.

    Parameters
    ----------
    model : Model, str or os.PathLike
    trial : Trial, str or os.PathLike
    progress : callable, optional
        Called with a one-line message per stage.
    frames : str, optional
        ``"START:END"`` in the file's own frame numbers, both included (:meth:`Trial.frames`).
    export_markers : str or os.PathLike, optional
        Also write the trial's markers plus each joint's centre / hinge-axis points as virtual markers to
        this TRC or C3D file (:mod:`identcheck.fit.export`).
    report : str or os.PathLike, optional
        Also write a self-contained HTML page of the fit to this file: the skeleton and its joints in 3-D, each
        marker's residual, every joint's verdict and intervals (:mod:`identcheck.report.html`).
    export_osim : str or os.PathLike, optional
        Also write the fitted skeleton as an OpenSim model (.osim: bodies, ball and pin joints at the fitted
        centres and axes, the markers on their bodies) with OpenSim's own package, the extra
        ``identcheck[osim]`` (:mod:`identcheck.fit.osim`).

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Bad model or trial file, or a model marker missing from the trial.
    """
    from identcheck.fit.result import FitResult
    from identcheck.fit.workflow import fit_trial

    scene = {}

    def keep(fitted_trial, fit, offset):
        scene["fitted"] = True
        if report is not None:
            from identcheck.fit.scene import trial_scene

            scene["scene"] = trial_scene(fitted_trial, fit, offset)
        if export_osim is not None:
            from identcheck.fit.osim import export_osim as write_osim

            write_osim(export_osim, fit, name=Path(str(model.source)).stem or "identcheck")

    _model_argument(model)
    with warnings.catch_warnings(record=True) as read:        # the reader's findings belong in the JSON too
        warnings.simplefilter("always")
        data = _frames(trial, frames)
    model = _model_with_joints(model, "fit")
    if export_osim is not None:
        from identcheck.fit.osim import name_problems

        problems = name_problems(model)
        if problems:
            raise InputError([f"--export-osim {export_osim}: " + p for p in problems], source=model.source)
    planned = _planned_once(model)
    doc = fit_trial(model, data, progress=progress, export=export_markers,
                    on_fit=keep if report is not None or export_osim is not None else None,
                    decided=lambda joints: _certified_unique(planned(), joints))
    doc["warnings"] = _one_units_question([{"kind": warning_kind(w.category), "message": str(w.message)} for w in read
                                           if issubclass(w.category, UserWarning)] + doc["warnings"])
    if not all(j["identifiable"] for j in doc["joints"].values()):
        _certified_identifiability(doc, planned())
    res = FitResult.from_dict(doc)
    if export_osim is not None and not scene.get("fitted"):
        raise InputError([f"--export-osim {export_osim}: no whole-tree fit to export"], source=data.source)
    if report is not None:
        _write_report(report, "fit", res.to_dict(), scene.get("scene"), f"{data.source} (model {model.source})")
    return res


def _planned_once(model):
    """A function returning ``plan``'s joints for `model` (exact ranks, no motion), computed on the first call only:
    ``fit`` asks for it only where its closed forms left a joint undecided or not identifiable (0.02-0.15 s)."""
    kept: list = []

    def planned() -> dict:
        if not kept:
            kept.append(plan(model, motion=False, robust=False, suggest=False).joints)
        return kept[0]
    return planned


def _certified_unique(planned: dict, joints) -> set:
    """Those of `joints` that ``plan``'s joints (`planned`) certify identifiable with one candidate: what ``fit`` judges
    by the likelihood although their closed form's case admits equal twins (:func:`fit_trial`'s ``decided``)."""
    return {j for j in joints if (planned.get(j) or {}).get("identifiable") and planned[j].get("candidates") == 1}


def _certified_identifiability(doc: dict, planned: dict) -> None:
    """Each joint's ``identifiable`` in `doc` (``fit``'s JSON, changed in place) as ``plan`` certifies it for the
    model (the whole tree's exact rank, every joint's points included), where ``fit`` had judged a joint by the case
    its closed form met. The two had disagreed: a joint whose closed form could not start (its points seen as one
    line after two one-marker segments, an ambiguous joint above it) was called not identifiable where ``plan``
    certifies it, and a revolute (2,1) decided by markers two joints beyond was called undecidable. A joint ``plan``
    certifies that ``fit`` could not start says so instead of "not identifiable". Run only when ``fit`` called some
    joint not identifiable (the plan's rank costs 0.02-0.15 s). `planned`: ``plan``'s joints for the model."""
    for name, j in doc["joints"].items():
        certified = bool((planned.get(name) or {}).get("identifiable", j["identifiable"]))
        if certified and not j["identifiable"] and not j["marker_distances"]:
            why = (f"identifiable ({planned[name]['case']}: plan's exact certificate), but no closed form could start "
                   f"it from {j['case']} with markers {j['markers_used'].get('parent_markers')} | "
                   f"{j['markers_used'].get('child_markers')}, so nothing bounds it here; the markers the plan uses "
                   f"are {planned[name].get('uses_virtual_markers') or 'its own'}")
            j["excitation"] = {"ok": False, "reason": why}
            if j.get("practical"):
                j["practical"] = dict(j["practical"], reason=why)
        j["identifiable"] = certified


def _write_report(path, kind: str, doc: dict, scene, title: str, figures: list | None = ()) -> None:
    """The run's HTML page (:mod:`identcheck.report.html`)."""
    import identcheck
    from identcheck.report.html import write_html

    write_html(path, kind, doc, scene, title, identcheck.__version__, figures)


def _evidence_svgs(diag) -> list | None:
    """The diagnosis' evidence figures as SVG for its page, or None when matplotlib is not installed."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return None
    from identcheck.report.diagnose_figures import evidence_svgs

    return evidence_svgs(diag)


@_one_blas_thread
def diagnose(model, trial, progress=None, max_steps: int | None = None, frames: str | None = None,
             export_markers=None, report=None):
    """Where the rigid-joint model and `trial` disagree: the named effects, adopted one at a time while
    they earn their parameters, with the gap before and after each.

    Parameters
    ----------
    model : Model, str or os.PathLike
    trial : Trial, str or os.PathLike
    progress : callable, optional
        Called with a one-line message per stage.
    max_steps : int, optional
        Most effects adopted (default :data:`identcheck.diagnose.workflow.MAX_STEPS`).
    frames : str, optional
        ``"START:END"`` in the file's own frame numbers, both included (:meth:`Trial.frames`).
    export_markers : str or os.PathLike, optional
        Also write the trial's markers plus each joint's centre / hinge-axis points, as the model with the
        adopted effects places them, to this TRC or C3D file (:mod:`identcheck.fit.export`).
    report : str or os.PathLike, optional
        Also write a self-contained HTML page: the skeleton with the adopted effects' fit in 3-D, each marker's
        residual, the effects with the gap each closed, and the joints (:mod:`identcheck.report.html`).

    Returns
    -------
    Diagnosis

    Raises
    ------
    InputError
        Bad files, a model marker missing from or never visible in the trial, or no measurement noise.
    """
    from identcheck.diagnose import workflow

    steps = workflow.MAX_STEPS if max_steps is None else max_steps
    model = _model_with_joints(model, "diagnose")         # (the model is read before the trial, as fit's is)
    with _kept_then_shown() as said:
        data = _frames(trial, frames)
        diag = workflow.diagnose(model, data, progress=progress, max_steps=steps)
        if export_markers is not None:
            from identcheck.fit.export import export_markers as write_markers

            write_markers(export_markers, data, diag.after.fit, diag.offset)
    diag = replace(diag, warnings=tuple(said))
    if report is not None:
        from identcheck.fit.scene import fit_scene

        rows = data.frame_number(range(data.n_frames))
        scene = fit_scene(diag.after.fit, diag.after.data, rows, diag.offset)
        _write_report(report, "diagnose", diag.to_dict(), scene, f"{data.source} (model {diag.ctx.model.source})",
                      _evidence_svgs(diag))
    return diag


@contextmanager
def _kept_then_shown():
    """Every warning said inside, kept as ``{"kind", "message"}`` (:func:`identcheck.errors.warning_kind`; each once,
    in order, a large span asked about once: :func:`_one_units_question`) whatever the caller's warning filters, and
    said again on leaving under the caller's filters (on standard error from the command line): what a verb's JSON
    carries does not depend on them. (Kept as they reached the display, a batch run, which ignores warnings, had
    written diagnose's JSON without its units question.) A DegenerateError raised inside carries them
    (``warnings``), for the degenerate answer's JSON."""
    kept: list = []
    recorded: list = []
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            try:
                yield kept
            except DegenerateError as exc:
                exc.warnings = _as_kept(said)
                raise
            finally:
                recorded = list(said)
                kept[:] = _as_kept(recorded)
    finally:                                 # said again under the caller's filters, an error raised or not
        seen, said_once = set(), {w["message"] for w in kept}
        for w in recorded:
            if (w.category, str(w.message)) not in seen and (
                    str(w.message) in said_once or not issubclass(w.category, UserWarning)):
                seen.add((w.category, str(w.message)))
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _as_kept(said) -> list:
    """The user warnings of a record, as the JSON keeps them (:func:`_kept_then_shown`)."""
    items = [{"kind": warning_kind(w.category), "message": str(w.message)} for w in said
             if issubclass(w.category, UserWarning)]
    return _one_units_question(list({w["message"]: w for w in items}.values()))


def _one_units_question(items: list) -> list:
    """`items` (``{"kind", "message"}``) less the model's large-span question where the trial's reader asked about
    its span already: a file in mm labelled cm is one mistake, said once (:data:`identcheck.io.trc.READ_TOO_LARGE`,
    :data:`identcheck.io.trc.MODEL_TOO_LARGE`)."""
    from identcheck.io.trc import MODEL_TOO_LARGE, READ_TOO_LARGE

    if not any(w["kind"] == "units" and READ_TOO_LARGE in w["message"] for w in items):
        return items
    return [w for w in items if not (w["kind"] == "units" and MODEL_TOO_LARGE in w["message"])]


@_one_blas_thread
def skeleton(trial, out=None, segments=None, root: str | None = None, frames: str | None = None,
             export_markers=None, progress=None):
    """A skeleton from a trial alone: the markers grouped into rigid segments, the tree by the minimum spanning
    tree over pairwise O'Brien joint-fit residuals (O'Brien et al. 2000, section 3.3), each joint's type from its
    motion, written as a model file the other verbs read (``identcheck skeleton``, docs/skeleton.md).

    Parameters
    ----------
    trial : Trial, str or os.PathLike
    out : str or os.PathLike, optional
        The model file (TOML) to write, with each joint's evidence as comments.
    segments : str, os.PathLike or dict, optional
        The grouping when it is known: a segments file (``[segments] NAME = ["M1", ...]``, or a model file) or a
        dict NAME -> markers; then only the tree and the types are inferred.
    root : str, optional
        The root segment, or one of its markers (default: the tree's centre).
    frames : str, optional
        ``"START:END"`` in the file's own frame numbers, both included (:meth:`Trial.frames`).
    export_markers : str or os.PathLike, optional
        A TRC or C3D file for the measured markers beside the articulated model's playback of them (``M.model``)
        and each joint's virtual markers.
    progress : callable, optional
        Called with a one-line message per stage.

    Returns
    -------
    SkeletonResult

    Raises
    ------
    InputError
        A bad trial or segments file, fewer than two markers, a never-visible marker, one rigid body, an unknown
        marker in `segments`, no group of three markers, or a bad root.
    """
    from identcheck.infer.workflow import infer_skeleton
    from identcheck.io.segments import read_segments

    source = "--segments"
    if segments is not None and not isinstance(segments, dict):
        source, segments = str(segments), read_segments(segments)
    return infer_skeleton(_frames(trial, frames), segments=segments, segments_source=source, root=root, out=out,
                          export=export_markers, progress=progress)


def _plan_is_numerical(*args, **kwargs) -> bool:
    """Might this ``plan`` call fit or simulate (practical verdicts, witness searches)? Its verdicts alone are exact
    arithmetic, without SciPy. Options passed by position are not inspected: SciPy is then loaded."""
    return kwargs.get("noise_mm") is not None or bool(kwargs.get("witness")) or len(args) > 1


@functools.partial(_one_blas_thread, with_scipy=_plan_is_numerical)
def plan(model, seed: int = 0, motion: bool = True, robust: bool = True, suggest: bool = True,
         fewest: bool = False, witness: bool = False, progress=None, noise_mm: float | None = None,
         practical_motion: str = "functional", frames: int = capture.FRAMES, max_seconds: float | None = None):
    """Check a marker plan before capture: which joints `model`'s markers identify, how, with how many
    samples, and the fewest markers to add (see :func:`identcheck.plan.analysis.plan_model`).

    With ``noise_mm``, each joint also gets ``practical``: what a capture of ``frames`` frames of
    ``practical_motion`` (a name of :data:`identcheck.fit.predict.MOTIONS`, or a recorded TRC/C3D trial whose
    motion to judge) with that noise would determine (:mod:`identcheck.fit.predict`); and, for a named motion,
    ``practical_suggestions`` ranks one added marker on each segment by the millimetres it would save
    (:mod:`identcheck.fit.marker_value`).

    ``max_seconds`` bounds the motion and robustness analyses together (default
    :data:`identcheck.plan.analysis.ANALYSES_BUDGET_S`), and separately the search for the fewest markers to add and
    the witness searches; what they leave unchecked is listed in ``unfinished``. ``noise_mm`` above
    :data:`identcheck.fit.predict.MAX_NOISE_MM` is refused (no capture system's noise).

    Returns
    -------
    PlanResult
    """
    from identcheck.plan.analysis import plan_model
    from identcheck.plan.result import PlanResult

    if noise_mm is not None:
        _number_argument(noise_mm, "noise_mm")
    _number_argument(seed, "seed", integer=True)
    if noise_mm is not None and capture.frames_problem(frames):
        raise InputError([f"frames {capture.frames_problem(frames)}"])
    m = load_model(model)
    res = plan_model(m, seed=seed, motion=motion, robust=robust, suggest=suggest,
                     fewest=fewest, witness=witness, progress=progress, max_seconds=max_seconds)
    if noise_mm is None:
        return res
    if progress:
        progress(f"predicting practical verdicts: {practical_motion}, {noise_mm} mm noise, {frames} frames")
    if str(practical_motion).lower().endswith((".trc", ".c3d")):
        from identcheck.fit.workflow import fit_trial

        fitted = fit_trial(m, read_trial(practical_motion), progress=progress,
                           decided=lambda joints: _certified_unique(res.joints, joints))["joints"]
        practical = {j: dict(v["practical"], predicted=True, motion=str(practical_motion)) for j, v in fitted.items()}
        extra = {"practical_suggestions_note": "one more marker is valued on a named motion only (a recorded trial's "
                                               "fit is not kept)"}
    else:
        from identcheck.fit.marker_value import marker_value
        from identcheck.fit.predict import noise_free_fit, predict

        fitted = noise_free_fit(m, practical_motion, frames, seed, progress=progress)
        practical = predict(m, noise_mm, practical_motion, frames, seed, fitted=fitted,
                            exact_candidates={j: v["candidates"] for j, v in res.joints.items()})
        best = fitted[1].best
        extra = ({"practical_suggestions": marker_value(m, best.fit, noise_mm, progress)} if best is not None else
                 {"practical_suggestions_note": "no whole-tree fit of the simulated capture to value markers on"})
    doc = res.to_dict()
    for j, p in practical.items():
        if j in doc["joints"]:
            doc["joints"][j]["practical"] = p
    doc.update(extra)
    return PlanResult.from_dict(doc, m.root, {s: seg.markers for s, seg in m.segments.items()})


@functools.partial(_one_blas_thread, with_scipy=False)  # the exact-case solvers need NumPy only
def identify(model, trial, joints=None, frames=None, precision: int | None = None):
    """Every joint `trial`'s samples admit, by the exact-case solvers of Pham et al. (revolute (2,1),
    spherical (3,q), spherical (2,2)), for `joints` of `model` (default: all).

    Parameters
    ----------
    frames : iterable of int, optional
        0-based frames; default every frame where the joint's markers are all visible.
    precision : int, optional
        Decimal digits (mpmath) instead of float64.

    Returns
    -------
    IdentifyResult
    """
    from identcheck.identify import identify as identify_joints

    return identify_joints(load_model(model), read_trial(trial), joints=joints, frames=frames, precision=precision)


@functools.partial(_one_blas_thread, with_scipy=False)  # exact arithmetic and mpmath: no SciPy
def table(seed: int = 0, joints=None, progress=None):
    """The identifiability table: every joint type x markers (p on the parent, q on the child), p, q in 0..3,
    with a certificate per row (``progress``: called with a line of text before each joint type).

    Returns
    -------
    TableResult
    """
    from identcheck.certify.joint_models import JOINTS
    from identcheck.certify.table import table as make_table

    _number_argument(seed, "seed", integer=True)
    if joints is not None:
        joints = [joints] if isinstance(joints, str) else list(joints)
        unknown = [j for j in joints if str(j).lower() not in JOINTS]
        if unknown:
            raise InputError([f"joints: unknown joint type(s) {', '.join(map(repr, unknown))}; known types: "
                              f"{', '.join(JOINTS)}"])
        joints = [str(j).lower() for j in joints]
    return make_table(seed=seed, joints=joints, progress=progress)


@_one_blas_thread
def rank(joint: str, p: int, q: int, samples: int | None = None, seed: int = 0, progress=None):
    """Exact generic rank of the sampled M-matrix of a case over the rationals (``samples`` rows, default
    the number of unknowns; at most :func:`identcheck.certify.exact_rank.distinct_tangents`). ``progress``:
    called with a line of text at most once a second on long runs.

    Returns
    -------
    RankCertificate
    """
    from identcheck.certify.exact_rank import rank as exact_rank

    for value, what in ((p, "p"), (q, "q"), (seed, "seed")) + (((samples, "samples"),) if samples is not None else ()):
        _number_argument(value, what, integer=True)
    return exact_rank(joint, p, q, n_samples=samples, seed=seed, progress=progress)


@_one_blas_thread
def verify(certificate, progress=None):
    """Re-check a saved certificate or table (a path, or its JSON object) from its own data (``progress``:
    called with a line of text as the checks go).

    Returns
    -------
    VerifyResult
        ``ok`` false with the problems when it does not hold.
    """
    from identcheck.certify.verify import verify as verify_certificate

    if not isinstance(certificate, dict):
        _path_argument(certificate, "certificate", "the path of a saved certificate or table, or its JSON object")
    return verify_certificate(certificate, progress=progress)


@_one_blas_thread
def derive(out="derivations/out", regenerate: bool = False):
    """Regenerate every derivation with SymPy, check each against the printed paper, write them as
    Markdown to `out`, and compare the solvers' generated modules (:mod:`identcheck.solve.generated`) with
    a fresh print of the derivations.

    Parameters
    ----------
    regenerate : bool
        Rewrite the generated modules that differ from the fresh print (else a difference makes the
        result not ``ok``), and the derivations' cache the package ships (:mod:`identcheck.certify.seed`).

    Returns
    -------
    DeriveResult
    """
    import dataclasses

    from identcheck.certify import seed
    from identcheck.derive.result import derive_and_write
    from identcheck.solve.generated.writer import sync

    res = derive_and_write(out)
    generated = sync(write=regenerate)
    shipped = dict(seed.write(), written=True) if regenerate else dict(seed.status(), written=False)
    return dataclasses.replace(res, generated=generated, seed=shipped)


def batch(verb: str, inputs, out, model=None, frames=None, noise_mm=None, motion=None, seed: int = 0,
          fast: bool = False, workers: int | None = None, scheduler: str | None = None, dashboard: str = ":8787",
          progress: bool = False):
    """Run ``fit``, ``diagnose`` or ``plan`` over many trials (or models x noise levels x motions) on a Dask
    cluster: one JSON per job in `out` (what ``identcheck VERB ... --json`` prints for it), and the summary
    table ``summary.csv`` / ``summary.parquet`` with one row per job x joint (``identcheck batch``).

    Resumable: a job whose JSON in `out` was made from the same input bytes, settings and identcheck version is
    skipped. A job that fails is an error row with its message; the other jobs go on. Needs the ``batch`` extra
    (``pip install 'identcheck[batch]'``). See docs/batch.md.

    Parameters
    ----------
    verb : {"fit", "diagnose", "plan"}
    inputs : str, os.PathLike or sequence of them
        ``fit`` / ``diagnose``: trial files, globs, folders (every ``.trc`` / ``.c3d`` below them), manifest CSVs
        (``trial,model[,frames]``, paths relative to the manifest), and one ``MODEL.toml`` for the trials not in
        a manifest. ``plan``: model files, globs, folders.
    out : str or os.PathLike
        The output folder (created); nothing is written outside it, and the inputs are only read.
    model : str or os.PathLike, optional
        The model of the trials outside manifests, instead of a ``.toml`` among `inputs`.
    frames : str or int, optional
        ``fit`` / ``diagnose``: ``"START:END"`` in the files' own frame numbers (a manifest row's own range comes
        first). ``plan``: the frames of the predicted capture (default 1000).
    noise_mm, motion : optional
        ``plan`` sweeps: noise levels (``[0.5, 1, 2]`` or ``"0.5,1,2"``) and motions (``"functional,flexion"``,
        or recorded trials); each model is planned at every noise level x motion.
    seed : int
        ``plan``'s seed.
    fast : bool
        ``plan``: skip the robustness and motion analyses (``plan --fast``).
    workers : int, optional
        Worker processes of the local cluster (default: one per CPU, at most one per job to run).
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``) to run on instead of a local cluster; its
        workers must see the input files at the same paths.
    dashboard : str
        Address of the local cluster's dashboard (``":0"``: any free port).
    progress : bool
        Print the dashboard address and a progress bar (counts, rate, ETA) on stderr.

    Returns
    -------
    pandas.DataFrame
        The summary (columns: :data:`identcheck.batch.summary.COLUMNS`), as written to ``out/summary.*``.

    Raises
    ------
    InputError
        Bad inputs (every problem at once; nothing is written), or an unreachable scheduler.
    ImportError
        The ``batch`` extra is not installed.
    """
    from identcheck.batch.runner import run

    return run(verb, inputs, out, verbs={"fit": fit, "diagnose": diagnose, "plan": plan}, model=model,
               frames=frames, noise_mm=noise_mm, motion=motion, seed=seed, fast=fast, workers=workers,
               scheduler=scheduler, dashboard=dashboard, progress=progress)
