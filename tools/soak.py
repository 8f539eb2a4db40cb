"""The soak (issue 13 §5): the served emulated board at real time for a long while, telemetry at
the highest rate, commands at 100 Hz, a fault injected now and then; fails on memory growth,
on frames lost, on an error or a fault nobody injected.

    python tools/soak.py --seconds 1800            # make soak (SOAK_SECONDS=...)

The board runs as ``utrf emulate`` in its own process (``BoardProcess``), the Hand in this one
over TCP, as a user's program would. Every ``--fault-every`` seconds one fault in turn: an
encoder unplugged, a finger jammed under load, a burst of line noise; each latched fault is
cleared and the finger driven again. Reported: the RSS of both processes after the warm-up
and at the end (and its peak), the board's lag events and real-time factor, the stream's
frames received and lost (seq gaps) and the board's own dropped count, the commands sent,
late and failed, and every fault latched. The figures go to ``--json`` (default
build/reliability/soak.json) for docs/reliability.md (tools/reliability_doc.py).

On a shared machine: both processes run at ``--nice`` (default -10, where permitted), and the
soak keeps a timeline, once a second, of what the link, the board and the emulator counted
(frames lost, resends, the emulator's lag events and simulated time). Each frame lost is
then split by where (dropped by the firmware, by its own ``tx_dropped``; or lost between its
UART and the Hand) and laid beside what happened in the same seconds: the emulated board
lagging the wall clock, a resend, an injected burst of noise. A lagging board is not a pass:
the verdict counts every frame lost whatever the cause, and the lag is reported beside it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from utrf.emulator import EmulatedBoard
from utrf.emulator.process import BoardProcess
from utrf.hand import Hand
from utrf.protocol import messages as M

REPO_BUILD = Path("build") / "reliability"
COMMAND_HZ = 100
# Growth allowed between the end of the warm-up and the end, per process (MiB): allocator
# noise and caches; a leak of a frame's worth a second is 0.2 MiB a minute and shows.
RSS_GROWTH_LIMIT_MIB = 8.0
# Below this share of real time in a timeline second, the board counts as lagging then.
LAGGING_BELOW = 0.95


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


def targets_at(t: float) -> dict[int, float]:
    """A slow wave on every finger, inside the default limits."""
    return {f: 0.45 + 0.35 * math.sin(2 * math.pi * 0.25 * t + f) for f in range(5)}


class Served:
    """The faults as ``utrf emulate``'s stdin commands, on the wall clock."""

    def __init__(self, board: BoardProcess) -> None:
        self.board = board

    def fault(self, command: str) -> None:
        self.board.command(command)

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)


class Driven:
    """The same faults on a driven board, in simulated time (the soak's deterministic twin)."""

    def __init__(self, board: EmulatedBoard, hand: Hand) -> None:
        self.board, self.hand = board, hand

    def fault(self, command: str) -> None:
        verb, arg = command.split()
        n = int(arg)
        if verb == "noise":
            self.board.inject_noise(n)
        elif verb == "block":
            self.board.block_finger(n, None, direction="both")
        else:
            {"unplug": self.board.unplug_encoder, "plug": self.board.plug_encoder,
             "unblock": self.board.unblock_finger}[verb](n)  # fmt: skip

    def sleep(self, seconds: float) -> None:
        self.hand.clock.sleep(seconds)


class Faults:
    """One fault in turn: what to do, which finger latches what, how to undo it."""

    def __init__(self, board: Served | Driven) -> None:
        self.board = board
        self.k = 0
        self.injected: list[dict[str, Any]] = []

    def inject(self, hand: Hand, t: float) -> None:
        kind = ("unplug", "block", "noise")[self.k % 3]
        finger = self.k % 5
        self.k += 1
        expect: set[str] = set()
        if kind == "unplug":
            self.board.fault(f"unplug {finger}")
            self.board.sleep(0.2)
            self.board.fault(f"plug {finger}")
            # out of its band; plugged back, the reading leaps from the rail to the angle
            expect = {"ENCODER_RANGE", "ENCODER_JUMP"}
        elif kind == "block":
            # jammed where it is while the wave pushes it on: a stall, or nothing if the wave
            # happens to hold still long enough (then it is only the block)
            self.board.fault(f"block {finger}")
            self.board.sleep(0.8)
            self.board.fault(f"unblock {finger}")
            expect = {"STALL"}
        else:
            self.board.fault("noise 64")
            self.board.sleep(0.05)
        self.board.sleep(0.05)
        self.injected.append(
            {"kind": kind, "finger": finger, "may_latch": sorted(expect), "t": round(t, 3)}
        )
        # what a user's program does: clear, and drive again (set_targets puts the fingers
        # back in POSITION: get_state and set_mode, round trips back to back)
        hand.clear_faults()
        hand.set_targets(targets_at(t))


