"""What ``identcheck batch`` is given, resolved into jobs before any work.

``fit`` and ``diagnose`` take trials: files, globs (``"trials/**/*.c3d"``), folders (every ``.trc`` / ``.c3d``
below them, hidden files left out) with one model (``MODEL.toml`` among the inputs, or ``model=``), or a manifest
CSV with the columns ``trial,model[,frames]`` (paths relative to the manifest's folder, ``frames`` as
``START:END`` in the file's own numbering like ``fit --frames``). ``plan`` takes model files (paths, globs,
folders of ``.toml``), each swept over noise levels x motions when ``noise_mm`` is given.

Every problem is collected and raised as one :class:`~identcheck.errors.InputError` naming the argument, or the
manifest and its line, so that a typo costs nothing: no cluster is started and nothing is written. A file that
exists but cannot be read as a trial is not a problem here: its job fails on its own, as an error row.
"""
from __future__ import annotations

import csv
import glob
import hashlib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from identcheck.errors import InputError
from identcheck.plan import capture
from identcheck.trial import FORMATS, frame_range

VERBS = ("fit", "diagnose", "plan")
"""The verbs a batch runs."""
MODEL_SUFFIX = ".toml"
MANIFEST_SUFFIX = ".csv"
MANIFEST_COLUMNS = ("trial", "model", "frames")
"""A manifest's columns; ``trial`` and ``model`` are required."""
GLOB_CHARS = "*?["
DEFAULT_MOTION = "functional"
"""As ``identcheck plan --motion``."""


@dataclass(frozen=True)
class Job:
    """One run of a verb: what a worker needs, and the name of its JSON in the output folder.

    Attributes
    ----------
    verb : str
        ``fit``, ``diagnose`` or ``plan``.
    name : str
        Unique within the batch, the same in every run of it: the job's JSON is ``OUT/<name>.json``.
    model : str
        The model file (absolute path: a worker of a remote cluster may have another working directory).
    trial : str or None
        The trial file (absolute), None for ``plan``.
    settings : Mapping
        Everything besides the input files that the verb's answer depends on (``verb``, ``frames``; for
        ``plan`` also ``seed``, ``fast``, ``noise_mm``, ``motion``), JSON values only: hashed by
        :func:`settings_hash`.
    """

    verb: str
    name: str
    model: str
    trial: str | None
    settings: Mapping

    @property
    def settings_hash(self) -> str:
        return settings_hash(self.settings)

    @property
    def input_files(self) -> tuple:
        """The files whose bytes the answer depends on: the model, then the trial (``plan``: a recorded motion)."""
        motion = self.settings.get("motion")
        extra = [motion] if self.verb == "plan" and motion and _is_trial(motion) else []
        return tuple([self.model] + ([self.trial] if self.trial else []) + extra)


