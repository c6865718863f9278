"""Shared by every benchmark script: write one key of benchmarks/results.json safely, and describe the machine."""
from __future__ import annotations

import json
import os
import platform
import tempfile
from pathlib import Path


def write_json(path: Path, key: str, value: dict, merge: bool = False) -> None:
    """Read-modify-write one key, keeping the others, atomically.

    ``merge=True`` updates ``data[key]`` with ``value`` (scripts that write a key in parts);
    otherwise ``value`` replaces it. Refuses to overwrite a file that is not valid JSON.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {}
    if path.exists():
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError:
            raise SystemExit(f"{path} is not valid JSON; refusing to overwrite it")
    data[key] = {**data.get(key, {}), **value} if merge else value
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(data, fh, indent=2, sort_keys=True, allow_nan=False)
        fh.write("\n")
    os.chmod(tmp, 0o644)  # mkstemp makes it private; results.json is meant to be read by anyone
    os.replace(tmp, path)


def machine_info(**extra) -> dict:
    """The machine and library versions a benchmark ran on (plus ``extra`` keys, e.g. load averages)."""
    import numpy
    import scipy
    import sympy

    return {"nproc": os.cpu_count(), "numpy": numpy.__version__, "scipy": scipy.__version__,
            "sympy": sympy.__version__, "python": platform.python_version(), "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(), "loadavg": list(os.getloadavg()), **extra}


def add_shard_arguments(ap) -> None:
    """``--shard K/N``, ``--rows FILE`` and ``--merge FILES...``: run a long per-trial benchmark as N processes
    side by side, then summarise their rows together (:func:`run_trials`)."""
    ap.add_argument("--shard", default=None, metavar="K/N",
                    help="evaluate only every N-th trial from the K-th and write the per-trial rows to --rows")
    ap.add_argument("--rows", type=Path, default=None, help="where the per-trial rows are written (JSON)")
    ap.add_argument("--merge", type=Path, nargs="+", default=None, help="row files of shards to summarise together")


def run_trials(entries: list, evaluate, args, describe) -> list | None:
    """Per-trial rows: read from ``args.merge``, or computed by ``evaluate(entry)`` for this shard's entries,
    each announced on stderr by ``describe(k, n, entry, row)`` and saved to ``args.rows`` as it comes. Returns
    None for a shard (its rows are in ``args.rows``; the merge run summarises)."""
    import sys

    if args.merge:
        return [r for f in args.merge for r in json.loads(f.read_text())]
    if args.shard:
        k0, n = (int(x) for x in args.shard.split("/"))
        entries = entries[k0::n]
    rows = []
    for k, e in enumerate(entries, 1):
        rows.append(evaluate(e))
        print(describe(k, len(entries), e, rows[-1]), file=sys.stderr)
        if args.rows:
            args.rows.write_text(json.dumps(rows))
    return None if args.shard else rows


def percent(share) -> str:
    """A share (0-1) as a whole percentage in four columns, ``   -`` when there is none."""
    return "   -" if share is None else f"{100 * share:4.0f}"


def by_category(rows: list) -> dict:
    """The rows under each of their ``categories`` (a row with several is under each), categories sorted."""
    out: dict = {}
    for r in rows:
        for c in r["categories"]:
            out.setdefault(c, []).append(r)
    return dict(sorted(out.items()))


def bin_names(edges, unit: str) -> list:
    """Names of the bins that the increasing `edges` cut a quantity into: ``< a unit``, ``a-b unit``, ``>= z unit``."""
    lo, hi = [None, *edges], [*edges, None]
    return [(f"< {b:g} {unit}" if a is None else f">= {a:g} {unit}" if b is None else f"{a:g}-{b:g} {unit}")
            for a, b in zip(lo, hi)]


def by_bin(rows: list, key: str, edges, unit: str) -> dict:
    """The rows grouped by the bin (:func:`bin_names`) of their value ``row[key]``, bins in order, empty ones and rows
    without the value left out."""
    import numpy as np

    names = bin_names(edges, unit)
    out: dict = {n: [] for n in names}
    for r in rows:
        if r.get(key) is not None:
            out[names[int(np.searchsorted(edges, r[key], side="right"))]].append(r)
    return {n: rs for n, rs in out.items() if rs}


def seconds_summary(rows: list) -> dict:
    """``median_seconds`` and ``max_seconds`` of the rows' ``seconds`` (None for no rows)."""
    import numpy as np

    times = [r["seconds"] for r in rows]
    return {"median_seconds": float(np.median(times)) if times else None,
            "max_seconds": float(np.max(times)) if times else None}


def error_rows(rows: list) -> list:
    """The rows that ended in an error, as ``[{"id", "error"}]`` (what :func:`errors_line` prints)."""
    return [{"id": r["id"], "error": r["error"]} for r in rows if "error" in r]


def errors_line(errors: list) -> list:
    """The table's line for trials that ended in an error (``[{"id", "error"}]``): empty when there are none."""
    if not errors:
        return []
    return [f"errors: {len(errors)}: " + "; ".join(f"{e['id']}: {e['error'][:120]}" for e in errors[:5])]


def warm_up(call) -> None:
    """One untimed call first (imports and first-call costs are not timed); a refusal of the input is fine."""
    import warnings

    from identcheck.errors import InputError

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            call()
        except InputError:
            pass


def benchmark_folder(args, folder, evaluate, describe, summarise, table, call) -> int:
    """The common run of a per-trial benchmark on a generator's folder (``index.json`` listing ``trials`` with a
    ``trc`` each): one untimed warm-up ``call(path of the first trial)``, the trials (or this shard's, or the
    merged shards' rows: :func:`run_trials`), the printed ``table(summarise(rows))``, and ``args.key`` of
    ``args.out`` written with the summary, the rows, where the trials came from and the machine."""
    index = json.loads((Path(folder) / "index.json").read_text()) if folder else {"trials": []}
    if index["trials"] and not args.merge:
        warm_up(lambda: call(Path(folder) / index["trials"][0]["trc"]))
    rows = run_trials(index["trials"], evaluate, args, describe)
    if rows is None:
        return 0
    summary = summarise(rows)
    print(table(summary))
    write_json(args.out, args.key, {"summary": summary, "rows": rows, "source": {
        "folder": str(folder) if folder else None, "generator": index.get("generator"), "seed": index.get("seed"),
        "n": index.get("n")}, "machine": machine_info()})
    return 0
