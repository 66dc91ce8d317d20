"""The C harness (``csrc/wcsim.c``) as Python calls it: ``_lib()`` is the library,
loaded once per process with the ctypes signature of every function a
``VirtualMega`` calls, and ``HarnessError`` is what a virtual board raises when it
cannot be made or stops unexpectedly.

The library is compiled on first use (``build.harness_library``, into the cache).
ctypes checks nothing a C prototype would: a missing ``restype`` truncates a 64-bit
pointer or cycle count to an int, so every signature is declared here, in one table,
and every board shares the one handle (``BootloaderMega`` adds the functions only it
calls to the same handle).
"""

from __future__ import annotations

import ctypes

from wcdrive.boards.simavr.build import harness_library
from wcdrive.errors import WcdriveError


class HarnessError(WcdriveError, RuntimeError):
    """The virtual board could not be made or stopped unexpectedly."""


def _load_library() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(harness_library()))
    p, u64, u32, i32, sz = ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint32, ctypes.c_int, ctypes.c_size_t
    u8p = ctypes.POINTER(ctypes.c_uint8)
    sig = {
        "wcsim_new": (p, [ctypes.c_char_p, ctypes.c_char_p, i32]),
        "wcsim_free": (None, [p]),
        "wcsim_cycle": (u64, [p]),
        "wcsim_crashed": (i32, [p]),
        "wcsim_schedule": (i32, [p, u64, i32, i32, i32, i32]),
        "wcsim_schedule_many": (i32, [p, sz, ctypes.POINTER(u64), u8p, u8p, u8p, u8p]),
        "wcsim_add_hook": (i32, [p, u32]),
        "wcsim_set_break_mask": (None, [p, u32]),
        "wcsim_run_until": (i32, [p, u64]),
        "wcsim_tx_count": (sz, [p]),
        "wcsim_tx_take": (sz, [p, ctypes.POINTER(u64), u8p, sz]),
        "wcsim_hits_count": (sz, [p]),
        "wcsim_hits_take": (sz, [p, ctypes.POINTER(u64), ctypes.POINTER(u32), ctypes.POINTER(u32), sz]),
        "wcsim_read": (i32, [p, u32, u8p, u32]),
        "wcsim_write": (i32, [p, u32, u8p, u32]),
        "wcsim_sp": (u32, [p]),
        "wcsim_ramend": (u32, [p]),
        "wcsim_vcd_pwm": (None, [p, i32, i32]),
        "wcsim_vcd_open": (i32, [p, ctypes.c_char_p, ctypes.c_char_p]),
        "wcsim_vcd_close": (None, [p]),
        "wcsim_reset": (i32, [p, i32]),
        "wcsim_mcusr": (ctypes.c_uint8, [p]),
        "wcsim_resets_count": (sz, [p]),
        "wcsim_resets_take": (sz, [p, ctypes.POINTER(u64), u8p, u8p, sz]),
        "wcsim_charge_irq_entry": (None, [p, i32]),
        "wcsim_irq_entries": (u64, [p, i32]),
        "wcsim_prof_set": (i32, [p, i32, ctypes.POINTER(u32), ctypes.POINTER(u32)]),
        "wcsim_prof_get": (u64, [p, i32]),
        "wcsim_pc": (u32, [p]),
        "wcsim_rx_index": (u64, [p]),
        "wcsim_rx_held": (i32, [p]),
        "wcsim_rx_lost_count": (sz, [p]),
        "wcsim_rx_lost_take": (sz, [p, ctypes.POINTER(u64), ctypes.POINTER(u64), u8p, u8p, sz]),
        "wcsim_eeprom_size": (u32, [p]),
        "wcsim_eeprom_read": (i32, [p, u32, u8p, u32]),
        "wcsim_eeprom_write": (i32, [p, u32, u8p, u32]),
    }
    for name, (restype, argtypes) in sig.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


_LIB: ctypes.CDLL | None = None


def _lib() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        _LIB = _load_library()
    return _LIB
