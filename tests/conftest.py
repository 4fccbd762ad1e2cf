"""Shared fixtures. Real datasets live in ../shared/data beside the repository: tests that need
them skip when the folder is absent, and fail when CI=true and it is absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("INSGNSS_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_data(*parts: str) -> Path:
    """Path under ../shared/data; skips the test if absent (fails in CI)."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"shared dataset {p} is missing in CI")
        pytest.skip(f"shared dataset {p} not present")
    return p


@pytest.fixture
def drive_dir() -> Path:
    return shared_data("gnss-imu-rtklibexplorer", "drive_0708")


@pytest.fixture
def pyshoe_dir() -> Path:
    return shared_data("pyshoe-vicon")
