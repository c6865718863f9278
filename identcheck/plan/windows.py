"""Whole-tree verdicts of a plan's variants — a marker removed, a joint held at one angle — from small
windows of the tree.

The plan's robustness and motion analyses ask, for every marker and every joint, which joints a variant
that differs from the plan in one place leaves locally identifiable. One whole-tree rank per variant makes
the analyses grow as the square of the model (a 200-segment chain: minutes). A *window* — a connected
set of joints, with their segments and those segments' markers — bounds the whole tree's verdicts from
both sides:

- *From below.* A window's equations are some of the whole tree's, and its other unknowns are the whole
  tree's too: a combination of constants its rows determine, the whole tree's rows determine. A joint
  locally identifiable in the window, judged there against every point adjacent to it (nothing set
  aside, the same points as in the whole tree), is locally identifiable in the whole tree.
- *From above.* The window's rows share with the rest of the tree only the poses of its boundary
  segments (those with a joint outside it): the constants of a cut joint, its angles and everything
  beyond appear in no window row. Given those poses (:attr:`identcheck.certify.tree_rank.TreeSpec.known`),
  any multipliers that make the whole tree's rows determine a quantity of the window's constants,
  restricted to the window's rows, determine it too. So a quantity the told window leaves undetermined,
  the whole tree leaves undetermined. Used for joints judged against all their adjacent points in both
  (markers, or a lone neighbouring centre on a segment without markers: :func:`_judged_alike`).

Windows are unions of *regions*: the tree cut at its *anchors*, segments with three or more markers, whose
poses their own markers fix — so both bounds usually agree on a region (a long stretch without anchors is
cut into pieces of a few joints). The plan's own regions certify its joints once (:class:`Windows`); a
variant keeps a joint's certificate when it changes nothing inside the joint's window, and every other
joint is judged on its window in the variant (below, then above), on a window one region wider, and on
the whole tree as the last resort. The verdicts are therefore those
of the whole-tree rank (each rank with the probability bound of :mod:`identcheck.certify.tree_rank`), at
the cost of a few small ranks per variant.
"""
from __future__ import annotations

from dataclasses import dataclass

from identcheck.certify import tree_rank

ANCHOR_MARKERS = 3          # markers that make a segment an anchor (its pose fixed by its own markers)
MAX_WIDENING = 1            # regions a window is widened by before the whole tree is used
CHUNK_JOINTS = 4            # joints of a piece when a region without anchors is cut


@dataclass(frozen=True)
class Change:
    """Where a variant differs from its plan: segments that lost a marker, joints held still."""

    segments: frozenset = frozenset()
    joints: frozenset = frozenset()

    def inside(self, window: frozenset, segments: frozenset) -> bool:
        """Does the variant change the equations of ``window`` (joint names), whose segments are ``segments``?"""
        return bool(self.joints & window or self.segments & segments)


def regions(spec: tree_rank.TreeSpec, chunk: int = CHUNK_JOINTS) -> list:
    """The tree cut at its anchors: joint-name sets, two joints together when they share a segment that is
    not an anchor (an anchor belongs to every region it touches); a region of more than ``chunk`` joints is
    cut further (:func:`split`)."""
    parent = {j[0]: j[0] for j in spec.joints}

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    at_segment: dict = {}
    for name, _, par, chi in spec.joints:
        for seg in (par, chi):
            if len(spec.markers[seg]) < ANCHOR_MARKERS:
                at_segment.setdefault(seg, []).append(name)
    for names in at_segment.values():
        for other in names[1:]:
            parent[find(other)] = find(names[0])
    groups: dict = {}
    for name, _, _, _ in spec.joints:
        groups.setdefault(find(name), set()).add(name)
    return [piece for g in groups.values() for piece in split(spec, g, chunk)]


def split(spec: tree_rank.TreeSpec, region, size: int = CHUNK_JOINTS) -> list:
    """A region of more than ``size`` joints (a long stretch without anchors) cut into connected pieces of about
    ``size`` joints, leaves first: any window bounds the whole tree, only how often it decides depends on the cut."""
    if len(region) <= size:
        return [frozenset(region)]
    chunks, pending = [], {}            # segment -> joints hanging from it, not yet in a chunk (connected through it)
    for name, _, par, chi in reversed([j for j in spec.joints if j[0] in region]):
        group = [name] + pending.pop(chi, [])
        if len(group) >= size:
            chunks.append(frozenset(group))
            continue
        pending.setdefault(par, []).extend(group)
        if len(pending[par]) >= size:
            chunks.append(frozenset(pending.pop(par)))
    chunks += [frozenset(group) for group in pending.values()]
    return chunks


