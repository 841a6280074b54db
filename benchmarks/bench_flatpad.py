"""Flat vision pad: displacement accuracy (shear and depth apart) against time per frame.

    uv run wott-hub bench flatpad [--quick]

Each grid plays the same gestures, scaled to its pad (a press in the middle, a
shearing slide, a tap near a corner, a two-finger pinch), through the simulator
(scene -> rendered marker images with blur and noise) and the estimator
(wott_vision detection + tracking, marker photometry, parallax solve, depth
model). Errors are RMSE over the free markers of every frame against the
scene's ground truth; "press" frames are presses, taps and pinches, "slide"
frames have an in-plane drag (which the depth prior reads as depth,
docs/flat-pad.md). Time is the median per frame from the grey image to the
N x 3 displacement (detection, tracking, photometry, solve), not the renderer.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from report import markdown_table, write_section
from wott_driver_flatpad.calibration import calibrate
from wott_driver_flatpad.depth import DepthModel
from wott_driver_flatpad.estimator import PadEstimator
from wott_driver_flatpad.evaluation import play_scene
from wott_driver_flatpad.geometry import PadLayout
from wott_driver_flatpad.simulator import PadSimulator, RenderSettings

from wott_hub.sim.scene import Scene

GRIDS = {
    "7x9 @ 2.5 mm": PadLayout(7, 9, pitch_mm=2.5, marker_radius_mm=0.5),
    "16x16 @ 1.5 mm": PadLayout(16, 16, pitch_mm=1.5, marker_radius_mm=0.35),
}


def gestures(layout: PadLayout) -> Scene:
    """The demo gestures with positions as fractions of the pad (so every grid gets the same touch)."""
    span = np.array([(layout.cols - 1) * layout.pitch_mm, (layout.rows - 1) * layout.pitch_mm])

    def at(fx: float, fy: float) -> list[float]:
        return [float(fx * span[0]), float(fy * span[1]), 0.0]

    return Scene.from_dict({"scene": {"name": "bench-flatpad"}, "step": [
        {"kind": "press", "at": at(0.5, 0.5), "start_s": 0.2, "duration_s": 0.8, "depth_mm": 1.5,
         "radius_mm": 5.0},
        {"kind": "slide", "at": at(0.27, 0.35), "to": at(0.73, 0.65), "shear_mm": 0.4, "start_s": 1.2,
         "duration_s": 1.2, "depth_mm": 1.0, "radius_mm": 5.0},
        {"kind": "tap", "at": at(0.72, 0.3), "start_s": 2.6, "depth_mm": 1.0, "radius_mm": 4.0},
        {"kind": "pinch", "at": at(0.22, 0.5), "to": at(0.78, 0.5), "approach_mm": 5.0, "start_s": 3.0,
         "duration_s": 0.8, "depth_mm": 1.0, "radius_mm": 4.0},
    ]})


def methods(layout: PadLayout, render: RenderSettings, quick: bool):
    yield "in-plane only (dz = 0)", lambda: PadEstimator(layout, depth=False)
    if not quick:
        yield "area, no parallax term", lambda: PadEstimator(layout, parallax=False)
    yield "area + parallax solve (physical)", lambda: PadEstimator(layout, DepthModel.physical(layout.optics))
    if quick:
        return
    t0 = time.perf_counter()
    model = calibrate(layout, render)
    cal_s = time.perf_counter() - t0
    yield (f"area + parallax, calibrated gain {model.coefficients[0]:.2f} (fit {cal_s:.2f} s)",
           lambda: PadEstimator(layout, model))


def fmt(v: float, digits: int = 3) -> str:
    return "n/a" if not np.isfinite(v) else f"{v:.{digits}f}"


def rest_noise(layout: PadLayout, render: RenderSettings, frames: int) -> tuple[float, float]:
    """RMS and max of |D| (mm) over free markers of untouched frames: the floor for ε."""
    sim = PadSimulator(layout, Scene("rest", ()), render)
    est = PadEstimator(layout)
    est.set_reference(sim.render(0.0)[0])
    norms = np.concatenate([np.linalg.norm(est.update(sim.render(0.0)[0]).displacement[layout.mesh.free],
                                           axis=1) for _ in range(frames)])
    return float(np.sqrt(np.mean(norms**2))), float(norms.max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="fewer frames and methods: a smoke run in seconds; prints, writes no report")
    ap.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    args = ap.parse_args()
    fps = 10.0 if args.quick else 30.0
    render = RenderSettings()
    rows, noise_rows = [], []
    for grid, layout in GRIDS.items():
        scene = gestures(layout)
        for name, make in methods(layout, render, args.quick):
            s = play_scene(layout, scene, fps, render=render, estimator=make())
            if "physical" in name:
                default = s
            rows.append([grid, name, fmt(s.estimate_cpu_ms, 2), fmt(s.estimate_ms, 2),
                         fmt(s.shear_rmse("press")), fmt(s.shear_rmse("slide")),
                         fmt(s.depth_rmse("press")), fmt(s.depth_rmse("slide")),
                         fmt(s.max_depth_err["press"], 2), s.lost])
            print(" | ".join(str(c) for c in rows[-1]), flush=True)
        for noise in ((2.0,) if args.quick else (0.0, 2.0, 5.0)):
            r = RenderSettings(noise_std=noise)
            rms, peak = rest_noise(layout, r, 10 if args.quick else 60)
            s = play_scene(layout, scene, fps, render=r) if noise != render.noise_std else default
            noise_rows.append([grid, noise, fmt(rms), fmt(peak), fmt(s.shear_rmse("press")),
                               fmt(s.depth_rmse("press")), fmt(float(np.median(s.render_s) * 1e3), 1)])
            print(" | ".join(str(c) for c in noise_rows[-1]), flush=True)
    o = PadLayout().optics
    body = (
        f"Camera {o.width}x{o.height}, f = {o.focal_px:.0f} px, effective distance {o.z_eff_mm:.2f} mm "
        f"({o.px_per_mm:.1f} px/mm); renderer blur σ = {render.blur_sigma} px, noise "
        f"{render.noise_std} grey levels unless stated; {fps:.0f} frames/s of scene time. "
        "RMSE in mm over free markers and frames; *press* = press, tap and pinch frames, *slide* = "
        "frames with an in-plane drag of 0.4 mm (its stretch is outside the depth model's prior, "
        "docs/flat-pad.md). ms/frame: grey image to N x 3 displacement, median; CPU time is the "
        "process's (wall time also counts waiting for the 2 cores shared with other work).\n\n"
        + markdown_table(["grid", "method", "CPU ms/frame", "wall ms/frame", "shear RMSE press",
                          "shear RMSE slide", "depth RMSE press", "depth RMSE slide",
                          "max depth err press", "lost"], rows)
        + "\n\n### Image noise\n\nDefault method (area + parallax, physical). Rest: |D| over the "
          "free markers of untouched frames, the floor under the deformation threshold ε. Render: "
          "the simulator's cost per frame (ground truth + wott_vision.render), for reference.\n\n"
        + markdown_table(["grid", "noise (grey levels)", "rest RMS mm", "rest max mm",
                          "shear RMSE press", "depth RMSE press", "render ms/frame"], noise_rows)
    )
    if args.no_write or args.quick:
        print(body)
        return
    cmd = "uv run wott-hub bench flatpad"
    path = write_section("flatpad", "Flat vision pad: accuracy against time per frame", body, cmd)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
