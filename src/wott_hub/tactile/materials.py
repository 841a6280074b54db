"""Skin materials: names, Shore hardness and the elastic modulus derived from it.

Datasheets give silicone skins as a Shore hardness and a "100 % modulus" (the
nominal stress at 100 % strain); mechanics needs a small-strain Young's
modulus E. Both routes are here, and both are approximations:

* **From a datasheet 100 % modulus** σ₁₀₀ (the preferred route): a neo-Hookean
  solid in uniaxial tension has nominal stress (E/3)(λ − λ⁻²); at λ = 2 that
  is 0.5833 E, so E = σ₁₀₀ / 0.5833. Silicones soften then stiffen, so the
  small-strain modulus of a real sample differs from this by up to about ±30 %.
* **From a Shore hardness** (when only that is known): a table of anchors,
  each the datasheet-derived E of a product at its nominal hardness, joined by
  straight lines in log E (``SHORE_00_ANCHORS``, ``SHORE_A_ANCHORS``). Past
  Shore A40 the table follows Gent's relation (Gent 1958),
  E = 0.0981 (56 + 7.62336 S) / (0.137505 (254 − 2.54 S)) MPa, which is
  fitted on harder rubbers and overestimates soft silicones (it gives 0.41 MPa
  at A10 where Dragon Skin 10's datasheet gives 0.26 MPa). Shore 00 above 50 is
  joined to Shore A through the durometer comparison 00-95 ≈ A70.

Sources: Smooth-On technical bulletins (Ecoflex series: 00-10, 00-30, 00-50;
Dragon Skin series: 10, 20, 30) for hardness, 100 % modulus and specific
gravity; A. N. Gent, Trans. IRI 34 (1958) 46 for Shore A; Qi, Joyce & Boyce,
Rubber Chem. Technol. 76 (2003) 419 for the neo-Hookean reading of Shore A;
Hoster et al., Polymers 18 (2026) 620 (a measured Shore 00/A to initial modulus
fit, 13 % worst error on its own samples) for the size of the scatter.
Uncertainty stated here (one standard deviation, relative): ±30 % on the Shore A
table and on datasheet σ₁₀₀ conversions, ±40 % on the Shore 00 table, ±50 %
outside the anchored range. Forces computed with these moduli inherit these
uncertainties one for one (force is linear in E); see docs/mechanics.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from wott_hub.errors import InvalidInput

__all__ = [
    "MATERIALS",
    "Material",
    "MaterialError",
    "SHORE_00_ANCHORS",
    "SHORE_A_ANCHORS",
    "modulus_from_100_percent",
    "modulus_uncertainty",
    "shore_to_modulus_mpa",
]


class MaterialError(InvalidInput):
    """Unknown hardness scale or a value outside it."""


_SHORE = re.compile(r"^\s*shore\s*(00|a)\s*-?\s*(\d+(?:\.\d+)?)\s*$", re.IGNORECASE)
_NEO_HOOKE_100 = (2.0 - 0.25) / 3.0  # σ₁₀₀ / E for a neo-Hookean solid at λ = 2
_PSI = 0.00689476  # MPa


def modulus_from_100_percent(sigma_100_mpa: float) -> float:
    """Small-strain Young's modulus (MPa) from a datasheet 100 % modulus, neo-Hookean reading."""
    if not (math.isfinite(sigma_100_mpa) and sigma_100_mpa > 0):
        raise MaterialError(f"100 % modulus must be a positive number of MPa, got {sigma_100_mpa}")
    return sigma_100_mpa / _NEO_HOOKE_100


def _gent(a: float) -> float:
    return 0.0981 * (56 + 7.62336 * a) / (0.137505 * (254 - 2.54 * a))


# (hardness, E in MPa, where it comes from). Datasheet anchors: E = σ₁₀₀ / 0.5833.
SHORE_00_ANCHORS: tuple[tuple[float, float, str], ...] = (
    (10.0, modulus_from_100_percent(8 * _PSI), "Ecoflex 00-10, 100 % modulus 8 psi"),
    (30.0, modulus_from_100_percent(10 * _PSI), "Ecoflex 00-30, 100 % modulus 10 psi"),
    (50.0, modulus_from_100_percent(12 * _PSI), "Ecoflex 00-50, 100 % modulus 12 psi"),
    (95.0, _gent(70.0), "durometer comparison 00-95 ~ A70, Gent at A70"),
)
SHORE_A_ANCHORS: tuple[tuple[float, float, str], ...] = (
    (10.0, modulus_from_100_percent(22 * _PSI), "Dragon Skin 10, 100 % modulus 22 psi"),
    (20.0, modulus_from_100_percent(49 * _PSI), "Dragon Skin 20, 100 % modulus 49 psi"),
    (30.0, modulus_from_100_percent(86 * _PSI), "Dragon Skin 30, 100 % modulus 86 psi"),
    (40.0, _gent(40.0), "Gent's relation from here up"),
)


