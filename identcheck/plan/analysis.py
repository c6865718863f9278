"""Check a marker plan before capture: which joints the markers identify, how, and the fewest markers to add.

Two layers (issue 7):

- *The verdict* is the whole tree's (:mod:`identcheck.certify.tree_rank`): a joint is locally identifiable
  when its gauge-invariant quantities are determined by the exact Jacobian of all markers over
  enough generic frames. That sees what per-joint reasoning cannot — joints that share an unknown
  motion can be identifiable together and not alone.
- *The explanation* is Pham et al.'s section V-B: propagate through the tree to a fixed point. A
  joint is settled by the identifiability table's case for the points its two segments carry,
  real markers or virtual ones (an identified centre is one point on both segments, a hinge two),
  from the root outwards and from the leaves inwards. The case's candidate count says whether the
  joint is unique; a joint that depends on virtual markers of a joint with several candidates
  inherits them (at most the product).

A joint is ``identifiable`` only when the explanation settles it with one candidate through
uniquely identified joints; ``local`` is the whole tree's verdict. The explanation never claims
more than the whole tree (checked on every plan: :class:`PlanInconsistency` otherwise).

A segment without markers (a trunk, a head) is judged by what the data determine on it: a joint there
is measured against the centres of its neighbours that the whole tree places relative to each other,
so a neck whose head carries no marker is the neck's undetermined quantity, not the shoulders' and
hips' (:func:`identcheck.certify.tree_rank.judged_points`; JSON ``undetermined`` and, per joint,
``undetermined_neighbours``).

The fewest markers to add (:func:`fewest_markers`) are minimal for the whole-tree rank: after them every
joint is locally identifiable and none is left several candidates by its case (:attr:`Plan.passes`), and
every plan with fewer added markers, on any segment, was checked to fail. Joints locally identifiable only
together pass with their candidates uncounted; the fewest markers for the propagation to prove every
joint unique are reported beside them (``suggestions_unique``) when they differ.
"""
from __future__ import annotations

import copy
import functools
import itertools
import json
import math
from dataclasses import dataclass, field
from importlib import resources

from identcheck.certify import tree_rank
from identcheck.progress import Progress
from identcheck.certify import twin as twin_certificate
from identcheck.io.atomic import atomic_write
from identcheck.plan import windows as plan_windows
from identcheck.plan.result import PlanResult

MAX_SUGGESTED = 6          # extra markers searched exhaustively (fewest first)
MAX_RANK_CHECKS = 400      # whole-tree ranks the fewest-marker search may ask about plans below the propagation's fix


class PlanInconsistency(RuntimeError):
    """The propagation settled a joint the whole-tree rank says is not locally identifiable (a bug)."""


# -- the identifiability table, as plan needs it --------------------------------------------------------
def table_summary() -> dict:
    """(type, p, q) -> row of ``identcheck table`` (identifiable, local, candidates, min_samples), p, q ≤ 3.

    Read from the package's copy (``identcheck/data/table_summary.json``, written by
    :func:`write_table_summary` from :func:`identcheck.certify.table.table`; a test recomputes it).
    """
    text = resources.files("identcheck").joinpath("data/table_summary.json").read_text(encoding="utf-8")
    return {(r["joint"], r["p"], r["q"]): r for r in json.loads(text)["cases"]}


def write_table_summary(path, seed: int = 0) -> dict:
    """Recompute the certified table (revolute, spherical) and keep the columns plan reads."""
    from identcheck.certify.table import table

    doc = table(seed=seed, joints=tree_rank.TYPES)
    keep = ("joint", "p", "q", "identifiable", "local", "candidates", "min_samples")
    out = {"format": "identcheck.table-summary/1", "seed": seed,
           "cases": [{k: c[k] for k in keep} for c in doc.cases]}
    atomic_write(path, json.dumps(out, indent=1) + "\n")
    return out


# -- the explanation: propagation to a fixed point --------------------------------------------------------
@dataclass
class Settled:
    """How the propagation settled one joint."""

    case: str
    p: int
    q: int
    parent_points: list
    child_points: list
    virtual: list                   # virtual markers among them
    case_candidates: int
    candidates: int                 # including those inherited from the joints whose virtual markers it uses
    case_min_samples: int
    depends_on: list                # joints whose virtual markers it uses
    step: int                       # propagation round (1 = from real markers only)
    rejected_by: dict | None = None  # the marker beyond another joint that rejects the case's other candidates


