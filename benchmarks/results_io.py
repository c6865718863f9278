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
