"""``uv run`` as the README types it starts the command without a bytecode pass over the venv.

With ``[tool.uv] compile-bytecode = true`` every ``uv run`` re-compiled ~6,500 files first
(0.8-1.6 s per start, astral-sh/uv#12202); the ``.pyc`` files are written once at install
instead (``uv sync --compile-bytecode``, docs/hub.md "Start-up").
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _uv() -> str:
    uv = os.environ.get("UV") or shutil.which("uv")  # `uv run pytest` exports UV
    assert uv, "uv not found: run the tests with `uv run pytest`"
    return uv


def test_project_does_not_ask_uv_run_to_compile_bytecode():
    with open(ROOT / "pyproject.toml", "rb") as f:
        settings = tomllib.load(f)["tool"]["uv"]
    assert "compile-bytecode" not in settings


def test_uv_run_starts_the_command_without_a_bytecode_pass():
    env = {k: v for k, v in os.environ.items() if k != "UV_COMPILE_BYTECODE"}
    res = subprocess.run([_uv(), "run", "python", "-c", "print('started')"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "started"
    assert "Bytecode compiled" not in res.stderr
