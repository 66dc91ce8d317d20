"""Physical parameters of the chair, with where each number comes from.

Geometry, encoder resolution and top speed are the seed's (guide section 1.4.2).
The rest are assumptions for a mid-size rear-wheel-drive power chair, chosen to be
typical rather than measured; change them per chair with ``dataclasses.replace``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from wcdrive.errors import WcdriveFileError
from wcdrive.protocol.spec import real

if TYPE_CHECKING:
    from wcdrive.plant.lidar import Lidar

G = 9.81


@dataclass(frozen=True)
class ChairParams:
    """Every physical parameter of the chair (frozen: vary one with
    ``dataclasses.replace``, as a scenario's ``[chair]`` table does)."""

    # --- seed (guide 1.4.2) ---
    wheelbase: float = real("WHEELBASE")            # m between the drive wheels
    wheel_radius: float = real("WHEEL_RADIUS")      # m (6 in)
    counts_per_rev: int = round(real("CPR"))        # 2500 PPR x 4
    top_wheel_speed: float = real("MAX_WHEEL_SPEED")  # rad/s at full duty (2.68 m/s)
    supply_voltage: float = 24.0       # V, 24 V brushed motors (rating; sets Ke)
    battery_voltage: float | None = None   # V at the driver now (None: the rating); a low battery
    current_limit: float = 13.0        # A per channel (the guide's SmartDriveDuo figure)

    # --- body (assumed) ---
    chair_mass: float = 110.0          # kg with batteries (typical mid-wheel/rear-wheel chairs: 100-140)
    occupant_mass: float = 80.0        # kg
    length: float = 1.0                # m, footprint used for the yaw inertia
    width: float = 0.65                # m
    # m: the footprint's centre (a length x width rectangle, square to the chair) ahead of
    # the drive axle: 0.3 m of frame behind the axle, 0.7 m (footrests) ahead. What
    # collides with a world's walls (wcdrive.plant.chair).
    footprint_ahead_of_axle: float = 0.2
    cog_ahead_of_axle: float = 0.12    # m: centre of gravity ahead of the drive axle
    cog_height: float = 0.45           # m: centre of gravity above the floor, seated occupant (assumed)
    caster_ahead_of_axle: float = 0.45  # m: caster pivots ahead of the drive axle
    caster_half_track: float = 0.25    # m: caster pivots either side of the centre line
    caster_trail: float = 0.05         # m: contact patch behind the pivot
    caster_max_swivel_rate: float = 8.0  # rad/s the caster can swing (inertia)
    caster_swivel_friction: float = 0.5  # N m of bearing friction resisting the swing
    caster_initial_offsets: tuple[float, float] = (0.02, -0.015)   # rad: no caster is perfectly aligned

    # --- tyres and floor (assumed) ---
    friction: float = 0.8              # drive tyre on a dry floor
    friction_left: float | None = None   # per-wheel override (a wet patch, say)
    friction_right: float | None = None
    caster_friction: float = 0.6
    rolling_resistance: float = 0.015  # drive wheels
    caster_rolling_resistance: float = 0.03
    tyre_stiffness: float = 100000.0   # N per m/s of longitudinal slip: the contact patch's damping
    lateral_stiffness: float = 20000.0  # N per m/s of lateral slip (damping, likewise)
    caster_stiffness: float = 20000.0  # N per m/s of caster side slip (regularised Coulomb)
    # The drive tyres' contact patch as a spring (the plant's static grip): N per m of
    # deflection, longitudinal and lateral. A small pneumatic tyre's carcass and tread:
    # 0.4 mm of deflection for the 77 N each wheel holds parked on 1:12 (assumed).
    tyre_contact_stiffness: float = 200000.0
    lateral_contact_stiffness: float = 100000.0

    # --- parking brake (assumed) ---
    parking_brake: bool = False        # an electromagnetic brake on each drive wheel (the seed chair: none)
    # N m at each wheel while engaged, holding and slipping alike. 33.7 N m each holds the
    # heaviest chair (110 kg with a 150 kg occupant) on 10 degrees (m g sin(10 deg) r / 2);
    # 50 N m holds it up to 14.9 degrees, 1.48 times what 10 degrees takes (where each dry
    # tyre, facing down, is asked 221 N of the 560 N it grips). The motors (14.6 N m each
    # at the wheel at the current limit) cannot turn it; engaged at speed it stops the
    # 190 kg chair at 3.2 m/s^2.
    brake_torque: float = 50.0
    brake_engage_delay: float = 0.05   # s from the pin going low to the brake holding (assumed)
    brake_release_delay: float = 0.05  # s from the pin going high to the brake letting go (assumed)

    # --- drive train (assumed) ---
    gear_ratio: float = 18.0
    gear_efficiency: float = 0.85
    armature_resistance: float = 0.3   # ohm
    wheel_inertia: float = 0.10        # kg m^2, wheel and tyre
    rotor_inertia: float = 1.5e-4      # kg m^2, reflected through gear_ratio**2
    viscous_friction: float = 0.02     # N m s/rad at the wheel

    # --- the battery (assumed figures of two 12 V 50 Ah AGM blocks in series) ---
    # With battery_capacity_ah 0 (the default) the driver sees an ideal supply,
    # battery_voltage or supply_voltage. Otherwise the motors see duty x the terminal
    # voltage: the open-circuit voltage, linear in the state of charge from
    # battery_empty_voltage to battery_full_voltage (an AGM block rests at about 11.8 V
    # empty and 12.8 V full), less battery_resistance times the driver's input current
    # (each motor's current times its duty); the charge drawn runs the state down.
    battery_capacity_ah: float = 0.0
    battery_charge: float = 1.0               # state of charge at the start, 0..1
    battery_empty_voltage: float = 23.6       # V open-circuit at 0 %
    battery_full_voltage: float = 25.6        # V open-circuit at 100 %
    battery_resistance: float = 0.05          # ohm: both blocks, their links and the fuse

    # --- the motors' windings (assumed: no datasheet figures were to hand) ---
    # Each winding one thermal mass, heated by its copper loss I^2 R (armature_resistance)
    # and cooled to ambient through a thermal resistance: at the 13 A current limit
    # (50.7 W) it settles 127 K above ambient, past a class B (130 deg C) rating from
    # 20 deg C, with a time constant of R C = 900 s. Small 24 V gear motors of a few
    # hundred watts run 1.5 to 3 K/W and 10 to 30 minutes.
    winding_thermal_resistance: float = 2.5   # K/W, winding to ambient
    winding_heat_capacity: float = 360.0      # J/K (0: no thermal model)
    ambient_temp: float = 20.0                # deg C
    winding_temp_rating: float = 130.0        # deg C: insulation class B

    # --- gyro: Bosch BMI085 figures from the seed ---
    gyro_rate_hz: float = 400.0
    gyro_noise_dps: float = 0.014      # deg/s rms
    gyro_bias_dps: float = 0.05        # deg/s initial bias, drawn per run
    gyro_bias_walk_dps_per_sqrt_s: float = 0.002

    @property
    def max_braking(self) -> float:
        """m/s^2: the hardest the motors can brake the chair on the flat: both at the
        driver's current limit (torque ``Ke G eff I``, ``Ke`` from the rated voltage at
        top speed) on the chair's mass and the wheels' and rotors' inertia, plus the
        drive wheels' rolling resistance. 1.12 m/s^2 for these figures:
        tests/sim/test_fault_injection.py checks it against a full-reverse stop."""
        ke = self.supply_voltage / (self.gear_ratio * self.top_wheel_speed)
        force = 2.0 * self.current_limit * ke * self.gear_ratio * self.gear_efficiency / self.wheel_radius
        inertia = 2.0 * (self.wheel_inertia + self.rotor_inertia * self.gear_ratio**2) / self.wheel_radius**2
        return force / (self.mass + inertia) + self.rolling_resistance * G

    @property
    def current_limit_speed(self) -> float:
        """m/s: below this speed the motors' own back-EMF, shorted by the driver at duty
        0, no longer reaches the current limit, and the braking fades."""
        ke = self.supply_voltage / (self.gear_ratio * self.top_wheel_speed)
        return self.current_limit * self.armature_resistance / (ke * self.gear_ratio) * self.wheel_radius

    @property
    def mass(self) -> float:
        """kg: chair and occupant."""
        return self.chair_mass + self.occupant_mass

    @property
    def yaw_inertia(self) -> float:
        """Uniform box about its centre (assumption): m (l^2 + w^2) / 12."""
        return self.mass * (self.length**2 + self.width**2) / 12.0

    @property
    def caster_load_share(self) -> float:
        """Static load on the casters: moments about the drive axle."""
        return self.cog_ahead_of_axle / self.caster_ahead_of_axle

    @property
    def drive_wheel_load(self) -> float:
        """N: the static normal force on each drive wheel."""
        return self.mass * G * (1.0 - self.caster_load_share) / 2.0

    @property
    def caster_load(self) -> float:
        """N: the static normal force on each caster."""
        return self.mass * G * self.caster_load_share / 2.0

    @property
    def wheel_total_inertia(self) -> float:
        """kg m^2 at the wheel: wheel and tyre, plus the rotor through gear_ratio**2."""
        return self.wheel_inertia + self.rotor_inertia * self.gear_ratio**2

    @property
    def motor_constant(self) -> float:
        """Ke = Kt (SI), chosen so that full duty on level ground gives the seed's top
        speed: V = Ke G w + R i, with i carrying rolling resistance and gear friction."""
        w = self.top_wheel_speed
        r = self.wheel_radius
        load = (self.rolling_resistance * self.drive_wheel_load * r
                + self.viscous_friction * w
                + self.caster_rolling_resistance * self.caster_load * r)   # per wheel
        g, eta, R, V = self.gear_ratio, self.gear_efficiency, self.armature_resistance, self.supply_voltage
        # V = k G w + R load / (k G eta)  ->  G w k^2 - V k + R load / (G eta) = 0
        a, b, c = g * w, -V, R * load / (g * eta)
        return (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)

    def grade_loads(self, slope: float, facing: float = 0.0) -> tuple[float, float]:
        """N: the static normal force on each drive wheel and on each caster on a grade of
        ``slope`` rad, the chair facing ``facing`` rad from the downhill heading (0:
        nose downhill, pi: nose uphill). On the flat, ``drive_wheel_load`` and
        ``caster_load``.

        Moments about the drive wheels' contact line: the floor carries ``m g cos(slope)``,
        and the grade's pull along the chair, ``m g sin(slope) cos(facing)`` at
        ``cog_height`` above the floor, tips the load onto the casters facing downhill and
        off them facing uphill::

            casters = m g (cos(slope) cog_ahead_of_axle
                           + sin(slope) cos(facing) cog_height) / caster_ahead_of_axle
            drive wheels = m g cos(slope) - casters

        each shared by two, the casters' share held within 0..m g cos(slope) (beyond it
        the chair tips; the plant does not model that). A cross slope moves no load
        between left and right in this model."""
        normal = self.mass * G * math.cos(slope)
        pull = self.mass * G * math.sin(slope) * math.cos(facing)
        casters = (normal * self.cog_ahead_of_axle + pull * self.cog_height) / self.caster_ahead_of_axle
        casters = min(max(casters, 0.0), normal)
        return 0.5 * (normal - casters), 0.5 * casters

    def rated_grade(self, occupant_mass: float | None = None) -> float:
        """degrees: the steepest grade the chair can climb from rest, facing uphill, with
        both motors at the driver's current limit (``occupant_mass`` kg in the seat, by
        default this one's).

        The static force balance at stall: the motors' torque at the current limit,
        ``Ke G eff I`` each, through the wheel radius, against the grade's pull and the
        rolling resistance of the loads ``grade_loads`` gives facing uphill::

            2 Ke G eff I / r = m g (A sin(t) + B cos(t))
            A = 1 + (crr - crr_caster) cog_height / caster_ahead_of_axle
            B = crr (1 - s) + crr_caster s,   s = cog_ahead_of_axle / caster_ahead_of_axle

        so ``t = asin(F / (m g hypot(A, B))) - atan2(B, A)``. Traction (``friction`` times
        the drive wheels' load) and tipping are not limits here; 0 when the motors
        cannot overcome rolling resistance."""
        ratio, rolling = self._grade_balance(occupant_mass, motors=2)
        if ratio >= 1.0:
            return 90.0
        return max(0.0, math.degrees(math.asin(ratio) - rolling))

    def hold_grade(self, occupant_mass: float | None = None, *, motors: int = 2) -> float:
        """degrees: the steepest grade on which ``motors`` motors (2 or 1), braking at the
        driver's current limit, hold the chair rolling nose downhill (``occupant_mass``
        kg in the seat, by default this one's); beyond it gravity beats the braking.

        Going down, rolling resistance helps the brakes. With the loads ``grade_loads``
        gives nose downhill, the rolling resistance is ``m g (B cos(t) - (A - 1) sin(t))``
        (A, B as in ``rated_grade``), so the balance of the grade's pull against the
        braking force F (``Ke G eff I / r`` a motor) and the rolling resistance is::

            F = m g (A sin(t) - B cos(t)),   t = asin(F / (m g hypot(A, B))) + atan2(B, A)

        Two motors hold 7.08 degrees with the default 80 kg occupant, where they climb
        4.87 (``rated_grade``); one motor alone holds 4.09."""
        if motors not in (1, 2):
            raise ValueError(f"motors must be 1 or 2, not {motors!r}")
        ratio, rolling = self._grade_balance(occupant_mass, motors=motors)
        if ratio >= 1.0:
            return 90.0
        return min(90.0, math.degrees(math.asin(ratio) + rolling))

    def _grade_balance(self, occupant_mass: float | None, *, motors: int) -> tuple[float, float]:
        """``(F / (m g hypot(A, B)), atan2(B, A))`` of ``rated_grade``'s force balance:
        ``motors`` motors' force at the driver's current limit, ``Ke G eff I / r`` each,
        against the chair's weight (``occupant_mass`` kg in the seat, by default this
        one's), and the rolling resistance's angle."""
        p = self if occupant_mass is None else dataclasses.replace(self, occupant_mass=occupant_mass)
        force = (motors * p.gear_ratio * p.gear_efficiency * p.motor_constant * p.current_limit
                 / p.wheel_radius)
        share = p.caster_load_share
        a = 1.0 + (p.rolling_resistance - p.caster_rolling_resistance) * p.cog_height / p.caster_ahead_of_axle
        b = p.rolling_resistance * (1.0 - share) + p.caster_rolling_resistance * share
        return force / (p.mass * G * math.hypot(a, b)), math.atan2(b, a)

    def wheel_friction(self, side: str) -> float:
        """The friction coefficient of the ``"left"`` or ``"right"`` drive tyre."""
        override = self.friction_left if side == "left" else self.friction_right
        return self.friction if override is None else override


class ChairFileError(WcdriveFileError):
    """A chair file (``load_chair``) is missing or malformed; the message names it."""


def chair_overrides(table: dict[str, object], where: str = "[chair]") -> dict[str, object]:
    """The ``ChairParams`` overrides of a ``[chair]`` table, checked: every key a field,
    every value of the field's kind (a number for a float, a pair for a tuple, true or
    false for a flag). ``ChairFileError`` names the first key that is not."""
    fields = {f.name: f for f in dataclasses.fields(ChairParams)}
    out: dict[str, object] = {}
    for name, value in table.items():
        if name not in fields:
            raise ChairFileError(f"{where}: unknown key {name!r} (not a ChairParams field)")
        default = fields[name].default
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, tuple):
            items = list(value) if isinstance(value, (list, tuple)) else []
            ok = len(items) == len(default) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in items)
            value = tuple(float(v) for v in items)
        elif isinstance(default, int):
            ok = number and float(value).is_integer()       # type: ignore[arg-type]
            value = round(value) if ok else value            # type: ignore[call-overload]
        else:
            ok = number or (default is None and value is None)
        if not ok:
            raise ChairFileError(f"{where}: {name} = {table[name]!r} is not a value of {fields[name].type}")
        out[name] = value
    return out


