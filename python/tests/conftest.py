"""Shared fixtures of the Python tests (run by scripts/test.sh in its virtual environment)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    """The repository root."""
    return ROOT


@pytest.fixture(scope="session")
def plugin_dir() -> Path:
    """Where scripts/test.sh built the compiled example plugins (MODESUITE_PLUGIN_DIR)."""
    d = os.environ.get("MODESUITE_PLUGIN_DIR")
    if not d:
        pytest.fail("MODESUITE_PLUGIN_DIR is not set: run the tests through scripts/test.sh")
    return Path(d)


@pytest.fixture(scope="session")
def modesuite_bin() -> Path:
    """The `modesuite` command that scripts/test.sh built (MODESUITE_BIN)."""
    b = os.environ.get("MODESUITE_BIN")
    if not b:
        pytest.fail("MODESUITE_BIN is not set: run the tests through scripts/test.sh")
    return Path(b)
