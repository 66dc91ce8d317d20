"""``python -m benchmarks.reliability [options]``: the reliability benchmark's command
line (``runner.main``; ``--help`` lists the options)."""

from __future__ import annotations

from .runner import main

if __name__ == "__main__":
    raise SystemExit(main())
