"""The report: a run's figures as markdown tables, and the problems it found."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from .common import STILL_WHEEL_FAULTS, Legacy, R1Slice, R2Result
from .inputs import CORRUPTIONS
from .r3 import R3Result, r3_problems


@dataclass
class Results:
    """Everything one run measured, with the wall time of each part."""

    seed: int
    counts: dict[str, int]
    r1_port: dict[str, R1Slice] = field(default_factory=dict)
    r1_firmware: dict[str, R1Slice] = field(default_factory=dict)
    r2_port: R2Result | None = None
    r2_firmware: R2Result | None = None
    legacy: Legacy | None = None
    r3: R3Result | None = None
    wall: dict[str, float] = field(default_factory=dict)



def _stats(values: list[float], unit: str, scale: float = 1.0, digits: int = 0) -> str:
    if not values:
        return "-"
    values = sorted(v * scale for v in values)
    median = values[len(values) // 2]
    return f"{median:.{digits}f} / {values[-1]:.{digits}f} {unit}"


def _r3_cell(r: R3Result | None) -> str:
    if r is None:
        return "not run"
    parts = []
    for kind, trials in r.trials.items():
        n = len(trials)
        parts.append(f"{kind}: {n - sum(not t.stopped_in_time() for t in trials)}/{n} stopped in time, "
                     f"{sum(t.noticed_s is not None for t in trials)}/{n} noticed, "
                     f"{sum(t.recovered_s is not None for t in trials)}/{n} driving again"
                     + ("" if kind == "link cut" else
                        f" ({sum(t.rehandshake for t in trials)}/{n} after a new hello)"))
    return "; ".join(parts) + (f"; **{len(r.executed_twice)} of {_n(r.acked)} executed frames "
                               "executed twice**")


def r3_table(r: R3Result | None) -> list[str]:
    """R3's figures by kind, as markdown lines."""
    if r is None:
        return []
    paced = "at real time" if r.pace == 1.0 else f"at {r.pace:g}x real time (the host's clock alike)"
    out = [f"R3 on the firmware in simavr with the chair on its pins, {paced}, driven by a "
           "`Wheelchair` at 20 Hz at 0.4-1.2 m/s (median / max, in ms of the board's clock "
           "from the fault; the host's times are wall times times the pace; driving again: "
           "from the end of the outage, or from the reset):", "",
           "| fault | trials | PWM 0 for good | standstill | travel (within issue 13's "
           "bound) | host notices (by) | driving again | reboot cause the host saw | frames the "
           "board executed after its reset before a new hello |",
           "|---|---:|---|---|---|---|---|---|---:|"]
    for kind, trials in r.trials.items():
        by = Counter(t.noticed_by or "not noticed" for t in trials)
        causes = Counter(t.boot_cause or "none" for t in trials)
        zero = [t.pwm_zero_s for t in trials if t.pwm_zero_s is not None]
        over = [t.pwm_zero_s - t.bound_s for t in trials if t.pwm_zero_s is not None]
        late = sum(t.pwm_zero_s is None for t in trials)
        within = sum(t.travel_m <= t.travel_bound_m for t in trials)
        first = (f"; PWM 0 at the reset's first instruction {sum(t.pwm_after == (0, 0) for t in trials)}"
                 f"/{len(trials)}" if kind == "DTR reset" else "")
        out.append(
            f"| {kind} | {len(trials)} | {_stats(zero, 'ms', 1e3)}"
            + (f", not by the end {late}" if late else "")
            + f" (bound {_stats([t.bound_s for t in trials], 'ms', 1e3)}; past it by "
            f"{_stats(over, 'ms', 1e3)}){first} | "
            f"{_stats([t.standstill_s for t in trials if t.standstill_s is not None], 'ms', 1e3)} | "
            f"{_stats([t.travel_m for t in trials], 'm', 1.0, 3)} ({within}/{len(trials)}) | "
            f"{_stats([t.noticed_s for t in trials if t.noticed_s is not None], 'ms', 1e3)} "
            f"({', '.join(f'{k} {v}' for k, v in by.items())}) | "
            f"{_stats([t.recovered_s for t in trials if t.recovered_s is not None], 'ms', 1e3)} | "
            f"{', '.join(f'{k} {v}' for k, v in causes.items())} | "
            f"{sum(t.executed_before_hello for t in trials)} in "
            f"{sum(t.executed_before_hello > 0 for t in trials)} trials |")
    losses = sum(t.link_losses_before for ts in r.trials.values() for t in ts)
    out += ["", f"Frames the board executed (ACKed): {_n(r.acked)}; executed twice: "
            f"{len(r.executed_twice)}. Link losses while driving, before a fault: {losses}; the "
            f"board fell at most {r.board_lag_s * 1e3:.0f} ms behind the wall clock."]
    return out




