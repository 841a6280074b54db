"""A wrong ``[usb]`` table: ``wott-hub run`` refuses it in one line naming the key, before anything starts;
``wott-hub config check`` says the same line."""

from __future__ import annotations

import pytest

from wott_hub.config import HubConfig


@pytest.mark.parametrize(("table", "said"), [
    ('adopt = "anyskin"', "[usb].adopt: a list of device family names, got 'anyskin'"),
    ('adopt = ["Any Skin"]', "[usb].adopt[0]: a device family name, got 'Any Skin'"),
    ('adopt = ["anyskin", "anyskin"]', "[usb].adopt: 'anyskin' is listed twice"),
    ("adpt = []", "[usb].adpt: unknown key (known: adopt); did you mean 'adopt'?"),
    ('adopt = ["anyskin", "anyskn"]', "[usb].adopt[1]: unknown family 'anyskn'; did you mean 'anyskin'?"),
    ('adopt = ["xela"]', "[usb].adopt[0]: family 'xela' declares no USB device the hub can adopt"),
])
def test_a_wrong_usb_table_is_one_line_naming_the_key(cli, one_error_line, tmp_path, table, said):
    config = tmp_path / "hub.toml"
    config.write_text(f"[hub]\nhttp_port = 0\nhistory = false\n\n[usb]\n{table}\n")
    line = one_error_line(cli("run", "--config", str(config), timeout=120), 2)
    assert line.startswith(f"error: {config}: ") and said in line, line
    check = cli("config", "check", "--config", str(config))
    assert check.returncode == 2 and line in check.stderr.splitlines(), check.stderr


def test_a_config_that_only_adopts_usb_devices_is_not_the_demo():
    cfg = HubConfig.from_dict({"usb": {"adopt": ["anyskin"]}})
    assert not cfg.demo and cfg.usb.adopt == ("anyskin",) and cfg.devices == ()
    assert HubConfig.from_dict({}).demo and not HubConfig().usb.enabled


def test_config_check_says_which_usb_families_are_adopted(cli, tmp_path):
    config = tmp_path / "hub.toml"
    config.write_text('[usb]\nadopt = ["anyskin", "taxel-array"]\n')
    res = cli("config", "check", "--config", str(config))
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"{config}: 0 device(s) and USB anyskin, taxel-array when plugged in: OK"