def driven_twin(elf: str | None, seconds: float, fault_every: float) -> dict[str, Any]:
    """The soak's load on a driven board in simulated time: the same wave of set_targets at
    COMMAND_HZ, the stream at its top rate, the same faults and recovery. No machine in it
    (deterministic): what the firmware drops here, it drops under this load anywhere."""
    with (
        EmulatedBoard(elf, realtime=False, seed=7) as board,
        Hand.emulated(board, telemetry_hz=M.MAX_TELEMETRY_HZ) as hand,
    ):
        faults = Faults(Driven(board, hand))
        hand.set_targets(targets_at(0.0))
        hand.clock.sleep(0.5)
        hand.reset_stats()
        s0 = hand.link_stats()
        t0 = board.sim_time
        next_fault = fault_every
        commands = 0
        while (t := board.sim_time - t0) < seconds:
            if t >= next_fault:
                faults.inject(hand, t)
                next_fault += fault_every
                continue
            hand.set_targets(targets_at(t), enable=False)
            commands += 1
            rest = 1.0 / COMMAND_HZ - (board.sim_time - t0 - t)
            if rest > 0:
                hand.clock.sleep(rest)
        st = hand.stats()
        s1 = hand.link_stats()
        return {
            "sim_seconds": round(board.sim_time - t0, 2),
            "commands": commands,
            "stream_frames": s1.stream_frames - s0.stream_frames,
            "stream_lost": s1.stream_lost - s0.stream_lost,
            "board_tx_dropped": st.tx_dropped,
            "board_tick_worst_s": st.tick_worst,
            "faults_injected": [f["kind"] for f in faults.injected],
        }


class Timeline:
    """Once a second, what changed: the Hand's link counters, the emulator's lag events and
    simulated time, commands late, faults injected. Kept whole for every second in which a
    frame was lost, a request resent or the board lagged (the rest only counted)."""

    def __init__(self, hand: Hand, board: BoardProcess) -> None:
        self.hand, self.board = hand, board
        self.rows: list[dict[str, Any]] = []
        self.seconds = 0
        self.lagging_seconds = 0
        self._last = self._counters(0)
        self._injected: list[str] = []

    def _counters(self, late: int) -> dict[str, Any]:
        ls = self.hand.link_stats()
        st = self.board.status()
        return {
            "wall": time.monotonic(),
            "sim": float(st.get("sim_time_s", 0.0)),
            "lag_events": int(st.get("lag_events", 0)),
            "lost": ls.stream_lost,
            "frames": ls.stream_frames,
            "retries": ls.retries,
            "rx_errors": ls.crc_errors + ls.framing_errors + ls.oversize,
            "late": late,
        }

    def injected(self, kind: str) -> None:
        self._injected.append(kind)

    def sample(self, t: float, late: int, counting: bool) -> None:
        now = self._counters(late)
        d = {k: now[k] - self._last[k] for k in now}
        self._last = now
        rate = d["sim"] / d["wall"] if d["wall"] > 0 else 1.0
        lagging = d["lag_events"] > 0 or rate < LAGGING_BELOW
        row = {
            "t": round(t, 1),
            "lost": d["lost"],
            "frames": d["frames"],
            "resends": d["retries"],
            "rx_errors": d["rx_errors"],
            "lag_events": d["lag_events"],
            "realtime": round(rate, 3),
            "late": d["late"],
            "injected": self._injected,
            "counted": counting,
        }
        self._injected = []
        if counting:
            self.seconds += 1
            self.lagging_seconds += lagging
        if d["lost"] or d["retries"] or d["rx_errors"] or lagging or row["injected"]:
            self.rows.append(row)

    def causes(self) -> dict[str, int]:
        """Frames lost (after the warm-up) by what else happened in that second or the two
        before: a fault injected (and the recovery after it), a resend, the board lagging,
        or nothing seen."""
        out: dict[str, int] = {}
        for i, row in enumerate(self.rows):
            if not (row["lost"] and row["counted"]):
                continue
            near = [r for r in self.rows[max(0, i - 3) : i + 1] if r["t"] >= row["t"] - 2.5]
            kinds = [k for r in near for k in r["injected"]]
            if kinds:
                cause = f"after {kinds[-1]} and its recovery"
            elif any(r["resends"] for r in near):
                cause = "a resend"
            elif any(r["lag_events"] or r["realtime"] < LAGGING_BELOW for r in near):
                cause = "board lagging"
            else:
                cause = "nothing seen"
            out[cause] = out.get(cause, 0) + row["lost"]
        return out


