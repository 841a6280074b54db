"""Issue 32 item 2: every command's ``--help`` says all its help text says, at 80 columns.

Rich markup once swallowed ``[[device]]``, ``[[security.client]]`` and ``[security]`` ("settings a []
table", "default:  tokens_file."): here every command's help and every option's help must appear
word for word in what ``--help`` prints, with no empty brackets and no line over 80 columns (save
one whose single word is longer).
"""

from __future__ import annotations

import re

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from wott_hub.cli import app

ROOT = get_command(app)


def _commands(group=ROOT, path=()):
    yield path, group
    for name, cmd in sorted(getattr(group, "commands", {}).items()):
        yield from _commands(cmd, (*path, name))


COMMANDS = list(_commands())


def _words(text: str) -> str:
    """Whitespace as one space; a word that click's wrapping broke after a hyphen joined again."""
    return re.sub(r"(?<=\w-) (?=\w)", "", " ".join(text.split()))


def _help(path) -> str:
    res = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80"}, terminal_width=80)
    assert res.exit_code == 0, res.output
    return res.output


@pytest.mark.parametrize(("path", "cmd"), COMMANDS, ids=[" ".join(p) or "wott-hub" for p, _ in COMMANDS])
def test_help_says_every_word_of_its_texts_within_80_columns(path, cmd):
    out = _help(path)
    flat = _words(out)
    assert "[]" not in out and "()" not in out, out
    texts = [cmd.help or ""] + [getattr(p, "help", None) or "" for p in cmd.params]
    for text in texts:
        for para in re.split(r"\n\s*\n", text.strip()):
            assert _words(para) in flat, f"{' '.join(path)} --help lost words of: {para!r}\n{out}"
    for line in out.splitlines():
        assert len(line) <= 80 or max(len(w) for w in line.split()) > 40, line


def test_the_names_rich_markup_swallowed_are_there():
    assert "[[device]]" in _words(_help(("plugins", "families")))
    assert "[[security.client]] lines" in _words(_help(("tokens", "create")))
    assert "the tokens_file of the config's [security] table" in _words(_help(("run",)))
    assert "[security] tokens_file or run --tokens" in _words(_help(("tokens", "list")))


def test_every_listing_command_has_json():
    listing = [("history", "list"), ("history", "audit"), ("devices", "list"), ("directory", "list"),
               ("plugins", "list"), ("plugins", "families"), ("tokens", "list"), ("discover",),
               ("config", "check")]
    for path in listing:
        assert "--json" in _help(path), path


@pytest.mark.parametrize(("path", "cmd"), [(p, c) for p, c in COMMANDS if getattr(c, "commands", None)],
                         ids=[" ".join(p) or "wott-hub" for p, c in COMMANDS if getattr(c, "commands", None)])
def test_a_groups_list_of_commands_cuts_no_summary(path, cmd):
    out = _help(path)
    listed = out.split("\nCommands:\n", 1)[1].splitlines()
    assert len([line for line in listed if line.strip()]) == len(cmd.commands)
    assert not [line for line in listed if line.rstrip().endswith("...")], out
