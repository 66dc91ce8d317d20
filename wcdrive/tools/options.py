"""Command-line flags that more than one tool takes, declared once.

``add_ros_output``: ``--mcap FILE``, ``--live`` and ``--live-port`` (the run as ROS 2
messages: into an MCAP file, or served to Foxglove), for ``wcdrive sim`` and
``wcdrive bench run``/``record``.
"""

from __future__ import annotations

import argparse

LIVE_PORT = 8765


def add_ros_output(parser: argparse.ArgumentParser, *, exclusive: bool, mcap_help: str,
                   live_help: str) -> None:
    """Adds ``--mcap``, ``--live`` and ``--live-port`` to ``parser``; with ``exclusive``,
    ``--mcap`` and ``--live`` refuse each other."""
    group = parser.add_mutually_exclusive_group() if exclusive else parser
    group.add_argument("--mcap", metavar="FILE", help=mcap_help)
    group.add_argument("--live", action="store_true", help=live_help)
    parser.add_argument("--live-port", type=int, default=LIVE_PORT,
                        help=f"--live: the port (default {LIVE_PORT})")