def window_spec(spec: tree_rank.TreeSpec, window: frozenset, told: bool = False) -> tree_rank.TreeSpec:
    """The sub-skeleton of the joints ``window`` (connected): their segments with their markers. ``told``: the
    poses of its boundary segments (a joint outside the window attached) are given."""
    joints = tuple(j for j in spec.joints if j[0] in window)
    segments = {s for j in joints for s in (j[2], j[3])}
    children = {j[3] for j in joints}
    roots = [s for s in segments if s not in children]
    if len(roots) != 1:
        raise ValueError(f"window {sorted(window)} is not a connected part of the tree")
    boundary = frozenset(s for j in spec.joints if j[0] not in window for s in (j[2], j[3]) if s in segments)
    return tree_rank.TreeSpec(roots[0], {s: spec.markers[s] for s in spec.markers if s in segments}, joints,
                              frozenset(spec.frozen & window), boundary if told else frozenset())


def widen(spec: tree_rank.TreeSpec, window: frozenset, all_regions: list) -> frozenset:
    """``window`` and every region that shares a segment with it."""
    segs = {s for j in spec.joints if j[0] in window for s in (j[2], j[3])}
    out = set(window)
    for region in all_regions:
        if any(j[2] in segs or j[3] in segs for j in spec.joints if j[0] in region):
            out |= region
    return frozenset(out)


def _same_points(whole: tree_rank.TreeSpec, part: tree_rank.TreeSpec, joint: str) -> bool:
    return tree_rank.adjacent_points(whole, joint) == tree_rank.adjacent_points(part, joint)


def _judged_alike(spec: tree_rank.TreeSpec, joint: str) -> bool:
    """Is ``joint`` judged against all its adjacent points, in any window as in the whole tree? Yes when each
    side offers markers only, or at most one other joint's centre: a centre on a segment without markers is
    left out only when the data place another of the segment's centres and not it
    (:func:`identcheck.certify.tree_rank.judged_points`), and a lone candidate is kept either way."""
    return all(len(side) <= 1 or all(p.kind == "marker" for p in side)
               for side in tree_rank.adjacent_points(spec, joint))


def shape(spec: tree_rank.TreeSpec) -> tuple:
    """What a skeleton's generic verdicts depend on, names left out: per segment its marker count and whether its
    poses are given; per joint its type, whether it is held still, and the segments it joins (in the spec's
    order). Two skeletons of one shape differ by renaming, so their generic ranks — and verdicts — agree."""
    index = {spec.root: 0}
    segments = [(len(spec.markers[spec.root]), spec.root in spec.known)]
    joints = []
    for name, kind, par, chi in spec.joints:
        index[chi] = len(segments)
        segments.append((len(spec.markers[chi]), chi in spec.known))
        joints.append((kind, name in spec.frozen, index[par], index[chi]))
    return tuple(segments), tuple(joints)


_VERDICTS: dict = {}          # (shape, seed) -> ([(local, set aside) per joint, in order], frames)
_MAX_VERDICTS = 20_000


def window_verdicts(part: tree_rank.TreeSpec, seed: int, warm_frames: int) -> tuple:
    """({joint: (locally identifiable, something set aside)}, frames used) of a window's whole-tree rank; a
    window of a shape ranked before (a chain's repeated regions) takes that rank's verdicts (:func:`shape`)."""
    key = (shape(part), seed)
    hit = _VERDICTS.get(key)
    if hit is None:
        rank = tree_rank.analyse(part, "GFp", seed, warm_frames=warm_frames, search_min_frames=False, share=False)
        hit = ([(rank.joints[j[0]].local, bool(rank.joints[j[0]].set_aside)) for j in part.joints], rank.frames)
        if len(_VERDICTS) > _MAX_VERDICTS:
            _VERDICTS.clear()
        _VERDICTS[key] = hit
    return {j[0]: v for j, v in zip(part.joints, hit[0])}, hit[1]


