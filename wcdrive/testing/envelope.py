"""The chair's operating envelope as drives to run: grades, ramp bands, loads, speeds,
turns, gains and host rates, each drive a scenario TOML (``wcdrive.sim.scenario``).

A drive is drawn from any source of choices (``wcdrive.hil.traces.Draw``:
``RandomDraw`` for the seeded ``benchmarks/envelope.py``, ``HypothesisDraw`` for the
property ``tests/sim/test_envelope_property.py`` through
``wcdrive.testing.strategies.envelope_drives``), so one generator serves both.

Inside the envelope (``INSIDE``):

* ``uniform``: a floor of one grade, the chair heading down, up or diagonally across it;
* ``cross``: the same with the floor falling across the drive (90 or 270 degrees);
* ``band_up``, ``band_down``: level, a ramp band up or down (from ``BAND_FROM`` m, 1.5 to
  4 m long) and the level beyond it: the transitions onto and off the ramp; the drive
  ends beyond the band, or on it (the chair stops and parks on the ramp).

Every grade is at most the rated grade of the drawn occupant (40 to 150 kg,
``ChairParams.rated_grade``). Each drive is ``cmdvel = [speed, 0]`` (speed up to the
full-speed command ``MAX_LINEAR``), then a turn ``[speed / 2, turn]`` (turn up to
``MAX_TURN`` rad/s either way), then a stop held ``STOP_S`` s; the host sends at 4 to
100 Hz, its first byte 0 to 50 ms later than a scenario's (``host_offset_s``: its
phase against the board's 50 ms ticks, which decides some knife-edge verdicts); the
gains are the defaults or one set (kp, ki, kd) drawn over the accepted ranges
(``protocol/spec.toml``'s ``GAIN_*``) for both wheels alike (wheels tuned far apart
are a known open problem, docs/safety.md). One chair in ``BRAKE_EVERY`` has a parking
brake the firmware owns (``[chair] parking_brake``, ``[params] brake_fitted = 1``).

Beyond the envelope (``BEYOND``): ``kerb_up``, ``kerb_down``, a 1:8 kerb cut
(``KERB_DEG``, 1.2 m long), steeper than any occupant's rated grade. There the board may
send its limit events, never a fault.

A healthy drive inside the envelope must send no ``EVT:FAULT`` and no limit event
(``LIMITS``); ``judge`` sorts a run's events for that.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from wcdrive.hil.traces import Draw
from wcdrive.plant.faults import SIDED_KINDS
from wcdrive.plant.params import ChairParams
from wcdrive.protocol import spec
from wcdrive.sim.scenario import MOTION_START_S

#: The drive classes inside the envelope, and beyond it.
INSIDE = ("uniform", "cross", "band_up", "band_down")
BEYOND = ("kerb_up", "kerb_down")
#: The board's limit events (PROTOCOL.md, "The chair's limits"; hold and rollaway).
LIMITS = ("EVT:STALLED_ON_GRADE", "EVT:OVERSPEED", "EVT:ROLLAWAY")
#: The fault kinds injected into the drives (``wcdrive.plant.faults``).
FAULT_KINDS = ("motor_dead", "encoder_cut", "encoder_reversed", "wheel_locked", "link_cut")
#: One drive in this many has a parking brake the firmware owns (drawn last of all).
BRAKE_EVERY = 3
#: m/s: the full-speed command (CMDVEL's range).
MAX_LINEAR = spec.real("MAX_LINEAR")
#: rad/s: the sharpest turn drawn.
MAX_TURN = 1.0
#: Hz: the host rates drawn (the first is the bundled scenarios').
HOST_RATES = (10.0, 4.0, 5.0, 20.0, 50.0, 100.0)
#: kg: the occupants.
OCCUPANT_MIN, OCCUPANT_MAX = 40.0, 150.0
#: deg: a 1:8 kerb cut; m: where ramp bands start; s: the stop at the end.
KERB_DEG = math.degrees(math.atan(1 / 8))
BAND_FROM = 1.0
STOP_S = 3.0
#: s: the chair's ramp to full speed at the default ``max_accel`` (5 rad/s^2 at the wheels).
_RAMP_S = MAX_LINEAR / (spec.real("MAX_ACCEL") * spec.real("WHEEL_RADIUS"))


@dataclass(frozen=True)
class Drive:
    """One drive of the envelope (module docstring) and, optionally, one injected fault.

    ``grade_deg`` is the steepest grade on the way (unsigned), ``rated_deg`` the
    occupant's rated grade; ``heading_deg`` the floor's ``downhill_heading_deg`` (the
    chair starts heading 0, along +x); ``gains`` None keeps the board's defaults.
    ``motion_s`` is when the commanded motion ends (the stop begins)."""

    case: str
    occupant: float
    grade_deg: float
    rated_deg: float
    heading_deg: float
    speed: float
    turn: float
    drive_s: float
    turn_s: float
    host_rate_hz: float
    gains: tuple[float, float, float] | None = None
    band_m: float = 0.0
    fault_kind: str | None = None
    fault_at: float | None = None
    fault_side: str | None = None
    #: s: the host's bytes this much later: its phase against the board's 50 ms ticks.
    host_offset_s: float = 0.0
    #: A parking brake the firmware owns (``brake_fitted`` 1).
    brake: bool = False

    @property
    def inside(self) -> bool:
        """True for a drive inside the envelope (``INSIDE``)."""
        return self.case in INSIDE

    @property
    def motion_s(self) -> float:
        """s from the start: the end of the commanded motion (segments start at
        ``MOTION_START_S``, ``host_offset_s`` later)."""
        return self.host_offset_s + MOTION_START_S + self.drive_s + self.turn_s

    @property
    def grade_fraction(self) -> float:
        """The steepest grade over the occupant's rated grade."""
        return self.grade_deg / self.rated_deg

    def with_fault(self, kind: str, at: float, side: str | None) -> Drive:
        """The same drive with one fault of ``kind`` at ``at`` s (on ``side``)."""
        return dataclasses.replace(self, fault_kind=kind, fault_at=at, fault_side=side)

    def toml(self, name: str = "envelope") -> str:
        """The drive as a scenario file's text (``wcdrive sim FILE`` runs it)."""
        lines = [f'name = "{name}"',
                 f'description = "{self.describe()}"',
                 f"host_rate_hz = {self.host_rate_hz:g}", "settle_s = 0.5",
                 f"host_offset_s = {self.host_offset_s:g}", "",
                 "[chair]", f"occupant_mass = {self.occupant:g}"]
        lines += ["parking_brake = true", ""] if self.brake else [""]
        params = ["brake_fitted = 1"] if self.brake else []
        if self.gains is not None:
            kp, ki, kd = self.gains
            params += [f"{k}_{s} = {v:g}" for s in "lr" for k, v in (("kp", kp), ("ki", ki), ("kd", kd))]
        if params:
            lines += ["[params]", *params, ""]
        lines += ["[world]"]
        if self.case in ("uniform", "cross"):
            lines += [f"slope_deg = {self.grade_deg:g}", f"downhill_heading_deg = {self.heading_deg:g}"]
        else:
            sign = -1.0 if self.case.endswith("_up") else 1.0
            lines += ["slope_deg = 0.0", "downhill_heading_deg = 0", "", "[[world.ramp]]",
                      f"from_x = {BAND_FROM:g}", f"to_x = {BAND_FROM + self.band_m:g}",
                      f"slope_deg = {sign * self.grade_deg:g}"]
        lines += ["", "[[segment]]", f"cmdvel = [{self.speed:g}, 0.0]", f"duration = {self.drive_s:g}", "",
                  "[[segment]]", f"cmdvel = [{self.speed / 2:g}, {self.turn:g}]",
                  f"duration = {self.turn_s:g}", "", "[[segment]]", "stop = true", f"duration = {STOP_S:g}"]
        if self.fault_kind is not None:
            lines += ["", "[[fault]]", f"at = {self.fault_at:g}", f'kind = "{self.fault_kind}"']
            if self.fault_side is not None:
                lines.append(f'side = "{self.fault_side}"')
        return "\n".join(lines) + "\n"

    def describe(self) -> str:
        """One line: the class, the load, the grade, the speed, the turn, rate and gains."""
        gains = "default gains" if self.gains is None else "kp/ki/kd {:g}/{:g}/{:g}".format(*self.gains)
        where = (f"{self.grade_deg:.2f} deg ({100 * self.grade_fraction:.0f} % of rated), "
                 f"downhill at {self.heading_deg:g} deg") if self.case in ("uniform", "cross") else \
            f"{self.grade_deg:.2f} deg band of {self.band_m:g} m ({100 * self.grade_fraction:.0f} % of rated)"
        text = (f"{self.case}: {self.occupant:g} kg, {where}, {self.speed:g} m/s for {self.drive_s:g} s, "
                f"turn {self.turn:g} rad/s, host {self.host_rate_hz:g} Hz "
                f"+{1000 * self.host_offset_s:g} ms, {gains}" + (", a brake" if self.brake else ""))
        if self.fault_kind is not None:
            side = f" {self.fault_side}" if self.fault_side else ""
            text += f"; {self.fault_kind}{side} at {self.fault_at:g} s"
        return text


