"""Real GelSight Mini presses (Taxim's, in the ``taxim`` wheel) as a folder recording, made once."""

from __future__ import annotations

from pathlib import Path

import pytest
from wott_driver_gel.evaluation import PressSet, load_taxim, write_recording


@pytest.fixture(scope="session")
def mini() -> PressSet:
    return load_taxim("gelsight_mini")


@pytest.fixture(scope="session")
def mini_recording(mini: PressSet, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[int]]:
    folder = tmp_path_factory.mktemp("mini") / "frames"
    at = write_recording(folder, mini.background, mini.presses)
    return folder, at