def set_priority(nice: int) -> int | str:
    """Raise (or lower) this process's priority before the board's process starts (it
    inherits it): the soak is about the firmware, not about who else uses the machine."""
    try:
        return os.nice(nice - os.nice(0))
    except OSError as exc:
        return f"not permitted ({exc.strerror}): {os.nice(0)}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1800.0)
    ap.add_argument("--fault-every", type=float, default=None, help="default: seconds / 12")
    ap.add_argument("--warmup", type=float, default=None, help="default: min(60, seconds / 10)")
    ap.add_argument("--elf", default=None)
    ap.add_argument("--json", type=Path, default=REPO_BUILD / "soak.json")
    ap.add_argument(
        "--nice", type=int, default=-10, help="both processes' nice value (default -10)"
    )
    ap.add_argument(
        "--driven-seconds",
        type=float,
        default=60.0,
        help="simulated seconds of the deterministic twin, after the soak (0: none)",
    )
    a = ap.parse_args(argv)
    nice = set_priority(a.nice)
    fault_every = a.fault_every or max(a.seconds / 12, 10.0)
    warmup = a.warmup if a.warmup is not None else min(60.0, a.seconds / 10)

    board = BoardProcess(a.elf, seed=7, pty=False, speed=1.0)
    frames = 0

    def on_state(_st: object) -> None:
        nonlocal frames
        frames += 1

    out: dict[str, Any] = {"seconds": a.seconds, "command_hz": COMMAND_HZ, "nice": nice}
    sent = late = failed = 0
    errors: list[str] = []
    try:
        assert board.url is not None
        hand = Hand.connect(board.url, telemetry_hz=M.MAX_TELEMETRY_HZ)
        out["telemetry_hz"] = hand.telemetry_hz
        hand.on_state(on_state)
        faults = Faults(Served(board))
        pids = {"host (Hand)": os.getpid(), "board (utrf emulate)": board._proc.pid}
        rss: dict[str, dict[str, float]] = {n: {"start": rss_mib(p)} for n, p in pids.items()}
        hand.set_targets(targets_at(time.monotonic()))
        timeline = Timeline(hand, board)
        t_start = time.monotonic()
        next_cmd = t_start
        next_fault = t_start + fault_every
        next_sample = t_start + 1.0
        warmed = False
        status0: dict[str, Any] = {}
        stats0 = None
        while True:
            now = time.monotonic()
            if now - t_start >= a.seconds:
                break
            if not warmed and now - t_start >= warmup:
                warmed = True
                for n, p in pids.items():
                    rss[n]["after_warmup"] = rss_mib(p)
                status0 = board.status()
                stats0 = hand.link_stats()
                board0 = hand.stats()
                frames_at_warm = frames
                wall_at_warm = time.monotonic()
            if now >= next_sample:
                timeline.sample(now - t_start, late, warmed)
                next_sample += 1.0
            if now >= next_fault:
                faults.inject(hand, time.monotonic())
                timeline.injected(faults.injected[-1]["kind"])
                next_fault += fault_every
                next_cmd = time.monotonic()
                continue
            if now < next_cmd:
                time.sleep(next_cmd - now)
                continue
            if now - next_cmd > 1.0 / COMMAND_HZ:
                late += 1
                next_cmd = now  # do not burst to catch up
            try:
                hand.set_targets(targets_at(now), enable=False)
            except Exception as exc:
                failed += 1
                if len(errors) < 20:
                    errors.append(f"{now - t_start:.1f} s: {exc!r}")
            sent += 1
            next_cmd += 1.0 / COMMAND_HZ
            for n, p in pids.items():
                rss[n]["peak"] = max(rss[n].get("peak", 0.0), rss_mib(p))
        elapsed = time.monotonic() - t_start
        for n, p in pids.items():
            rss[n]["end"] = rss_mib(p)
        status1 = board.status()
        wall_counted = time.monotonic() - wall_at_warm
        stats1 = hand.link_stats()
        board_stats = hand.stats()
        seen = [
            {"finger": e.finger, "faults": e.new_faults.name, "board_time_s": e.board_time}
            for e in hand.faults_seen
        ]
        hand.close()
    finally:
        final = board.close()
    assert stats0 is not None, "the soak ended before its warm-up"
    allowed = {(f["finger"], n) for f in faults.injected for n in f["may_latch"]}
    names = list(hand.fingers)
    unexpected = [
        s
        for s in seen
        if not all((names.index(s["finger"]), b) in allowed for b in s["faults"].split("|"))
    ]
    lost = stats1.stream_lost - stats0.stream_lost
    dropped = board_stats.tx_dropped - board0.tx_dropped
    sim_counted = float(status1.get("sim_time_s", 0)) - float(status0.get("sim_time_s", 0))
    out.update(
        {
            "elapsed_s": round(elapsed, 1),
            "counted_after_s": round(warmup, 1),
            "rss_mib": {n: {k: round(v, 1) for k, v in d.items()} for n, d in rss.items()},
            "commands_sent": sent,
            "commands_late": late,
            "commands_failed": failed,
            "errors": errors,
            "stream_frames": frames,
            "stream_frames_after_warmup": frames - frames_at_warm,
            "stream_lost": lost,
            "board_tx_dropped": dropped,
            "host_side_lost": lost - dropped,
            "board_tx_dropped_in_warmup": board0.tx_dropped,
            "host_rx_errors": (stats1.crc_errors + stats1.framing_errors + stats1.oversize)
            - (stats0.crc_errors + stats0.framing_errors + stats0.oversize),
            "lost_by_cause": timeline.causes(),
            "timeline": timeline.rows,
            "telemetry_dropped_by_consumer": stats1.telemetry_dropped,
            "link_retries": stats1.retries - stats0.retries,
            "link_timeouts": stats1.timeouts - stats0.timeouts,
            "crc_errors": stats1.crc_errors - stats0.crc_errors,
            "board_rx_overruns": board_stats.rx_overruns - board0.rx_overruns,
            "board_tick_overruns": board_stats.tick_overruns - board0.tick_overruns,
            "board_tick_worst_s": board_stats.tick_worst,
            "board_rx_repeats": board_stats.rx_repeats - board0.rx_repeats,
            "lag_events": int(status1.get("lag_events", 0)) - int(status0.get("lag_events", 0)),
            "realtime_factor": round(sim_counted / wall_counted, 3) if wall_counted else None,
            "capacity": status1.get("capacity"),
            "seconds_counted": timeline.seconds,
            "seconds_lagging": timeline.lagging_seconds,
            "board_status": {k: status1.get(k) for k in ("sim_time_s", "resets", "clients")},
            "faults_injected": faults.injected,
            "faults_latched": seen,
            "faults_unexpected": unexpected,
            "final": final,
        }
    )
    if a.driven_seconds > 0:
        twin_faults = min(fault_every, a.driven_seconds / 6)
        out["driven"] = driven_twin(a.elf, a.driven_seconds, twin_faults)
    growth = {
        n: d["end"] - d["after_warmup"] for n, d in out["rss_mib"].items() if "after_warmup" in d
    }
    out["rss_growth_mib"] = {n: round(g, 1) for n, g in growth.items()}
    problems = []
    for n, g in growth.items():
        if g > RSS_GROWTH_LIMIT_MIB:
            problems.append(f"{n} grew {g:.1f} MiB (limit {RSS_GROWTH_LIMIT_MIB})")
    if lost or dropped:
        problems.append(
            f"{lost} stream frames lost: the firmware dropped {dropped}, "
            f"{lost - dropped} lost between its UART and the Hand"
        )
    twin = out.get("driven")
    if twin and (twin["stream_lost"] or twin["board_tx_dropped"]):
        problems.append(
            f"in the driven twin ({twin['sim_seconds']:.0f} s simulated, no machine load) the "
            f"firmware dropped {twin['board_tx_dropped']} and {twin['stream_lost']} were lost"
        )
    if failed:
        problems.append(f"{failed} commands failed: {errors[:3]}")
    if unexpected:
        problems.append(f"faults nobody injected: {unexpected[:3]}")
    out["problems"] = problems
    out["passed"] = not problems
    out["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    git = ["git", "rev-parse", "--short", "HEAD"]
    out["commit"] = subprocess.run(git, capture_output=True, text=True, check=False).stdout.strip()
    out["load_average"] = os.getloadavg()
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(out, indent=1, default=str) + "\n")
    print(
        f"soak {elapsed:.0f} s: {sent} commands ({late} late, {failed} failed), "
        f"{frames} state frames at {out['telemetry_hz']} Hz, {lost} lost "
        f"(the firmware dropped {dropped}; by cause {out['lost_by_cause']}), "
        f"lag events {out['lag_events']} ({timeline.lagging_seconds} of {timeline.seconds} s "
        f"lagging, real-time factor {out['realtime_factor']}), nice {nice}, "
        f"{len(seen)} faults latched ({len(unexpected)} unexpected) of "
        f"{len(faults.injected)} injected"
    )
    if twin:
        print(f"  driven twin: {twin}")
    for n, d in out["rss_mib"].items():
        print(f"  RSS {n}: " + ", ".join(f"{k} {v:.1f} MiB" for k, v in d.items()))
    for p in problems:
        print(f"  FAIL: {p}")
    return 0 if not problems else 1


if __name__ == "__main__":
    sys.exit(main())