def _log_interp(x: float, anchors: tuple[tuple[float, float, str], ...]) -> float:
    """Piecewise-linear in log E through the anchors, extended linearly (in log E) at both ends."""
    xs = [a[0] for a in anchors]
    logs = [math.log(a[1]) for a in anchors]
    i = 1
    while i < len(xs) - 1 and x > xs[i]:
        i += 1
    x0, x1, y0, y1 = xs[i - 1], xs[i], logs[i - 1], logs[i]
    return math.exp(y0 + (y1 - y0) * (x - x0) / (x1 - x0))


def _parse(shore: str) -> tuple[str, float]:
    m = _SHORE.match(shore)
    if not m:
        raise MaterialError(f"cannot read hardness {shore!r}: expected 'Shore 00-NN' or 'Shore ANN'")
    scale, value = m.group(1).upper(), float(m.group(2))
    if not 0 <= value <= 100:
        raise MaterialError(f"hardness {shore!r} is outside 0..100")
    return scale, value


def shore_to_modulus_mpa(shore: str) -> float:
    """Young's modulus (MPa) from a hardness string such as ``"Shore 00-30"`` or ``"Shore A20"``."""
    scale, value = _parse(shore)
    if scale == "00":
        return _log_interp(min(value, 95.0), SHORE_00_ANCHORS)
    if value <= SHORE_A_ANCHORS[-1][0]:
        return _log_interp(value, SHORE_A_ANCHORS)
    return _gent(min(value, 95.0))  # Gent's relation diverges at 100


def modulus_uncertainty(shore: str) -> float:
    """Relative one-sigma uncertainty of :func:`shore_to_modulus_mpa` for this hardness."""
    scale, value = _parse(shore)
    if scale == "00":
        return 0.4 if 10 <= value <= 50 else 0.5
    return 0.3 if 10 <= value <= 95 else 0.5


@dataclass(frozen=True, slots=True)
class Material:
    """A skin material as the TD advertises it, with the numbers mechanics needs.

    ``modulus_100_mpa`` is the datasheet 100 % modulus; when given it sets E
    (neo-Hookean reading) instead of the Shore table. ``damping_time_s`` is the
    Kelvin-Voigt retardation time τ = η/E: the dashpot of every element is τ
    times its spring, so the loss tangent at angular frequency ω is ωτ. 0.5 ms
    gives tan δ ≈ 0.03 at 10 Hz and 0.3 at 100 Hz, the order reported for
    platinum-cure silicones in that band (a Kelvin-Voigt solid cannot follow
    the measured, flatter, frequency dependence; this is its main limit).
    """

    material_type: str
    shore_hardness: str
    density_kg_m3: float = 1070.0
    youngs_modulus_mpa: float | None = None  # overrides everything when measured
    modulus_100_mpa: float | None = None  # datasheet 100 % modulus
    damping_time_s: float = 5e-4

    @property
    def modulus_mpa(self) -> float:
        if self.youngs_modulus_mpa is not None:
            return self.youngs_modulus_mpa
        if self.modulus_100_mpa is not None:
            return modulus_from_100_percent(self.modulus_100_mpa)
        return shore_to_modulus_mpa(self.shore_hardness)

    @property
    def modulus_uncertainty(self) -> float:
        """Relative one-sigma uncertainty of :attr:`modulus_mpa` (0.1 for a measured modulus)."""
        if self.youngs_modulus_mpa is not None:
            return 0.1
        if self.modulus_100_mpa is not None:
            return 0.3
        return modulus_uncertainty(self.shore_hardness)


MATERIALS: dict[str, Material] = {
    "ecoflex-00-10": Material("ecoflex", "Shore 00-10", 1040.0, modulus_100_mpa=8 * _PSI),
    "ecoflex-00-30": Material("ecoflex", "Shore 00-30", 1070.0, modulus_100_mpa=10 * _PSI),
    "ecoflex-00-50": Material("ecoflex", "Shore 00-50", 1070.0, modulus_100_mpa=12 * _PSI),
    "dragonskin-10": Material("dragonskin", "Shore A10", 1070.0, modulus_100_mpa=22 * _PSI),
    "dragonskin-20": Material("dragonskin", "Shore A20", 1080.0, modulus_100_mpa=49 * _PSI),
    "dragonskin-30": Material("dragonskin", "Shore A30", 1080.0, modulus_100_mpa=86 * _PSI),
}
