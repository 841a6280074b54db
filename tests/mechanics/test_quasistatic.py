"""The steady state against analytic answers, and the contact conditions."""

import numpy as np
import pytest

from wott_hub.tactile import flat_pad
from wott_hub.tactile.mechanics import FlatPunch, QuasiStatic, SkinModel, SkinParams, Sphere, press_on


def _membrane_centre(p: float, a: float, tension: float, terms: int = 199) -> float:
    """Centre deflection of a square membrane (side a, tension T, clamped edges) under pressure p."""
    total = 0.0
    for m in range(1, terms + 1, 2):
        for n in range(1, terms + 1, 2):
            total += np.sin(m * np.pi / 2) * np.sin(n * np.pi / 2) / (m * n * (m * m + n * n))
    return 16 * p * a * a / (np.pi**4 * tension) * total


def test_clamped_square_membrane_under_pressure():
    """-T ∇²w = p with w = 0 on the edges: centre deflection 0.0737 p a² / T, within 1 %."""
    rows, pitch, tension, pressure = 25, 2.0, 0.5, 1e-3  # N/mm, MPa
    pad = flat_pad(rows, rows, pitch_mm=pitch)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=1.0, foundation=0.0, shear_layer=0.0,
                                  pretension_n_per_mm=tension))
    f = np.zeros((pad.n_nodes, 3))
    f[:, 2] = -pressure * pad.node_areas
    u = m.to_nodes(QuasiStatic(m).solve(nodal_force=f).u)
    a = (rows - 1) * pitch
    exact = _membrane_centre(pressure, a, tension)
    assert exact == pytest.approx(0.07367 * pressure * a * a / tension, rel=1e-3)
    assert -u[(rows * rows) // 2, 2] == pytest.approx(exact, rel=0.01)
    assert np.abs(u[:, :2]).max() < 1e-12  # a flat membrane loaded normally does not move in plane


def test_line_load_on_winkler_bed_with_shear_layer_decays_like_pasternak():
    """k w − T w'' = P δ(x): w = P/(2√(kT)) e^{−|x|/ℓ}, ℓ = √(T/k) = h/3 for the default layer."""
    h, pitch, e = 9.0, 0.5, 0.1
    rows, cols = 5, 121
    pad = flat_pad(rows, cols, pitch_mm=pitch, clamp_border=False)
    grid = np.arange(pad.n_nodes).reshape(rows, cols)
    free = np.ones(pad.n_nodes, bool)
    free[grid[:, [0, -1]].ravel()] = False  # clamp only the strip's two ends
    pad = pad.with_free(free)
    m = SkinModel(pad, SkinParams(modulus_mpa=e, thickness_mm=h))
    k, tension = e / h, m.params.membrane_tension_n_per_mm
    line = 1e-3  # N/mm along y
    f = np.zeros((pad.n_nodes, 3))
    mid = grid[:, cols // 2]
    f[mid, 2] = -line * pad.node_areas[mid] / pitch
    w = -m.to_nodes(QuasiStatic(m).solve(nodal_force=f).u)[:, 2].reshape(rows, cols)
    assert np.ptp(w, axis=0).max() < 1e-9 * w.max()  # uniform across the strip
    ell = np.sqrt(tension / k)
    assert ell == pytest.approx(h / 3)
    x = (np.arange(cols) - cols // 2) * pitch
    side = (x > 0) & (x < 3 * ell)
    slope = np.polyfit(x[side], np.log(w[2, side]), 1)[0]
    assert -1 / slope == pytest.approx(ell, rel=0.01)
    assert w[2, cols // 2] == pytest.approx(line / (2 * np.sqrt(k * tension)), rel=0.02)


def test_punch_wider_than_the_skin_presses_every_node_by_its_depth():
    pad = flat_pad(8, 8, pitch_mm=2.0)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.2, thickness_mm=2.0))
    depth = 0.4
    centre = pad.nodes.mean(axis=0)
    s = QuasiStatic(m).solve([press_on(m, centre, FlatPunch(100.0), depth_mm=depth)])
    u = m.to_nodes(s.u)
    assert np.allclose(u[pad.free, 2], -depth, rtol=2e-3)
    # the force: the Winkler bed under the free nodes plus the shear layer pulling on the clamped ring
    k_bed = 0.2 / 2.0 * pad.node_areas[pad.free].sum()
    tension = m.params.membrane_tension_n_per_mm
    edges = pad.edges
    crossing = (pad.free[edges[:, 0]] != pad.free[edges[:, 1]]).sum()  # unit cotangent weight each
    assert -s.forces[0][2] == pytest.approx(depth * (k_bed + tension * crossing), rel=2e-3)


def test_force_control_finds_the_depth_that_gives_the_force(barrel_model):
    qs = QuasiStatic(barrel_model)
    by_depth = qs.solve([press_on(barrel_model, [0, 53, 130], Sphere(8.0), depth_mm=2.0)])
    target = float(np.linalg.norm(by_depth.forces[0]))
    by_force = qs.solve([press_on(barrel_model, [0, 53, 130], Sphere(8.0), force_n=target)])
    axis = press_on(barrel_model, [0, 53, 130], Sphere(8.0), depth_mm=1.0).axis
    assert by_force.forces[0] @ axis == pytest.approx(by_depth.forces[0] @ axis, rel=1e-6)
    assert by_force.depths[0] == pytest.approx(2.0, abs=1e-6)
    assert np.allclose(by_force.u, by_depth.u, atol=1e-6)


def test_contact_never_pulls_and_nothing_penetrates(pad_model):
    qs = QuasiStatic(pad_model)
    press = press_on(pad_model, pad_model.mesh.nodes.mean(axis=0), Sphere(5.0), depth_mm=1.2)
    s = qs.solve([press])
    g = qs.geometries([press])[0]
    gaps = qs.solver()._gaps(s.u, g, 1.2)
    assert gaps.min() > -2e-3 * 1.2  # the 1e-3 penalty: penetration of about 0.1 % of the depth
    fz = pad_model.to_nodes(s.f_contact)[:, 2]
    assert (fz <= 1e-12).all() and fz.sum() < 0  # every contact force pushes down, into the pad


def test_sticking_press_carries_the_contact_along():
    pad = flat_pad(15, 15, pitch_mm=1.0)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=3.0))
    centre = pad.nodes.mean(axis=0)
    s = QuasiStatic(m).solve([press_on(m, centre, FlatPunch(2.5), depth_mm=0.5, shear_mm=[0.3, 0, 0])])
    u = m.to_nodes(s.u)
    under = np.linalg.norm(pad.nodes[:, :2] - centre[:2], axis=1) < 1.5
    assert np.allclose(u[under, 0], 0.3, atol=1e-3) and np.allclose(u[under, 2], -0.5, atol=1e-3)
    assert s.forces[0][0] > 0  # the skin is dragged along +x
