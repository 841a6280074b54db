"""Issue 32 item 2: the listing commands' tables fit the width they are given and never cut a value:
prose wraps at spaces, then columns go by priority, then rows become blocks."""

from __future__ import annotations

import importlib
import json

import pytest

table = importlib.import_module("wott_hub.cli._table")
Column, render = table.Column, table.render

URL = "http://127.0.0.1:41075/wot/urn:wott-hub:h286d4f83371:device:barrel-1"
TIME = "2026-11-27 12:26:33.633"


def _rows(n: int = 3):
    return [{"id": f"barrel-{k}", "family": "barrel-vision", "from": TIME, "url": URL,
             "why": "the camera at /dev/video2 stopped answering; retried every 30 s until it comes back",
             "n": 1000 * k} for k in range(n)]


def test_everything_fits_a_wide_terminal_unchanged():
    cols = [Column("id", "id"), Column("family", "family", drop=1), Column("from", "from"),
            Column("URL", "url")]
    lines = render(cols, _rows(), width=200)
    assert lines[0].split() == ["id", "family", "from", "URL"]
    assert all(URL in line and TIME in line for line in lines[2:])
    assert not any("not shown" in line for line in lines)


def test_columns_are_dropped_by_priority_and_named_never_cut():
    cols = [Column("id", "id"), Column("family", "family", drop=2), Column("n", "n", drop=1, align=">"),
            Column("from", "from"), Column("URL", "url")]
    lines = render(cols, _rows(), width=110)
    assert lines[0].split() == ["id", "n", "from", "URL"]  # family (2) went before n (1)
    assert lines[-1] == "(family: not shown at 110 columns; a wider terminal or --json shows them)"
    body = lines[2:-1]
    assert all(len(line) <= 110 for line in lines[:-1])
    assert [line.split()[0] for line in body] == ["barrel-0", "barrel-1", "barrel-2"]
    assert all(URL in line and TIME in line for line in body)


def test_prose_wraps_at_spaces_before_a_column_is_dropped():
    cols = [Column("id", "id"), Column("family", "family", drop=1), Column("why", "why", wrap=True)]
    lines = render(cols, _rows(1), width=60)
    assert lines[0].split() == ["id", "family", "why"] and all(len(line) <= 60 for line in lines)
    prose = " ".join(line[len("barrel-0  barrel-vision  "):].strip() for line in lines[2:])
    assert prose == _rows(1)[0]["why"]  # every word, in order, none split


def test_rows_become_blocks_when_even_the_essentials_do_not_fit():
    cols = [Column("id", "id"), Column("from", "from"), Column("URL", "url")]
    lines = render(cols, _rows(2), width=80)
    assert lines[:4] == ["id:   barrel-0", f"from: {TIME}", f"URL:  {URL}", ""]
    assert len([line for line in lines if line.startswith("URL:")]) == 2


def test_multi_line_cells_and_titles():
    cols = [Column("plugin", "p"), Column("families", "f")]
    lines = render(cols, [{"p": "barrel", "f": "barrel-vision\nbarrel-sim"}], width=80, title="plugins")
    assert lines == ["plugins", "plugin  families", "------  -------------", "barrel  barrel-vision",
                     "        barrel-sim"]


@pytest.mark.parametrize("width", [40, 60, 80, 100, 140])
def test_no_value_is_ever_cut_at_any_width(width):
    cols = [Column("id", "id"), Column("family", "family", drop=1), Column("from", "from"),
            Column("URL", "url", drop=2), Column("why", "why", wrap=True)]
    text = "\n".join(render(cols, _rows(), width=width))
    for row in _rows():
        assert row["id"] in text and TIME in text
        assert URL in text or "URL" in text.splitlines()[-1]  # whole, or named as not shown


def test_tokens_list_at_80_columns_keeps_names_and_ids_whole(cli, tmp_path):
    file = tmp_path / ("a-rather-long-folder-name-" * 3) / "tokens.json"
    tokens = (("dashboard-of-the-ward-3-night-shift", "read"), ("robot-cell-controller", "control"))
    for name, scope in tokens:
        assert cli("tokens", "create", name, "--scope", scope, "--file", str(file)).returncode == 0
    res = cli("tokens", "list", "--file", str(file))
    assert res.returncode == 0, res.stderr
    listed = {t["name"]: t
              for t in json.loads(cli("tokens", "list", "--file", str(file), "--json").stdout)}
    assert all(len(line) <= 80 for line in res.stdout.splitlines())
    for name, t in listed.items():
        assert f"{name}  " in res.stdout and t["id"] in res.stdout and t["where"] == str(file)