def _gains(draw: Draw) -> tuple[float, float, float] | None:
    if draw.boolean(0.5):
        return None
    kp = round(draw.real(spec.real("GAIN_P_MIN"), spec.real("GAIN_P_MAX")), 2)
    lo, hi = math.log10(max(spec.real("GAIN_I_MIN"), 0.01)), math.log10(spec.real("GAIN_I_MAX"))
    ki = round(10 ** draw.real(lo, hi), 3)
    kd = round(draw.real(0.0, spec.real("GAIN_D_MAX")), 3)
    return kp, ki, kd


def drive(draw: Draw, cases: tuple[str, ...] = INSIDE) -> Drive:
    """One healthy drive of a class in ``cases`` (module docstring), drawn from ``draw``.
    The simplest choices come first (what hypothesis shrinks toward): the first class,
    the lightest occupant, the level, the slowest speed, no turn, 10 Hz, default gains."""
    case = draw.choice(cases)
    occupant = float(round(draw.real(OCCUPANT_MIN, OCCUPANT_MAX)))
    rated = ChairParams(occupant_mass=occupant).rated_grade()
    # the envelope's edge (the steepest grades, the slowest speeds) drawn often
    fraction = draw.choice((draw.real(0.0, 1.0), 0.7, 0.8, 0.9, 1.0))
    grade = KERB_DEG if case.startswith("kerb") else math.floor(fraction * rated * 1000) / 1000
    heading = 0.0
    if case == "uniform":
        heading = draw.choice((0.0, 180.0, 45.0, 135.0, 225.0, 315.0))
    elif case == "cross":
        heading = draw.choice((90.0, 270.0))
    speed = round(draw.choice((draw.real(0.3, MAX_LINEAR), MAX_LINEAR, 1.0, 0.5, 0.3)), 2)
    turn = draw.choice((0.0, round(draw.real(-MAX_TURN, MAX_TURN), 2)))
    band = 0.0
    if case.startswith("kerb"):
        band = 1.2
    elif case.startswith("band"):
        band = round(draw.real(1.5, 4.0), 1)
    if case in ("uniform", "cross"):
        drive_s = round(draw.real(3.0, 6.0), 1)
    else:
        # beyond the band and 1.5 m on, or (one in three) to its middle, where it stops
        end = BAND_FROM + band / 2 if draw.boolean(1 / 3) else BAND_FROM + band + 1.5
        drive_s = round(min(end / speed + _RAMP_S * speed / MAX_LINEAR / 2 + 0.5, 20.0), 1)
    rate = draw.choice(HOST_RATES)
    gains = _gains(draw)
    # drawn last, so that a seed's other choices stay what they were before the phase
    offset = round(draw.real(0.0, 0.05), 4)
    # and the brake after it, for the same reason
    brake = draw.boolean(1 / BRAKE_EVERY)
    return Drive(case=case, occupant=occupant, grade_deg=grade, rated_deg=rated, heading_deg=heading,
                 speed=speed, turn=turn, drive_s=drive_s, turn_s=2.0, host_rate_hz=rate,
                 gains=gains, band_m=band, host_offset_s=offset, brake=brake)


