"""``History``: a list that keeps only its newest ``maxlen`` items (a ring buffer), for
the histories long-lived objects keep (a chair's errors and events, the telemetry).

It is a ``list`` (equality, slicing, ``in``, ``len`` as usual), so code that reads a
history needs no change; ``append`` and ``extend`` drop the oldest items past the
bound, and ``maxlen`` can be changed at any time (lowering it trims at once).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from typing import SupportsIndex, TypeVar

T = TypeVar("T")

#: The default bound of every history (items).
DEFAULT_HISTORY = 10_000


class History(list[T]):
    """A list bounded to its newest ``maxlen`` items (module docstring)."""

    def __init__(self, items: Iterable[T] = (), maxlen: int = DEFAULT_HISTORY) -> None:
        super().__init__()
        self._maxlen = _check(maxlen)
        self._lock = threading.Lock()
        self.dropped = 0            #: items dropped so far to keep the bound
        self.extend(items)

    @property
    def maxlen(self) -> int:
        """The bound; setting it trims the oldest items at once."""
        return self._maxlen

    @maxlen.setter
    def maxlen(self, value: int) -> None:
        self._maxlen = _check(value)
        with self._lock:
            self._trim()

    def _trim(self) -> None:
        excess = len(self) - self._maxlen
        if excess > 0:
            del self[:excess]
            self.dropped += excess

    def append(self, item: T) -> None:
        """Appends ``item``, dropping the oldest past ``maxlen``."""
        with self._lock:
            super().append(item)
            self._trim()

    def extend(self, items: Iterable[T]) -> None:
        """Appends ``items``, dropping the oldest past ``maxlen``."""
        with self._lock:
            super().extend(items)
            self._trim()

    def insert(self, index: SupportsIndex, item: T) -> None:
        """Inserts ``item``, dropping the oldest past ``maxlen``."""
        with self._lock:
            super().insert(index, item)
            self._trim()


def _check(maxlen: int) -> int:
    if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen < 1:
        raise ValueError(f"a history's bound must be an integer >= 1, not {maxlen!r}")
    return maxlen
