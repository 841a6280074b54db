"""The contact finder on real GelSight Mini frames under an illumination drift, and a press split in two."""

from __future__ import annotations

import numpy as np
from wott_driver_gel.contacts import ContactParams, find_contacts
from wott_driver_gel.driver import DRIFT_SIGMA_MM
from wott_driver_gel.evaluation import PressSet
from wott_driver_gel.rest import RestReference, smooth

K = 0.0295  # mm/px, Taxim's Mini


def params(**kw: float) -> ContactParams:
    base: dict[str, float] = {"min_area_px": 0.5 / K**2, "open_px": 5, "drift_sigma_px": DRIFT_SIGMA_MM / K}
    base.update(kw)
    return ContactParams(**base)  # type: ignore[arg-type]


def drifted(image: np.ndarray) -> np.ndarray:
    """``image`` under a smooth light change: each channel's gain a different ramp across the view (up to
    ±12 %) and an offset of a few grey levels, as an LED warming up or the exposure moving makes it."""
    h, w = image.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    gains = np.stack([1 + 0.12 * (xx - 0.5), 1 - 0.10 * (yy - 0.5), 1 + 0.08 * (xx + yy - 1)], axis=-1)
    out = image.astype(np.float64) * gains + np.array([3.0, -2.0, 4.0])
    result: np.ndarray = np.clip(np.rint(out), 0, 255).astype(np.uint8)
    return result


def test_drift_gives_no_phantom_and_keeps_each_press_one_contact(mini: PressSet) -> None:
    ref = RestReference(smooth(mini.background, 2.0), 0.0, mini.background)
    # without the drift removal the drifted background alone is "touched"
    assert find_contacts(drifted(mini.background), ref, params(drift_sigma_px=0.0))[0]
    assert find_contacts(drifted(mini.background), ref, params())[0] == []
    for i in range(0, len(mini.presses), 3):  # the same contact as without the drift
        (steady,), _ = find_contacts(mini.presses[i], ref, params())
        found, _ = find_contacts(drifted(mini.presses[i]), ref, params())
        assert len(found) == 1, (i, found)
        assert np.hypot(found[0].x - steady.x, found[0].y - steady.y) * K < 0.05, (i, found[0], steady)
        assert abs(found[0].radius / steady.radius - 1) < 0.1, (i, found[0], steady)
        x, y = mini.centres_px[i]  # and near the hand label (press 15's estimate is 0.65 mm from it)
        assert np.hypot(found[0].x - x, found[0].y - y) * K < 0.8, (i, found[0])


def test_a_press_split_by_a_gap_is_joined_into_one_contact(mini: PressSet) -> None:
    ref = RestReference(smooth(mini.background, 2.0), 0.0, mini.background)
    i = 5
    x = int(mini.centres_px[i][0])
    cut = mini.presses[i].copy()
    cut[:, x - 6:x + 6] = mini.background[:, x - 6:x + 6]  # a band at rest through the contact's middle
    apart, _ = find_contacts(cut, ref, params(join_k=0.0))
    assert len(apart) == 2
    joined, _ = find_contacts(cut, ref, params())
    assert len(joined) == 1
    assert abs(joined[0].x - x) < 0.2 / K
