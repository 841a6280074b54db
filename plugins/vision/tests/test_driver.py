"""CameraDriver's run loop on its own: a source that cannot open, breaks mid-stream, ends, is closed.

The barrel and flat-pad tests run it with real cameras files and simulators; here a minimal
family (frames are numbers, the displacement is that number everywhere) pins the loop's own
rules: which reason health gives, when it reconnects, when the device ends, what close releases.
"""

import asyncio

import numpy as np
import pytest
from wott_vision.camera import CameraError
from wott_vision.driver import CameraDriver

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Health
from wott_hub.examples import example_device


class NotAtRest(ValueError):
    pass


class Estimator:
    def __init__(self) -> None:
        self.has_reference = False
        self.resets = 0

    def set_reference(self, image) -> None:
        if image != "rest":
            raise NotAtRest(f"frame {image!r}")
        self.has_reference = True

    def reset_tracking(self) -> None:
        self.resets += 1


class NumberDriver(CameraDriver):
    reference_error = NotAtRest

    def _estimate(self, image) -> np.ndarray:
        self.set_health(Health.ok)
        return np.full((self.description.mesh.n_nodes, 3), float(image))


class Recording:
    """A recording: its frames, then (False, None) as a video file at its end (``ended``: a scene that
    does not loop, the device is done)."""

    def __init__(self, frames: list, *, ended: bool = False) -> None:
        self.frames, self.end_is_final = list(frames), ended
        self.ended = False
        self.released = False
        self.health_at_read: list = []  # the driver's health as each read starts
        self.driver: CameraDriver | None = None

    def read(self):
        self.health_at_read.append(self.driver.health())
        if not self.frames:
            self.ended = self.end_is_final
            return False, None
        return True, self.frames.pop(0)

    def release(self) -> None:
        self.released = True


def make_driver(opener, readers: list[Recording]) -> NumberDriver:
    driver = NumberDriver(example_device("flat"), Estimator(), opener, source_name="rec",
                          backoff=Backoff(initial_s=0.01, cap_s=0.02))
    for r in readers:
        r.driver = driver
    return driver


def test_health_reasons_reconnects_and_the_end_of_a_finite_source():
    readers = [Recording(["touched", "rest", 1.0, "garbled"]), Recording([2.0], ended=True)]
    opened: list = []

    def opener():
        opened.append(driver.health())
        if len(opened) == 1:
            raise CameraError("camera source 'rec.avi': no such file")
        return readers[len(opened) - 2]

    driver = make_driver(opener, readers)

    async def run():
        return [float(f.displacement[0, 0]) async for f in driver.frames()]

    values = asyncio.run(asyncio.wait_for(run(), 10))
    assert values == [0.0, 1.0, 2.0]  # the rest frame, then each frame's estimate; the reference survives
    # a camera error is reported in its own words; a fault anywhere else says where it happened
    assert opened[1].state is Health.disconnected and opened[2].state is Health.disconnected
    assert opened[1].reason == "camera source 'rec.avi': no such file"
    assert opened[2].reason == "rec failed: could not convert string to float: 'garbled'"
    health = readers[0].health_at_read[1]
    assert (health.state, health.reason) == (Health.degraded, "waiting for the skin at rest: frame 'touched'")
    assert driver.reconnects == 1 and driver.estimator.resets == 1  # tracking restarts on the reopen
    assert all(r.released for r in readers)


def test_close_releases_a_source_whose_frames_are_not_being_read():
    reader = Recording(["rest"] + [1.0] * 100)
    driver = make_driver(lambda: reader, [reader])

    async def run():
        agen = driver.frames()
        first = [await agen.__anext__(), await agen.__anext__()]
        await driver.close()  # the consumer holds the generator and is not resuming it
        assert reader.released
        with pytest.raises(StopAsyncIteration):
            await agen.__anext__()
        return first

    assert len(asyncio.run(asyncio.wait_for(run(), 10))) == 2
    assert driver.reconnects == 0 and driver.health().state is Health.ok


def test_raw_samples_are_the_last_frame_read_as_it_is_grey_or_rgb():
    """ServesRawSignals (issue 29): a reference to the last images read, a camera's BGR reversed as a
    view, None before the first frame or for a name the device has not."""
    from wott_hub.plugin_api import RawSignal, ServesRawSignals

    grey = np.arange(12, dtype=np.uint8).reshape(3, 4)
    bgr = np.zeros((3, 4, 3), np.uint8)
    bgr[..., 0] = 200  # blue in OpenCV's order

    class PairEstimator(Estimator):
        def set_reference(self, images) -> None:
            self.has_reference = True

    driver = NumberDriver(example_device("flat"), PairEstimator(), lambda: None, source_name="pair")
    assert isinstance(driver, ServesRawSignals) and driver.raw_sample("bottom") is None
    driver.raw_signals = (RawSignal("bottom", "image", (3, 4)), RawSignal("top", "image", (3, 4)))
    driver._raw = (123, (grey, bgr))  # what the worker thread assigns as it reads a pair
    bottom, top = driver.raw_sample("bottom"), driver.raw_sample("top")
    assert bottom.t_ns == 123 and bottom.array is grey  # as read: no copy
    assert top.array.shape == (3, 4, 3) and top.array[0, 0].tolist() == [0, 0, 200]  # RGB
    assert np.shares_memory(top.array, bgr)  # a view
    assert driver.raw_sample("left") is None
