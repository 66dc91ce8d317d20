"""A simulated board's gyro reaches a ``connect(url, ros=sink)`` sink for as long as
the chair runs: the board keeps its newest 4,000 samples (10 s at 400 Hz), and every
sample taken after that still goes out once."""

from __future__ import annotations

import time
from typing import Any

import wcdrive
from tests.support.board_of import board_of
from wcdrive.boards.sim_board import GYRO_HISTORY


class Imu:
    """A sink that keeps the ``/imu`` messages' angular rates."""

    def __init__(self) -> None:
        self.rates: list[float] = []

    def publish(self, topic: str, message: dict[str, Any], log_time: float) -> None:
        if topic == "/imu":
            self.rates.append(message["angular_velocity"]["z"])

    def close(self) -> None:
        pass


def test_the_gyro_goes_on_past_its_history() -> None:
    sink = Imu()
    with wcdrive.connect("sim://?speed=10", ros=sink) as chair:
        board = board_of(chair._session.port)
        deadline = time.monotonic() + 30.0
        while board.time < 25.0 and time.monotonic() < deadline:
            chair.set_velocity(0.3, 0.5)
            time.sleep(0.02)
        taken = board.loop.gyro.times.dropped + len(board.loop.gyro.times)
    assert taken > 2 * GYRO_HISTORY                   # the board dropped most of them
    assert len(sink.rates) >= taken - 400, (len(sink.rates), taken)    # all but the last second's
    assert len(sink.rates) <= taken
