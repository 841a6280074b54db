import math

import pytest

from wott_hub.tactile.materials import (
    MATERIALS,
    SHORE_00_ANCHORS,
    SHORE_A_ANCHORS,
    Material,
    MaterialError,
    modulus_from_100_percent,
    modulus_uncertainty,
    shore_to_modulus_mpa,
)

PSI = 0.00689476


def test_datasheet_reading_is_neo_hookean():
    # nominal stress of a neo-Hookean solid at stretch 2 is (E/3)(2 - 1/4)
    e = modulus_from_100_percent(10 * PSI)
    assert e * (2 - 0.25) / 3 == pytest.approx(10 * PSI)
    assert MATERIALS["ecoflex-00-30"].modulus_mpa == pytest.approx(0.1182, rel=1e-3)
    assert MATERIALS["dragonskin-30"].modulus_mpa == pytest.approx(1.017, rel=1e-3)


def test_table_goes_through_its_anchors_and_the_materials_agree_with_it():
    for anchors, scale in ((SHORE_00_ANCHORS, "00-"), (SHORE_A_ANCHORS, "A")):
        for hardness, e, _source in anchors:
            assert shore_to_modulus_mpa(f"Shore {scale}{hardness:g}") == pytest.approx(e, rel=1e-9)
    for m in MATERIALS.values():  # a material's datasheet modulus is the table's value at its hardness
        assert shore_to_modulus_mpa(m.shore_hardness) == pytest.approx(m.modulus_mpa, rel=1e-9)


@pytest.mark.parametrize("scale,top", [("00-", 100), ("A", 100)])
def test_modulus_is_continuous_and_increasing(scale, top):
    values = [shore_to_modulus_mpa(f"Shore {scale}{h / 4:g}") for h in range(0, 4 * top + 1)]
    assert all(math.isfinite(v) and v > 0 for v in values)
    assert all(b >= a for a, b in zip(values, values[1:], strict=False))
    jumps = [b / a for a, b in zip(values, values[1:], strict=False)]
    assert max(jumps) < 1.15  # no step between table segments (a quarter point apart)


def test_soft_end_of_shore_a_meets_the_shore_00_silicones():
    # Ecoflex 00-30 is about Shore A0: the two scales should not disagree by more than their uncertainty
    assert shore_to_modulus_mpa("Shore A0") == pytest.approx(shore_to_modulus_mpa("Shore 00-30"), rel=0.4)


def test_uncertainty_and_priority():
    assert modulus_uncertainty("Shore A20") == 0.3 and modulus_uncertainty("Shore 00-30") == 0.4
    assert modulus_uncertainty("Shore 00-80") == 0.5
    m = Material("x", "Shore A20", youngs_modulus_mpa=0.5, modulus_100_mpa=1.0)
    assert m.modulus_mpa == 0.5 and m.modulus_uncertainty == 0.1
    assert Material("x", "Shore A20", modulus_100_mpa=0.35).modulus_mpa == pytest.approx(0.6)
    assert Material("x", "Shore A20").modulus_mpa == pytest.approx(shore_to_modulus_mpa("Shore A20"))


@pytest.mark.parametrize("bad", ["Shore D40", "A20", "Shore 00-120", "", "Shore A101", "Shore A NaN"])
def test_bad_hardness_is_a_clear_error(bad):
    with pytest.raises(MaterialError):
        shore_to_modulus_mpa(bad)


def test_bad_100_percent_modulus():
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(MaterialError):
            modulus_from_100_percent(bad)
