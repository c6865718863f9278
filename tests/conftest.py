import os

# Small dense solves on 2 cores: BLAS threads only fight each other (and pytest runs one test at a time).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from hypothesis import HealthCheck, settings

settings.register_profile("ci", max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
if str(TESTS) not in sys.path:           # shared helpers (strategies, float_tree) for tests in every subfolder
    sys.path.insert(0, str(TESTS))


@pytest.fixture(scope="session")
def examples() -> Path:
    """The repository's bundled example models."""
    return ROOT / "examples"


@pytest.fixture(scope="session")
def real_file():
    """``real_file(name)``: a real recording, the repository's copy (``examples/real/``) first, else the shared
    folder's (``tests/real_data.py``); the test skips when neither exists."""
    from real_data import real_file as find

    def get(name: str) -> Path:
        path = find(name)
        if not path.exists():
            pytest.skip(f"real recording {name} not available (examples/real/ or the shared folder)")
        return path
    return get