def faulty(draw: Draw, base: Drive, kind: str) -> Drive:
    """``base`` with a fault of ``kind`` (``FAULT_KINDS``) at a drawn moment of its
    motion (from 0.5 s to 1 s before the stop), on a drawn side for the sided kinds."""
    at = round(draw.real(0.5, max(0.6, base.motion_s - 1.0)), 2)
    side = draw.choice(("left", "right")) if kind in SIDED_KINDS else None
    return base.with_fault(kind, at, side)


@dataclass(frozen=True)
class Verdict:
    """A run's events sorted (``judge``): ``faults`` (``EVT:FAULT`` lines), ``limits``
    (``LIMITS``), with their times; ``first_fault_s`` None without one."""

    faults: tuple[tuple[float, str], ...]
    limits: tuple[tuple[float, str], ...]

    @property
    def first_fault_s(self) -> float | None:
        """s: the first ``EVT:FAULT`` (None: none)."""
        return self.faults[0][0] if self.faults else None


def judge(events: list[tuple[float, str]] | list[list[object]]) -> Verdict:
    """The ``EVT:FAULT`` and limit lines of a run's events ((time, line) pairs, as
    ``SimResult.link.events`` or ``wcdrive sim --json``'s ``events``)."""
    pairs = [(float(t), str(line)) for t, line in events]  # type: ignore[arg-type]
    return Verdict(faults=tuple(p for p in pairs if p[1].startswith("EVT:FAULT")),
                   limits=tuple(p for p in pairs if p[1].startswith(LIMITS)))
