"""The plant's C kernel (``csrc/chair_kernel.c``) as Python sees it: ``ChairStruct``,
the ctypes mirror of its ``chair_t`` (the chair's parameters, the Chipmunk functions it
calls and the state both paths step); ``load_kernel``, the library with its functions'
signatures set; ``bind_chipmunk``, which gives the struct the plant's space and body and
Chipmunk's functions; ``KernelSampler``, what ``Plant.advance_batch`` needs of a sensor
that takes its samples in the kernel's call (``wcdrive.plant.sensors.Gyro``).

``load_kernel`` holds ``ChairStruct`` to ``chair_t`` as the compiler laid it out
(``wcdrive.plant.struct_layout``) and raises ``StructLayoutError`` where they differ:
a mirror out of step with its C struct would have the kernel read and write the wrong
bytes, with no error but wrong motion.

The kernel calls pymunk's own Chipmunk through function pointers (``bind_chipmunk``)
rather than linking Chipmunk itself: it steps the very space pymunk holds, and a step
costs well under a microsecond.
"""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from wcdrive._util.native import BuildError, library, record
from wcdrive.plant.struct_layout import check_layout
from wcdrive.plant.terrain import MAX_RAMPS

if TYPE_CHECKING:
    import numpy as np
    import pymunk

_D = ctypes.c_double
_P = ctypes.c_void_p


class ChairStruct(ctypes.Structure):
    """``chair_t`` of chair_kernel.c: parameters, Chipmunk handles and the state."""

    _fields_ = [(n, _D) for n in ("half_base", "r", "cog_x", "caster_x", "caster_y", "trail",
                                  "swivel_max", "swivel_friction")]
    _fields_ += [("mu", _D * 2)]
    _fields_ += [(n, _D) for n in ("mu_c", "n_drive", "n_caster", "crr", "crr_c", "c_long", "c_lat",
                                  "c_caster", "j", "b", "k1", "k2", "ke_g", "tau_max", "i_max_r",
                                  "res")]
    _fields_ += [(n, _P) for n in ("space", "body", "get_velocity", "get_angle",
                                  "get_angular_velocity", "set_force", "set_torque", "space_step",
                                  "update_position", "update_velocity", "get_damping", "get_gravity",
                                  "get_sleep_threshold", "each_body", "each_constraint", "body_each_shape",
                                  "get_body_type")]
    _fields_ += [(n, _D * 2) for n in ("volts", "angle", "speed", "current", "slip", "force",
                                      "caster_heading")]
    _fields_ += [(n, _D) for n in ("scrub_energy", "scrub_time", "swivel_work", "side_impulse", "time")]
    _fields_ += [(n, ctypes.c_int32 * 2) for n in ("locked", "dead")]
    _fields_ += [("custom_funcs", ctypes.c_int32)]
    _fields_ += [(n, ctypes.c_int32) for n in ("terrain", "n_ramps")]
    _fields_ += [(n, _D) for n in ("mass_g", "cog_h", "n_drive0", "n_caster0", "down_c", "down_s",
                                  "slope_sin", "slope_cos")]
    _fields_ += [(n, _D * MAX_RAMPS) for n in ("ramp_from", "ramp_to", "ramp_sin", "ramp_cos")]
    _fields_ += [("get_position", _P)]
    _fields_ += [(n, _D) for n in ("k_long", "k_lat", "inv_k_long", "inv_k_lat")]
    _fields_ += [(n, _D * 2) for n in ("defl", "defl_lat")]
    _fields_ += [(n, _D) for n in ("brake_torque", "brake_wait")]
    _fields_ += [(n, _D) for n in ("th_res", "th_cap", "t_amb")]
    _fields_ += [("temp", _D * 2)]
    _fields_ += [(n, _D) for n in ("bat_e0", "bat_e1", "bat_r", "bat_cap", "soc", "bat_v")]
    _fields_ += [("duty", _D * 2)]
    _fields_ += [(n, ctypes.c_int32) for n in ("has_brake", "brake_pin", "brake_engaged")]


_KERNEL_SOURCE = Path(__file__).resolve().parent / "csrc" / "chair_kernel.c"
_kernel: ctypes.CDLL | bool | None = None