def far_marker(spec: tree_rank.TreeSpec, name: str, one_side: str, one_points=()) -> dict | None:
    """A real marker beyond another joint k of ``one_side`` (the one-point segment of a revolute (2,1)):
    it stays at a fixed distance from k's centre, a point fixed in that segment, which rejects the case's
    other candidates (:mod:`identcheck.certify.twin`). Not when the case's own point on ``one_side``
    is k's centre or on k's axis (``one_points``): the far marker then keeps its distance in every
    candidate's frame."""
    attached = ([spec.parent_joint[one_side]] if one_side in spec.parent_joint else []) + spec.children[one_side]
    for k, kind, par, chi in attached:             # in the spec's order: a segment's parent joint comes first
        if any(str(pt).startswith(k + ".") for pt in one_points):
            continue
        if k != name:
            far = chi if one_side == par else par
            if spec.markers[far]:
                return {"marker": spec.markers[far][0], "segment": far, "joint": k, "joint_type": kind}
    return None


@functools.lru_cache(maxsize=None)
def _twin_certificate_once(far_joint: str) -> dict:
    return twin_certificate.certify(0, far_joint)


def _twin_certificate(far_joint: str) -> dict:
    """The twin certificate for a far marker beyond a ``far_joint`` (:func:`identcheck.certify.twin.certify`,
    seed 0): exact and deterministic, so proved once per process and handed out as a fresh copy."""
    return copy.deepcopy(_twin_certificate_once(far_joint))


def _count(points: list) -> int:
    """Known points of a segment for the table, capped at 3 (an axis gives two, collinear points)."""
    return min(len(points), 3)


def propagate(spec: tree_rank.TreeSpec, rows: dict) -> dict:
    """Pham V-B: settle joints whose segments carry enough known points; add their virtual markers; repeat.

    Unique cases are taken first, to a fixed point; only when none is left is a locally identifiable
    case with several candidates taken (its virtual markers carry the ambiguity down). A joint settled
    ambiguously is settled again if more virtual markers later give it a case with fewer candidates.
    """
    known = {s: list(ms) for s, ms in spec.markers.items()}
    origin: dict = {}                # virtual marker -> joint
    settled: dict = {}
    step = 0

    def best(name, kind, par, chi):
        P = [m for m in known[par] if origin.get(m) != name]
        C = [m for m in known[chi] if origin.get(m) != name]
        p, q = _count(P), _count(C)
        row = rows[(kind, p, q)]
        if not row["local"]:
            return None
        P, C = P[:3], C[:3]
        virt = [m for m in P + C if m in origin]
        deps = sorted({origin[m] for m in virt})
        inherited = math.prod(settled[d].candidates for d in deps) if deps else 1
        own, rejected = row["candidates"], None
        if kind == "revolute" and own > 1 and (p, q) in ((2, 1), (1, 2)):
            rejected = far_marker(spec, name, chi if (p, q) == (2, 1) else par, C if (p, q) == (2, 1) else P)
            if rejected is not None:
                cert = _twin_certificate(rejected["joint_type"])
                if cert["certified"]:
                    own, rejected = 1, dict(rejected, certificate=cert)
                else:
                    rejected = None
        return Settled(f"{kind}({p},{q})", p, q, P, C, virt, row["candidates"], own * inherited,
                       row["min_samples"], deps, step, rejected)

    def settle(name, kind, par, chi, st):
        fresh = name not in settled
        settled[name] = st
        if fresh:
            pts = [f"{name}.centre"] if kind == "spherical" else [f"{name}.axis[0]", f"{name}.axis[1]"]
            for seg in (par, chi):
                for v in pts:
                    known[seg].append(v)
                    origin[v] = name

    while True:
        step += 1
        changed = False
        for unique_only in (True, False):
            for name, kind, par, chi in spec.joints:
                old = settled.get(name)
                if old is not None and old.candidates == 1:      # cannot improve
                    continue
                st = best(name, kind, par, chi)
                if st is None or (unique_only and st.candidates > 1):
                    continue
                if old is None or st.candidates < old.candidates:
                    settle(name, kind, par, chi, st)
                    changed = True
            if changed:
                break
        if not changed:
            return settled


# -- the plan ----------------------------------------------------------------------------------------------
@dataclass
class Plan:
    """Verdict and explanation for every joint of a marker plan."""

    spec: tree_rank.TreeSpec
    rank: tree_rank.TreeRank
    settled: dict
    joints: dict = field(default_factory=dict)     # name -> contract dict

    @property
    def local_joints(self) -> list:
        """The joints the whole tree leaves locally identifiable."""
        return [n for n, j in self.joints.items() if j["local"]]

    @property
    def all_identifiable(self) -> bool:
        return all(j["identifiable"] for j in self.joints.values())

    @property
    def all_local(self) -> bool:
        return all(j["local"] for j in self.joints.values())

    @property
    def passes(self) -> bool:
        """The target of the fewest-marker suggestions: every joint locally identifiable (whole-tree rank) and
        none settled by a case that leaves it several candidates. A joint locally identifiable only through
        the whole tree passes: its candidates are not counted, and no marker is known to be needed."""
        return all(j["local"] and j["candidates"] in (None, 1) for j in self.joints.values())