# ---- report --------------------------------------------------------------------------
def _n(x: int) -> str:
    return f"{x:,}"


def _pct(a: int, b: int) -> str:
    if b == 0:
        return "-"
    p = 100.0 * a / b
    return "0" if a == 0 else f"{p:.3g} %"


def _r1_cell(slices: dict[str, R1Slice], firmware: bool) -> str:
    if not slices:
        return "not run"
    s, g = slices["strict"], slices["legacy"]
    total = s.total + g.total
    crashes = s.crashes + g.crashes
    hangs = s.hangs + g.hangs
    invalid = s.invalid + g.invalid
    motions = s.invalid_motions + g.invalid_motions
    params = s.invalid_param_changes + g.invalid_param_changes
    drives = s.controls["drive"] + g.controls["drive"]
    drives_ok = s.controls_ok["drive"] + g.controls_ok["drive"]
    refused = s.refused_neutral + g.refused_neutral
    waits = s.neutral_waits + g.neutral_waits
    in_wait = s.neutral_motions + g.neutral_motions
    worst = max(s.worst_s, g.worst_s) * 1e3
    if firmware:
        ls = [x.lockstep for x in (s, g) if x.lockstep]
        slowest = (f"a byte waits at most {worst:.2f} ms for processByte, "
                   f"{sum(x.lost_bytes for x in ls)} bytes lost, ticks at most "
                   f"{max(x.max_tick_gap_ms for x in ls)} ms apart")
    else:
        slowest = f"slowest line {worst:.2f} ms"
    text = (f"{_n(total)} lines ({_n(s.total)} after hello, {_n(g.total)} before): "
            f"**{crashes} crashes, {hangs} hangs** ({slowest}), "
            f"**{motions} motions** and {params} parameter changes from "
            f"{_n(invalid)} invalid lines; **{in_wait} motions while the board waited for neutral** "
            f"({_n(waits)} waits the stream began); valid motions carried out {_n(drives_ok)}/{_n(drives)}"
            + (f", {_n(refused)} refused while it waited for neutral" if refused else ""))
    if firmware:
        mism = sum(x.mismatches for x in ls)
        text += (f"; **port = firmware: {mism} mismatches** in {_n(sum(x.events for x in ls))} "
                 f"events ({_n(sum(x.ticks for x in ls))} ticks, {_n(sum(x.fields for x in ls))} "
                 f"values and TX streams of {_n(sum(x.tx_bytes for x in ls))} bytes compared), "
                 f"{sum(x.runs for x in ls)} boots")
    return text


def _r2_cell(r: R2Result | None) -> str:
    if r is None:
        return "not run"
    frames = sum(r.frames.values())
    text = (f"{_n(frames)} frames: **{sum(r.executed.values())} executed, "
            f"{sum(r.acked.values())} ACKed**, {r.crashes} crashes, {r.hangs} hangs; "
            f"{_n(r.refused)} of the {_n(r.commands)} commands they make refused")
    if r.lockstep is not None:
        ls = r.lockstep
        text += (f" (a byte waits at most {ls.max_latency_s * 1e3:.2f} ms, {ls.lost_bytes} lost); "
                 f"**port = firmware: {ls.mismatches} mismatches** in {_n(ls.events)} events "
                 f"({_n(ls.fields)} values compared), {ls.runs} boots")
    return text


def markdown(res: Results) -> str:
    """The tables, ready to paste."""
    out = [f"Seed {res.seed}; counts {res.counts}.", ""]
    out += ["| test | on the port | on the firmware (simavr, lock step) |", "|---|---|---|"]
    out.append("| R1: random and mutated lines, 0 crashes, 0 hangs, 0 motions from invalid input, "
               f"port = firmware | {_r1_cell(res.r1_port, False)} | "
               f"{_r1_cell(res.r1_firmware, True)} |")
    out.append("| R2: 1- to 3-bit flips and bursts of 2 to 16 bits in valid motion frames, the `$` "
               f"included, after hello: 0 executed, 0 ACKed | {_r2_cell(res.r2_port)} | "
               f"{_r2_cell(res.r2_firmware)} |")
    out.append("| R3: the link cut, the board unplugged and a DTR reset, each mid-motion: the "
               "chair stops within the watchdog bound (a reset: PWM 0 from its first "
               "instruction), the host notices and re-handshakes, no frame executed twice | - | "
               f"{_r3_cell(res.r3)} |")
    out += ["", *_r1_details(res), "", *r3_table(res.r3), "", *_reply_table(res), "",
            *_comparison_table(res), ""]
    total = sum(res.wall.values())
    out.append("Wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in res.wall.items())
               + f"; total {total:.1f} s.")
    return "\n".join(out)


