"""Shared test configuration."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "occtool", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow], print_blob=True
)
# CI (.ci/run sets HYPOTHESIS_PROFILE=ci) draws the same examples on every run, so a landing
# never hangs on a new random draw; local runs keep exploring, and a failure they find
# becomes an @example.
settings.register_profile("ci", parent=settings.get_profile("occtool"), derandomize=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "occtool"))

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "fixtures"
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture
def fixtures_dir() -> Path:
    return FIXTURES


@pytest.fixture
def shared_data() -> Path:
    """The real data sets beside the checkout (../shared/data); tests skip when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not beside this checkout")
    return SHARED_DATA
