"""Small skins the mechanics tests share (built once per session: assembly is the slow part)."""

from __future__ import annotations

import pytest

from wott_hub.tactile import MATERIALS, flat_pad, taclink_barrel
from wott_hub.tactile.mechanics import SkinModel


@pytest.fixture(scope="session")
def barrel_model() -> SkinModel:
    return SkinModel.from_material(taclink_barrel(), MATERIALS["ecoflex-00-30"], 3.0)


@pytest.fixture(scope="session")
def pad_model() -> SkinModel:
    return SkinModel.from_material(flat_pad(13, 13, pitch_mm=1.5), MATERIALS["ecoflex-00-50"], 4.0)