def _r1_details(res: Results) -> list[str]:
    out = ["| R1 slice | lines (random / mutated / valid) | invalid (oracle) | motions from invalid "
           "| mutations that are valid input (of which drove) | waits for neutral the stream began "
           "(motions during them) | valid drive / stop / get-set carried out |",
           "|---|---|---|---|---|---|---|"]
    for side, slices in (("port", res.r1_port), ("firmware", res.r1_firmware)):
        for name, st in slices.items():
            valid = st.total - st.lines["random"] - st.lines["mutated"]
            ok = " / ".join(f"{_n(st.controls_ok[k])}/{_n(st.controls[k])}"
                            for k in ("drive", "stop", "param") if st.controls[k])
            if st.refused_latched:
                ok += f" ({_n(st.refused_latched)} drives refused: a fault latched)"
            if st.refused_neutral:
                ok += f" ({_n(st.refused_neutral)} drives refused: waiting for neutral)"
            out.append(f"| {side}, {'after hello' if name == 'strict' else 'before hello (legacy)'} | "
                       f"{_n(st.lines['random'])} / {_n(st.lines['mutated'])} / {_n(valid)} | "
                       f"{_n(st.invalid)} | {st.invalid_motions} | {_n(st.mutated_valid)} "
                       f"({_n(st.mutated_valid_drove)}) | {_n(st.neutral_waits)} ({st.neutral_motions}) "
                       f"| {ok} |")
    return out


def _reply_table(res: Results) -> list[str]:
    """R1 answers per 100 lines on the port, by source, and the firmware's totals."""
    cols: list[tuple[str, R1Slice, str]] = []
    for name, st in res.r1_port.items():
        tag = "after hello" if name == "strict" else "before hello"
        for group in ("random", "mutated", "valid"):
            cols.append((f"{group}, {tag}", st, group))
    kinds = sorted({k for _, st, _ in cols for (_, k) in st.answers})
    out = ["R1 answers per 100 lines on the port (a tick after every line; a line that makes "
           "more than 3 commands loses the answers past the third):", "",
           "| answer | " + " | ".join(c[0] for c in cols) + " |",
           "|---|" + "---:|" * len(cols)]

    def lines_in(st: R1Slice, group: str) -> int:
        if group == "valid":
            return st.total - st.lines["random"] - st.lines["mutated"]
        return st.lines[group]

    for kind in [*kinds, "(no answer)"]:
        cells = []
        for _, st, group in cols:
            count = st.silent[group] if kind == "(no answer)" else st.answers[group, kind]
            total = lines_in(st, group)
            cells.append(f"{100.0 * count / total:.2f}" if total else "-")
        out.append(f"| {kind} | " + " | ".join(cells) + " |")
    out += ["", "Answers suppressed by the 3-per-tick budget on the port: " + ", ".join(
        f"{'after hello' if name == 'strict' else 'before hello'} {_n(st.suppressed)}"
        for name, st in res.r1_port.items()) + "."]
    if res.r1_firmware:
        out += ["", "On the firmware, at wire speed (3 answers per 50 ms tick, the rest suppressed): "
                + "; ".join(
                    f"{'after hello' if name == 'strict' else 'before hello'}: {_n(st.total)} lines, "
                    + ", ".join(f"{k} {_n(v)}" for (_, k), v in sorted(st.answers.items()))
                    + f", suppressed {_n(st.suppressed)}"
                    for name, st in res.r1_firmware.items()) + "."]
        latched: Counter[int] = Counter()
        for st in res.r1_firmware.values():
            latched.update(st.latched)
        if latched:
            out += ["", "Faults the firmware latched (its encoders stand still: R1 drives no plant, "
                    "so a drive that builds duty latches a stalled wheel's fault, and the drives "
                    "after it are refused until the next chunk's reboot): " + ", ".join(
                        f"{_fault_names(flags)} {n}" for flags, n in sorted(latched.items())) + "."]
    return out


