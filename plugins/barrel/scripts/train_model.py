"""Train the barrel skin's default displacement model on simulated presses and export it as ONNX.

    nice -n 19 uv run python plugins/barrel/scripts/train_model.py   # writes the shipped model (~30 min)
    uv run python plugins/barrel/scripts/train_model.py --quick    # a small smoke run into /tmp

Data: ``wott_driver_barrel.dataset`` (random presses and drags of 1-3 indenters
on the TacLink mesh, ground truth from the Kelvin-Voigt skin the simulators use, or
``--ground-truth indentation`` for the older model; marker image
displacement from the camera model). Model: ``training.fit_local_ridge``.
Accuracy is measured on a held-out set made with another seed and printed,
with the numbers docs/barrel-vision.md quotes. Needs the dev group (``onnx``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from wott_driver_barrel.dataset import ContactSampler, Dataset, make_dataset
    from wott_driver_barrel.model import DisplacementModel, default_model_path
    from wott_driver_barrel.onnx_export import local_ridge_model, save
    from wott_driver_barrel.settings import build_layout
    from wott_driver_barrel.training import fit_local_ridge, rmse_mm

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    # the shipped model: 3,500 Kelvin-Voigt touches (about 30 ms of CPU each; 8,000 were no more
    # accurate, docs/barrel-vision.md), 0.08 px assumed noise (keeps the skin at rest under epsilon)
    ap.add_argument("--samples", type=int, default=3500)
    ap.add_argument("--test-samples", type=int, default=400)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--radius-mm", type=float, default=40.0, help="markers a node looks at")
    ap.add_argument("--lam", type=float, default=1.0, help="ridge penalty")
    ap.add_argument("--noise-px", type=float, default=0.08, help="detector noise assumed in training")
    ap.add_argument("--f-px", type=float, default=234.0, help="cameras: fisheye focal length, px")
    ap.add_argument("--offset-mm", type=float, default=6.0, help="cameras: distance beyond the rims, mm")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--ground-truth", choices=("kelvin-voigt", "indentation"), default="kelvin-voigt",
                    help="skin mechanics of the training and test data (default: the simulators' own)")
    ap.add_argument("--baseline", type=Path, default=None,
                    help="an .onnx model to score on the same held-out set (e.g. the shipped one, before)")
    ap.add_argument("--cache", type=Path, default=None,
                    help="an .npz of the training and held-out sets: read if it exists, else written "
                         "(refit with other --lam / --noise-px without regenerating the data)")
    ap.add_argument("--out", type=Path, default=None, help="default: the packaged model file")
    ap.add_argument("--quick", action="store_true", help="2000 samples, written to /tmp (a few minutes)")
    a = ap.parse_args(argv)
    if a.quick:
        a.samples, a.test_samples = 2000, 300
        a.out = a.out or Path("/tmp/barrel-local-ridge-quick.onnx")
    out = a.out or default_model_path()

    # the same layout code as the driver's ``cameras`` setting, so a model fits the device it is for
    layout = build_layout({"f_px": a.f_px, "offset_mm": a.offset_mm, "width": a.width, "height": a.height})
    mesh = layout.mesh
    sampler = ContactSampler()
    t0 = time.perf_counter()
    if a.cache is not None and a.cache.exists():
        z = np.load(a.cache)
        train = Dataset(z["train_x"], z["train_y"], np.empty(0))
        test = Dataset(z["test_x"], z["test_y"], np.empty(0))
        a.samples, a.test_samples = len(train.features), len(test.features)
    else:
        train = make_dataset(layout, a.samples, seed=a.seed, sampler=sampler, model=a.ground_truth)
        test = make_dataset(layout, a.test_samples, seed=a.seed + 1000, sampler=sampler, model=a.ground_truth)
        if a.cache is not None:
            np.savez(a.cache, train_x=train.features, train_y=train.targets, test_x=test.features,
                     test_y=test.targets)
    t1 = time.perf_counter()
    model = fit_local_ridge(layout, train.features, train.targets, radius_mm=a.radius_mm, lam=a.lam,
                            noise_px=a.noise_px)
    t2 = time.perf_counter()
    rng = np.random.default_rng(a.seed + 2000)
    noisy = test.features + rng.normal(0, a.noise_px, test.features.shape).astype(np.float32)
    pred = model.predict(noisy)
    acc = {
        "rmse_mm_free_nodes": round(rmse_mm(pred, test.targets), 4),
        "rmse_mm_deformed_nodes": round(rmse_mm(pred, test.targets, min_norm_mm=0.5), 4),
        "rms_truth_mm_free_nodes": round(rmse_mm(np.zeros_like(test.targets), test.targets), 4),
        "rms_truth_mm_deformed_nodes": round(rmse_mm(np.zeros_like(test.targets), test.targets,
                                                     min_norm_mm=0.5), 4),
        "test_samples": a.test_samples,
    }
    if a.baseline is not None:
        base = DisplacementModel(a.baseline, n_features=layout.n_features, n_cameras=2, free=mesh.free)
        bpred = np.stack([base.predict_markers(x)[mesh.free].ravel() for x in noisy])
        acc["baseline"] = {"model": str(a.baseline),
                           "rmse_mm_free_nodes": round(rmse_mm(bpred, test.targets), 4),
                           "rmse_mm_deformed_nodes": round(rmse_mm(bpred, test.targets, min_norm_mm=0.5), 4)}
    info = dict(model.info, ground_truth=a.ground_truth,
                sampler={k: getattr(sampler, k) for k in sampler.__dataclass_fields__},
                seed=a.seed, accuracy=acc)
    model.info = info
    onnx_model = local_ridge_model(model, layout.n_features, {
        "wott.layout": f"taclink 16 rings x 16 rays, z 25-235 mm; equidistant fisheye f={a.f_px} px, "
                       f"{a.offset_mm} mm beyond the rims, {a.width}x{a.height} "
                       "(wott_driver_barrel.geometry)",
        "wott.output": f"{layout.mesh.free.sum()} free nodes x 3, mm, ascending node index",
    })
    save(onnx_model, out)
    # the file must reproduce the fitted map through onnxruntime, the way the driver runs it
    rt = DisplacementModel(out, n_features=layout.n_features, n_cameras=2, free=mesh.free)
    d = rt.predict_markers(noisy[0])
    np.testing.assert_allclose(d[mesh.free].ravel(), pred[0], atol=1e-3)
    print(json.dumps({
        "out": str(out), "bytes": out.stat().st_size, "parameters": model.n_parameters,
        "data_s": round(t1 - t0, 1), "fit_s": round(t2 - t1, 1), **info,
    }, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
