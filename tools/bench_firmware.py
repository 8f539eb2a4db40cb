"""Firmware benchmark: memory, the control tick's CPU load, and the PID's step figures.

    python -m tools.bench_firmware [--update docs/benchmarks.md] [--seconds 2]

Run by `make bench-firmware`, which builds the ELF, the host library and the emulator's
harness (build/emulator/libutrf_sim.so) first. Every figure is measured here:

- flash and static RAM from `avr-size` on build/firmware/utrf.elf; the kinematics table's
  bytes and worst error from its generator;
- the control tick on the emulated board (tools.tick_bench, on the harness's simavr): the
  firmware's own measurement (get_stats: tick_mean over 1024 ticks, tick_worst) and the
  harness's cycle profiles of app::tick(), with five fingers in closed loop and the state
  stream on, under seven kinds of host traffic; with each, the receive path (issue 19): the
  harness models the ATmega2560's two-byte receive FIFO and times each byte from its stop bit
  to the firmware's read of UDR0, and counts the bytes lost;
- the awake cycles under the twin's traffic (tools.fw_profile: the grasp hold's host traffic,
  the state stream at 100 Hz and at 1 kHz, no plant): the share of the cycles the CPU was not
  asleep and where they go, per function; with ``--reference-elf`` (make bench-firmware
  FW_REF_ELF=...), another build's beside it, from the same runs' traffic;
- the step response of the default gains on the reference finger plant (tests/firmware/
  fwsim.py), through the host build of the firmware core.
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
from pathlib import Path

from tools import tick_bench
from tools.doc_sections import cpu_name, write_section

REPO = Path(__file__).resolve().parents[1]
ELF = REPO / "build" / "firmware" / "utrf.elf"
TABLE = REPO / "firmware" / "src" / "generated" / "kinematics_table.h"
BEGIN = "<!-- BEGIN firmware (make bench-firmware) -->"
END = "<!-- END firmware -->"
CPU_HZ = 16_000_000
TICK_CYCLES = CPU_HZ // 1000
TARGET = 0.15  # issue 11 goal 4: the tick at most 15 % of the CPU at its worst
BOUND = 0.235  # the house rule and issue 23: every row's own worst at most 23.5 %


def run(cmd: list[str]) -> str:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, check=True).stdout


def memory() -> dict[str, int]:
    sizes: dict[str, int] = {}
    for line in run(["avr-size", "-A", str(ELF)]).splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith(".") and parts[1].isdigit():
            sizes[parts[0]] = int(parts[1])
    data, bss, noinit = sizes.get(".data", 0), sizes.get(".bss", 0), sizes.get(".noinit", 0)
    return {
        "flash": sizes[".text"] + data,
        "ram": data + bss + noinit,
        "data": data,
        "bss": bss,
        "noinit": noinit,
    }


def table() -> list[str]:
    out = run([sys.executable, "-m", "tools.kinematics_table", "--check"])
    return [ln for ln in out.splitlines() if ln.startswith(("geometry", "total"))]


def tick_load(scenario: str, seconds: float) -> dict:
    return tick_bench.run(ELF, scenario, seconds)


def step_figures() -> list[tuple[float, dict[str, float]]]:
    import ctypes

    from tests.firmware import fwsim  # the host build's driver, shared with the firmware tests

    lib = fwsim.load_library(fwsim.build_library())
    rows = []
    for step in (0.2, 0.5, 1.0):
        sim = fwsim.Sim(lib)
        eeprom = sim.eeprom()
        ctypes.memset(eeprom, 0xFF, len(eeprom))  # blank: the default gains
        sim.power_on()
        rows.append((step, fwsim.step_figures(fwsim.step_response(sim, step), step)))
    return rows


BYTE_CYCLES = 160  # one byte at 1 Mbaud (10 bits)


def frame_bytes() -> int:
    """Bytes of a set_targets frame on the wire (what the typical row sends)."""
    from utrf.protocol import messages as m
    from utrf.protocol.framing import encode_frame

    body = m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=31, value=(0.4,) * 5).encode()
    return len(encode_frame(1, m.SetTargets.ID, body))


def burst_bound(own_worst: float, per_byte: float, frame: int) -> float:
    """A whole frame arriving as the tick starts, with the tick at its own worst: the tick
    lasts T = own + n * per_byte, where n, the bytes that arrive within T, is at most the
    frame's (one every BYTE_CYCLES)."""
    t = own_worst
    for _ in range(100):
        n = min(frame, int(t // BYTE_CYCLES) + 1)
        t_next = own_worst + n * per_byte
        if t_next == t:
            break
        t = t_next
    return t


def verdict(loads: list[dict]) -> list[str]:
    """What the rows say against the target, in figures taken from them.

    The tick's worst is its own work: simavr's cycles from app::tick()'s entry to its return,
    less the interrupts that nest in it, worst over the rows of normal traffic (heartbeats,
    set_targets at 200 Hz, moves with the 1 kHz stream). Those interrupts (the UART's, one a
    byte) are the line's load, spent whenever their bytes come, inside the tick or after it;
    counting them in the tick would charge the same cycles twice and make the figure depend
    on where a frame happens to fall. Whether the tick keeps its deadline with them is the
    elapsed figure (nested interrupts included) and the overrun count, reported beside it."""
    normal = [d for d in loads if d["scenario"] in ("idle", "typical", "moves")]
    own_worst = max(d["sim_own_worst_cycles"] for d in normal)
    own_mean = max(d["sim_own_mean_cycles"] for d in normal)
    elapsed = max(max(d["tick_worst_us"] * 16, d["sim_tick_worst_cycles"]) for d in normal)
    overruns = sum(d["tick_overruns"] for d in loads)
    met = own_worst <= TARGET * TICK_CYCLES
    typical = next(d for d in loads if d["scenario"] == "typical")
    nested = typical["sim_nested_mean_cycles"] * typical["sim_ticks"]
    per_byte = nested / max(1, typical["sim_nested_interrupts"])
    frame = frame_bytes()
    bound = burst_bound(own_worst, per_byte, frame)
    return [
        f"The tick's worst (its own work, nested interrupts left out; normal traffic: the "
        f"heartbeat, 200 Hz set_targets and moves rows) is {own_worst:,} cycles "
        f"({pct(own_worst)}), its mean at most {own_mean:,.0f} ({pct(own_mean)}): "
        + ("the 15 % target is **met**." if met else "the 15 % target is **not met**.")
        + f" Elapsed, with the UART's interrupts nested in it, the worst is {elapsed:,} cycles "
        f"({pct(elapsed)}; firmware and simavr), {overruns} overruns in all rows. Bound for a "
        f"whole set_targets frame ({frame} bytes) arriving as the tick starts at its own worst "
        f"({per_byte:.0f} cycles a byte, entry to reti): {bound:,.0f} cycles ({pct(bound)}). "
        "See firmware/README.md, Timing, for what the tick does.",
        "",
        every_row(loads),
    ]


def every_row(loads: list[dict]) -> str:
    """The house rule's bound, on every row (the own worst: nested interrupts left out)."""
    bound = BOUND * TICK_CYCLES
    over = [d for d in loads if d["sim_own_worst_cycles"] > bound]
    worst = max(loads, key=lambda d: d["sim_own_worst_cycles"])
    text = (
        f"Every row against the house rule's bound, {100 * BOUND:.1f} % ({bound:,.0f} cycles, "
        f"the own worst): the worst row is {worst['scenario']}, "
        f"{worst['sim_own_worst_cycles']:,} cycles ({pct(worst['sim_own_worst_cycles'])}); "
    )
    if not over:
        return text + "every row is within it: **met**."
    return text + (
        "over it: "
        + ", ".join(f"{d['scenario']} {d['sim_own_worst_cycles']:,}" for d in over)
        + ": **not met**."
    )


def silent_verdict(loads: list[dict]) -> list[str]:
    """The one tick in which the host's silence puts every finger on the safe action."""
    silent = next((d for d in loads if d["scenario"] == "silent"), None)
    if silent is None:
        return []
    own, isr = silent["sim_own_worst_cycles"], silent["sim_isr_worst_cycles"]
    return [
        "",
        f"When the host falls silent, the tick that puts all five fingers on the safe action "
        f"(HOLD) is the row's worst: {own:,} cycles ({pct(own)}), {isr:,} ({pct(isr)}) for "
        f"the whole interrupt; {silent['fault_frames']} fault frames report it.",
    ]


def round_trips(loads: list[dict]) -> list[str]:
    """Issue 11 goal 3 on the simulated board: from a request's first byte on the line to its
    reply's last byte off it, with the 1 kHz stream on."""
    d = next((d for d in loads if d["scenario"] == "latency"), None)
    if d is None:
        return []
    line = {
        name: (frame_bytes_of(name) + frame_bytes_of("ack" if name == "set_targets" else "pong"))
        * BYTE_CYCLES
        / 16.0
        for name in ("ping", "set_targets")
    }
    return [
        "",
        "Round trips on the simulated board (the latency row; issue 11 goal 3: 99th percentile "
        "at most 800 µs): from a request's first byte on the line to its reply's last stop bit, "
        "one request at a time, each 0.5-3 ms after the last reply, 1 kHz state stream on.",
        "",
        "| request | n | line's own time | median | 99th percentile | worst |",
        "|---|---|---|---|---|---|",
        f"| ping | {d['ping_n']} | {line['ping']:.0f} µs | {d['ping_median_us']:.0f} µs | "
        f"{d['ping_p99_us']:.0f} µs | {d['ping_max_us']:.0f} µs |",
        f"| set_targets | {d['targets_n']} | {line['set_targets']:.0f} µs | "
        f"{d['targets_median_us']:.0f} µs | {d['targets_p99_us']:.0f} µs | "
        f"{d['targets_max_us']:.0f} µs |",
        "",
        "Where the time goes (both requests together, median / 99th percentile): the request "
        f"on the line {d['seg_in_median_us']:.0f} / {d['seg_in_p99_us']:.0f} µs; from its last "
        f"byte to dispatch's entry (loop() noticing it: the tick, the pass under way) "
        f"{d['seg_notice_median_us']:.0f} / {d['seg_notice_p99_us']:.0f} µs; from dispatch to "
        f"the reply's first byte on the line (dispatch, a frame ahead on the line) "
        f"{d['seg_reply_median_us']:.0f} / {d['seg_reply_p99_us']:.0f} µs; the reply on the "
        f"line {d['seg_out_median_us']:.0f} / {d['seg_out_p99_us']:.0f} µs.",
        "",
        "loop() sleeps (idle mode) when a pass would find nothing to do: share of the cycles "
        "the CPU slept, per row: "
        + ", ".join(f"{d['scenario']} {100 * d['asleep']:.1f} %" for d in loads)
        + " (the loop() passes above are timed entry to entry: a pass's sleep is in it).",
    ]


RX_GOAL = 200  # issue 19 goal: worst arrival-to-read (cycles), two thirds of two byte times


def receive_path(loads: list[dict], what: dict[str, str]) -> list[str]:
    """Issue 19 item 6: the receive path with the chip's receiver modelled (a two-byte FIFO
    behind the shift register; harness/uart_bridge.c), per row."""
    lines = [
        "",
        "Receive path (issue 19 goal: 0 overruns in every row, worst arrival-to-read at most "
        f"{RX_GOAL} cycles; two byte times, {2 * BYTE_CYCLES} cycles, is the deadline the "
        "ATmega2560's two-byte receive FIFO gives before the next byte's start bit overruns "
        "it). The harness models that receiver instead of simavr's 64-byte queue and times "
        "each byte from the end of its stop bit to the firmware's read of UDR0; *lost* are the "
        "bytes it dropped (DOR0), *DOR seen* the overruns the firmware counted (get_stats: "
        "uart_overruns, one per DOR0 report). *ring full*: bytes the firmware's own 128-byte "
        "ring refused (rx_overruns: requests arriving faster than it answers them).",
        "",
        "| host traffic | bytes read | wait mean / worst | over a frame | lost / DOR seen "
        "| ring full | frames / bad CRC / bad framing |",
        "|---|---|---|---|---|---|---|",
    ]
    for d in loads:
        lines.append(
            f"| {what[d['scenario']]} | {d['rx_reads']:,} | {d['rx_wait_mean_cycles']:.0f} / "
            f"{d['rx_wait_worst_cycles']} cycles | {d['rx_waits_over_a_frame']:,} | "
            f"{d['rx_bytes_lost']} / {d['uart_overruns']} | {d['rx_overruns']:,} | "
            f"{d['rx_frames']:,} / {d['rx_crc_errors']} / {d['rx_framing_errors']} |"
        )
    worst = max(loads, key=lambda d: d["rx_wait_worst_cycles"])
    lost = sum(d["rx_bytes_lost"] for d in loads)
    met = lost == 0 and worst["rx_wait_worst_cycles"] <= RX_GOAL
    lines += [
        "",
        f"Worst wait {worst['rx_wait_worst_cycles']} cycles ({what[worst['scenario']]}, at "
        f"{worst['rx_wait_worst_at_s']:.6f} s), {lost} bytes lost in all rows: the goal is "
        + ("**met**." if met else "**not met**.")
        + " See firmware/README.md (The receive path) for what holds a byte up.",
    ]
    return lines


def frame_bytes_of(name: str) -> int:
    """Bytes on the wire of the frames the latency row exchanges."""
    from utrf.protocol import messages as m
    from utrf.protocol.framing import encode_frame

    if name == "set_targets":
        body = m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=31, value=(0.4,) * 5).encode()
        return len(encode_frame(1, m.SetTargets.ID, body))
    if name == "ack":
        return len(encode_frame(1, m.Ack.ID, m.Ack(msg_id=m.SetTargets.ID).encode()))
    if name == "ping":
        return len(encode_frame(1, m.Ping.ID, m.Ping(token=0).encode()))
    return len(encode_frame(1, m.Pong.ID, m.Pong(token=0, board_time=0.0).encode()))


def pct(cycles: float) -> str:
    return f"{100 * cycles / TICK_CYCLES:.1f} %"


def short_name(name: str) -> str:
    """A function's name without its namespaces, arguments and clone suffix; an interrupt's
    vector named."""
    from tools.fw_profile import label

    base = label(name.split(" [clone")[0])
    if base.startswith("__vector_"):
        return base
    # The namespaces out before the arguments: "(anonymous namespace)::" has a parenthesis.
    base = base.replace("utrf::", "").replace("(anonymous namespace)::", "")
    return base.split("(")[0] if not base.startswith("(") else base


CPU_SECONDS = 120.0  # the grasp hold's length (make bench-twin)
PLANT_SECONDS = 10.0  # the hold with the plant, after its closing
CPU_REPEATS = 3


def twin_awake(seconds: float, reference: Path | None) -> list[str]:
    """The awake share under the twin's traffic, and its largest parts (tools.fw_profile)."""
    from tools import fw_profile

    lines = [
        "### Awake cycles under the twin's traffic (issue 20)",
        "",
        f"`tools.fw_profile` ({seconds:g} s simulated a row, `make profile-firmware` for the "
        "whole list): the ELF on the emulated board with no plant, the grasp hold's host "
        "traffic (heartbeats, five fingers in POSITION at their still encoders' angles), the "
        "state stream at 100 Hz (the hold's) and at 1 kHz; every cycle counted at the "
        "instruction that spent it (the harness's PC histogram), the slept ones left out. "
        "simavr skips slept cycles in one step, so the awake ones are the twin's firmware cost "
        "(and the board's headroom). The last row is the twin's hold itself (`tools.fw_profile "
        f"--plant`: `utrf hil grasp-hold --emulated`'s run, seed 0, {PLANT_SECONDS:g} s of "
        "hold after the closing, the closing counted): the encoders move and carry the "
        "emulated sensor's noise, so the paths for still inputs seldom apply there.",
        "",
    ]
    header = "| state stream | awake (this build) | awake cycles a second |"
    rule = "|---|---|---|"
    if reference:
        header += f" `{reference}` | ratio |"
        rule += "---|---|"
    lines += [header + " largest parts (cycles a second) |", rule + "---|"]
    rows = [(f"{rate} Hz", rate, False, seconds) for rate in (100, 1000)]
    rows.append(("100 Hz, the grasp hold with the MuJoCo hand", 100, True, PLANT_SECONDS))
    for label, rate, plant, secs in rows:
        a = fw_profile.awake(ELF, secs, rate, plant)
        parts = ", ".join(f"{short_name(k)} {v:,.0f}" for k, v in list(a["functions"].items())[:6])
        row = f"| {label} | {100 * a['share']:.1f} % | {a['per_s']:,.0f} |"
        if reference:
            r = fw_profile.awake(reference, secs, rate, plant)
            row += (
                f" {100 * r['share']:.1f} %, {r['per_s']:,.0f} cycles/s | "
                f"{a['per_s'] / r['per_s']:.2f} |"
            )
        lines.append(f"{row} {parts} |")
    lines.append("")
    if reference:
        import os

        v = fw_profile.versus(ELF, reference, CPU_SECONDS, CPU_REPEATS)
        runs = {k: ", ".join(f"{x:.2f}" for x in v[k]) for k in ("this", "ref")}
        load = os.getloadavg()[0]
        lines += [
            f"What simavr costs the host for each ELF alone (`tools.fw_profile --versus`: the "
            f"process CPU time of {CPU_SECONDS:g} s simulated under the 100 Hz traffic above, "
            f"the two ELFs alternating, {CPU_REPEATS} runs each; `make profile-firmware "
            f"FW_REF_ELF=...`): this build {runs['this']} s, `{reference}` {runs['ref']} s: "
            f"**{v['ratio']:.2f}** (medians; load average {load:.1f}).",
            "",
        ]
    return lines


def render(
    mem: dict,
    tbl: list[str],
    loads: list[dict],
    steps: list,
    seconds: float,
    awake: list[str] | None = None,
) -> str:
    now = datetime.date.today().isoformat()
    lines = [
        BEGIN,
        "## Firmware",
        "",
        f"Measured with `make bench-firmware` (`python -m tools.bench_firmware`) on "
        f"{cpu_name()}, avr-gcc 5.4 (Debian), simavr 1.6, {now}.",
        "",
        "### Memory (`avr-size -A build/firmware/utrf.elf`)",
        "",
        "| what | bytes | target |",
        "|---|---|---|",
        f"| flash (.text + .data) | {mem['flash']:,} | 65,536 (64 KB) |",
        f"| static RAM (.data {mem['data']} + .bss {mem['bss']} + .noinit {mem['noinit']}) "
        f"| {mem['ram']:,} | 3,072 (3 KB) |",
    ]
    lines += [f"| kinematics table: {t} | | |" for t in tbl]
    lines += [
        "",
        "### Control tick (five fingers in POSITION, 1 kHz = 16,000 cycles)",
        "",
        f"The emulator's harness (`tools/tick_bench.py` over `libutrf_sim.so`: simavr with the "
        "emulated board's UART line, ADC and timers) runs the ELF "
        f"{seconds:g} s per row (after 0.3 s of start-up and a reset_stats),"
        " the encoders sweeping ±0.4 rad at 1.3 Hz, the state stream at 500 Hz (1 kHz in the "
        "moves row, 10 s, and the latency row, 5 s). *firmware*: "
        "its own figures (get_stats; timer 2 and timer 1, around app::tick() in the timer "
        "interrupt, nested UART/ADC interrupts included). *simavr*: cycles from app::tick()'s "
        "entry to its return (the harness's function profile); *own* is that less the "
        "interrupts served while it ran (*nested*: the UART's receive interrupt, one a byte; "
        "the transmitter's too; timer 0's waits for the tick's end), each counted from the "
        "cycle it is entered to the end of its reti. *whole interrupt*: the timer interrupt's "
        "calls that ran a tick, from its vector to the end of its reti (register saves, the "
        "tick's timing and bookkeeping included). Target: at most 15 % (2,400 cycles). The "
        "tick is plain C++ (no assembly).",
        "",
        "| host traffic | ticks | overruns | firmware mean | firmware worst | simavr mean | "
        "simavr worst | own mean / worst | nested mean / worst | whole interrupt mean / worst |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    what = {
        "idle": "heartbeats only",
        "typical": "set_targets at 200 Hz",
        "stress": "set_targets back to back (line saturated)",
        "silent": "none: the host falls silent, HOLD at the heartbeat timeout",
        "moves": "1 kHz stream, a five-finger move every 0.4 s, heartbeats",
        "latency": "1 kHz stream, ping and set_targets one at a time, 0.5-3 ms apart",
        "heavy": "1 kHz stream, requests back to back (moves, pings, get_state, get_stats), "
        "save_config every 0.5 s",
    }
    for d in loads:
        fm, fw = d["tick_mean_us"] * 16, d["tick_worst_us"] * 16
        lines.append(
            f"| {what[d['scenario']]} | {d['ticks']} | {d['tick_overruns']} | "
            f"{d['tick_mean_us']} µs ({pct(fm)}) | {d['tick_worst_us']} µs ({pct(fw)}) | "
            f"{d['sim_tick_mean_cycles']:,.0f} cycles ({pct(d['sim_tick_mean_cycles'])}) | "
            f"{d['sim_tick_worst_cycles']:,} cycles ({pct(d['sim_tick_worst_cycles'])}) | "
            f"{d['sim_own_mean_cycles']:,.0f} / {d['sim_own_worst_cycles']:,} | "
            f"{d['sim_nested_mean_cycles']:,.0f} / {d['sim_nested_worst_cycles']:,} | "
            f"{d['sim_isr_mean_cycles']:,.0f} ({pct(d['sim_isr_mean_cycles'])}) / "
            f"{d['sim_isr_worst_cycles']:,} ({pct(d['sim_isr_worst_cycles'])}) |"
        )
    lines += [
        "",
        "| host traffic | state frames / dropped / seq gaps | rx frames / overruns | "
        "interrupts nested in the tick | loop() passes / longest |",
        "|---|---|---|---|---|",
    ]
    for d in loads:
        lines.append(
            f"| {what[d['scenario']]} | {d['state_frames']} / {d['tx_dropped']} / "
            f"{d['state_seq_gaps']} | {d['rx_frames']} / {d['rx_overruns']} | "
            f"{d['sim_nested_interrupts']:,} | {d['loop_passes']:,} / "
            f"{d['loop_worst_cycles']:,} cycles ({d['loop_worst_cycles'] / 16e3:.1f} ms) |"
        )
    lines += ["", *verdict(loads), *silent_verdict(loads), *round_trips(loads)]
    lines += [*receive_path(loads, what), ""]
    lines += awake or []
    lines += [
        "### PID step response (default gains, reference plant, host build of the core)",
        "",
        "Plant (tests/firmware/fwsim.py `FingerPlant`): θ'' = (6 rad/s · (u − 0.03 sign) − θ')"
        " / 30 ms, the net duty u from the motor pins; the encoder quantised by the ADC.",
        "",
        "| step | rise 10-90 % | overshoot | settling (2 %) | error at rest |",
        "|---|---|---|---|---|",
    ]
    for step, f in steps:
        lines.append(
            f"| {step:g} rad | {f['rise_s'] * 1e3:.0f} ms | {100 * f['overshoot']:.1f} % | "
            f"{f['settle_s'] * 1e3:.0f} ms | {1e3 * f['final_error_rad']:+.1f} mrad |"
        )
    lines.append(END)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--update", type=Path, help="write the section into this markdown file")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated seconds per load")
    parser.add_argument(
        "--reference-elf", type=Path, help="another build's ELF beside this one (awake cycles)"
    )
    args = parser.parse_args(argv)
    mem = memory()
    tbl = table()
    loads = [tick_load(s, args.seconds) for s in ("idle", "typical", "stress", "silent")]
    loads.append(tick_load("moves", max(args.seconds, 10.0)))  # issue 11 goal 2: 10 s at 1 kHz
    loads.append(tick_load("latency", max(args.seconds, 5.0)))  # issue 11 goal 3
    loads.append(tick_load("heavy", args.seconds))  # issue 19 item 6: the receive path
    steps = step_figures()
    awake = twin_awake(args.seconds, args.reference_elf)
    section = render(mem, tbl, loads, steps, args.seconds, awake)
    print(section)
    if args.update:
        write_section(args.update, section, BEGIN, END)
        print(f"updated {args.update}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
