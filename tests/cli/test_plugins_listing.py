"""Issue 32 item 2 for ``wott-hub plugins``: the listings at 80 columns (a real process). Apart from
tests/cli/test_demo.py: they need no hub, and a demo fleet left simulating while they run costs CPU."""

from __future__ import annotations

import re


def test_plugins_list_and_families_at_80_columns(cli):
    res = cli("plugins", "list")
    assert res.returncode == 0 and all(len(line) <= 80 for line in res.stdout.splitlines())
    for dist in ("wott-driver-barrel", "wott-driver-flatpad", "wott-driver-taxel"):
        assert re.search(rf"\s{dist}\s", res.stdout), res.stdout
    res = cli("plugins", "families")
    lines = res.stdout.splitlines()
    assert res.returncode == 0 and len(lines) < 40 and all(len(line) <= 80 for line in lines)
    res = cli("plugins", "families", "taxel-array")
    assert res.returncode == 0 and "rule: port required unless simulate = true" in res.stdout
    assert re.search(r"^kpa_per_count +0\.01 +number, >0, ≤10 ", res.stdout, re.M), res.stdout
    assert re.search(r"^port +string ", res.stdout, re.M)