def _fault_names(flags: int) -> str:
    from wcdrive.protocol.codec import fault_names

    return "|".join(fault_names(flags)) or "none"


def _comparison_table(res: Results) -> list[str]:
    r2, lg = res.r2_port, res.legacy
    if r2 is None or lg is None:
        return []
    out = ["Corrupted motion commands by kind of corruption: v3 frames after hello (R2, port) "
           "against the bare v1 line before hello and a model of v2's XOR frames:", "",
           "| corruption | v3: executed / ACKed | v1 line before hello: different motion / "
           "same motion / refused | v2 model (XOR): different motion / same / refused |",
           "|---|---|---|---|"]

    def row(name: str, kinds: tuple[str, ...]) -> str:
        frames = sum(r2.frames[k] for k in kinds)
        n1 = sum(lg.frames[k] for k in kinds)
        n2 = sum(lg.frames_v2[k] for k in kinds)

        def rates(table: Counter[tuple[str, str]], n: int) -> str:
            return " / ".join(_pct(sum(table[k, outcome] for k in kinds), n)
                              for outcome in ("different", "same", "refused")) + f" of {_n(n)}"

        return (f"| {name} | {sum(r2.executed[k] for k in kinds)} / {sum(r2.acked[k] for k in kinds)}"
                f" of {_n(frames)} | {rates(lg.v1, n1)} | {rates(lg.v2, n2)} |")

    for kind in CORRUPTIONS:
        out.append(row(kind, (kind,)))
    out.append(row("all", CORRUPTIONS))
    stops = sum(v for (_, o), v in lg.v1.items() if o == "stop")
    stops2 = sum(v for (_, o), v in lg.v2.items() if o == "stop")
    out += ["", f"(Corruptions that turned the command into a stop: v1 {_n(stops)}, v2 model "
            f"{_n(stops2)}; v2 model frames ACKed while executing a different motion: "
            f"{_n(sum(lg.v2_acked_different.values()))}.)"]
    return out


def problems(res: Results) -> list[str]:
    """What the run found wrong (empty: every figure is as required)."""
    found = []
    for side, slices in (("port", res.r1_port), ("firmware", res.r1_firmware)):
        for name, st in slices.items():
            bad = {"crashes": st.crashes, "hangs": st.hangs, "motions from invalid input":
                   st.invalid_motions, "parameter changes from invalid input":
                   st.invalid_param_changes,
                   "valid motions not carried out": st.controls["drive"] - st.controls_ok["drive"]
                   - st.refused_latched - st.refused_neutral,
                   "motions while the board waited for neutral": st.neutral_motions,
                   "neutral preludes that left the board waiting": st.preludes_failed,
                   "faults latched but a still wheel's": sum(
                       n for flags, n in st.latched.items() if flags & ~STILL_WHEEL_FAULTS)}
            if side == "port":
                bad["valid stops/params not carried out"] = (
                    st.controls["stop"] + st.controls["param"]
                    - st.controls_ok["stop"] - st.controls_ok["param"])
            if st.lockstep is not None:
                bad["port/firmware mismatches"] = st.lockstep.mismatches
            bad["board lines that failed their v4 check"] = sum(
                n for (_, kind), n in st.answers.items() if kind == "BAD FRAME")
            found += [f"R1 {side} {name}: {v} {k}" for k, v in bad.items() if v]
            found += [f"  {e}" for e in st.examples] if any(bad.values()) else []
    for side, r in (("port", res.r2_port), ("firmware", res.r2_firmware)):
        if r is None:
            continue
        bad = {"executed": sum(r.executed.values()), "ACKed": sum(r.acked.values()),
               "crashes": r.crashes, "hangs": r.hangs,
               "commands not refused": r.commands - r.refused,
               "neutral preludes that left the board waiting": r.preludes_failed}
        if r.lockstep is not None:
            bad["port/firmware mismatches"] = r.lockstep.mismatches
        found += [f"R2 {side}: {v} {k}" for k, v in bad.items() if v]
        found += [f"  {e}" for e in r.examples] if any(bad.values()) else []
    for slices in (res.r1_firmware,):
        for st in slices.values():
            if st.lockstep and st.lockstep.examples:
                found += [f"  {e}" for e in st.lockstep.examples]
    if res.r2_firmware and res.r2_firmware.lockstep and res.r2_firmware.lockstep.examples:
        found += [f"  {e}" for e in res.r2_firmware.lockstep.examples]
    if res.r3 is not None:
        found += r3_problems(res.r3)
    return found


