"""The controller on wcdrive's simulated chair, through the plugin only (no conftest)."""

from __future__ import annotations

import math

from gotogoal import GoToGoal
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant.faults import Fault
from wcdrive.testing import strategies

PERIOD = 0.1          # s: the controller's rate (the board's watchdog is 500 ms)


def drive(chair, controller: GoToGoal, seconds: float) -> bool:
    """Closes the loop on the ground-truth pose; True once arrived."""
    for _ in range(round(seconds / PERIOD)):
        if controller.arrived(chair.pose):
            chair.set_velocity(0.0, 0.0)
            chair.run(PERIOD)
            return True
        chair.set_velocity(*controller.command(chair.pose))
        chair.run(PERIOD)
    return controller.arrived(chair.pose)


def test_reaches_a_goal_ahead(wc_port) -> None:
    assert drive(wc_port, GoToGoal((1.5, 0.0)), 15.0)


@settings(max_examples=6, deadline=None)
@given(x=st.floats(-2.0, 2.0), y=st.floats(-2.0, 2.0))
def test_reaches_any_goal_nearby(x: float, y: float) -> None:
    from wcdrive.testing import SteppedChair

    chair = SteppedChair()
    assert drive(chair, GoToGoal((x, y), tolerance=0.15), 30.0), chair.pose


def test_a_cut_encoder_stops_the_chair_short(wc_faulty_port) -> None:
    chair = wc_faulty_port(Fault(kind="encoder_cut", at=1.0, side="left"))
    assert not drive(chair, GoToGoal((3.0, 0.0)), 6.0)
    assert any(e.startswith("FAULT,") for e in chair.events)
    assert chair.pwm == (0, 0)


@settings(max_examples=5, deadline=None)
@given(fault=strategies.faults(duration=4.0))
def test_the_controller_never_commands_out_of_range_under_faults(wc_faulty_port, fault) -> None:
    chair = wc_faulty_port(fault)
    controller = GoToGoal((2.0, 1.0))
    for _ in range(40):
        linear, angular = controller.command(chair.pose)
        assert abs(linear) <= controller.max_linear and abs(angular) <= controller.max_angular
        assert math.isfinite(linear) and math.isfinite(angular)
        chair.set_velocity(linear, angular)
        chair.run(PERIOD)


@settings(max_examples=10, deadline=None)
@given(stream=strategies.byte_streams())
def test_garbage_on_the_line_then_the_controller_still_arrives(stream: bytes) -> None:
    from wcdrive.testing import SteppedChair

    chair = SteppedChair()
    chair.send(stream + b"\n")
    chair.run(0.6)
    chair.command(b"reset")     # whatever the garbage latched (an e-stop), reset it once parked
    chair.run(1.5)
    # and the motion it started, stopped by the board's watchdog (or the e-stop just
    # released): the board drives again only after a neutral command has stood 2 ticks
    chair.stop()
    chair.run(0.15)
    drive(chair, GoToGoal((1.0, 0.0)), 12.0)
    assert chair.pose[0] > 0.0


def test_live_chair_fixture(wc_chair) -> None:
    assert wc_chair.link_ok