def _chair_file(path: Path) -> dict[str, object]:
    """A chair file's tables; ``ChairFileError`` when it cannot be read or is not TOML."""
    try:
        return tomllib.loads(path.read_text())
    except OSError as exc:
        raise ChairFileError(f"cannot read chair file {path}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ChairFileError(f"{path}: not valid TOML: {exc}") from None


def load_chair_overrides(path: str | Path) -> dict[str, object]:
    """The checked ``[chair]`` table of a chair file (``load_chair``), as overrides."""
    path = Path(path)
    data = _chair_file(path)
    table = data.get("chair")
    if not isinstance(table, dict):
        raise ChairFileError(f"{path}: no [chair] table")
    return chair_overrides(table, f"{path}: [chair]")


def load_chair(path: str | Path) -> ChairParams:
    """The ``ChairParams`` of a chair file: a TOML file whose ``[chair]`` table overrides
    the defaults, as a scenario's does (what ``wcdrive bench identify`` writes, and what
    ``sim://?chair=`` and ``simavr://?chair=`` load). Other tables in the file are left
    alone. ``ChairFileError`` when the file is missing, not TOML, has no ``[chair]``
    table or a key that ``chair_overrides`` refuses."""
    return dataclasses.replace(ChairParams(), **load_chair_overrides(path))  # type: ignore[arg-type]


def load_chair_lidar(path: str | Path) -> Lidar | None:
    """The lidar of a chair file's ``[lidar]`` table, or None without one: its keys
    ``model``, ``mount`` (``"x,y,z,roll,pitch,yaw"`` or six numbers, m and degrees),
    ``driver``, ``inverted`` and ``angle_compensate``, the URL's ``lidar=`` and
    ``lidar_*`` options (``wcdrive.plant.lidar.lidar_from_table``). ``ChairFileError``
    names the file and the bad key or value."""
    from wcdrive.plant.lidar import lidar_from_table

    path = Path(path)
    table = _chair_file(path).get("lidar")
    if table is None:
        return None
    if not isinstance(table, dict):
        raise ChairFileError(f"{path}: lidar is not a table")
    try:
        return lidar_from_table(table)
    except ValueError as exc:
        raise ChairFileError(f"{path}: [lidar] {exc}") from None


def chair_toml(overrides: Mapping[str, object], comments: dict[str, str] | None = None,
               header: str = "") -> str:
    """A chair file's text: ``header`` as ``#`` comment lines, then the ``[chair]`` table
    of ``overrides`` (each value with ``repr``'s round-trip digits), each line followed
    by its entry of ``comments`` after a ``#``. ``load_chair`` reads it back."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines.append("[chair]")
    for name, value in overrides.items():
        chair_overrides({name: value})
        text = f"{name} = {_toml_value(value)}"
        note = (comments or {}).get(name)
        lines.append(f"{text:<40} # {note}" if note else text)
    return "\n".join(lines) + "\n"


def _toml_value(value: object) -> str:
    """A ``[chair]`` value as TOML: true/false, an array for a tuple, else ``repr``'s
    round-trip digits."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)
