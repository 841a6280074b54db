"""Part of ``bench gel`` (and runnable alone: ``uv run python benchmarks/gel_steps.py``): what each step of a
gel frame's path costs, one by one, and the floor beside the decoders.

The frames are the cost benchmark's (``bench_gel.sensor_cases``: Taxim's real Mini frames shaped to
320 x 240, the real DIGIT rest frame with modelled presses), written as the recordings are (PNG, and JPEG
at quality 95). Each step is timed alone in process CPU time (``time.process_time``), OpenCV on one
thread (its pool's spinning is not the step's), as the median of 7 batches: a share of the machine's
time, not a wall time, so a busy machine inflates every row alike. The floors: a PNG's pixels are the
zlib stream of its IDAT chunks, so inflating that stream alone (Python's zlib) is what any PNG decoder must
do; the Mini's native JPEG is a made one (a real frame enlarged to 3280 x 2464, quality 90), decoded at
1/8 as the driver does (libjpeg still entropy-decodes every 8 x 8 block; the scaling spares the inverse
DCT).
"""

from __future__ import annotations

import struct
import sys
import tempfile
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["native_jpeg", "steps"]


def _ms(fn: Callable[[], Any], n: int = 50, batches: int = 7) -> float:
    fn()
    out = []
    for _ in range(batches):
        t = time.process_time()
        for _ in range(n):
            fn()
        out.append((time.process_time() - t) / n)
    return 1e3 * float(np.median(out))


def native_jpeg() -> np.ndarray:
    """A Mini's native 3280 x 2464 JPEG (quality 90) made from a real frame (Taxim's press 5, enlarged)."""
    import cv2
    from wott_driver_gel.evaluation import load_taxim
    from wott_driver_gel.specs import MINI_NATIVE

    full = cv2.resize(load_taxim("gelsight_mini").presses[5], MINI_NATIVE, interpolation=cv2.INTER_CUBIC)
    ok, jpeg = cv2.imencode(".jpg", full, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    return jpeg


def _idat(path: Path) -> bytes:
    """The concatenated IDAT payload of a PNG: its zlib stream."""
    data, pos, out = path.read_bytes(), 8, b""
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        if data[pos + 4:pos + 8] == b"IDAT":
            out += data[pos + 8:pos + 8 + n]
        pos += 12 + n
    return out


def _family(folder: Path, family: str, rest: np.ndarray, pressed: np.ndarray) -> dict[str, float]:
    """The recording's decoders and the estimator's steps of one family, ms."""
    import cv2
    from wott_driver_gel.contacts import find_contacts
    from wott_driver_gel.drift import drift
    from wott_driver_gel.evaluation import write_recording
    from wott_driver_gel.rest import magnitude, smooth
    from wott_driver_gel.settings import open_gel

    c: dict[str, float] = {}
    for suffix in (".png", ".jpg"):
        write_recording(folder / suffix[1:], rest, pressed[None], suffix=suffix)
    png, jpg = folder / "png" / "00005.png", folder / "jpg" / "00005.jpg"
    c["png"] = _ms(lambda: cv2.imread(str(png), cv2.IMREAD_COLOR))
    stream = _idat(png)
    c["inflate"] = _ms(lambda: zlib.decompress(stream))
    c["jpg"] = _ms(lambda: cv2.imread(str(jpg), cv2.IMREAD_COLOR))
    driver = open_gel("steps", family, {"source": str(folder / "png"), "realtime": False})
    driver._open()
    for _ in range(5):  # the rest reference
        driver._step()
    driver._release()
    est = driver.estimator
    ref, p = est.reference, est.params
    assert ref is not None
    frame = smooth(pressed, p.sigma_px)
    d = cv2.subtract(frame, ref.image)
    c["smooth"] = _ms(lambda: smooth(pressed, p.sigma_px))
    c["change"] = _ms(lambda: magnitude(cv2.subtract(frame, ref.image)))
    c["rest"] = _ms(lambda: est.estimate(rest))
    c["drift"] = _ms(lambda: drift(d, 8.0, p.drift_sigma_px, p.drift_iters))
    c["contacts"] = _ms(lambda: find_contacts(frame, ref, p, smoothed=True))
    c["press"] = _ms(lambda: est.estimate(pressed))
    assert est.estimate(pressed).contacts
    zeros = np.zeros((driver.description.mesh.n_nodes, 3))
    c["mm"] = _ms(lambda: driver._frame(0, zeros))
    return c


def steps() -> list[list[str]]:
    """Rows (step, DIGIT ms, Mini ms, what bounds it)."""
    import cv2
    from bench_gel import sensor_cases
    from wott_driver_gel.sources import decode_reduced, rotate_digit, shape_mini

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        cases = sensor_cases()
        with tempfile.TemporaryDirectory() as tmp:
            cols = {family: _family(Path(tmp) / family, family, rest, presses[0])
                    for family, (rest, presses, _fps) in cases.items()}
        qvga = np.ascontiguousarray(np.rot90(cases["digit"][0], -1))  # as the DIGIT sends it
        cols["digit"]["turn_old"] = _ms(lambda: cv2.flip(cv2.transpose(qvga), 0))
        cols["digit"]["turn"] = _ms(lambda: rotate_digit(qvga))
        jpeg = native_jpeg()
        cols["gelsight-mini"]["native"] = _ms(lambda: decode_reduced(jpeg, 8), n=5)
        reduced = decode_reduced(jpeg, 8)
        cols["gelsight-mini"]["shape"] = _ms(lambda: shape_mini(reduced))
    finally:
        cv2.setNumThreads(threads)
    dg, mi = cols["digit"], cols["gelsight-mini"]

    def cell(c: dict[str, float], k: str) -> str:
        return f"{c[k]:.2f}" if k in c else ""

    kb = len(jpeg) // 1000
    rows = [
        ("recording: PNG read and decoded (`cv2.imread`)", "png", "its zlib stream, inflated: below"),
        ("  the PNG's zlib stream (IDAT) inflated alone", "inflate", "the floor of any PNG decoder"),
        ("recording: JPEG (quality 95) read and decoded", "jpg", "libjpeg-turbo"),
        (f"sensor: the Mini's native 3280 x 2464 JPEG ({kb} kB) decoded at 1/8", "native",
         "entropy decoding of every 8 x 8 block"),
        ("sensor: the Mini's frame cropped and resized to 320 x 240 (`shape_mini`)", "shape", ""),
        ("sensor: the DIGIT's frame turned, transpose + flip (before)", "turn_old", ""),
        ("sensor: the DIGIT's frame turned, one `cv2.rotate` (now)", "turn", ""),
        ("the frame smoothed (Gaussian, 2 px, 3 channels, to float)", "smooth", "one pass over the frame"),
        ("its change from the reference and the change's norm", "change", ""),
        ("**a frame at rest, all of `GelEstimator.estimate`**", "rest", "smooth + change + a max"),
        ("the illumination drift (a touched frame)", "drift", ""),
        ("the contacts of a touched frame (drift, mask, components, centres)", "contacts", ""),
        ("**a touched frame, all of `GelEstimator.estimate`**", "press", ""),
        ("the frame handed over (contacts in mm, `TactileFrame`)", "mm", ""),
    ]
    return [[what, cell(dg, k), cell(mi, k), why] for what, k, why in rows]


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from report import markdown_table

    print(markdown_table(["step (one frame)", "DIGIT 240 x 320, ms", "Mini 320 x 240, ms", "bound"], steps()))