def _set_aside_text(jr) -> str:
    """What a joint was not judged against: undetermined centres of its neighbours on a segment without
    markers, which belong to those joints' verdicts."""
    if not jr.set_aside:
        return ""
    by_seg: dict = {}
    for a in jr.set_aside:
        by_seg.setdefault(a["segment"], []).append(a["joint"])
    judged = {p.segment: [p.name for p in pts] for pts in jr.points for p in pts}
    parts = [f"on {seg} (no markers) it is judged against the centres the data determine there "
             f"({', '.join(judged.get(seg, [])) or 'none'}); where the centre of {', '.join(js)} lies on {seg} "
             f"is not determined, and that belongs to the verdict of {', '.join(js)}, not to this one's"
             for seg, js in by_seg.items()]
    return "; " + "; ".join(parts)


def _bare_below(spec, chi: str) -> bool:
    """No marker on ``chi`` or on any segment below it."""
    return not any(spec.markers[s] for s in _subtree(spec, chi))


def _subtree(spec, seg: str) -> list:
    """``seg`` and every segment below it."""
    out, todo = [], [seg]
    while todo:
        s = todo.pop()
        out.append(s)
        todo += [j[3] for j in spec.children[s]]
    return out


def _reason(spec, name, kind, par, chi, jr, st) -> str:
    """The joint's ``reason``: how it was settled (or why not), then any undetermined neighbours it was not
    judged against."""
    return _explain(spec, name, kind, par, chi, jr, st) + _set_aside_text(jr)


def _explain(spec, name, kind, par, chi, jr, st) -> str:
    """Why the joint has its verdict: the propagation's case, the whole tree's shared motion, or what the
    whole tree leaves undetermined."""
    np_, nc = len(spec.markers[par]), len(spec.markers[chi])
    if st is not None:
        via = f" with virtual markers {', '.join(st.virtual)}" if st.virtual else ""
        txt = (f"settled by {st.case}: {', '.join(st.parent_points) or '-'} on {par} | "
               f"{', '.join(st.child_points) or '-'} on {chi}{via}")
        if st.rejected_by is not None:
            r = st.rejected_by
            txt += (f"; {st.case} alone admits {st.case_candidates} joints (mirror images count), but marker "
                    f"{r['marker']} on {r['segment']}, beyond {r['joint_type']} joint {r['joint']}, must stay at a "
                    f"fixed distance from a point of {chi if st.q == 1 else par}, and that rejects the other "
                    f"{st.case_candidates - 1} (exact certificate, identcheck.certify.twin)")
            txt += "; unique" if st.candidates == 1 else (f"; it inherits the {st.candidates} candidates of "
                                                          f"{', '.join(st.depends_on)} (at most)")
        elif st.case_candidates > 1:
            txt += (f"; {st.case} admits {st.case_candidates} joints that explain generic data equally well (mirror "
                    "images count), so it is locally, not uniquely, identifiable")
        elif st.candidates > 1:
            txt += (f"; it inherits the {st.candidates} candidates of {', '.join(st.depends_on)} (at most; whether "
                    "markers further down tell them apart is not decided here)")
        else:
            txt += "; unique"
        return txt
    if jr.local:
        return (f"locally identifiable only through the whole tree: with its own markers ({kind}({min(np_, 3)},"
                f"{min(nc, 3)}) on {par} | {chi}) and any virtual markers the propagation finds, no table case "
                "settles it, but the segments share unknown motion with other joints that pins it; how many "
                "candidates generic data admit is not known")
    if not jr.quantities:
        return (f"nothing measures it: {chi if not spec.markers[chi] else par} carries no markers and no other ball "
                "joint to measure the joint against")
    missing = ", ".join(jr.undetermined[:4]) + (" ..." if len(jr.undetermined) > 4 else "")
    what = "centre" if kind == "spherical" else "hinge"
    bare = (f"; nothing on {chi} or below it carries a marker, so nothing measures where {name}'s {what} is"
            if _bare_below(spec, chi) else "")
    return (f"not identifiable: {kind}({min(np_, 3)},{min(nc, 3)}) with the markers of {par} | {chi} (and any "
            f"virtual markers) is not locally identifiable (see `identcheck table`), and the whole tree leaves "
            f"{missing} undetermined{bare}; add markers (see suggestions)")


