"""Issue 32 item 7: docs/configuration.md has a complete ``[[device]]`` example and the settings table of
every first-party family, and each example is a config ``wott-hub config check`` accepts.

The examples are read from the committed page itself (its ``toml`` blocks), so what a reader copies
is what is checked; the page being the generated one is tests/test_config_bounds.py's check.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "configuration.md"


def _examples() -> dict[str, str]:
    """Each family's section of the page: its name -> its ``toml`` example."""
    text = PAGE.read_text()
    out = {}
    for family, body in re.findall(r'^### `family = "([^"]+)"`\n(.*?)(?=^### |^## )', text, re.S | re.M):
        blocks = re.findall(r"```toml\n(.*?)```", body, re.S)
        assert len(blocks) == 1, family
        out[family] = blocks[0]
    return out


def test_every_first_party_family_has_a_settings_table_and_an_example():
    from wott_hub.config_docs import FIRST_PARTY
    from wott_hub.plugins import get_registry

    families = {f.name for f in get_registry().families().values() if f.plugin in FIRST_PARTY}
    assert families == {"scene", "wot-remote", "barrel-vision", "flat-vision", "taxel-array", "anyskin",
                        "xela", "gelsight-mini", "digit"}
    assert set(_examples()) == families
    text = PAGE.read_text()
    for key in ("`kpa_per_count`", "`optics.focal_px`", "`cameras.f_px`", "`idle_timeout_s`", "`rate_hz`"):
        assert f"| {key} |" in text, key
    assert "Rules: `port` required unless `simulate = true`." in text


def test_each_example_is_a_whole_device_the_check_accepts(cli, tmp_path):
    examples = _examples()
    for family, example in examples.items():
        (device,) = tomllib.loads(example)["device"]
        assert device["family"] == family and device["id"]
        assert len(device) >= 4, f"{family}: a complete example sets more than id and family"
    config = tmp_path / "hub.toml"
    config.write_text("\n".join(examples.values()))
    res = cli("config", "check", "--config", str(config))
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"{config}: {len(examples)} device(s): OK"


def test_the_scene_example_opens(cli, tmp_path):
    config = tmp_path / "hub.toml"
    config.write_text(_examples()["scene"])
    res = cli("config", "check", "--config", str(config), "--open", timeout=180)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[0].startswith("opened finger-1 (scene): 256 nodes, shape rectangularPrism")


def test_the_commented_example_config_passes_the_check(cli):
    res = cli("config", "check", "--config", str(ROOT / "docs" / "hub.example.toml"))
    assert res.returncode == 0, res.stderr
