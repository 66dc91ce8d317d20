"""One motion-command core for every host (``wcdrive.protocol.motion``): the same wheel
order, the same validation and the same bytes through ``Wheelchair``, ``SteppedChair``,
the scenario runner, the ROS 2 recorder and the CAN gateway."""

from __future__ import annotations

import warnings

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.protocol import can_frames
from wcdrive.protocol.codec import MAX_ANGULAR, MAX_LINEAR, MAX_WHEEL
from wcdrive.protocol.motion import (
    VelocityCommand,
    WheelCommand,
    find_motion,
    parse_motion,
    velocity_command,
    wheel_command,
)
from wcdrive.sim.scenario import Segment
from wcdrive.testing.stepped import SteppedChair

speeds = st.floats(-MAX_WHEEL, MAX_WHEEL)


@given(left=speeds, right=speeds)
def test_a_wheel_command_reads_back_as_the_wheels_it_was_given(left: float, right: float) -> None:
    command = parse_motion(wheel_command(left, right))
    assert isinstance(command, WheelCommand)
    assert command.left == pytest.approx(left, abs=0.0015)
    assert command.right == pytest.approx(right, abs=0.0015)


@given(linear=st.floats(-MAX_LINEAR, MAX_LINEAR), angular=st.floats(-MAX_ANGULAR, MAX_ANGULAR))
def test_a_velocity_command_reads_back_and_is_found_in_a_frame(linear: float, angular: float) -> None:
    body = velocity_command(linear, angular)
    command = parse_motion(body)
    assert isinstance(command, VelocityCommand)
    assert command.linear == pytest.approx(linear, abs=0.0015)
    assert find_motion(b"$12:" + body + b"*ABCD\n") == command


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), MAX_WHEEL + 0.01])
def test_a_wheel_speed_out_of_range_is_refused_by_every_host(bad: float) -> None:
    with pytest.raises(ValueError):
        wheel_command(bad, 0.0)
    with pytest.raises(ValueError):
        SteppedChair().set_wheels(left=bad, right=0.0)


def _setpoints(chair: SteppedChair) -> tuple[float, float]:
    chair.run(0.5)
    s = chair.loop.fw.state
    return s.targetL, s.targetR


def test_stepped_chair_takes_the_wheels_by_name_as_wheelchair_does() -> None:
    chair = SteppedChair()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        chair.set_wheels(left=1.0, right=2.0)
    left, right = _setpoints(chair)
    assert (left, right) == pytest.approx((1.0, 2.0), abs=1e-3)


def test_stepped_chair_positional_wheels_keep_their_old_order_and_warn() -> None:
    chair = SteppedChair()
    with pytest.warns(DeprecationWarning, match=r"set_wheels\(left=\.\.\., right=\.\.\.\)"):
        chair.set_wheels(2.0, 1.0)               # (right, left), as before
    left, right = _setpoints(chair)
    assert (left, right) == pytest.approx((1.0, 2.0), abs=1e-3)


def test_a_velocity_at_the_exact_limit_drives_the_stepped_chair() -> None:
    """The board reads "9.400" just past its binary32 limit; every host sends 9.399."""
    chair = SteppedChair()
    chair.set_velocity(0.0, MAX_ANGULAR)
    chair.run(0.3)
    assert not [m for m in chair.messages if type(m).__name__ in ("Error", "Nak")], list(chair.messages)
    assert chair.feedback is not None and chair.feedback.mode == "CMDVEL"


def test_the_scenario_files_wheel_order_is_the_wires() -> None:
    assert Segment("wheel", (2.0, 1.0), 1.0).command() == wheel_command(left=1.0, right=2.0)


def test_the_can_gateway_reads_the_same_grammar() -> None:
    frames = can_frames.command_to_frames(b"rn1.500,lp0.250")
    (can_id, data), = frames
    assert can_id == can_frames.CMD_WHEELS
    assert can_frames.frame_to_command(can_id, data).startswith(b"$0:rn1.500,lp0.250,*")