def analyse(spec: tree_rank.TreeSpec, rows: dict | None = None, field_kind: str = "GFp", seed: int = 0,
            warm_frames: int = 0, search_min_frames: bool = True, progress=None) -> Plan:
    """Whole-tree verdict plus propagation explanation for one marker plan (``warm_frames``,
    ``search_min_frames``: see :func:`identcheck.certify.tree_rank.analyse`; a variant ranked only for its
    verdicts passes ``search_min_frames=False``, and its ``min_samples`` are then not reported)."""
    rows = rows or table_summary()
    rank = tree_rank.analyse(spec, field_kind, seed, warm_frames=warm_frames, search_min_frames=search_min_frames,
                             progress=progress)
    settled = propagate(spec, rows)
    plan = Plan(spec, rank, settled)
    for name, kind, par, chi in spec.joints:
        jr, st = rank.joints[name], settled.get(name)
        if st is not None and not jr.local:
            raise PlanInconsistency(f"joint {name}: propagation settled it by {st.case} but the whole-tree rank "
                                    f"leaves {jr.undetermined} undetermined")
        identifiable = st is not None and st.candidates == 1
        min_samples = None
        if jr.local:
            min_samples = max(jr.min_frames, st.case_min_samples if st else 0)
        plan.joints[name] = {
            "type": kind, "parent": par, "child": chi,
            "identifiable": identifiable, "local": jr.local,
            "candidates": (st.candidates if st else None),
            "case": st.case if st else f"{kind}({_count(spec.markers[par])},{_count(spec.markers[chi])})",
            "min_samples": min_samples,
            "uses_virtual_markers": list(st.virtual) if st else [],
            "settled_by": ("propagation" if st else ("whole tree (shared motion)" if jr.local else None)),
            "jointly_only": bool(jr.local and st is None),
            "depends_on": list(st.depends_on) if st else [],
            "step": st.step if st else None,
            "rejected_by": ({k: v for k, v in st.rejected_by.items() if k != "certificate"}
                            if st and st.rejected_by else None),
            "reason": _reason(spec, name, kind, par, chi, jr, st),
        }
        if jr.set_aside:
            plan.joints[name]["undetermined_neighbours"] = [dict(a) for a in jr.set_aside]
    return plan


# -- motion, robustness, suggestions ---------------------------------------------------------------------
ANALYSES_BUDGET_S = 30.0
"""Seconds the optional per-joint and per-marker analyses (motion, robustness) may take together by default
(``plan --max-seconds``): each variant is a whole-tree rank, so their cost grows with the model's size; past the
budget the plan says which joints and markers were not analysed (``unfinished``) instead of running on."""


class Budget:
    """A deadline shared by the optional analyses, with a progress line per variant (throttled to one a second)."""

    def __init__(self, seconds: float | None, progress=None):
        self.seconds = ANALYSES_BUDGET_S if seconds is None else float(seconds)
        self._line = Progress(progress)
        self.skipped: dict = {}

    def spent(self) -> bool:
        return self._line.elapsed > self.seconds

    def tick(self, what: str, k: int, n: int) -> None:
        self._line(lambda: f"{what}: {k} of {n} ({self._line.elapsed:.0f} s of at most {self.seconds:g} s)",
                   force=k == n)


def motion_needed(spec: tree_rank.TreeSpec, plan: Plan, seed: int = 0, budget: Budget | None = None,
                  windows: plan_windows.Windows | None = None) -> dict:
    """For each locally identifiable joint, the joints whose motion must be exercised: held at one angle in
    every frame, they would leave it undetermined (whole-tree verdicts with that joint frozen, from the
    smallest windows that decide them: :mod:`identcheck.plan.windows`). Joints whose freezing the budget left
    unchecked are listed in ``budget.skipped["motion_needed"]``."""
    budget = budget or Budget(float("inf"))
    windows = windows or plan_windows.Windows(spec, plan.local_joints, plan.rank.frames, seed)
    need = {n: [] for n in plan.joints}
    names = [j[0] for j in spec.joints]
    for k, name in enumerate(names):
        if budget.spent():
            budget.skipped["motion_needed"] = names[k:]
            break
        budget.tick("motion each joint needs", k + 1, len(names))
        frozen = windows.variant_local(spec.freezing([name]), plan_windows.Change(joints=frozenset([name])))
        for other, local in frozen.items():
            if not local:
                need[other].append(name)
    return need


