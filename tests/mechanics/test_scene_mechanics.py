"""Scenes with model = "kelvin-voigt": the simulators' ground truth from the skin mechanics."""

import numpy as np
import pytest

from wott_hub.sim.scene import Scene, SceneError, SceneSimulator
from wott_hub.tactile import MATERIALS, flat_pad, taclink_barrel
from wott_hub.tactile.indentation import indent

BARREL = taclink_barrel()
PRESS = dict(kind="press", at=[0.0, 53.0, 130.0], depth_mm=2.0, radius_mm=8.0, start_s=0.1, duration_s=0.4)


def _scene(*steps, **head) -> Scene:
    return Scene.from_dict({"scene": {"model": "kelvin-voigt"} | head, "step": list(steps)})


def test_kelvin_voigt_scene_gives_finite_ground_truth_from_the_material():
    scene = _scene(PRESS, material="dragonskin-10")
    assert scene.model == "kelvin-voigt"
    d = scene.displacement_at(0.3, BARREL)
    assert d.shape == (707, 3) and np.isfinite(d).all()
    assert 1.0 < np.abs(d).max() <= 2.0 + 1e-3  # the tip lands between nodes: they move a bit less
    assert (d[~BARREL.free] == 0).all()
    assert np.abs(scene.displacement_at(0.05, BARREL)).max() == 0  # before the press: at rest
    sim = scene._simulators[BARREL]
    assert sim.model.params.modulus_mpa == MATERIALS["dragonskin-10"].modulus_mpa


def test_stiffer_material_needs_more_force_for_the_same_press():
    forces = []
    for material in ("ecoflex-00-10", "dragonskin-30"):
        sim = SceneSimulator(_scene(PRESS, material=material), BARREL)
        sim.displacement_at(0.3)
        forces.append(np.linalg.norm(sim.contact_forces[0]))
    ratio = MATERIALS["dragonskin-30"].modulus_mpa / MATERIALS["ecoflex-00-10"].modulus_mpa
    assert forces[1] / forces[0] == pytest.approx(ratio, rel=1e-6)  # linear in E


def test_backward_euler_simulator_settles_on_the_quasi_static_answer():
    scene = _scene(PRESS)
    qs, be = SceneSimulator(scene, BARREL), SceneSimulator(scene, BARREL, integrator="backward-euler")
    for k in range(int(0.4 * 120)):
        t = k / 120
        d_be = be.displacement_at(t)
    d_qs = qs.displacement_at(t)
    assert np.abs(d_be - d_qs).max() < 1e-3
    assert np.allclose(be.contact_forces[0], qs.contact_forces[0], rtol=1e-3)
    be.displacement_at(0.0)  # back in time: restarts from the settled state, no error
    assert np.abs(be.displacement_at(0.0)).max() == 0


def test_force_controlled_step_and_flat_punch():
    step = dict(kind="press", at=[0.0, 53.0, 130.0], force_n=4.0, radius_mm=6.0, indenter="flat",
                start_s=0.0, duration_s=1.0, ramp_s=0.0)
    sim = SceneSimulator(_scene(step), BARREL)
    sim.displacement_at(0.5)
    assert np.linalg.norm(sim.contact_forces[0]) == pytest.approx(4.0, rel=1e-6)
    presses = sim.scene.presses_at(0.5, BARREL)
    assert type(presses[0].shape).__name__ == "FlatPunch" and presses[0].force_n == 4.0


def test_slide_with_shear_sticks_and_drags():
    pad = flat_pad(16, 16, pitch_mm=1.5)
    step = dict(kind="slide", at=[8.0, 11.25, 0.0], to=[14.0, 11.25, 0.0], depth_mm=1.0, radius_mm=4.0,
                shear_mm=0.4, start_s=0.0, duration_s=1.0, ramp_s=0.0)
    scene = _scene(step, material="ecoflex-00-50", thickness_mm=4.0)
    d = scene.displacement_at(0.5, pad)
    assert d[:, 0].max() > 0.3  # dragged along +x
    assert np.isfinite(d).all()


def test_refined_ground_truth_is_read_back_at_the_device_nodes():
    scene = _scene(PRESS, refine=1)
    sim = SceneSimulator(scene, BARREL)
    d = sim.displacement_at(0.3)
    assert d.shape == (707, 3) and sim.model.mesh.n_nodes > 707
    coarse = SceneSimulator(_scene(PRESS), BARREL)
    coarse.displacement_at(0.3)
    # a finer skin is softer around a small indenter: less force for the same depth
    assert np.linalg.norm(sim.contact_forces[0]) < np.linalg.norm(coarse.contact_forces[0])


def test_indentation_model_is_unchanged_and_the_default():
    scene = Scene.from_dict({"step": [PRESS]})
    assert scene.model == "indentation"
    d = scene.displacement_at(0.3, BARREL)
    assert np.abs(d).max() > 0.5
    assert np.array_equal(d, indent(BARREL, scene.indenters_at(0.3, BARREL)))  # the Gaussian bump


@pytest.mark.parametrize("data,match", [
    ({"scene": {"model": "fem"}}, "scene.model"),
    ({"scene": {"model": "kelvin-voigt", "material": "jelly"}}, "scene.material"),
    ({"step": [PRESS | {"force_n": 3.0}]}, "force_n"),
    ({"scene": {"model": "kelvin-voigt"}, "step": [PRESS | {"indenter": "cube"}]}, "indenter"),
    ({"scene": {"model": "kelvin-voigt"}, "step": [PRESS | {"force_n": -1.0}]}, "force_n"),
    ({"scene": {"model": "kelvin-voigt", "thickness_mm": 0}}, "thickness_mm"),
    ({"scene": {"model": "kelvin-voigt", "skin": 3}}, "skin"),
])
def test_bad_scenes_are_refused(data, match):
    with pytest.raises(SceneError, match=match):
        Scene.from_dict(data)


def test_bad_skin_parameters_and_deep_backed_presses_are_refused():
    with pytest.raises(SceneError, match="foundation"):
        SceneSimulator(_scene(PRESS, skin={"foundation": -1.0}), BARREL)
    with pytest.raises(SceneError, match="no_such_field"):
        SceneSimulator(_scene(PRESS, skin={"no_such_field": 1.0}), BARREL)
    deep = PRESS | {"depth_mm": 3.5, "at": [11.0, 11.0, 0.0]}
    with pytest.raises(SceneError, match="deeper than the 3 mm skin"):
        SceneSimulator(_scene(deep, skin={"backed": True}), flat_pad(12, 12, pitch_mm=2.0))
