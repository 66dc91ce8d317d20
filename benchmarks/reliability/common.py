"""What the experiments share: the protocol's limits, the run sizes, what a line did
to the firmware, and the records of results."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from wcdrive.firmware.params import PARAMS
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import board_unframe, frame
from wcdrive.protocol.motion import velocity_command
from wcdrive.protocol.spec import integer, real

ElfPath = str | Path | None
Sram = dict[str, float | int]

CMD_MAX_LEN = integer("CMD_MAX_LEN")
SEQ_MAX = integer("SEQ_MAX")
MAX_LINEAR = real("MAX_LINEAR")
MAX_ANGULAR = real("MAX_ANGULAR")
MAX_WHEEL = real("MAX_WHEEL_SPEED")
#: protocol v4: the board frames its lines from its answer on
HELLO_FRAME = frame(b"hello:4", 1)
TICK_MS = 50
NEUTRAL_TICKS = integer("NEUTRAL_TICKS")
#: The neutral prelude (protocol/PROTOCOL.md, "Neutral before motion"): after a boot the
#: board drives only once a neutral command has stood NEUTRAL_TICKS ticks. After hello a
#: host sends the stop ``Wheelchair.stop`` sends (``connect`` does), the hello's seq + 1;
#: before hello, the opening of the seed era's ros2_control plugin.
NEUTRAL_FRAME = frame(velocity_command(0.0, 0.0), 2)
NEUTRAL_LEGACY = b"rp0.0,lp0.0,\n"
#: How long the firmware runs after the prelude before the hostile input: what
#: ``wcdrive.host.neutral`` waits for a board whose telemetry carries no state (NEUTRAL_TICKS
#: ticks, the tick the stop came in, one to spare).
NEUTRAL_WAIT_S = (NEUTRAL_TICKS + 2) * TICK_MS / 1000
HANG_S = 0.050                      # a line (port) or a byte (firmware) must be done within a tick

QUICK = {"port_lines": 20_000, "port_frames": 20_000, "legacy_frames": 20_000,
         "firmware_lines": 600, "firmware_frames": 400, "r3_trials": 5}
FULL = {"port_lines": 1_000_000, "port_frames": 1_000_000, "legacy_frames": 1_000_000,
        "firmware_lines": 100_000, "firmware_frames": 10_000, "r3_trials": 100}



# ---- what a line did -------------------------------------------------------------
Motion = tuple[int, float, float, int, float, float]
PARAM_FIELDS = tuple(p.field for p in PARAMS)



def motion_of(s: FirmwareState) -> Motion:
    """The commanded motion: mode, targets, and the pivot with its pending targets."""
    pivot = s.pivotPhase
    return (s.mode, s.targetL, s.targetR, pivot, s.pendingL if pivot else 0.0,
            s.pendingR if pivot else 0.0)


def motion_in(d: dict[str, float | int]) -> Motion:
    """``motion_of`` for a lock-step snapshot of the firmware's SRAM."""
    pivot = int(d["pivotPhase"])
    return (int(d["mode"]), float(d["targetL"]), float(d["targetR"]), pivot,
            float(d["pendingL"]) if pivot else 0.0, float(d["pendingR"]) if pivot else 0.0)


def neutral_prelude(strict: bool) -> bytes:
    """The neutral command a host sends after boot (after its hello with ``strict``)."""
    return NEUTRAL_FRAME if strict else NEUTRAL_LEGACY


def is_stop(m: Motion) -> bool:
    """No wheel target and no pivot under way."""
    return m[1] == 0.0 and m[2] == 0.0 and m[3] == 0


def params_of(s: FirmwareState) -> tuple[float | int, ...]:
    return tuple(getattr(s, f) for f in PARAM_FIELDS)


def answer_kinds(out: bytes) -> list[str]:
    """The answers in a chunk of output (feedback, TLM and BOOT lines left out), v4
    frames unframed; a line that looks framed and fails its check is ``BAD FRAME``
    (the board never sends one)."""
    kinds = []
    for raw in out.split(b"\r\n"):
        unframed = board_unframe(raw)
        line = raw if unframed is None else unframed[0]
        if unframed is None and b"*" in raw:
            kinds.append("BAD FRAME")
            continue
        head = line[:4]
        if head in (b"ERR:", b"EVT:"):
            kinds.append(line.decode("latin-1"))
        elif head == b"ACK:":
            kinds.append("ACK")
        elif head == b"NAK:":
            kinds.append("NAK:" + line.split(b",", 1)[1].decode("latin-1"))
        elif head == b"PAR:":
            kinds.append("PAR")
        elif line.startswith(b"HELLO:"):
            kinds.append("HELLO")
    return kinds