def load_kernel() -> ctypes.CDLL | None:
    """The C kernel (``chair_advance``, ``gyro_samples``): the one the install built, else
    compiled on first use; None when neither can be had. Raises
    ``wcdrive.plant.struct_layout.StructLayoutError`` when ``ChairStruct`` does not lay
    ``chair_t`` out as the compiler did."""
    global _kernel
    if _kernel is None:
        try:
            lib, how = library("wcdrive.plant._chair_kernel", _KERNEL_SOURCE, "chairkernel", ("-lm",),
                               ("-O2", "-ffp-contract=off"))
            check_layout(ChairStruct, lib, "chair_layout")
            lib.chair_advance.argtypes = [ctypes.POINTER(ChairStruct), ctypes.c_int32, _D, _D,
                                          _P, _P, _P]
            lib.chair_advance.restype = None
            lib.gyro_samples.argtypes = [ctypes.c_int32, _P, _P, _P, ctypes.c_int32, _P, _P]
            lib.gyro_samples.restype = ctypes.c_int32
            lib.chair_advance_sampled.argtypes = [ctypes.POINTER(ChairStruct), ctypes.c_int32, _D, _P, _P, _P,
                                                  _P, _P, ctypes.c_int32, _P, _P]
            lib.chair_advance_sampled.restype = ctypes.c_int32
            _kernel = lib
            record("plant kernel", how)
        except (BuildError, OSError) as exc:            # OSError: no writable cache
            record("plant kernel", f"Python ({exc})".splitlines()[0])
            _kernel = False
    return _kernel if isinstance(_kernel, ctypes.CDLL) else None


def bind_chipmunk(s: ChairStruct, space: pymunk.Space, body: pymunk.Body) -> None:
    """Gives the kernel's struct ``space`` and ``body`` (their Chipmunk objects) and the
    addresses of the Chipmunk functions it calls, from pymunk's own library."""
    from pymunk._chipmunk import ffi, lib

    def address(name: str) -> int:
        return int(ffi.cast("uintptr_t", ffi.addressof(lib, name)))

    s.space = int(ffi.cast("uintptr_t", space._space))
    s.body = int(ffi.cast("uintptr_t", body._body))
    s.get_velocity = address("cpBodyGetVelocity")
    s.get_angle = address("cpBodyGetAngle")
    s.get_angular_velocity = address("cpBodyGetAngularVelocity")
    s.set_force = address("cpBodySetForce")
    s.set_torque = address("cpBodySetTorque")
    s.space_step = address("cpSpaceStep")
    s.update_position = address("cpBodyUpdatePosition")
    s.update_velocity = address("cpBodyUpdateVelocity")
    s.get_damping = address("cpSpaceGetDamping")
    s.get_gravity = address("cpSpaceGetGravity")
    s.get_sleep_threshold = address("cpSpaceGetSleepTimeThreshold")
    s.each_body = address("cpSpaceEachBody")
    s.each_constraint = address("cpSpaceEachConstraint")
    s.body_each_shape = address("cpBodyEachShape")
    s.get_body_type = address("cpBodyGetType")
    s.get_position = address("cpBodyGetPosition")


class KernelSampler(Protocol):
    """What ``Plant.advance_batch`` needs of a sensor that samples the plant's steps in
    the kernel's call (``wcdrive.plant.sensors.Gyro``)."""

    @property
    def kernel_ready(self) -> bool:
        """Whether it can take its samples in the kernel (else ``sample_steps`` is called)."""

    def sample_steps(self, t0: float, dt: float, rates: np.ndarray, rates_at: int | None = None) -> None:
        """Its samples of ``len(rates)`` steps of ``dt`` from ``t0`` with these yaw rates."""

    def kernel_arguments(self, t0: float, steps: int, dt: float) -> tuple[int, int, int, int, int]:
        """``chair_advance_sampled``'s sampler arguments for ``steps`` steps of ``dt``
        from ``t0``: the addresses of its 8 parameters and of its next random draw, the
        most samples, the addresses of the times and values buffers."""

    def kernel_took(self, count: int) -> None:
        """The kernel wrote ``count`` samples (and moved the next time and the bias on)."""