def settings_hash(settings: Mapping) -> str:
    """SHA-256 (hex) of the settings' canonical JSON (keys sorted, no spaces): equal iff the settings are.

    :func:`fit_settings` and :func:`plan_settings` build settings with one type per key (floats as floats), so
    that equal settings are equal dicts."""
    text = json.dumps(dict(settings), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def fit_settings(verb: str, frames: str | None) -> dict:
    """The settings of a ``fit`` or ``diagnose`` job: the verb and the frame range (None: every frame)."""
    return {"verb": verb, "frames": None if frames in (None, "") else str(frames).strip()}


def plan_settings(seed: int, fast: bool, noise_mm: float | None, motion: str | None, frames: int | None) -> dict:
    """The settings of a ``plan`` job. Without a noise level the motion and its frames do not enter the answer,
    so they are None (changing them re-runs nothing)."""
    practical = noise_mm is not None
    return {"verb": "plan", "seed": int(seed), "fast": bool(fast),
            "noise_mm": float(noise_mm) if practical else None,
            "motion": str(motion or DEFAULT_MOTION) if practical else None,
            "frames": int(frames or capture.FRAMES) if practical else None}


def resolve(verb: str, inputs, model=None, frames=None, noise_mm=None, motion=None, seed: int = 0,
            fast: bool = False) -> list:
    """The jobs of a batch, in input order, each once.

    Parameters
    ----------
    verb : str
        One of :data:`VERBS`.
    inputs : str, os.PathLike or sequence of them
        ``fit`` / ``diagnose``: trial files, globs, folders and manifest CSVs, and at most one ``.toml`` model
        for the trials that are not in a manifest (the CONTRACT's ``batch VERB MODEL TRIALS...``).
        ``plan``: model files, globs and folders.
    model : str or os.PathLike, optional
        The model of the trials outside manifests (instead of a ``.toml`` among `inputs`); for ``plan``, one
        more model.
    frames : str or int, optional
        ``fit`` / ``diagnose``: ``"START:END"`` for every trial whose manifest row gives none. ``plan``: frames of
        the predicted capture (default 1000).
    noise_mm : float, str or sequence, optional
        ``plan``: noise levels to sweep (``"0.5,1,2"`` or ``[0.5, 1, 2]``); None: the plan alone.
    motion : str or sequence, optional
        ``plan``: motions to sweep (names of ``identcheck plan --motion``, or recorded trials); default functional.
    seed : int
    fast : bool
        ``plan``: skip the per-marker robustness and motion analyses (``plan --fast``).

    Returns
    -------
    list of Job

    Raises
    ------
    InputError
        Every problem at once: unknown verb, a path that is not there, a glob that matches nothing, a folder
        without trials, no model or two, a manifest row without a trial or model (naming the CSV line), a bad
        frame range, noise level or motion.
    """
    if verb not in VERBS:
        raise InputError([f"batch verb {verb!r}: one of {', '.join(VERBS)}"])
    items = [str(i) for i in ([inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs or []))]
    problems: list = []
    specs = _plan_jobs(items, model, frames, noise_mm, motion, seed, fast, problems) if verb == "plan" else \
        _trial_jobs(verb, items, model, frames, problems)
    if not problems and not specs:
        problems.append("no jobs: give trials (files, globs, folders) and a model, or a manifest CSV"
                        if verb != "plan" else "no jobs: give model files (.toml), globs or folders")
    if problems:
        raise InputError(problems)
    return _named(verb, specs)


# ------------------------------------------------------------------------------------- fit, diagnose
def _trial_jobs(verb, items, model, frames, problems) -> list:
    """(model, trial, settings) of every trial, manifests' rows first in their order, then the rest."""
    models = [i for i in items if _suffix(i) == MODEL_SUFFIX]
    manifests = [i for i in items if _suffix(i) == MANIFEST_SUFFIX]
    trial_specs = [i for i in items if i not in models and i not in manifests]
    if frames not in (None, ""):
        _check_frames(str(frames), "--frames", problems)
    if model is not None and models:
        problems.append(f"the model is given twice ({model} and {', '.join(models)}): give it once")
    elif len(models) > 1:
        problems.append(f"one model for the trials of files, globs and folders ({', '.join(models)} given); map "
                        "trials to models with a manifest CSV (trial,model[,frames])")
    the_model = model if model is not None else (models[0] if models else None)
    if the_model is not None and not Path(the_model).is_file():
        problems.append(f"model {the_model}: no such file")
    rows = []
    for m in manifests:
        rows += _manifest(m, problems)
    found = _files(trial_specs, FORMATS, "trial (.trc, .c3d), model (.toml) or manifest (.csv)", problems)
    if found and the_model is None:
        problems.append("trials without a model: give MODEL.toml (or --model FILE) before them, or map trials to "
                        "models with a manifest CSV (trial,model[,frames])")
    rows += [(str(the_model), t, None) for t in found]
    specs, seen = [], set()
    for m, t, f in rows:
        settings = fit_settings(verb, f if f else frames)
        key = (os.path.realpath(m), os.path.realpath(t), settings["frames"])
        if key not in seen:
            seen.add(key)
            specs.append((os.path.abspath(m), os.path.abspath(t), settings))
    return specs


def _manifest(path, problems) -> list:
    """(model, trial, frames) of each row of the manifest CSV at `path`; problems name the file and line."""
    where = Path(path)
    if not where.is_file():
        problems.append(f"manifest {path}: no such file")
        return []
    base = where.parent
    rows = []
    try:
        with open(where, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = None
            for cells in reader:
                line = reader.line_num
                if not any(c.strip() for c in cells) or cells[0].lstrip().startswith("#"):
                    continue
                if header is None:
                    header = [c.strip().lower() for c in cells]
                    unknown = [c for c in header if c not in MANIFEST_COLUMNS]
                    lacking = [c for c in ("trial", "model") if c not in header]
                    if unknown or lacking or len(set(header)) != len(header):
                        problems.append(f"{path}, line {line}: the header must name the columns trial,model[,frames] "
                                        f"(found {','.join(header)})")
                        return []
                    continue
                if len(cells) > len(header):
                    problems.append(f"{path}, line {line}: {len(cells)} cells, the header names {len(header)}")
                    continue
                row = dict(zip(header, (c.strip() for c in cells)))
                trial, model, frames = row.get("trial", ""), row.get("model", ""), row.get("frames", "")
                bad = False
                for col, value, suffixes in (("trial", trial, FORMATS), ("model", model, (MODEL_SUFFIX,))):
                    if not value:
                        problems.append(f"{path}, line {line}: no {col}")
                        bad = True
                        continue
                    full = base / value
                    if not full.is_file():
                        problems.append(f"{path}, line {line}: {col} {value}: no such file ({full})")
                        bad = True
                    elif full.suffix.lower() not in suffixes:
                        problems.append(f"{path}, line {line}: {col} {value}: not a {col} file "
                                        f"({', '.join(suffixes)})")
                        bad = True
                if frames and not _check_frames(frames, f"{path}, line {line}: frames", problems):
                    bad = True
                if not bad:
                    rows.append((str(base / model), str(base / trial), frames or None))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        problems.append(f"manifest {path}: cannot be read ({exc})")
        return []
    if not rows and not any(p.startswith(f"{path},") for p in problems):
        problems.append(f"manifest {path}: no rows")
    return rows


def _check_frames(spec: str, what: str, problems) -> bool:
    """True when `spec` is ``START:END`` (either end may be left out); else a problem naming `what`."""
    try:
        start, end = frame_range(spec)
    except ValueError:
        problems.append(f"{what} {spec!r}: expected START:END in the file's own frame numbers")
        return False
    if start is not None and end is not None and end < start:
        problems.append(f"{what} {spec!r}: END before START")
        return False
    return True


# ------------------------------------------------------------------------------------------------ plan
def _plan_jobs(items, model, frames, noise_mm, motion, seed, fast, problems) -> list:
    """(model, None, settings) for every model x noise level x motion."""
    models = _files(items + ([str(model)] if model is not None else []), (MODEL_SUFFIX,), "model (.toml)", problems)
    noises = _numbers(noise_mm, "--noise-mm", problems)
    motions = _words(motion) or [DEFAULT_MOTION]
    n_frames = capture.FRAMES
    if frames not in (None, ""):
        try:
            n_frames = int(str(frames).strip())
        except ValueError:
            n_frames = str(frames)
        if capture.frames_problem(n_frames):
            problems.append(f"--frames {capture.frames_problem(n_frames)} (plan takes the number of frames of the "
                            "capture it predicts)")
            n_frames = capture.FRAMES            # the jobs are not run: the problems are raised first
    if noises is None:
        if motion not in (None, "", []):
            problems.append("--motion applies with --noise-mm (the practical verdicts); give both")
        return [(os.path.abspath(m), None, plan_settings(seed, fast, None, None, None)) for m in models]
    from identcheck.fit.predict import MOTIONS, motion_problem

    checked = []
    for m in motions:
        if motion_problem(m):
            problems.append(motion_problem(m))
        else:
            checked.append(m if m in MOTIONS else os.path.abspath(m))
    return [(os.path.abspath(m), None, plan_settings(seed, fast, s, mo, n_frames))
            for m in models for s in noises for mo in checked]


def _numbers(value, what, problems):
    """Positive floats from ``"0.5,1,2"``, a number or a sequence (None when `value` is None)."""
    if value is None or value == "":
        return None
    out = []
    for word in _words(value):
        try:
            x = float(word)
            if not x > 0 or x == float("inf"):
                raise ValueError
            out.append(x)
        except (TypeError, ValueError):
            problems.append(f"{what} {word}: a positive noise level in mm")
    return sorted(set(out), key=out.index)


def _words(value) -> list:
    """A comma-separated string, a scalar or a sequence as a list of stripped strings (empty ones left out)."""
    if value is None:
        return []
    parts = str(value).split(",") if isinstance(value, str) else \
        [str(v) for v in (value if isinstance(value, (list, tuple)) else [value])]
    return [p.strip() for p in parts if p.strip()]


# ------------------------------------------------------------------------------------------ shared
def _files(specs, suffixes, what, problems) -> list:
    """Every file that `specs` (paths, globs, folders) name with one of `suffixes`, once each (by real path),
    in order: a folder's files sorted, below it at any depth, hidden ones (``.name``) left out."""
    out, seen = [], set()

    def take(path: Path):
        real = os.path.realpath(path)
        if real not in seen:
            seen.add(real)
            out.append(str(path))

    def broken(paths) -> None:
        """Links among `paths` whose target is missing: named, never skipped in silence."""
        for f in paths:
            if os.path.islink(f) and not os.path.exists(f):
                problems.append(f"{f}: a link to {os.readlink(f)}, which does not exist")

    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            named = [f for f in p.rglob("*") if f.suffix.lower() in suffixes
                     and not any(part.startswith(".") for part in f.relative_to(p).parts)]
            broken(named)
            found = sorted(f for f in named if f.is_file())
            if not found and not any(os.path.islink(f) for f in named):
                problems.append(f"{spec}: a folder without {what.split(' ')[0]} files ({', '.join(suffixes)})")
            for f in found:
                take(f)
        elif p.is_file():
            if p.suffix.lower() in suffixes:
                take(p)
            else:
                problems.append(f"{spec}: not a {what}")
        elif any(c in spec for c in GLOB_CHARS):
            named = [f for f in glob.glob(spec, recursive=True) if Path(f).suffix.lower() in suffixes]
            broken(named)
            found = sorted(Path(f) for f in named if os.path.isfile(f))
            if not found and not any(os.path.islink(f) for f in named):
                problems.append(f"{spec}: no {what.split(' ')[0]} file ({', '.join(suffixes)}) matches")
            for f in found:
                take(f)
        elif os.path.islink(spec):
            broken([spec])
        else:
            problems.append(f"{spec}: no such file or folder")
    return out


def _suffix(path: str) -> str:
    return Path(path).suffix.lower()


def _is_trial(path: str) -> bool:
    return _suffix(str(path)) in FORMATS


def _slug(text: str) -> str:
    """`text` as a safe file-name part: runs of other characters than letters, digits, ``.+-`` become ``_``."""
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", text).strip("._") or "job"


def _named(verb, specs) -> list:
    """Jobs with names from their trial, model and settings, made unique by a short hash where two coincide."""
    def base(model, trial, s):
        if verb == "plan":
            name = Path(model).stem
            if s["noise_mm"] is not None:
                motion = Path(s["motion"]).name if _is_trial(s["motion"]) else s["motion"]
                name += f"--noise{s['noise_mm']:g}mm--{motion}"
        else:
            name = f"{Path(trial).name}--{Path(model).stem}"
            if s["frames"]:
                name += f"--frames{s['frames'].replace(':', '-')}"
        return _slug(name)

    names = [base(*spec) for spec in specs]
    jobs = []
    for (model, trial, s), name in zip(specs, names):
        if names.count(name) > 1:
            ident = json.dumps([model, trial, s], sort_keys=True)
            name = f"{name}-{hashlib.sha256(ident.encode()).hexdigest()[:8]}"
        jobs.append(Job(verb=verb, name=f"{name}.{verb}", model=model, trial=trial, settings=s))
    return jobs
