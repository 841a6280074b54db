"""The two public faces hold: plugins import only ``wott_hub.plugin_api``; ``wott_hub`` stays lazy.

Why a test and not a convention: a first-party plugin reaching into an
internal module is how the next refactor of the hub breaks every plugin, and
third-party authors copy what the first-party plugins do.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import wott_hub
from wott_hub import plugin_api

ROOT = Path(__file__).resolve().parents[2]
API = "wott_hub.plugin_api"


def wott_hub_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import of a ``wott_hub`` module in ``path``, at any depth."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules = [node.module]
            if node.module == "wott_hub":  # from wott_hub import plugin_api / tactile
                modules = [f"wott_hub.{alias.name}" for alias in node.names]
        else:
            continue
        found += [(node.lineno, m) for m in modules if m == "wott_hub" or m.startswith("wott_hub.")]
    return found


def first_party_plugin_modules() -> list[Path]:
    return sorted(ROOT.glob("plugins/*/src/**/*.py"))


def test_there_are_first_party_plugins_to_check():
    packages = {p.relative_to(ROOT).parts[3] for p in first_party_plugin_modules()}
    assert {"wott_driver_barrel", "wott_driver_flatpad", "wott_driver_taxel", "wott_vision"} <= packages


def test_first_party_plugins_import_nothing_of_wott_hub_but_the_plugin_api():
    offenders = [f"{path.relative_to(ROOT)}:{line}: {module}"
                 for path in first_party_plugin_modules()
                 for line, module in wott_hub_imports(path) if module != API]
    assert offenders == [], "import these names from wott_hub.plugin_api instead:\n" + "\n".join(offenders)


def test_the_import_check_sees_every_kind_of_import(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("import wott_hub.tactile\nfrom wott_hub import hub\n"
                      "def f():\n    from wott_hub.plugins.settings import backoff\n"
                      "from wott_hub.plugin_api import Driver\nimport numpy\n")
    assert wott_hub_imports(sample) == [(1, "wott_hub.tactile"), (2, "wott_hub.hub"),
                                        (5, API), (4, "wott_hub.plugins.settings")]


def test_every_name_of_the_plugin_api_resolves_and_the_list_is_flat_and_sorted():
    assert plugin_api.__all__ == sorted(plugin_api.__all__, key=lambda n: (not n.isupper(), n))
    assert len(set(plugin_api.__all__)) == len(plugin_api.__all__)
    for name in plugin_api.__all__:
        assert getattr(plugin_api, name) is not None, name


def test_the_plugin_api_covers_what_the_first_party_plugins_use():
    used = set()
    for path in first_party_plugin_modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == API:
                used |= {alias.name for alias in node.names}
    assert used and used <= set(plugin_api.__all__)


def test_no_module_of_wott_hub_imports_the_plugin_api():
    """A leaf: nothing inside depends on it, so it can never close an import cycle."""
    importers = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "src" / "wott_hub").rglob("*.py"))
                 if any(m == API for _, m in wott_hub_imports(p))]
    assert importers == []


def test_every_name_of_the_embedding_face_resolves():
    from wott_hub.config import HubConfig
    from wott_hub.errors import WottHubError
    from wott_hub.hub import Hub, serve

    assert wott_hub.Hub is Hub and wott_hub.serve is serve and wott_hub.HubConfig is HubConfig
    assert wott_hub.WottHubError is WottHubError and issubclass(wott_hub.DriverError, WottHubError)
    assert wott_hub.DriverError is plugin_api.DriverError
    for name in wott_hub.__all__:
        assert getattr(wott_hub, name) is not None, name
    assert set(wott_hub.__all__) <= set(dir(wott_hub))


def test_an_unknown_name_is_an_attribute_error():
    try:
        wott_hub.NoSuchThing  # noqa: B018
    except AttributeError as e:
        assert "NoSuchThing" in str(e)
    else:
        raise AssertionError("wott_hub.NoSuchThing resolved")


PROBE = r'''
import json, sys
before = set(sys.modules)
import wott_hub
after_top = sorted(m for m in set(sys.modules) - before if m.startswith("wott_hub"))
import wott_hub.plugin_api
heavy = [m for m in ("wott_hub.hub", "wott_hub.servient", "wott_hub.history", "wott_hub.config",
                     "wott_hub.network", "cv2", "onnxruntime", "sqlalchemy") if m in sys.modules]
print(json.dumps({"top": after_top, "heavy": heavy}))
'''


def test_importing_wott_hub_or_the_plugin_api_loads_no_hub():
    """In a fresh process: the faces are lazy, a plugin's import stays cheap."""
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["top"] == ["wott_hub"]
    assert result["heavy"] == []
