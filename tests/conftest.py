"""Shared fixtures. Real data lives in ../shared/data (never copied into the repo).

Set MOCAP_GAPFILL_DATA to point elsewhere. When the data is absent, data tests skip, unless
MOCAP_GAPFILL_REQUIRE_DATA=1 (CI sets it), which turns that into a failure.
"""

import os
from pathlib import Path

import pytest

from mocap_gapfill.__main__ import choose_blas_kernel

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(os.environ.get("MOCAP_GAPFILL_DATA", ROOT.parent / "shared" / "data"))

os.environ.setdefault("OMP_NUM_THREADS", "1")
choose_blas_kernel()  # as the command line does (before anything loads numpy)


@pytest.fixture(scope="session")
def data_dir():
    if not (DATA / "MANIFEST.md").is_file():
        if os.environ.get("MOCAP_GAPFILL_REQUIRE_DATA") == "1":
            pytest.fail(f"motion data not found at {DATA}")
        pytest.skip(f"motion data not found at {DATA}")
    return DATA


@pytest.fixture(scope="session")
def daz_rotation_kb(data_dir):
    """Every Daz-friendly BVH take as a knowledge base with bone rotations, every 4th frame (30
    poses a second); a test takes its own subject out (``evaluate.kb_without``). Built once per
    session: reading every take is the slow part."""
    from mocap_gapfill.core.kb import build_kb

    return build_kb([data_dir / "cmu/bvh/daz_friendly"], fps=120, skip_frames=6, stride=4)


_EXIT = {}


def pytest_sessionfinish(session, exitstatus):
    _EXIT["status"] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    from mocap_gapfill.addon.bpy_exit import leave_if_bpy_would_crash

    leave_if_bpy_would_crash(_EXIT.get("status", 0))