def robustness(spec: tree_rank.TreeSpec, plan: Plan, rows: dict, seed: int = 0, budget: Budget | None = None,
               windows: plan_windows.Windows | None = None) -> dict:
    """For each marker: does the plan stay all-identifiable without it, and which joints would it lose (the
    propagation for ``joints_lost``; the whole-tree verdicts, from the smallest windows that decide them, for
    ``joints_no_longer_local``). Markers the budget left unchecked are listed in ``budget.skipped["robustness"]``
    (and absent here)."""
    budget = budget or Budget(float("inf"))
    windows = windows or plan_windows.Windows(spec, plan.local_joints, plan.rank.frames, seed)
    out = {}
    every = [(seg, m) for seg, ms in spec.markers.items() for m in ms]
    for k, (seg, m) in enumerate(every):
        if budget.spent():
            budget.skipped["robustness"] = [mk for _, mk in every[k:]]
            break
        budget.tick("markers the plan cannot lose", k + 1, len(every))
        variant = spec.without(m)
        settled = propagate(variant, rows)
        local = windows.variant_local(variant, plan_windows.Change(segments=frozenset([seg])), known_local=settled)
        lost = [n for n, j in plan.joints.items()
                if j["identifiable"] and not (n in settled and settled[n].candidates == 1)]
        lost_local = [n for n, j in plan.joints.items() if j["local"] and not local[n]]
        out[m] = {"segment": seg, "plan_survives": not lost and not lost_local,
                  "joints_lost": lost, "joints_no_longer_local": lost_local}
    return out


@dataclass
class Fix:
    """The fewest markers to add (:func:`fewest_markers`), and how far their minimality was checked."""

    extra: dict | None          # segment -> markers to add: {} none needed, None none found within the limit
    unique_extra: dict | None   # the fewest for which the propagation settles every joint uniquely (None: none)
    fewer_checked: int          # plans with fewer added markers (the plan itself included) the whole-tree rank
    #                             rejected
    fewer_bare: int             # plans with fewer added markers skipped: a subtree stays bare (cannot pass)
    complete: bool              # every plan with fewer added markers was ruled out (False: the budget ran out)
    failure_bound: float = 0.0  # probability that any of those rejections is wrong (sum of their plans' bounds)
    out_of_time: tuple = ()     # the joints whose search the time budget stopped (then nothing was found)
    unchecked: bool = False     # the time budget stopped the check that no plan with fewer markers passes

    @property
    def markers(self) -> int | None:
        return None if self.extra is None else sum(self.extra.values())

    def check(self) -> dict:
        """The ``suggestions_check`` JSON: what was searched and what minimality rests on."""
        return {"target": "every joint locally identifiable (whole-tree rank) and none settled with several "
                          "candidates", "markers": self.markers, "minimal": self.complete,
                "fewer_plans_checked": self.fewer_checked, "fewer_plans_bare": self.fewer_bare,
                "failure_probability_bound": self.failure_bound,
                "method": "every plan with fewer added markers, on any segment (those without markers too), "
                          "rejected by the whole-tree rank, or skipped when a joint's subtree stays without markers"}


def as_suggestions(extra: dict | None) -> list:
    """``{segment: count}`` as the contract's ``[{"segment", "add_markers"}]`` (empty for None)."""
    return [{"segment": s, "add_markers": c} for s, c in (extra or {}).items()]


def suggestions(spec: tree_rank.TreeSpec, rows: dict, seed: int = 0, max_markers: int = MAX_SUGGESTED) -> list | None:
    """Fewest extra markers (``[{"segment", "add_markers"}]``) after which the plan :attr:`~Plan.passes`,
    ``[]`` when it already does, None when no addition of up to ``max_markers`` markers does
    (:func:`fewest_markers`)."""
    fix = fewest_markers(spec, rows, seed, max_markers)
    return None if fix.extra is None else as_suggestions(fix.extra)


def fewest_markers(spec: tree_rank.TreeSpec, rows: dict, seed: int = 0, max_markers: int = MAX_SUGGESTED,
                   budget: int = MAX_RANK_CHECKS, base: Plan | None = None, clock: Budget | None = None) -> Fix:
    """The fewest extra markers after which the plan :attr:`~Plan.passes`, minimal for the whole-tree rank.

    The propagation's fix (:func:`unique_suggestions`) passes, so it bounds the count from above. Every
    plan with fewer added markers — multisets of all segments, those without markers included — is then
    asked, fewest first, and the first that passes is the answer; if none does, the propagation's fix
    is. So no plan with one marker fewer passes: each was rejected by the whole-tree rank, or skipped
    because it leaves some joint's whole subtree without a marker (nothing then varies that joint's
    centre or axis, so the rank cannot determine them: such a plan provably fails). ``budget`` caps the
    whole-tree ranks; when it runs out, the propagation's fix is returned with ``complete`` False. ``clock``, a
    time budget (:class:`Budget`): the search over multisets grows exponentially with the segments a joint's
    markers could go on (a chain of 25 bare links took 92 s, a bare star of 30 did not end in 120), so when it
    is spent nothing is suggested and the joints still open are named in ``out_of_time``."""
    base = base or analyse(spec, rows, seed=seed)
    try:
        unique = {} if base.all_identifiable else unique_suggestions(spec, rows, seed, max_markers, clock)
    except OutOfTime as stop:
        return Fix(None, None, 1, 0, False, base.rank.failure_bound, stop.joints)
    if base.passes:
        return Fix({}, unique, 0, 0, True, 0.0)
    upper = max_markers if unique is None else sum(unique.values()) - 1
    needs = _bare_subtrees(spec)
    checked, bare, fail = 1, 0, base.rank.failure_bound       # the plan itself (0 added) fails
    for k in range(1, upper + 1):
        level_checked = level_bare = 0
        for combo in itertools.combinations_with_replacement(list(spec.markers), k):
            # (the plans skipped as bare are counted one by one too: 46 million on a chain of 80 segments)
            if clock is not None and (level_checked + level_bare) % 1024 == 0 and clock.spent():
                # the propagation's fix stands; that no plan with fewer markers passes is left unchecked
                return Fix(unique, unique, checked + level_checked, bare + level_bare, False, fail, unchecked=True)
            if not all(need & set(combo) for need in needs):
                level_bare += 1
                continue
            if checked + level_checked >= budget:
                return Fix(unique, unique, checked + level_checked, bare + level_bare, False, fail)
            extra = _count_segments(combo)
            cand = analyse(_with_extra(spec, extra), rows, seed=seed, warm_frames=base.rank.frames - 1,
                           search_min_frames=False)
            if cand.passes:
                return Fix(extra, unique, checked, bare, True, fail)
            level_checked += 1
            fail += cand.rank.failure_bound
        checked, bare = checked + level_checked, bare + level_bare
    return Fix(unique, unique, checked, bare, True, fail)


