"""``wcdrive.testing``: what a downstream test suite needs to test against the chair.

- The pytest plugin (``wcdrive.testing.plugin``), registered through the ``pytest11``
  entry point, so installing wcdrive is enough: fixtures ``wc_chair`` (a ``sim://``
  chair, closed after the test), ``wc_simavr_chair`` (the compiled firmware in simavr;
  skipped, with the reason, when the AVR toolchain or libsimavr is missing),
  ``wc_port`` (the bit-exact port and the plant as a ``SteppedChair``: no thread, the
  test advances time) and ``wc_faulty_port`` (a factory: a ``SteppedChair`` with
  faults injected).
- Hypothesis strategies (``wcdrive.testing.strategies``): ``commands()``,
  ``byte_streams()``, ``encoder_traces()``, ``traces()``, ``scenarios()`` and
  ``faults()``, the generators the project's own differential tests use.

This package sits with the tools (docs/architecture.md): it may use the harness
(``wcdrive.hil``), and nothing in the library imports it.
"""

from __future__ import annotations

from wcdrive.testing.stepped import SteppedChair

__all__ = ["SteppedChair"]
