"""A test's real part (Xvfb, PostgreSQL, a browser) is missing: skip on a developer's machine,
fail under CI=true, where .ci/run installs it and its absence is a defect of the set-up."""

from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def need(available: bool, why: str) -> None:
    """Skip (or, under CI, fail) the calling test when `available` is false."""
    if available:
        return
    if in_ci():
        pytest.fail(f"{why} (CI=true: .ci/run must install it; a missing real part fails, never skips)")
    pytest.skip(why)
