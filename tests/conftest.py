"""Shared test fixtures: where the shared folder (paper data, specs, schemas) lives."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: ``../shared`` beside the checkout (CI clones the project with shared/ beside it)
SHARED = REPO.parent / "shared"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not SHARED.is_dir():
        pytest.fail(f"the shared folder is missing: expected {SHARED}")
    return SHARED


@pytest.fixture(scope="session")
def paper_data(shared_dir) -> Path:
    return shared_dir / "data" / "paper"
