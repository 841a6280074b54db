"""``wott-hub calibrate``: a family's calibration through its plugin (the gel sensors' depth from Taxim's
real ball presses); every refusal one line and exit 2."""

from __future__ import annotations

from importlib import resources

import numpy as np


def test_calibrate_writes_the_gel_depth_table_and_refusals_are_one_line(cli, one_error_line, tmp_path):
    with resources.as_file(resources.files("taxim") / "calib" / "gelsight_mini" / "dataPack.npz") as data:
        out = tmp_path / "mini-depth.npz"
        res = cli("calibrate", "gelsight-mini", str(data), "-o", str(out), "--option", "ball_diameter_mm=4")
        assert res.returncode == 0, res.stderr
        assert res.stdout.startswith(f"wrote {out}") and "24 presses of a 4 mm ball" in res.stdout
        with np.load(out) as f:
            assert f["lut"].shape == (64, 64, 64, 2) and float(f["ball_radius_mm"]) == 2.0
        line = one_error_line(cli("calibrate", "gelsight-mini", str(data), "-o", str(out)), 2)
        assert "ball_diameter_mm" in line
        res = cli("calibrate", "gelsight-mini", str(data), "-o", str(out), "--option", "x")
        line = one_error_line(res, 2)
        assert "--option: expected KEY=VALUE" in line
    line = one_error_line(cli("calibrate", "flat-vision", "x.npz", "-o", str(out)), 2)
    assert "has no calibration" in line
    line = one_error_line(cli("calibrate", "no-such", "x.npz", "-o", str(out)), 2)
    assert "not installed" in line
