"""Every hook is documented for plugin authors, and only real hooks are (like datasette's check)."""

from __future__ import annotations

import ast
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


def test_there_are_hooks_for_families_opening_demo_devices_claiming_usb_devices_and_calibrating():
    assert set(hook_specs()) == {"wott_hub_families", "wott_hub_open_device", "wott_hub_demo_devices",
                                 "wott_hub_claim_td", "wott_hub_usb_devices", "wott_hub_calibrate"}


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


def _section(text: str, name: str) -> str:
    start = re.search(rf"^### `?{name}\(", text, flags=re.MULTILINE)
    assert start, name
    end = re.search(r"^##", text[start.end():], flags=re.MULTILINE)
    return text[start.end(): start.end() + end.start()] if end else text[start.end():]


def test_every_hook_has_a_test_named_after_it():
    """datasette's guard: a hook nobody tests by name is a hook nobody noticed breaking."""
    names = set()
    for path in DOC.parents[1].joinpath("tests", "plugins").glob("test_*.py"):
        names |= {n.name for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.FunctionDef)}
    missing = sorted(h for h in hook_specs() if f"test_hook_{h}" not in names)
    assert not missing, f"no test_hook_<name> in tests/plugins for: {missing}"


def test_every_hook_has_a_documented_example_that_implements_it_and_a_real_user():
    text = DOC.read_text()
    for name in hook_specs():
        section = _section(text, name)
        examples = re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)
        assert examples, f"{name}: no python example in docs/plugins.md"
        namespace: dict[str, object] = {}
        exec(compile(examples[0], f"docs/plugins.md:{name}", "exec"), namespace)  # defines, calls nothing
        impl = namespace.get(name)
        assert callable(impl) and hasattr(impl, f"{hookspecs.PROJECT}_impl"), f"{name}: not a hookimpl"
        users = re.findall(r"`((?:src|plugins)/[\w/.]+\.py)`", section.split("Used by", 1)[-1])
        assert "Used by" in section and users, f"{name}: no 'Used by' naming a real plugin module"
        sources = [(DOC.parents[1] / user).read_text() for user in users]  # each exists
        assert any(f"def {name}(" in src for src in sources), f"{name}: none of {users} implements it"
