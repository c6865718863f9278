# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # `identcheck diagnose`: finding what the rigid-joint model misses
#
# A joint fit assumes two things: every segment is rigid (its markers keep their distances), and
# the segments meet at the declared joints (a ball joint at the hip, a hinge at the knee). Real
# recordings break both: skin slides over bone, a marker gets knocked, labels swap, the knee is
# not a perfect hinge. `diagnose` fits the rigid-joint model, measures how far the markers are
# from it (the **gap**), compares that with what measurement noise alone would leave (the
# **noise floor**), and while the gap is larger, tries a list of named effects and keeps the one
# that explains most of the gap for the parameters it costs.
#
# This notebook hides one effect in a synthetic trial, where the truth is known, and walks
# through what `diagnose` finds. Every cell asserts what it shows, so executing the notebook
# (`tests/notebooks/test_notebooks.py`) is a test.

# %%
import os

# The fits are many small matrix solves: extra BLAS threads cost more than they save.
# This must be set before numpy is loaded.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import json  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import matplotlib  # noqa: E402

matplotlib.use("Agg")  # no display: figures go to a temporary directory and are shown from there
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from IPython.display import Image, display  # noqa: E402

import identcheck  # noqa: E402
from identcheck.report import diagnose_figures as figures  # noqa: E402
from identcheck.bundle.hypothesis import centre_world  # noqa: E402
from identcheck.diagnose.workflow import diagnose  # noqa: E402
from identcheck.effects.registry import inject_effect, true_centre_world  # noqa: E402
from identcheck.io.model import Model  # noqa: E402
from identcheck.simulate.rigid import simulate  # noqa: E402

ROOT = Path(identcheck.__file__).resolve().parents[1]
FIGS = Path(tempfile.mkdtemp(prefix="diagnose_walkthrough_"))


def show(path):
    display(Image(filename=str(path)))


# %% [markdown]
# ## 1. The model and a synthetic trial
#
# `examples/diagnose_leg.toml` is a right leg with three markers on each segment (pelvis, thigh,
# shank), a ball joint at the hip and a hinge at the knee. Three markers per segment are what
# `diagnose` needs: with three, each segment's own pose can be found from its markers alone, so a
# marker that leaves its segment's rigid pattern can be told apart from a joint that misbehaves.
#
# We simulate 1000 frames (10 s at 100 Hz) of random leg motion, with 0.5 mm of white noise on every
# marker coordinate, the kind of noise a good camera system has.

# %%
model = Model.from_toml(ROOT / "examples" / "diagnose_leg.toml")
print({s: list(model.segments[s].markers) for s in model.segments})
print({j: (model.joints[j].type, model.joints[j].parent, model.joints[j].child) for j in model.joints})

N_FRAMES, NOISE_MM, SEED = 1000, 0.5, 1
rigid = simulate(model, n_frames=N_FRAMES, noise_mm=NOISE_MM, seed=SEED)
assert rigid.trial.n_frames == N_FRAMES and rigid.trial.n_markers == 9

# %% [markdown]
# ## 2. Hide one effect
#
# `inject_effect` adds one named effect to the simulated body, at a place and size drawn from the
# seed, and records what it did. Here: **soft tissue**, one marker that moves on its segment as a
# smooth function of the joint angle above it, the way a thigh marker rides on the quadriceps when
# the hip flexes. `diagnose` is not told any of this.

# %%
EFFECT = "soft_tissue"
sim = inject_effect(rigid, EFFECT, seed=SEED)
hidden = sim.settings["effect"]
print("hidden:", hidden["name"], hidden["where"])
print(f"the marker moves up to {hidden['params']['max_displacement_mm']:.1f} mm on its segment")
assert hidden["name"] == EFFECT

# %% [markdown]
# ## 3. Diagnose
#
# `diagnose(model, trial)` does, in order:
#
# 1. **Noise floor.** Two markers on one rigid segment keep their distance, so the frame-to-frame
#    jitter of that distance is measurement noise. From it, the gap that noise alone would leave
#    after a least-squares fit.
# 2. **Rigid-joint fit.** Every segment rigid, every joint as declared, fitted to all frames at
#    once. Its gap is the "gap before".
# 3. **Effects, one at a time.** Each named effect looks at the residuals and proposes where it
#    could act (which marker, segment, joint or frames); each proposal is added to the model and
#    refitted; the one that earns its extra parameters best is kept. This repeats until the gap is
#    consistent with the noise floor (or nothing earns its parameters).

# %%
diag = diagnose(model, sim.trial)
summary = diag.to_dict()
short = {k: summary[k] for k in ("noise_sigma_mm", "noise_floor", "gap_before", "gap_after", "effects")}
print(json.dumps(short, indent=1))
print(f"noise per coordinate: {diag.ctx.noise.sigma_mm:.3f} mm frame to frame "
      f"(simulated {NOISE_MM} mm); whole-trial scatter {diag.ctx.noise.sigma_scatter_mm:.3f} mm")
assert abs(diag.ctx.noise.sigma_mm - NOISE_MM) < 0.1 * NOISE_MM

# %% [markdown]
# The noise estimate recovers the simulated 0.5 mm. The whole-trial scatter is a second estimate
# (from how much each distance varies over the whole trial): it is larger here, because the
# soft-tissue marker's distances to its neighbours change slowly with the hip angle, and that is
# exactly the kind of slow change the frame-to-frame estimate ignores. On a real trial, a scatter
# many times the frame-to-frame noise says the segments deform, or the data were filtered.
#
# The JSON is what `identcheck diagnose MODEL TRIAL --json` prints. Its joints, after the effect is
# modelled:

# %%
for name, j in summary["joints"].items():
    print(name, j["type"], "rms residual", j["rms_residual"], "mm;", "marker distances",
          {m: round(v, 1) for m, v in j["marker_distances"].items()})

# %% [markdown]
# ## 4. Where the residual sits
#
# The residual map shows, for every marker (rows) and frame (columns), how far the measured
# marker is from the model. Before: one row stands out, the soft-tissue marker, and it changes
# smoothly with the motion. After: every row is at the noise level. The bars at the bottom give
# each marker's RMS residual before and after, against the noise (dashed).

# %%
show(figures.residual_map(diag, FIGS / "residuals.png"))

# %% [markdown]
# ## 5. The gap, step by step
#
# The gap of the rigid model, then after each adopted effect, against the noise floor (red). One
# step brings it down to the floor: one effect was hidden, one was found.

# %%
show(figures.gap_steps(diag, FIGS / "gap_per_step.png"))

# %% [markdown]
# ## 6. The evidence
#
# Why `diagnose` called it soft tissue and not, say, a slipped marker: the residual of that marker,
# expressed on its own segment, plotted against the joint angle that drives it. Before, it follows
# the angle (a slip would be a step in time, not a curve in angle); after, it is flat.

# %%
for k, step in enumerate(diag.steps, 1):
    print(f"{k}. {step.name} {step.where}: gap {step.gap_before:.3f} -> {step.gap_after:.3f} mm")
    show(figures.evidence(step, FIGS / f"evidence_{k}.png", diag.first_frame, diag.numbered(step.where)))

# %% [markdown]
# ## 7. Did modelling the effect move the joints back to the truth?
#
# This is the question a biomechanist cares about. An unmodelled soft-tissue marker pulls the fitted
# joints towards a compromise. We compare, frame by frame, the fitted joint with the true one:
#
# * **hip (ball joint):** the distance between the fitted and the true centre;
# * **knee (hinge):** a hinge's centre can slide along its axis without changing anything the
#   markers see, so instead we measure the distance from the true knee centre to the fitted axis
#   line.

# %%
def axis_line(h, joint):
    """Point (F, 3) and unit direction (F, 3) of a fitted hinge in the world, or None if not a hinge."""
    if h.chain.types[joint] != "revolute":
        return None
    parent = h.chain.parent[joint]
    direction = h.fit.seg_R[parent] @ h.fit.state.axis[joint]
    direction = direction / np.linalg.norm(direction, axis=-1, keepdims=True)
    return centre_world(h, joint) + diag.offset, direction     # diagnose fits the trial moved near the origin


def joint_error(h, joint):
    """Per-frame error (mm) of `joint` in hypothesis `h` against the truth (the fit's world moved back by
    ``diag.offset`` into the file's coordinates)."""
    true = true_centre_world(sim, joint)
    line = axis_line(h, joint)
    if line is None:
        return np.linalg.norm(centre_world(h, joint) + diag.offset - true, axis=1)
    point, direction = line
    v = true - point
    return np.linalg.norm(v - np.sum(v * direction, axis=1, keepdims=True) * direction, axis=1)


errors = {(j, which): joint_error(h, j) for j in model.joints
          for which, h in (("before", diag.before), ("after", diag.after))}
for j in model.joints:
    what = "centre to true centre" if model.joints[j].type == "spherical" else "true centre to fitted axis"
    print(f"{j} ({what}): before {np.mean(errors[j, 'before']):.2f} mm, "
          f"after {np.mean(errors[j, 'after']):.2f} mm (mean over frames)")

fig, axes = plt.subplots(1, len(model.joints), figsize=(11, 3.4), sharey=False)
t = np.arange(N_FRAMES) / rigid.trial.rate_hz
for ax, j in zip(axes, model.joints):
    ax.plot(t, errors[j, "before"], lw=0.8, label="rigid-joint model")
    ax.plot(t, errors[j, "after"], lw=0.8, label="with the named effect")
    ax.set_title(f"{j}: " + ("centre error" if model.joints[j].type == "spherical" else "distance to axis"))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mm")
    ax.grid(alpha=0.3)
axes[0].legend(fontsize=8)
fig.tight_layout()
fig.savefig(FIGS / "joint_errors.png", dpi=100)
plt.close(fig)
show(FIGS / "joint_errors.png")

# %% [markdown]
# ## 8. What this example shows
#
# The hidden effect is named first, at the right marker, and once it is modelled the gap is at the
# noise floor: nothing else is left to explain. The joint estimates after modelling it are at
# least as close to the truth as before.

# %%
first = diag.steps[0]
assert first.name == hidden["name"], (first.name, hidden)
assert first.where.get("markers") == hidden["where"]["markers"], (first.where, hidden["where"])
assert diag.gap_after <= 1.5 * diag.noise_floor, (diag.gap_after, diag.noise_floor)
assert diag.gap_after < diag.gap_before
for j in model.joints:
    assert np.mean(errors[j, "after"]) <= np.mean(errors[j, "before"]) + 0.1, j
print(f"named first: {first.name} at {first.where['markers']}; gap {diag.gap_before:.2f} -> "
      f"{diag.gap_after:.2f} mm, floor {diag.noise_floor:.2f} mm")

# %%
import shutil  # noqa: E402

shutil.rmtree(FIGS)  # the notebook leaves nothing behind
