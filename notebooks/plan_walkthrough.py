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
# # `identcheck plan`: will these markers identify every joint?
#
# Before a capture session you choose where the markers go. `plan` answers, for every joint of
# the skeleton, whether generic motion recorded with those markers determines the joint (its
# centre, or its hinge axis). It also explains the answer, and if the answer is no, it names
# the fewest markers to add.
#
# - **Verdict.** The exact rank of the whole skeleton's Jacobian, computed over a finite field at a
#   random point, with the probability of a wrong verdict stated.
# - **Explanation.** Pham et al.'s propagation (section V-B): an identified joint centre or hinge
#   serves as virtual markers on both of its segments.
# - **Evidence (`--witness`).** For a joint the plan does not identify, a second skeleton that
#   reproduces every marker of a simulated trial, checked at 50 digits.
#
# Every cell asserts what it shows, so executing this notebook (`tests/notebooks/test_notebooks.py`) is a test.

# %%
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import matplotlib  # noqa: E402

matplotlib.use("Agg")
from IPython.display import Image, display  # noqa: E402

import identcheck  # noqa: E402
from identcheck.plan import analysis as plan  # noqa: E402
from identcheck.plan import witness as plan_witness
from identcheck.certify import tree_rank
from identcheck.plan import witness_search as tree_witness
from identcheck.io.model import Model  # noqa: E402
from identcheck.report.plan_figure import draw  # noqa: E402
from identcheck.report.text import plan_text  # noqa: E402

ROOT = Path(identcheck.__file__).resolve().parents[1]
FIGS = Path(tempfile.mkdtemp(prefix="plan_walkthrough_"))

# %% [markdown]
# ## The 16-marker body of Pham et al.
#
# Three markers sit on the trunk and one on each other link: 14 links, 13 joints. The paper
# argues that every joint can be identified, and the plan agrees, but not for the paper's reason.
# The knees and elbows are settled by the revolute (2,1) case: the hip (or shoulder) centre and one
# thigh marker against one shank marker. By ERRATA E1 and E2 that case alone admits four joints.
# What decides among them is the single foot (or hand) marker beyond the ankle (or wrist). It must
# stay at a fixed distance from a point of the shank, and that rejects the other three joints.
# `identcheck.certify.twin` proves this exactly, on a random rational subject with modular
# arithmetic over every conjugate.

# %%
body = Model.from_toml(ROOT / "examples" / "body16.toml")
result = plan.plan_model(body, robust=False)
print(plan_text(result))
assert result.all_identifiable
knee = result.joints["knee_l"]
assert knee["case"] == "revolute(2,1)" and knee["candidates"] == 1 and knee["rejected_by"]["marker"] == "LANKLE"

# %%
draw(result, FIGS / "body16.png", title="body16")
display(Image(filename=str(FIGS / "body16.png")))

# %% [markdown]
# ## Evidence for "not identifiable": a second skeleton
#
# The sparse leg has three pelvis markers and one marker each on the thigh and the shank. The hip
# is a (3,1) sphere and is identified. The knee is revolute (2,1) on the hip centre. `--witness`
# simulates the plan and builds the other closed-form joint of ERRATA E1, for the whole leg:
#
# 1. The thigh is rolled about the line through the hip centre and its marker, frame by frame.
#    Its two points cannot see that roll.
# 2. The shank is turned about the new hinge.
# 3. Gauss-Newton polishes the result. Then, at 50 digits, every marker of every frame is
#    reproduced, including held-out frames the search never saw.

# %%
leg = Model.from_toml(ROOT / "examples" / "sparse_leg.toml")
result = plan.plan_model(leg, robust=False, motion=False, witness=True)
w = result.joints["knee_r"]["alternative"]
print({k: w[k] for k in ("verified", "quantity", "true", "alternative", "max_marker_error_mm",
                         "held_out_max_marker_error_mm", "frames", "held_out_frames")})
assert w["verified"] and w["max_marker_error_mm"] < 1e-30 and w["held_out_max_marker_error_mm"] < 1e-30
assert abs(w["alternative"] - w["true"]) > 1e-3 * abs(w["true"])

# %% [markdown]
# ## A marker further down tells the candidates apart
#
# Add a foot with one marker, on a ball joint below the shank. The table still gives the knee four
# candidates, but in the whole tree the foot marker, seen through the ankle, must stay at a fixed
# distance from a point fixed in the shank. The knee's twin moves the shank differently and cannot
# keep that distance. The plan now calls the knee identifiable, backed by the exact certificate.
# The whole-tree search agrees: from the twin, Gauss-Newton stalls with markers visibly off.

# %%
with_foot = Model.from_dict({
    "segments": {"pelvis": {"markers": ["LASI", "RASI", "SACR"]}, "thigh": {"markers": ["THI"]},
                 "shank": {"markers": ["TIB"]}, "foot": {"markers": ["TOE"]}},
    "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"},
               "knee": {"type": "revolute", "parent": "thigh", "child": "shank"},
               "ankle": {"type": "spherical", "parent": "shank", "child": "foot"}}})
spec = tree_rank.TreeSpec.from_model(with_foot)
p = plan.analyse(spec)
print(p.joints["knee"]["reason"])
assert p.joints["knee"]["identifiable"] and p.joints["knee"]["rejected_by"]["marker"] == "TOE"

truth, held = plan_witness.simulated_truth(with_foot, spec, 20, seed=2)
st = p.settled["knee"]
search = tree_witness.construct(spec, truth, 20, "knee", "isolated", held_out_truth=held, n_held_out=20,
                                case_points={"knee": (st.parent_points, st.child_points)})
print(f"from the twin, the search stalls with markers {search.closest_miss_mm:.2g} mm off")
assert search.witness is None and search.closest_miss_mm > 0.1

no_toe = spec.without("TOE")
found = plan_witness.witnesses(with_foot, no_toe, plan.analyse(no_toe), seed=2)["knee"]
print("without the foot marker:", "verified" if found["verified"] else "not found")
assert found["verified"]