def judge_on_window(spec: tree_rank.TreeSpec, window: frozenset, joints, seed: int = 0, warm_frames: int = 0) -> tuple:
    """(joint -> True (locally identifiable in ``spec``), False (not), or None (the window cannot tell), frames
    the window's rank used), for the ``joints`` of ``window``, from its rank below and, for those still open, its
    told rank above. ``warm_frames``: frames to start the scan from (the verdicts do not depend on it)."""
    part = window_spec(spec, window)
    below, frames = window_verdicts(part, seed, warm_frames)
    out = {}
    for n in joints:
        local, aside = below[n]
        out[n] = True if (local and not aside and _same_points(spec, part, n)) else None
    open_ = [n for n in joints if out[n] is None and _judged_alike(spec, n) and _same_points(spec, part, n)]
    if open_ and part.joints and any(j[0] not in window for j in spec.joints):
        above, _ = window_verdicts(window_spec(spec, window, told=True), seed, warm_frames)
        for n in open_:
            if not above[n][0]:
                out[n] = False
    return out, frames


class Windows:
    """A plan's joints, each certified locally identifiable on the smallest window tried (or on the whole
    tree), and the verdicts of its variants from those windows.

    ``local``: the plan's locally identifiable joints (its whole-tree verdicts); ``frames``: the frames its
    whole-tree rank used (a variant ranked on the whole tree starts from one fewer); ``chunk``: see
    :func:`regions`; ``tick(what, k, n)``: called per region certified (progress)."""

    def __init__(self, spec: tree_rank.TreeSpec, local, frames: int, seed: int = 0, chunk: int = CHUNK_JOINTS,
                 tick=None):
        self.spec, self.seed, self.frames = spec, seed, frames
        self.local = set(local)
        self.regions = regions(spec, chunk)
        self.certificate: dict = {}       # joint -> window that certifies it, None: only the whole tree
        self._frames: dict = {}           # window -> frames its rank used (where a variant's scan starts)
        self._segments: dict = {}         # window -> its segments
        everything = frozenset(j[0] for j in spec.joints)
        for k, region in enumerate(self.regions):
            if tick:
                tick("windows of the tree", k + 1, len(self.regions))
            todo = [n for n in region if n in self.local]
            window = region
            for _ in range(MAX_WIDENING + 1):
                if not todo or window == everything:
                    break
                found, self._frames[window] = judge_on_window(spec, window, todo, seed)
                for n in todo:
                    if found[n]:
                        self.certificate[n] = window
                todo = [n for n in todo if not found[n]]
                window = widen(spec, window, self.regions)
            for n in todo:
                self.certificate[n] = None

    def _segments_of(self, window: frozenset) -> frozenset:
        """The segments a window's joints join (computed once per window)."""
        if window not in self._segments:
            self._segments[window] = frozenset(s for j in self.spec.joints if j[0] in window for s in (j[2], j[3]))
        return self._segments[window]

    def variant_local(self, variant: tree_rank.TreeSpec, change: Change, known_local=()) -> dict:
        """For each of the plan's locally identifiable joints: is it still locally identifiable in ``variant``
        (the plan with ``change``)? ``known_local``: joints already known to be (settled by the variant's
        propagation).

        A joint held still is not: its child, constants and all, can be re-attached about any other centre
        (and axis) with every marker trajectory unchanged — nothing else couples the two segments — and that
        moves its distances to the markers; so it is answered without a rank."""
        out = {n: True for n in self.local}
        for n in change.joints & self.local:
            out[n] = False
        todo = {}
        for n in self.local:
            cert = self.certificate[n]
            if n in known_local or n in change.joints or (cert is not None and
                                                           not change.inside(cert, self._segments_of(cert))):
                continue
            todo.setdefault(cert, []).append(n)
        whole = []
        everything = frozenset(j[0] for j in self.spec.joints)
        for window, names in todo.items():
            for _ in range(MAX_WIDENING + 1):
                if window is None or window == everything or not names:
                    break
                found, _ = judge_on_window(variant, window, names, self.seed,
                                           max(0, self._frames.get(window, 0) - 1))
                for n in names:
                    if found[n] is not None:
                        out[n] = found[n]
                names = [n for n in names if found[n] is None]
                window = widen(self.spec, window, self.regions)
            whole += names
        if whole:
            rank = tree_rank.analyse(variant, "GFp", self.seed, warm_frames=self.frames - 1,
                                     search_min_frames=False)
            for n in whole:
                out[n] = rank.joints[n].local
        return out