def _bare_subtrees(spec: tree_rank.TreeSpec) -> list:
    """For each joint whose child and everything below it carry no marker, the set of those segments: a
    plan that passes has an added marker in each (else the joint's constants move no marker)."""
    return [set(_subtree(spec, chi)) for _, _, _, chi in spec.joints if _bare_below(spec, chi)]


def _count_segments(combo) -> dict:
    """A multiset of segments as {segment: count}, in first-seen order."""
    extra: dict = {}
    for s in combo:
        extra[s] = extra.get(s, 0) + 1
    return extra


class OutOfTime(Exception):
    """The time budget of the fewest-marker search (:func:`fewest_markers`' ``clock``) was spent; ``joints``: the
    names of the joints it was settling."""

    def __init__(self, joints):
        super().__init__(f"the search for the fewest markers ran out of time ({', '.join(joints)})")
        self.joints = tuple(joints)


def unique_suggestions(spec: tree_rank.TreeSpec, rows: dict, seed: int = 0,
                       max_markers: int = MAX_SUGGESTED, clock: Budget | None = None) -> dict | None:
    """Fewest extra markers (segment -> count) after which the propagation settles every joint with one
    candidate and the whole-tree rank confirms it (every joint identifiable), or None when no addition of
    up to ``max_markers`` markers suffices.

    A marker on segment X can change a joint not yet uniquely settled only if the joint touches X (X's
    points) or a neighbour of X (a far marker beyond its one-point segment); a uniquely settled joint's
    virtual markers are fixed. So each open joint is influenced by its segments and their neighbours;
    open joints whose influencing segments overlap form a component, components are independent, and
    their fewest additions add up. Each is found exhaustively over multisets of its influencing
    segments, fewest first, screened by the propagation; the whole-tree rank checks the union (and on
    the rare failure the search is repeated over all the segments at once). Raises :class:`OutOfTime` when `clock`
    (a :class:`Budget`) is spent first."""
    base = propagate(spec, rows)
    open_joints = [j for j in spec.joints if not (j[0] in base and base[j[0]].candidates == 1)]
    if not open_joints:
        return {}
    extra: dict = {}
    for comp in _components(spec, open_joints):
        found = _fewest(spec, rows, comp, max_markers - sum(extra.values()), clock=clock)
        if found is None:
            return None
        extra.update(found)
    if analyse(_with_extra(spec, extra), rows, seed=seed).all_identifiable:
        return extra
    return _fewest(spec, rows, open_joints, max_markers, seed=seed, clock=clock)


def _influencing(spec, joints: list) -> set:
    """Segments where a marker could change how ``joints`` settle: theirs and their neighbours."""
    own = {s for j in joints for s in (j[2], j[3])}
    return own | {s for k in spec.joints if {k[2], k[3]} & own for s in (k[2], k[3])}


def _components(spec, joints: list) -> list:
    """Joints grouped by overlapping influencing segments (connected components)."""
    comps: list = []
    for j in joints:
        mine = _influencing(spec, [j])
        touching = [c for c in comps if mine & _influencing(spec, c)]
        merged = [j] + [k for c in touching for k in c]
        comps = [c for c in comps if c not in touching] + [merged]
    return comps


