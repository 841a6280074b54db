from functools import lru_cache

import pytest


@lru_cache(maxsize=1)
def _layout():
    from wott_driver_barrel.settings import build_layout

    return build_layout()


@pytest.fixture(scope="session")
def layout():
    """The TacLink mesh with its markers and cameras (built once: ray casting takes a moment)."""
    return _layout()
