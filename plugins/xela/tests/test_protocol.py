"""The server's messages as the public ROS wrappers document them (omron-sinicx/xela_server_ros), built
here by hand: read exactly, and every malformed one a reason, never an exception."""

from __future__ import annotations

import json

import numpy as np
import pytest
from wott_driver_xela.protocol import Problem, Reading, Update, Welcome, parse, reading_of

COUNTS = np.arange(72).reshape(24, 3) * 7 + 29_950  # resting near 30,000


def entry(**over) -> dict:
    e = {"time": 1768296808.5565615, "sensor": "1", "data": ",".join(f"{v:04X}" for v in COUNTS.ravel()),
         "model": "uSPa46", "taxels": 24}
    e.update(over)
    return e


def test_the_welcome_then_data_messages():
    assert parse(json.dumps({"message": "Welcome", "version": "1.7.6"})) == Welcome()
    msg = parse(json.dumps({"message": 983, "time": 1768296808.56, "sensors": 2, "1": entry(),
                            "2": entry(model="uSPa44"), "complete": 1768296808.562364}))
    assert isinstance(msg, Update) and msg.number == 983 and sorted(msg.sensors) == ["1", "2"]
    r = reading_of("1", msg.sensors["1"])
    assert isinstance(r, Reading) and r.model == "uSPa46" and r.forces is None
    np.testing.assert_array_equal(r.counts, COUNTS)


def test_the_newer_integer_list_and_calibrated_forces():
    forces = (np.arange(72) / 1000 - 0.03).tolist()
    r = reading_of("3", entry(data=COUNTS.ravel().tolist(), calibrated=forces))
    assert isinstance(r, Reading)
    np.testing.assert_array_equal(r.counts, COUNTS)
    np.testing.assert_array_equal(r.forces, np.array(forces).reshape(24, 3))


@pytest.mark.parametrize(("over", "reason"), [
    ({"model": "uSPa99"}, "position 1: model 'uSPa99' is not one this hub knows (uSPa22, uSPa44, uSPa46)"),
    ({"model": "uSPa44"}, "position 1: 'data' holds 72 values, uSPa44 has 16 taxels x 3 = 48"),
    ({"data": "8197,829A,zz"}, "position 1: 'data' holds 3 values, uSPa46 has 24 taxels x 3 = 72"),
    ({"data": ",".join(["ZZZZ"] * 72)}, "position 1: 'data' holds a value that is not a number, uSPa46"),
    ({"data": [1.5] * 72}, "position 1: 'data' holds a value that is not a number"),
    ({"data": 7}, "position 1: 'data' is a int"),
    ({"calibrated": [0.1] * 71}, "position 1: 'calibrated' holds 71 values, uSPa46 has 24 taxels x 3 = 72"),
    ({"calibrated": ["x"] * 72}, "position 1: 'calibrated' holds a value that is not a number"),
])
def test_a_wrong_entry_is_a_reason_naming_the_position_and_field(over, reason):
    got = reading_of("1", entry(**over))
    assert isinstance(got, Problem) and got.reason.startswith(reason)


@pytest.mark.parametrize(("text", "reason"), [
    ("{not json", "a message that is not JSON"), ("[1, 2]", "a message that is a JSON list, not an object"),
])
def test_a_message_that_is_no_object_is_a_reason(text, reason):
    got = parse(text)
    assert isinstance(got, Problem) and got.reason.startswith(reason)
    assert reading_of("2", "text") == Problem("position 2: its entry is a str, not an object")
