"""Where ``diagnose`` spends its CPU time, by step of its search, on a folder of trials.

Each trial (a ``.trc`` or ``.c3d`` with its ``.toml`` model beside it, as the held-out generators write them) is
diagnosed in this process with the workflow's steps wrapped: the rigid fit it starts from, the detectors (every
effect's ``propose``), each effect's candidate fits (``apply``) and screens, the null refit that measures drift, the
fits on of a candidate about to be adopted (``polish``), the final fit, and the report's joints (covariance, profiles,
bootstrap). Time is exclusive: a step's seconds leave out the steps it calls (the adoption step's leave out the
polishing and the full fits of screened proposals it asks for). Each step also counts the normal-equation builds (one
a Levenberg-Marquardt iteration) it makes. The table and ``results.json`` give each step's share of the whole.

    python benchmarks/heldout_effects/generator.py --out /tmp/hx --n 120 --seed 83 --version 2
    python benchmarks/bench_diagnose_phases.py /tmp/hx --limit 12 [--key diagnose_phases]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_io  # noqa: E402

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")


class PhaseClock:
    """Exclusive time by label for nested calls: the innermost label open is charged, so that every second between
    :meth:`start` and :meth:`stop` goes to exactly one label (``"other"`` outside any). `clock`: the time function
    (CPU seconds by default)."""

    def __init__(self, clock=time.process_time):
        self.clock, self.seconds, self.counts, self.stack = clock, Counter(), Counter(), []
        self._last = None

    def _charge(self) -> None:
        now = self.clock()
        self.seconds[self.stack[-1] if self.stack else "other"] += now - self._last
        self._last = now

    def start(self) -> None:
        self._last, self.stack = self.clock(), []
        self.seconds.clear()
        self.counts.clear()

    def stop(self) -> dict:
        self._charge()
        return dict(self.seconds)

    def enter(self, label: str) -> None:
        self._charge()
        self.stack.append(label)

    def leave(self) -> None:
        self._charge()
        self.stack.pop()

    def count(self) -> None:
        """One more event (a normal-equation build) for the label open now."""
        self.counts[self.stack[-1] if self.stack else "other"] += 1

    def wrap(self, owner, name: str, label) -> None:
        """Charge `owner.name` (a function or method) to `label` (a string, or a function of the call's arguments)."""
        f = getattr(owner, name)

        def timed(*args, **kwargs):
            self.enter(label(*args) if callable(label) else label)
            try:
                return f(*args, **kwargs)
            finally:
                self.leave()
        setattr(owner, name, timed)


def instrument(clock: PhaseClock) -> None:
    """Wrap the workflow's steps (module docstring) to charge `clock`."""
    import identcheck.bundle.chain as chain
    import identcheck.bundle.hypothesis as hypothesis
    import identcheck.diagnose.workflow as workflow
    from identcheck.effects.registry import EFFECTS

    for eff in EFFECTS.values():
        clock.wrap(eff, "propose", "detectors")
        clock.wrap(eff, "apply", f"fit: {eff.name}")
        clock.wrap(eff, "screen", f"screen: {eff.name}")
    clock.wrap(workflow, "start", "rigid start")
    clock.wrap(workflow, "creep", "drift refit")
    clock.wrap(workflow, "choose", "adoption")
    clock.wrap(hypothesis.Hypothesis, "polish", "polish")
    clock.wrap(hypothesis.Hypothesis, "converged", "final fit")
    clock.wrap(workflow.Diagnosis, "to_dict", "report (joints)")
    normal = chain._normal

    def counted(*args, **kwargs):
        clock.count()
        return normal(*args, **kwargs)
    chain._normal = counted


def trials(folder: Path, limit: int | None) -> list:
    """(model, trial) pairs of `folder`, in name order, at most `limit`."""
    out = []
    for model in sorted(folder.glob("*.toml")):
        trial = next((model.with_suffix(s) for s in (".trc", ".c3d") if model.with_suffix(s).exists()), None)
        if trial is not None:
            out.append((model, trial))
    return out[:limit] if limit else out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="trials with their .toml models beside them")
    ap.add_argument("--limit", type=int, default=None, help="the first N trials only")
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results.json")
    ap.add_argument("--key", default="diagnose_phases")
    a = ap.parse_args(argv)
    from identcheck.api import diagnose

    clock = PhaseClock()
    instrument(clock)
    rows = []
    for model, trial in trials(a.folder, a.limit):
        clock.start()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            doc = diagnose(str(model), str(trial)).to_dict()
        seconds = clock.stop()
        rows.append({"trial": trial.name, "effects": [e["name"] for e in doc["effects"]],
                     "cpu_s": round(sum(seconds.values()), 3),
                     "phases_s": {k: round(v, 3) for k, v in sorted(seconds.items())},
                     "normal_builds": dict(sorted(clock.counts.items()))})
        print(f"{trial.name}: {rows[-1]['cpu_s']:.1f} s, {sum(clock.counts.values())} builds", flush=True)
    total = Counter()
    builds = Counter()
    for r in rows:
        total.update(r["phases_s"])
        builds.update(r["normal_builds"])
    whole = sum(total.values()) or 1.0
    print(f"\n{'step':28s} {'CPU s':>8s} {'share':>6s} {'builds':>7s}")
    for k, v in total.most_common():
        print(f"{k:28s} {v:8.1f} {v / whole:6.1%} {builds[k]:7d}")
    summary = {k: {"cpu_s": round(v, 2), "share": round(v / whole, 4), "normal_builds": builds[k]}
               for k, v in total.most_common()}
    results_io.write_json(a.out, a.key, {"folder": str(a.folder), "trials": len(rows), "cpu_s": round(whole, 2),
                                         "summary": summary, "rows": rows,
                                         "machine": results_io.machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
