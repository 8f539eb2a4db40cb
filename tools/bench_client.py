"""Benchmarks of the Hand client on the real firmware and the emulated board, in simulated time.

- Round-trip latency of a command: from the request's first byte queued on the host's side of
  the UART to its reply's last byte received, in simulated time (driven board, a Hand over a
  SimLink), for ping, set_targets and get_state, with the state stream off and at its top
  rate (1 kHz).
  The board exchanges with the host every ``--exchange-us`` (20 µs here): the resolution.
- The highest telemetry rate with no drops at the default baud rate (1 Mbaud): a sweep of
  rates with five fingers under position control following minimum-jerk moves, frames counted
  on the host (seq gaps) and in the firmware (``tx_dropped``).

Prints a Markdown section and writes it into docs/benchmarks.md between the client markers.
Run with ``make bench-client``.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

from tools.doc_sections import cpu_name, write_section
from utrf.emulator import DEFAULT_ELF, EmulatedBoard
from utrf.hand import Hand
from utrf.protocol import messages as m
from utrf.protocol.framing import encode_frame
from utrf.trajectory import sample_min_jerk

REPO = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN client (make bench-client) -->"
END = "<!-- END client -->"
BITS_PER_BYTE = 10  # 8N1


def state_frame_bytes() -> int:
    """A state frame on the wire (COBS code and delimiter included)."""
    return m.State.SIZE + 6


FIST = [1.15, 1.40, 1.40, 1.40, 1.40]
#: the commands whose round trip is measured
REQUESTS: dict[str, m.Message] = {
    "ping": m.Ping(token=0x1234),
    "set_targets": m.SetTargets(m.TargetKind.JOINT2_ANGLE, 0b11111, (0.3,) * 5),
    "get_state": m.GetState(),
}


def wire_us(request: m.Message) -> float:
    """Microseconds on the line for the request's frame and its reply's, at the default baud."""
    reply_cls = type(request).REPLY
    fields = {}
    for f in reply_cls.FIELDS:  # any valid reply: only its length matters
        zero = f.enum(next(iter(f.enum))) if f.enum else 0
        fields[f.name] = (zero,) * f.count if f.count else zero
    if reply_cls is m.Ack:
        fields["msg_id"] = request.ID
    reply = reply_cls(**fields)
    n = len(encode_frame(0, request.ID, request.encode()))
    n += len(encode_frame(0, reply_cls.ID, reply.encode()))
    return n * BITS_PER_BYTE / m.DEFAULT_BAUD * 1e6


def latency(elf: Path, exchange_s: float, n: int, telemetry_hz: int, seed: int) -> dict:
    """Round trips (s, simulated) of ping, set_targets and get_state."""
    out: dict[str, list[float]] = {k: [] for k in REQUESTS}
    rng = np.random.default_rng(seed)
    with (
        EmulatedBoard(elf, realtime=False, seed=seed, exchange_period=exchange_s) as board,
        Hand.emulated(board, telemetry_hz=telemetry_hz) as hand,
    ):
        hand.move([0.3] * 5, 0.2)  # five fingers under position control meanwhile
        retries0 = hand.link_stats().retries
        for _ in range(n):
            for name, req in REQUESTS.items():
                hand.clock.sleep(float(rng.uniform(0.5e-3, 3e-3)))  # off the loop's phase
                t0 = board.sim_time
                hand.link.request(req)
                out[name].append(board.sim_time - t0)
        retries = hand.link_stats().retries - retries0
        fw = hand.stats()
    return {"samples": out, "retries": retries, "tick_overruns": fw.tick_overruns}


def telemetry(elf: Path, rate: int, seconds: float, command_hz: float, seed: int) -> dict:
    """Frames expected, received, lost (host) and dropped (firmware) at a stream rate."""
    with (
        EmulatedBoard(elf, realtime=False, seed=seed) as board,
        Hand.emulated(board, telemetry_hz=rate) as hand,
    ):
        hand.move([0.3] * 5, 0.2, wait=False)
        hand.reset_stats()
        s0 = hand.link_stats()
        t0 = board.sim_time
        wall0 = time.perf_counter()
        start, goal = [0.3] * 5, FIST
        while board.sim_time - t0 < seconds:
            if not command_hz:
                hand.clock.sleep(0.2)  # holding: heartbeats only
                continue
            # Command traffic beside the stream: minimum-jerk moves sent from the host as
            # set_targets at command_hz (the board's own moves would put one command on the line).
            begin = hand.clock.now()
            for t, targets in sample_min_jerk(start, goal, 0.8, command_hz):
                hand.set_targets([float(v) for v in targets])
                hand.clock.sleep(max(0.0, begin + t - hand.clock.now()))
            start, goal = goal, start
        elapsed = board.sim_time - t0
        s1 = hand.link_stats()
        fw = hand.stats()
        wall = time.perf_counter() - wall0
    received = s1.stream_frames - s0.stream_frames
    return {
        "rate": rate,
        "command_hz": command_hz,
        "seconds": elapsed,
        "expected": rate * elapsed,
        "received": received,
        "lost": s1.stream_lost - s0.stream_lost,
        "tx_dropped": fw.tx_dropped,
        "damaged": s1.crc_errors + s1.framing_errors - s0.crc_errors - s0.framing_errors,
        "line_share": received * state_frame_bytes() * BITS_PER_BYTE / m.DEFAULT_BAUD / elapsed,
        "tick_overruns": fw.tick_overruns,
        "wall": wall,
    }


def us(x: float) -> str:
    return f"{x * 1e6:,.0f} µs"


def report(lat: dict[int, dict], sweep: list[dict], args: argparse.Namespace, took: float) -> str:
    lines = [
        BEGIN,
        "## Client",
        "",
        f"Measured with `make bench-client` (`python -m tools.bench_client`) on {cpu_name()}, "
        f"Python {platform.python_version()}, {date.today().isoformat()}: the real firmware "
        "(`build/firmware/utrf.elf`) on the driven emulated board, a `Hand` over a `SimLink`, "
        f"times in simulated seconds; {took:.0f} s of wall time in all.",
        "",
        "### Round trip of a command",
        "",
        f"From the request's first byte queued on the host's side of the UART to the reply's "
        f"last byte received; {args.latency_n} of each, spread over the loop's phase, five "
        "fingers under position control. Resolution: the board's exchange period with the "
        f"host, {args.exchange_us:g} µs. *Line* is the two frames' bytes at 10 bits a byte at "
        "1 Mbaud; the rest is the firmware: its `loop()` takes the request and dispatches it, "
        "the tick holds the loop while it runs (the UART's transmitter runs on), and the reply "
        "waits for at most the one state frame on the line (the board hands its own frames to "
        "the UART only when its transmit buffer is empty).",
        "",
        "| command | state stream | median | 99th percentile | worst | line | retries |",
        "|---|---|---|---|---|---|---|",
    ]
    for hz, res in lat.items():
        for name, xs in res["samples"].items():
            lines.append(
                f"| `{name}` | {hz or 'off'}{' Hz' if hz else ''} | "
                f"**{us(statistics.median(xs))}** | {us(float(np.percentile(xs, 99)))} | "
                f"{us(max(xs))} | {wire_us(REQUESTS[name]):,.0f} µs | {res['retries']} |"
            )
    moving = [r for r in sweep if r["command_hz"]]
    clean = [r for r in moving if r["lost"] == 0 and r["tx_dropped"] == 0]
    best = max(clean, key=lambda r: r["rate"], default=None)
    idle = next(r for r in sweep if not r["command_hz"])
    lines += [
        "",
        "### Telemetry rate at the default baud rate (1 Mbaud)",
        "",
        f"Each row: {args.seconds:g} s simulated. Five fingers under position control, "
        "holding still (set_targets: none, heartbeats only) or following minimum-jerk moves "
        "(fist ↔ 0.3 rad) streamed at the rate given; frames *expected* at the stream rate, "
        "*received* by the host, *lost* (seq gaps seen by the host), *dropped* by the firmware "
        "(`tx_dropped`: a frame fell due while `loop()` was busy with a request, or found no "
        "room in the transmit buffer), *damaged* (CRC or framing errors). The protocol caps "
        f"the stream at {m.MAX_TELEMETRY_HZ} Hz (`set_telemetry` refuses more); a "
        f"{state_frame_bytes()}-byte state frame takes "
        f"{state_frame_bytes() * BITS_PER_BYTE / m.DEFAULT_BAUD * 1e3:.2f} ms of the line.",
        "",
        "| stream | set_targets | expected | received | lost | dropped | damaged | "
        "line busy with state | tick overruns |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in sweep:
        commands = f"{r['command_hz']:g} Hz" if r["command_hz"] else "none"
        lines.append(
            f"| {r['rate']} Hz | {commands} | {r['expected']:,.0f} | "
            f"{r['received']:,} | {r['lost']} | {r['tx_dropped']} | {r['damaged']} | "
            f"{100 * r['line_share']:.0f} % | {r['tick_overruns']} |"
        )
    idle_ok = idle["lost"] == 0 and idle["tx_dropped"] == 0
    summary = f"Holding still, {idle['rate']} Hz (the protocol's maximum) " + (
        "arrives with no frame lost." if idle_ok else f"loses {idle['lost']} frames."
    )
    if best is None:
        summary += " While moving, every rate lost frames."
    else:
        summary += (
            f" While moving, the highest rate with no frame lost or dropped is "
            f"**{best['rate']} Hz**"
        )
        summary += (
            "; above it the firmware drops a frame now and then while it handles a "
            "`set_targets`, and the host counts every loss the firmware does."
            if best["rate"] < m.MAX_TELEMETRY_HZ
            else "."
        )
    lines += ["", summary]
    lines.append(END)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elf", type=Path, default=DEFAULT_ELF)
    p.add_argument("--latency-n", type=int, default=200, help="round trips of each command")
    p.add_argument("--exchange-us", type=float, default=20.0, help="latency resolution, µs")
    p.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per rate")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--no-update", action="store_true", help="print only")
    args = p.parse_args(argv)
    if not DEFAULT_ELF.exists() and args.elf == DEFAULT_ELF:
        print(f"bench_client: {DEFAULT_ELF} not found: run `make firmware`", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    lat = {
        hz: latency(args.elf, args.exchange_us * 1e-6, args.latency_n, hz, args.seed)
        for hz in (0, m.MAX_TELEMETRY_HZ)
    }
    sweep = [telemetry(args.elf, m.MAX_TELEMETRY_HZ, args.seconds, 0.0, args.seed)]
    sweep += [
        telemetry(args.elf, rate, args.seconds, 50.0, args.seed) for rate in (250, 500, 750, 1000)
    ]
    sweep.append(telemetry(args.elf, m.MAX_TELEMETRY_HZ, args.seconds, 200.0, args.seed))
    section = report(lat, sweep, args, time.perf_counter() - t0)
    print(section)
    if not args.no_update:
        write_section(BENCH_DOC, section, BEGIN, END)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