# ---- results -------------------------------------------------------------------
@dataclass
class Lockstep:
    """Lock-step totals over the simavr runs of one test."""

    runs: int = 0
    events: int = 0
    ticks: int = 0
    fields: int = 0
    tx_bytes: int = 0
    mismatches: int = 0
    examples: list[str] = field(default_factory=list)
    max_latency_s: float = 0.0      # a byte on the wire to its processByte
    max_tick_gap_ms: int = 0
    lost_bytes: int = 0
    extra_boots: int = 0


#: The faults a firmware whose encoders stand still (R1 on the firmware drives no plant)
#: may latch under a drive: a stalled wheel, or both (the driver).
STILL_WHEEL_FAULTS = 0x01 | 0x02 | 0x40


@dataclass
class R1Slice:
    """R1 on one side, for the lines sent after hello (strict) or before (legacy)."""

    lines: Counter[str] = field(default_factory=Counter)      # by source
    invalid: int = 0
    invalid_motions: int = 0
    invalid_param_changes: int = 0
    mutated_valid: int = 0              # mutations that are valid input (oracle)
    mutated_valid_drove: int = 0
    controls: Counter[str] = field(default_factory=Counter)   # valid lines by kind
    controls_ok: Counter[str] = field(default_factory=Counter)
    #: valid drives refused because a fault was latched when they came (firmware R1)
    refused_latched: int = 0
    #: valid drives refused (``neutral``) because the board waited for neutral when they
    #: came: after a wait the stream itself started (a PPM loss frame, a watchdog stop
    #: of a motion after silence, an e-stop or fault released by ``reset``)
    refused_neutral: int = 0
    #: lines (any source) that drove while the board waited for neutral: a safety violation
    neutral_motions: int = 0
    #: waits for neutral the stream started (after the prelude)
    neutral_waits: int = 0
    #: runs whose neutral prelude did not bring the board to neutral before the stream
    preludes_failed: int = 0
    #: faults latched, by flags (firmware R1: its encoders stand still, so only a stalled
    #: wheel's or the driver's fault can latch)
    latched: Counter[int] = field(default_factory=Counter)
    answers: Counter[tuple[str, str]] = field(default_factory=Counter)   # (group, kind)
    silent: Counter[str] = field(default_factory=Counter)    # lines without an answer, by group
    suppressed: int = 0
    crashes: int = 0
    hangs: int = 0
    worst_s: float = 0.0
    examples: list[str] = field(default_factory=list)
    lockstep: Lockstep | None = None

    @property
    def total(self) -> int:
        return sum(self.lines.values())


@dataclass
class R2Result:
    """R2 on one side."""

    frames: Counter[str] = field(default_factory=Counter)    # by corruption
    executed: Counter[str] = field(default_factory=Counter)
    acked: Counter[str] = field(default_factory=Counter)
    commands: int = 0                    # commands the frames split into (oracle)
    refused: int = 0                     # of those, refused (rejectedCount)
    preludes_failed: int = 0             # boards the neutral prelude did not bring to neutral
    answers: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    hangs: int = 0
    worst_s: float = 0.0
    examples: list[str] = field(default_factory=list)
    lockstep: Lockstep | None = None


@dataclass
class Legacy:
    """Outcomes of corrupted lines on a board that never said hello (v1), and in the v2
    model: by corruption, "refused", "same" (the intended motion), "different" (another
    motion), "stop"."""

    v1: Counter[tuple[str, str]] = field(default_factory=Counter)
    v2: Counter[tuple[str, str]] = field(default_factory=Counter)
    v2_acked_different: Counter[str] = field(default_factory=Counter)
    frames: Counter[str] = field(default_factory=Counter)        # v1 lines by corruption
    frames_v2: Counter[str] = field(default_factory=Counter)