def _fewest(spec, rows, joints: list, max_markers: int, seed: int | None = None, clock: Budget | None = None
            ) -> dict | None:
    """Fewest extra markers on the influencing segments of ``joints`` after which the propagation settles
    all of them uniquely (and, with ``seed``, the whole-tree rank confirms every joint of the plan); raises
    :class:`OutOfTime` when `clock` is spent first."""
    names = [j[0] for j in joints]
    near = _influencing(spec, joints)
    segs = [s for s in spec.markers if s in near]
    tried = 0
    for k in range(1, max_markers + 1):
        for combo in itertools.combinations_with_replacement(segs, k):
            tried += 1
            if clock is not None and tried % 32 == 0:
                clock.tick("fewest markers to add", k, max_markers)
                if clock.spent():
                    raise OutOfTime([j[0] for j in spec.joints if j[0] in names])     # (the tree's order)
            extra = _count_segments(combo)
            cand = _with_extra(spec, extra)
            settled = propagate(cand, rows)
            if not all(n in settled and settled[n].candidates == 1 for n in names):
                continue
            if seed is None or analyse(cand, rows, seed=seed).all_identifiable:
                return extra
    return None


def _with_extra(spec: tree_rank.TreeSpec, extra: dict) -> tree_rank.TreeSpec:
    markers = {s: ms + tuple(f"+{s}.{i + 1}" for i in range(extra.get(s, 0))) for s, ms in spec.markers.items()}
    return tree_rank.TreeSpec(spec.root, markers, spec.joints, spec.frozen, spec.known)


def fewest_local(spec: tree_rank.TreeSpec, rows: dict, seed: int = 0, budget: Budget | None = None) -> dict:
    """A finding: the fewest markers, kept from this plan, for which every joint stays locally identifiable
    (greedy removal, each removal checked by the whole-tree rank), within `budget`.

    Each marker is tried once, in order: a marker that cannot go leaves a joint undetermined, and with fewer markers
    beside it still would (the whole-tree rank only falls as markers go), so trying it again after later removals,
    as a restart from the first marker after each removal did, finds nothing new; that had taken the square of the
    markers' count in ranks (a 20-segment chain of 3 markers each past 120 s, whatever ``--max-seconds`` said). Out
    of time, the markers not tried yet are kept and ``complete`` is false."""
    budget = budget or Budget(float("inf"))
    current, removed = spec, []
    markers = [m for ms in spec.markers.values() for m in ms]
    complete = True
    for k, m in enumerate(markers, 1):
        if budget.spent():
            complete = False
            break
        budget.tick("fewest markers keeping every joint locally identifiable", k, len(markers))
        cand = current.without(m)
        if all(j.local for j in tree_rank.analyse(cand, "GFp", seed).joints.values()):
            current = cand
            removed.append(m)
    kept = sum(len(ms) for ms in current.markers.values())
    return {"markers": kept, "removable": removed,
            "per_segment": {s: list(ms) for s, ms in current.markers.items()},
            "method": "greedy removal while every joint stays locally identifiable (whole-tree rank)",
            "complete": complete}


def _suggestion_keys(fix: Fix) -> dict:
    """The JSON keys of a fix: ``suggestions`` (the fewest markers for the whole-tree rank), how that was
    checked, and the fewest for a proof of uniqueness by propagation when those differ."""
    keys = {"suggestions": as_suggestions(fix.extra), "suggestions_check": fix.check()}
    if fix.extra is None:
        keys["suggestions_note"] = (
            f"none found: the search stopped at its time budget before settling {', '.join(fix.out_of_time)}"
            if fix.out_of_time else
            f"no addition of up to {MAX_SUGGESTED} markers makes every joint locally identifiable" if fix.complete
            else f"none found: the search stopped after {fix.fewer_checked} whole-tree ranks")
    if fix.unique_extra != fix.extra:
        keys["suggestions_unique"] = as_suggestions(fix.unique_extra)
        if fix.unique_extra is None:
            keys["suggestions_unique_note"] = (f"no addition of up to {MAX_SUGGESTED} markers lets the propagation "
                                               "settle every joint uniquely")
    return keys


