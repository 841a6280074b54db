"""Every hook is documented for plugin authors, and only real hooks are (like datasette's check)."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from wott_hub.plugins import hookspecs

DOC = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def hook_specs() -> dict[str, object]:
    return {name: fn for name, fn in inspect.getmembers(hookspecs, inspect.isfunction)
            if hasattr(fn, f"{hookspecs.PROJECT}_spec")}


def documented_hooks() -> list[str]:
    return re.findall(r"^### `?(wott_hub_\w+)\(", DOC.read_text(), flags=re.MULTILINE)


def test_there_are_hooks_for_families_opening_demo_devices_and_claiming():
    assert set(hook_specs()) == {"wott_hub_families", "wott_hub_open_device", "wott_hub_demo_devices",
                                 "wott_hub_claim_service", "wott_hub_claim_td"}


def test_every_hook_is_documented_in_docs_plugins_md():
    documented = documented_hooks()
    assert sorted(documented) == sorted(hook_specs()), "one '### hook(args)' heading per hook, please"
    assert len(documented) == len(set(documented))


def test_each_documented_signature_matches_the_spec():
    text = DOC.read_text()
    for name, fn in hook_specs().items():
        args = ", ".join(inspect.signature(fn).parameters)
        assert re.search(rf"^### `?{name}\({args}\)", text, flags=re.MULTILINE), f"{name}({args})"


def test_every_hookspec_docstring_says_when_it_is_called_and_what_to_return():
    for name, fn in hook_specs().items():
        doc = inspect.getdoc(fn) or ""
        assert "Called" in doc and "Return" in doc, name
