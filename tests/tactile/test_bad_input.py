"""Bad input (issue 31): NaN/Inf nodes, an empty mesh region, a frame out of order give a clear error or a
documented skip, never a contact."""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.examples import example_device
from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameError, FrameProcessor, ProcessingParams, SkinMesh, TactileFrame, flat_pad

PAD = example_device("flat")
MS = 1_000_000


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_inf_nodes_are_refused_before_processing_and_the_next_frame_is_taken(bad):
    proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=0.02))
    d = np.zeros_like(PAD.mesh.nodes)
    d[100, 2] = -0.5
    assert len(proc.process(TactileFrame(0, d)).contacts) == 1
    d2 = d.copy()
    d2[40] = bad
    with pytest.raises(FrameError, match="NaN/Inf at 1 node"):
        TactileFrame(1, d2)  # the frame is never built: nothing downstream sees it
    r = proc.process(TactileFrame(2, d))
    assert [c.id for c in r.contacts] == [1] and not r.actions  # the same finger, as if nothing came


def test_displacement_of_clamped_nodes_only_is_no_contact():
    d = np.zeros_like(PAD.mesh.nodes)
    d[PAD.mesh.clamped_indices] = 3.0
    r = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=0.02)).process(TactileFrame(0, d))
    assert r.contacts == [] and not r.packet_due and not r.actions


def test_nodes_in_no_cell_make_no_contact():
    """An empty mesh region (nodes no cell joins: no skin, no area): its displacement is reported in
    the packet, but no contact comes of it; the rest of the skin is unaffected."""
    mesh = flat_pad(8, 8, pitch_mm=2.0)
    keep = [k for k, cell in enumerate(mesh.cells.tolist()) if 27 not in cell]  # node 27 left in no cell
    holed = SkinMesh(mesh.nodes, mesh.cells[keep], mesh.free)
    d = np.zeros((64, 3))
    d[27, 2] = -1.0
    d[10, 2] = -0.8
    r = FrameProcessor(holed, ProcessingParams(epsilon_mm=0.1)).process(TactileFrame(0, d))
    assert r.deformed_nodes.tolist() == [10, 27]
    assert [c.nodes.tolist() for c in r.contacts] == [[10]]


def test_a_frame_out_of_order_is_refused_and_leaves_no_trace():
    """A clear error (the pipeline counts it and skips the frame), never a contact or an action: the
    next frame in order carries on as if the refused one had not come."""
    steps = [{"kind": "press", "at": [12.0, 12.0, 0.0], "start_s": 0.05, "duration_s": 0.5, "depth_mm": 0.8,
              "radius_mm": 3.0}]
    scene = Scene.from_dict({"step": steps})
    proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=0.02))
    acts = []
    for k in range(30):
        acts += proc.process(TactileFrame(k * 10 * MS, scene.displacement_at(k / 100, PAD.mesh))).actions
    with pytest.raises(FrameError, match="goes back"):
        proc.process(TactileFrame(5 * MS, np.zeros_like(PAD.mesh.nodes)))  # would release, if taken
    r = proc.process(TactileFrame(300 * MS, scene.displacement_at(0.3, PAD.mesh)))
    assert len(r.contacts) == 1 and r.contacts[0].id == 1 and not r.actions
    assert acts == ["touch"]