def plan_model(model, seed: int = 0, motion: bool = True, robust: bool = True, suggest: bool = True,
               fewest: bool = False, witness: bool = False, progress=None, max_seconds: float | None = None) -> PlanResult:
    """Check a marker plan: every joint's verdict and explanation, the fewest markers to add, and (optional
    analyses) the motion each joint needs, the markers the plan cannot lose, the fewest markers that keep
    every joint locally identifiable.

    Parameters
    ----------
    model : Model
    seed : int
        Seed of the random prime and point of the whole-tree rank.
    motion, robust, suggest, fewest : bool
        Run the motion, robustness, suggestion and fewest-markers analyses.
    witness : bool
        Also simulate the plan and search every joint it does not identify for a second skeleton verified
        at 50 digits (:mod:`identcheck.plan.witness`; seconds to a minute).
    progress : callable, optional
        Called with a message per stage (at most one a second in the per-joint and per-marker analyses).
    max_seconds : float, optional
        Budget of the motion and robustness analyses together (default :data:`ANALYSES_BUDGET_S`), separately of
        the search for the fewest markers to add (the same default), and of the witness searches (default
        :data:`identcheck.plan.witness.BUDGET_S`); what they leave unchecked is listed under ``unfinished``.

    Returns
    -------
    PlanResult
    """
    spec = tree_rank.TreeSpec.from_model(model)
    rows = table_summary()
    if progress:
        progress(f"whole-tree rank of {len(spec.joints)} joints")
    plan = analyse(spec, rows, seed=seed, progress=progress)
    doc = {"all_identifiable": plan.all_identifiable, "all_local": plan.all_local, "joints": plan.joints}
    doc["suggestions"] = []
    if suggest and not plan.all_identifiable:           # (each search on its own clock, started when it starts)
        fix = fewest_markers(spec, rows, seed, base=plan, clock=Budget(max_seconds, progress))
        doc.update(_suggestion_keys(fix))
        if fix.out_of_time:
            doc.setdefault("unfinished", {})["suggestions"] = list(fix.out_of_time)
        if fix.unchecked:
            doc.setdefault("unfinished", {})["suggestions_minimal"] = False
    if witness:
        from identcheck.plan import witness as plan_witness

        for n, w in plan_witness.witnesses(model, spec, plan, seed, progress, max_seconds).items():
            doc["joints"][n]["alternative"] = w
            if w.get("method") == "not_searched":
                doc.setdefault("unfinished", {}).setdefault("witness", []).append(n)
    windows = None
    budget = Budget(max_seconds, progress)
    if motion or robust:
        windows = plan_windows.Windows(spec, plan.local_joints, plan.rank.frames, seed, tick=budget.tick)
    if motion:
        needs = motion_needed(spec, plan, seed, budget, windows)
        for n in doc["joints"]:
            doc["joints"][n]["motion_needed"] = None if "motion_needed" in budget.skipped else needs[n]
    if robust:
        doc["robustness"] = robustness(spec, plan, rows, seed, budget, windows)
    fewest_budget = Budget(max_seconds, progress)
    if fewest:
        doc["fewest_local"] = fewest_local(spec, rows, seed, fewest_budget)
        if not doc["fewest_local"]["complete"]:
            doc.setdefault("unfinished", {})["fewest_local"] = True
    reasons = []
    if budget.skipped:
        doc["unfinished"] = dict(doc.get("unfinished", {}), **budget.skipped)
        reasons.append(f"the motion and robustness analyses stopped at their budget of {budget.seconds:g} s (one "
                       "whole-tree rank per joint and per marker); `plan --max-seconds` raises it, `--fast` skips them")
    if "witness" in doc.get("unfinished", {}):
        reasons.append("the witness searches stopped at their budget; `plan --max-seconds` raises it")
    if "suggestions" in doc.get("unfinished", {}):
        reasons.append(f"the search for the fewest markers to add stopped at its budget of {budget.seconds:g} s "
                       "before settling these joints; `plan --max-seconds` raises it")
    if "suggestions_minimal" in doc.get("unfinished", {}):
        reasons.append(f"the check that no plan with fewer markers passes stopped at its budget of {budget.seconds:g} "
                       "s: the suggestion passes but may not be the fewest; `plan --max-seconds` raises it")
    if doc.get("unfinished", {}).get("fewest_local"):
        reasons.append(f"the greedy removal behind fewest_local stopped at its budget of {fewest_budget.seconds:g} s: "
                       "the markers not tried yet are kept; `plan --max-seconds` raises it")
    if reasons:
        doc["unfinished"]["reason"] = "; ".join(reasons)
    undetermined = {n: list(plan.rank.joints[n].undetermined) for n, j in plan.joints.items() if not j["local"]}
    if undetermined:
        doc["undetermined"] = undetermined
    jointly = [n for n, j in plan.joints.items() if j["jointly_only"]]
    if jointly:
        doc["shared_motion"] = (f"{', '.join(jointly)}: locally identifiable only together (the whole tree's rank), "
                                "not by any joint's own markers and the virtual markers propagation finds")
    r = plan.rank
    doc["certificate"] = {
        "method": "exact rank of the whole-tree Jacobian at a random point over GF(p), p a uniform 61-bit prime",
        "prime": r.prime, "frames": r.frames, "constants": r.n_constants, "dim_determined": r.dim_w,
        "degree_bound": r.degree_bound, "failure_probability_bound": r.failure_bound,
        "seed": seed}
    return PlanResult.from_dict(doc, model.root, {s: seg.markers for s, seg in model.segments.items()})

