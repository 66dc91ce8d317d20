"""``python benchmarks/reliability.py [options]``: runs the reliability benchmark, the
package ``benchmarks/reliability/`` (its docstring says what it measures; ``--help``
lists the options). The package is found first on this directory's path, so
``import reliability`` here is the package, not this file."""

from __future__ import annotations

from reliability.runner import main

if __name__ == "__main__":
    raise SystemExit(main())
