"""The exit safety of every chair: each way a program lets go of one sends a stop (best
effort) and closes its port (``wcdrive.host.wheelchair`` module docstring says which).

``register(chair, session, on_close)`` gives the chair its ``weakref.finalize`` (run by
``close``, garbage collection and interpreter exit); ``stop_all`` runs every open
chair's; ``install_signal_handlers`` makes ``SIGTERM`` and ``SIGHUP`` run ``stop_all``
before the process dies as the signal would have killed it. The finalizer refers to
the session only, never to the chair, so that it can run when the chair is collected.
"""

from __future__ import annotations

import os
import signal
import threading
import weakref
from collections.abc import Callable
from types import FrameType

from wcdrive.host.session import Session

__all__ = ["STOP_SIGNALS", "install_signal_handlers", "register", "stop_all"]

#: The signals whose default action (terminate, no cleanup) the chairs' handler replaces.
STOP_SIGNALS = ("SIGTERM", "SIGHUP")


#: The chairs of this process: their shutdown, by session (the closed ones are pruned
#: as new ones come). No lock: a finalizer may run on any thread, in the middle of
#: anything (garbage collection), so every use is one atomic dict operation.
_OPEN: dict[int, weakref.finalize] = {}
_HANDLED: set[int] = set()


def _shutdown(session: Session, on_close: Callable[[], None] | None) -> None:
    """The way out of every chair (``close``, garbage collection, interpreter exit, a
    signal): a stop, then the port closes. Refers to the session only, never to the
    ``Wheelchair``, so that it can run when that is collected."""
    try:
        session.close(session.stop_line())
    finally:
        if on_close is not None:
            on_close()


def stop_all() -> int:
    """Stops and closes every chair this process has open (best effort); returns how
    many. What the signal handler does; also for a program's own handlers."""
    finalizers = [f for f in tuple(_OPEN.values()) if f.alive]
    for finalizer in finalizers:
        try:
            finalizer()
        except Exception:
            pass
    return len(finalizers)


def _on_signal(signum: int, frame: FrameType | None) -> None:
    stop_all()
    signal.signal(signum, signal.SIG_DFL)
    os.kill(os.getpid(), signum)            # dies as the signal would have killed it


def install_signal_handlers() -> list[str]:
    """Installs the stop-then-die handler for ``SIGTERM`` and ``SIGHUP`` where their
    action is still the default (never over a handler the program installed); only
    from the main thread. Returns the signals it installed now. ``Wheelchair`` calls it
    unless ``stop_on_signals=False``."""
    if threading.current_thread() is not threading.main_thread():
        return []
    installed = []
    for name in STOP_SIGNALS:
        signum = getattr(signal, name, None)
        if signum is None or signum in _HANDLED:
            continue
        try:
            if signal.getsignal(signum) is signal.SIG_DFL:
                signal.signal(signum, _on_signal)
                _HANDLED.add(signum)
                installed.append(name)
        except (OSError, ValueError):
            pass
    return installed


def register(chair: object, session: Session, on_close: Callable[[], None] | None) -> weakref.finalize:
    """``chair``'s way out: a finalizer that stops ``session`` and closes its port, then
    calls ``on_close``; kept among this process's open chairs (``stop_all``)."""
    finalizer = weakref.finalize(chair, _shutdown, session, on_close)
    for key, other in tuple(_OPEN.items()):
        if not other.alive:
            _OPEN.pop(key, None)
    _OPEN[id(session)] = finalizer
    return finalizer
