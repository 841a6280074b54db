import numpy as np
import pytest

from wott_hub.tactile import FrameError, TactileFrame


def test_valid_frame_is_float64():
    f = TactileFrame(5, np.zeros((4, 3), dtype=np.float32), pressure=[0, 1, 2, 3])
    assert f.displacement.dtype == np.float64 and f.pressure.shape == (4,) and f.n_nodes == 4


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_are_rejected(bad):
    d = np.zeros((10, 3))
    d[7, 1] = bad
    with pytest.raises(FrameError, match="NaN/Inf at 1 node.*first node 7"):
        TactileFrame(0, d)


def test_nan_pressure_is_rejected():
    with pytest.raises(FrameError, match="pressure has NaN"):
        TactileFrame(0, np.zeros((2, 3)), pressure=[0.0, np.nan])


@pytest.mark.parametrize("shape", [(10,), (10, 2), (10, 3, 1), (3, 10)])
def test_wrong_shapes_are_rejected(shape):
    with pytest.raises(FrameError, match="shape"):
        TactileFrame(0, np.zeros(shape))


def test_pressure_shape_must_match():
    with pytest.raises(FrameError, match=r"pressure must have shape \(2,\)"):
        TactileFrame(0, np.zeros((2, 3)), pressure=[1.0, 2.0, 3.0])


@pytest.mark.parametrize("t", [-1, 1.5, "0"])
def test_bad_timestamps_are_rejected(t):
    with pytest.raises(FrameError, match="t_ns"):
        TactileFrame(t, np.zeros((1, 3)))
