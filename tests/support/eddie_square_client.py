"""A serial client for the Eddie board written the way existing Eddie drivers are
(eddiebot's ``Eddie::command``): pyserial only, the mnemonic in upper case and its
parameters as C++'s ``std::hex`` prints an ``int`` (lower case, negatives as 32-bit
two's complement), a CR, then up to 80 ms for the first byte of the reply and the rest
up to its CR; replies parsed at fixed positions (``DIST``: ``substr(0, 8)`` and
``substr(9, 8)``). It drives a square of ``--side`` metres with ``GOSPD``, keeps its
own odometry from ``DIST`` (36 positions per revolution, 0.0762 m radius, 0.3 m
separation) and prints it as JSON. It knows nothing of wcdrive.

    python tests/support/eddie_square_client.py /dev/pts/3 --side 1.0
"""

from __future__ import annotations

import argparse
import json
import math
import time

import serial

RADIUS, SEPARATION, PER_REV = 0.0762, 0.3, 36
M_PER_POSITION = 2 * math.pi * RADIUS / PER_REV


def int_to_hex(n: int) -> str:
    return format(n & 0xFFFFFFFF, "x")


class Eddie:
    def __init__(self, path: str) -> None:
        self.port = serial.Serial(path, 115200, timeout=0)
        self.port.write(b"\r\r\r")
        time.sleep(0.1)
        self.port.reset_input_buffer()
        self.x = self.y = self.th = 0.0
        self.last: tuple[int, int] | None = None

    def command(self, text: str) -> str:
        self.port.write(text.encode() + b"\r")
        start = time.monotonic()
        first = b""
        while not first:
            first = self.port.read(1)
            if not first:
                if time.monotonic() - start >= 0.08:
                    raise RuntimeError(f"no reply to {text!r}")
                time.sleep(0.001)
        out = bytearray(first)
        while not out.endswith(b"\r"):
            out += self.port.read(1)
        return out.decode()

    def odometry(self) -> None:
        reply = self.command("DIST")
        if reply.startswith("ERROR") or len(reply) < 18:
            raise RuntimeError(reply)
        left, right = (int(reply[i:i + 8], 16) for i in (0, 9))
        left, right = (v - (1 << 32) if v & 0x80000000 else v for v in (left, right))
        if self.last is not None:
            dl = (left - self.last[0]) * M_PER_POSITION
            dr = (right - self.last[1]) * M_PER_POSITION
            d, dth = (dl + dr) / 2, (dr - dl) / SEPARATION
            self.x += d * math.cos(self.th + dth / 2)
            self.y += d * math.sin(self.th + dth / 2)
            self.th += dth
        self.last = (left, right)

    def gospd(self, left: int, right: int) -> None:
        assert self.command(f"GOSPD {int_to_hex(left)} {int_to_hex(right)}") == "\r"

    def settle(self) -> None:
        self.gospd(0, 0)
        for _ in range(30):
            self.odometry()
            time.sleep(0.02)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("path")
    ap.add_argument("--side", type=float, default=1.0)
    ap.add_argument("--speed", type=int, default=30, help="positions per second")
    args = ap.parse_args()
    bot = Eddie(args.path)
    assert bot.command("RST") == "\r"
    bot.odometry()
    corners = []
    for k in range(4):
        x0, y0 = bot.x, bot.y
        bot.gospd(args.speed, args.speed)
        while math.hypot(bot.x - x0, bot.y - y0) < args.side - 0.03:
            time.sleep(0.01)
            bot.odometry()
        bot.settle()
        target = (k + 1) * math.pi / 2
        turn = args.speed // 2
        bot.gospd(-turn, turn)                   # counter-clockwise
        while bot.th < target - 0.06:
            time.sleep(0.01)
            bot.odometry()
        bot.settle()
        corners.append((bot.x, bot.y, bot.th))
    bot.command("STOP 0")
    print(json.dumps({"x": bot.x, "y": bot.y, "theta": bot.th, "corners": corners}))


if __name__ == "__main__":
    main()
