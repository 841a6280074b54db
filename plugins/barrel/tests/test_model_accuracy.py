"""The shipped model is trained on the Kelvin-Voigt ground truth the simulators use (issue 14)
and meets its stated accuracy on it (docs/barrel-vision.md, "The default model")."""

import json

import numpy as np
from wott_driver_barrel.dataset import make_dataset
from wott_driver_barrel.model import DisplacementModel, default_model_path
from wott_driver_barrel.settings import demo_scene_path
from wott_driver_barrel.training import rmse_mm

# measured on the training run's held-out set (400 touches): 0.172 mm over free nodes, 1.33 mm over
# nodes displaced > 0.5 mm (truth RMS 0.364 / 3.88); the tolerances leave room for a 120-touch sample
TOL_HELD_OUT_FREE_MM = 0.21
TOL_HELD_OUT_DEFORMED_MM = 1.6
# the demo scene, exact marker motion: about 0.45 of the signal's RMS (per step 0.37-0.50)
TOL_DEMO_RATIO = 0.6
TOL_DEMO_DEFORMED_MM = 1.6


def test_default_model_is_trained_on_kelvin_voigt_and_meets_its_accuracy(layout):
    free = layout.mesh.free
    m = DisplacementModel(default_model_path(), n_features=layout.n_features, n_cameras=2, free=free)
    info = json.loads(m.metadata["wott.model"])
    assert info["ground_truth"] == "kelvin-voigt"
    test = make_dataset(layout, 120, seed=1001)  # the held-out seed of train_model.py
    noisy = test.features + np.random.default_rng(7).normal(0, 0.05, test.features.shape).astype(np.float32)
    pred = np.stack([m.predict_markers(x)[free].ravel() for x in noisy])
    assert rmse_mm(pred, test.targets) < TOL_HELD_OUT_FREE_MM
    assert rmse_mm(pred, test.targets, min_norm_mm=0.5) < TOL_HELD_OUT_DEFORMED_MM
    assert rmse_mm(pred, test.targets) < 0.6 * rmse_mm(np.zeros_like(pred), test.targets)


def test_demo_scene_on_the_kelvin_voigt_skin_from_exact_marker_motion(layout):
    # the model's own share of the error on the demo scene's Kelvin-Voigt skin (through the images
    # the tracker adds to it: docs/barrel-vision.md, "The default model")
    from wott_hub.sim.scene import Scene

    text = demo_scene_path().read_text().replace("[scene]\n", '[scene]\nmodel = "kelvin-voigt"\n', 1)
    scene = Scene.from_dict(__import__("tomllib").loads(text.replace("loop = true", "loop = false")))
    free = layout.mesh.free
    m = DisplacementModel(default_model_path(), n_features=layout.n_features, n_cameras=2, free=free)
    truth = np.array([scene.displacement_at(k / 10, layout.mesh) for k in range(int(scene.duration_s * 10))])
    est = np.array([m.predict_markers(layout.features(t))[free].ravel() for t in truth])
    truth = truth[:, free].reshape(len(truth), -1)
    assert rmse_mm(est, truth) < TOL_DEMO_RATIO * rmse_mm(np.zeros_like(truth), truth)
    assert rmse_mm(est, truth, min_norm_mm=0.5) < TOL_DEMO_DEFORMED_MM
