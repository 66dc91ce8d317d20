"""Where a lidar sits on the chair: ``LidarMount``, a pose ``x, y, z, roll, pitch, yaw``
in base_link, and the rotation of the laser frame its driver's scans are in.

    mount = parse_mount("-0.30,0,0.25,180,0,180")     # m and degrees: head down, facing back
    mount.yaw, mount.roll                             # radians: pi, pi
    mount.laser_rotation                              # the /tf_static quaternion (x, y, z, w)

The device's front is its laser frame's -x (the drivers publish the device's angle
``a`` as ``pi - a``: ``wcdrive.plant.lidar_driver``). Head down (a roll of pi) the head
turns the other way round as seen from above, so the beams' order is mirrored: a driver
not told (``inverted`` false) publishes them as if head up, and the laser frame that
makes them land where they point keeps the roll of pi; a driver told reverses them, and
that frame has no roll.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")


@dataclass(frozen=True)
class LidarMount:
    """Where the lidar sits on the chair (base frame, metres and degrees), whether it is
    mounted head down, and whether its driver is told so (``inverted`` parameter).

    As a pose ``x, y, z, roll, pitch, yaw`` (``roll``, ``pitch``, ``yaw`` in radians, the
    URDF's fixed-axis order, ``Rz(yaw) Ry(pitch) Rx(roll)``): the device's frame in
    base_link, its front along the laser frame's -x. Only a level mount is modelled: a
    roll of 0 or pi (head down), a pitch of 0 (``from_degrees`` takes a pitch of 180 as
    the same pose, a roll of 180 and a yaw 180 on). A head-down device sweeps the other
    way round, so its scan is the mirror image of a head-up one's."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.4
    yaw_deg: float = 0.0
    inverted: bool = False
    driver_inverted: bool = False

    @property
    def roll(self) -> float:
        """The device's roll (rad): pi head down, else 0."""
        return math.pi if self.inverted else 0.0

    @property
    def pitch(self) -> float:
        """The device's pitch (rad): 0, the only one modelled."""
        return 0.0

    @property
    def yaw(self) -> float:
        """The device's yaw (rad)."""
        return math.radians(self.yaw_deg)

    @property
    def tf_roll(self) -> float:
        """The roll of the laser frame in ``/tf_static`` (0 or pi)."""
        return math.pi if self.inverted != self.driver_inverted else 0.0

    @property
    def laser_rotation(self) -> tuple[float, float, float, float]:
        """The laser frame's rotation in base_link as a quaternion (x, y, z, w): the
        device's, ``Rz(yaw) Ry(pitch) Rx(roll)``, turned a half turn about its x axis
        when the driver is told ``inverted`` (its beams then come in the head-up order):
        ``Rz(yaw) Rx(tf_roll)``. A scan's beam at angle ``a`` points along this rotation
        of ``(cos a, sin a, 0)``."""
        return quaternion_rpy(self.tf_roll, self.pitch, self.yaw)

    @classmethod
    def from_degrees(cls, x: float, y: float, z: float, roll: float, pitch: float, yaw: float,
                     driver_inverted: bool = False) -> LidarMount:
        """The mount at ``x, y, z`` (m) turned ``roll, pitch, yaw`` (degrees, URDF order).
        A ``ValueError`` names a value that is not finite, or a roll or pitch other than
        0 or 180 (a tilted scan plane is not modelled)."""
        for name, value in zip(_NAMES, (x, y, z, roll, pitch, yaw), strict=True):
            if not math.isfinite(value):
                raise ValueError(f"lidar mount {name} {value!r} is not a finite number")
        for name, value in (("roll", roll), ("pitch", pitch)):
            if value % 180.0 != 0.0:
                raise ValueError(f"lidar mount {name} {value:g} deg: only 0 or 180 is modelled "
                                 "(the scan plane level, head up or down)")
        flip = pitch % 360.0 == 180.0     # Ry(pi) = Rz(pi) Rx(pi)
        return cls(x=x, y=y, z=z, yaw_deg=yaw + 180.0 if flip else yaw,
                   inverted=(roll % 360.0 == 180.0) != flip, driver_inverted=driver_inverted)


def quaternion_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of ``Rz(yaw) Ry(pitch) Rx(roll)`` (radians)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def parse_mount(text: str, driver_inverted: bool = False) -> LidarMount:
    """``x,y,z,roll,pitch,yaw`` (m and degrees, as a URL's ``lidar_mount=`` gives it):
    ``LidarMount.from_degrees``. A ``ValueError`` names the bad value."""
    parts = text.split(",")
    if len(parts) != 6:
        raise ValueError(f"lidar mount {text!r}: x,y,z,roll,pitch,yaw (m, m, m, deg, deg, deg), "
                         f"six numbers, not {len(parts)}")
    values = []
    for name, part in zip(_NAMES, parts, strict=True):
        try:
            values.append(float(part))
        except ValueError:
            raise ValueError(f"lidar mount {name} {part.strip()!r} is not a number") from None
    x, y, z, roll, pitch, yaw = values
    return LidarMount.from_degrees(x, y, z, roll, pitch, yaw, driver_inverted)


#: The seed's mount: its static transform base_link -> laser, 0.20 m ahead of the axle
#: midpoint and 0.30 m up, no rotation (seed 000, "Static TF Publishers").
SEED_MOUNT = LidarMount(x=0.20, y=0.0, z=0.30)
