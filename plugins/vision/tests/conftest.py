from pathlib import Path

import pytest

TACLINK = Path(__file__).resolve().parents[3] / ".." / "shared" / "data" / "taclink"


@pytest.fixture(scope="session")
def taclink_dir() -> Path:
    if not (TACLINK / "real_up_7660.jpg").exists():
        pytest.fail(f"reference data missing: {TACLINK} (../shared must sit beside the checkout)")
    return TACLINK.resolve()
