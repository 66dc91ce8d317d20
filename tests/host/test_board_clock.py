"""Odometry on the board's clock: ``TLM:`` millis time the twist and the
stamps, a filter maps them to the host's clock, and a board reset neither stops the
board time nor sends the pose back to 0 (a ``Reset`` reaches the subscribers)."""

from __future__ import annotations

import itertools
import math
import random
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import wcdrive
from tests.support.board_of import board_of
from wcdrive.errors import WcdriveNeutralError
from wcdrive.host.boardclock import BoardClock, ClockFilter


# ---- the clock on its own ----------------------------------------------------------------
@given(rate=st.floats(0.2, 5.0), offset=st.floats(-1e4, 1e4), seed=st.integers(0, 2**16))
def test_the_filter_finds_rate_offset_and_the_latency_floor(rate: float, offset: float, seed: int) -> None:
    """Host arrival = offset + rate * board + a latency of 1..20 ms (the floor 1 ms):
    the filter recovers the rate and maps board time onto the floor."""
    rng = random.Random(seed)
    f = ClockFilter()
    for k in range(400):
        board = 0.05 * k
        f.add(board, offset + rate * board + 0.001 + rng.random() * 0.019)
    assert f.rate == pytest.approx(rate, rel=2e-3)
    board = 0.05 * 399
    assert abs(f.to_host(board) - (offset + rate * board + 0.001)) < 0.004


def test_millis_wraps_and_a_reset_carries_board_time_on() -> None:
    clock = BoardClock()
    top = (1 << 32) - 100
    times = [clock.update(0.05 * k, (top + 50 * k) % (1 << 32)).board for k in range(6)]
    assert times[0] == pytest.approx(top / 1000.0)                       # the board's own clock
    assert [t - times[0] for t in times] == pytest.approx([0.05 * k for k in range(6)])  # over the wrap
    before = clock.last
    assert before is not None
    after = clock.update(before.arrival + 1.0, 20)                        # reset, 1 s later
    assert after.reset and clock.resets == 1
    assert after.board == pytest.approx(before.board + 1.0, abs=1e-6)    # carries on
    nxt = clock.update(before.arrival + 1.05, 70)
    assert not nxt.reset and nxt.board - after.board == pytest.approx(0.05)


def test_a_board_without_tlm_counts_ticks() -> None:
    clock = BoardClock()
    boards = [clock.update(0.1 * k + (0.03 if k % 2 else 0.0), None).board for k in range(5)]
    assert boards == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])


# ---- on the simulated boards -------------------------------------------------------------
def _twist_ratios(url: str, linear: float = 0.5, angular: float = 0.2) -> tuple[float, float, float]:
    """Drives ``url`` at a constant command; returns the mean ratios odometry/plant of
    the linear and angular twist over the settled part, and the clock's rate."""
    with wcdrive.connect(url) as chair:
        board = board_of(chair._session.port)
        lin: list[float] = []
        ang: list[float] = []
        start = board.plant.time
        while board.plant.time - start < 6.0:             # board seconds
            chair.set_velocity(linear, angular)
            time.sleep(0.02)
            if board.plant.time - start > 3.0:            # settled: 3 s of board time in
                est = chair.odometry
                with board._lock:
                    v, w = board.plant.axle_velocity()[0], board.plant.yaw_rate
                lin.append(est.linear / v)
                ang.append(est.angular / w)
        return sum(lin) / len(lin), sum(ang) / len(ang), chair.board_clock.filter.rate


def test_twist_on_a_fast_simulated_board_is_the_plants() -> None:
    """``sim://?speed=4``: four board seconds per host second. Timed by arrival the twist
    read 4.5x too high; on the board's clock it is the plant's within 5%."""
    lin, ang, rate = _twist_ratios("sim://?speed=4")
    assert lin == pytest.approx(1.0, abs=0.05)
    assert ang == pytest.approx(1.0, abs=0.05)
    assert rate == pytest.approx(0.25, rel=0.02)


@pytest.mark.simavr
def test_twist_on_simavr_is_the_plants() -> None:
    """``simavr://`` runs as fast as simavr can: whatever its rate, the twist is the
    plant's within 5%."""
    lin, ang, _ = _twist_ratios("simavr://")
    assert lin == pytest.approx(1.0, abs=0.05)
    assert ang == pytest.approx(1.0, abs=0.05)


def test_a_reset_mid_drive_keeps_the_pose_and_tells_the_subscribers() -> None:
    """The board resets while driving (``PortLoop.reset``: millis and counts from 0, a
    fresh setup, hello again): the pose carries on, board time and the stamps go on
    forward, and a ``Reset`` reaches ``on_reset`` callbacks (and ``chair.resets``);
    ``on_link`` gets no ``Reset`` (it keeps its LinkLost/LinkRestored pairs)."""
    seen: list[object] = []
    links: list[object] = []
    with wcdrive.connect("sim://?speed=4") as chair:
        chair.on_reset(seen.append)
        chair.on_link(links.append)
        stream = chair.telemetry(timeout=5.0, link_events=True)
        next(stream)                                 # subscribed from here on
        board = board_of(chair._session.port)

        def drive(seconds: float) -> None:
            start = board.plant.time
            while board.plant.time - start < seconds:
                try:
                    chair.set_velocity(0.4, 0.0)
                except WcdriveNeutralError:          # reset: drives on after a neutral
                    chair.wait_for_neutral()
                except wcdrive.WcdriveError:         # during the reset's hello
                    pass
                time.sleep(0.02)

        drive(3.0)
        before = chair.odometry
        with board._lock:
            board.loop.reset()
        drive(3.0)
        after = chair.odometry
        with board._lock:
            truth = board.plant.pose
        resets = [e for e in seen if isinstance(e, wcdrive.Reset)]
        assert len(resets) == 1 and resets[0].cause in ("boot", "millis") and chair.resets == resets
        assert not any(isinstance(e, wcdrive.Reset) for e in links)
        assert resets[0].pose[0] >= before.pose.x - 1e-9          # from where it was
        assert after.pose.x > before.pose.x + 0.5                 # and on from there
        assert after.pose.x == pytest.approx(truth[0], abs=0.1)    # still the chair's x
        assert after.board_time is not None and before.board_time is not None
        assert after.board_time > before.board_time + 2.9
        events = []
        for item in stream:
            events.append(item)
            if isinstance(item, wcdrive.Telemetry) and item.board_time and item.board_time > after.board_time:
                break
        stamps = [e.board_time or 0.0 for e in events if isinstance(e, wcdrive.Telemetry)]
        assert all(b > a for a, b in itertools.pairwise(stamps))
        assert not math.isnan(after.pose.theta)


@settings(max_examples=50)
@given(seed=st.integers(0, 2**32 - 1), speed=st.sampled_from([0.5, 1.0, 4.0, 10.0]))
def test_stamps_only_go_forward_however_the_lines_arrive(seed: int, speed: float) -> None:
    """Lines that arrive late, in bursts after a stall, or on time: every tick's host
    stamp is later than the one before (the filter's fit moves back when a line shows a
    lower latency floor; the stamps must not). Red without the forward rule: the fit
    alone goes back on most such runs."""
    rng = random.Random(seed)
    clock = BoardClock()
    arrival, last = 0.0, -math.inf
    for i in range(300):
        due = i * 0.05 / speed
        arrival = max(arrival, due + rng.choice([0.0, 0.001, 0.002, rng.uniform(0.0, 0.3)]))
        sample = clock.update(arrival, i * 50)
        assert sample.host > last, (i, last, sample)
        last = sample.host
