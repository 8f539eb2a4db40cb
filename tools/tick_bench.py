"""The firmware's control tick under protocol traffic, on the emulated board's harness.

    python -m tools.tick_bench <elf> <scenario> <seconds>      prints one JSON object

Runs the ELF on the one simavr harness (``libutrf_sim.so``, through
:class:`utrf.emulator._native.NativeBoard`: its ELF loading, UART bridge, timers and ADC) and
reports the control tick as the firmware measures it (get_stats: tick_worst, tick_mean,
overruns), the simulator's cycle profiles of ``app::tick()`` (elapsed, its own work with the
interrupts nested in it left out, those interrupts), of the timer interrupt that runs it, and
of ``app::loop()``'s passes, plus the telemetry it streams. Used by ``tools.bench_firmware``
(``make bench-firmware``) and tests/firmware/test_fw_avr.py.

Scenarios (all five fingers in POSITION, encoders sweeping, 500 Hz telemetry):
  idle      no requests beyond heartbeats (20 Hz)
  typical   set_targets at 200 Hz
  stress    set_targets back to back: the receive line saturated at 1 Mbaud
  silent    nothing at all: after the heartbeat timeout (0.5 s by default) the safe action
            (HOLD by default) takes every finger in one tick, the tick this row's worst shows
  moves     1 kHz stream, a five-finger move every 0.4 s, heartbeats between
  latency   1 kHz stream, ping and set_targets one at a time, each 0.5-3 ms after the last
            reply: round trips from the request's first byte on the line to the reply's last byte
            off it (its stop bit), and where the time goes
  heavy     the heaviest traffic the protocol allows: 1 kHz stream, requests back to back (the
            receive line saturated): five-finger moves, pings, get_state, get_stats and
            heartbeats in turn, and a save_config (EEPROM writes) every 0.5 s
Every row also reports the receive path as the harness models the chip's receiver (a two-byte
FIFO behind the shift register): bytes read, the worst and mean wait from a byte's stop bit to
the firmware's read of UDR0, bytes that waited over a frame, bytes lost (DOR0), and the
firmware's own count of the overruns it saw (get_stats: uart_overruns).
The host's frames drift against the tick (its clock is not the board's): each period is a
little longer than nominal, so that over a run of a second or more the frames start at every
phase of the tick, the worst (a frame arriving while the tick runs) included.
  pins      (<seconds> unused) the driver pins and PWM timers through a sequence of modes, as
            registers (the harness reads them per board_pins.h), for tests/firmware/test_fw_avr.py
  tickdead  (<seconds>: the phase) timer 2's clock stopped at 0.3 s + phase: how long until
            every STBY pin is low, from the stop and from the last tick's entry
Frames are built and parsed by the host's protocol package (utrf.protocol), generated from the
same definition as the firmware's.

Where the cycles go: with UTRF_PC_PROFILE=<file>, a row also writes the cycles per instruction
address over its measured seconds ("<hex byte address> <cycles>" lines), of app::tick()'s own
work, or with UTRF_PC_PROFILE_OF=loop|dispatch|all of loop()'s or dispatch::handle()'s own
work (interrupts nested in them left out) or of every instruction (sleep included). Map the
addresses with avr-objdump -d -C.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path

from utrf.emulator._native import NativeBoard
from utrf.protocol import messages as m
from utrf.protocol.framing import Frame, decode_stream, encode_frame

CPU_HZ = 16_000_000
TICK_VECTOR = 13  # TIMER2_COMPA
TICK, LOOP, DISPATCH = 0, 1, 2  # the harness's function profile slots
SCENARIOS = (
    "idle",
    "typical",
    "stress",
    "silent",
    "moves",
    "latency",
    "heavy",
    "pins",
    "tickdead",
)
CHUNK = CPU_HZ // 2000  # the encoders' inputs are set every 0.5 ms at most
ALL = 0x1F


def lround(x: float) -> int:
    """C's lround: halves away from zero."""
    return math.floor(x + 0.5) if x >= 0 else -math.floor(-x + 0.5)


def addresses(elf: Path) -> dict[str, int]:
    """app::tick(), app::loop() and dispatch::handle() (byte addresses) from the ELF."""
    nm = subprocess.run(["avr-nm", "-C", str(elf)], capture_output=True, text=True, check=True)
    want = {"tick": " utrf::app::tick()", "loop": " utrf::app::loop()"}
    found: dict[str, int] = {}
    for line in nm.stdout.splitlines():
        for key, suffix in want.items():
            if line.endswith(suffix):
                found[key] = int(line.split()[0], 16)
        if " utrf::dispatch::handle(" in line:
            found["dispatch"] = int(line.split()[0], 16)
    return found


class Bench:
    """The board, the host's side of the line, and what came back."""

    def __init__(self, elf: Path) -> None:
        self.board = NativeBoard(elf, seed=0)
        self.board.set_capture(True)
        self.addr = addresses(elf)
        self.seq = 0
        self.still = False  # the pins scenario holds the encoders still
        self.broken_encoder = -1  # ... and may unplug one (0 V)
        self.pending = bytearray()  # captured bytes of the frame under way
        self.state_frames = self.state_gaps = self.nacks = self.faults = 0
        self.last_state_seq = -1
        self.stats: m.Stats | None = None
        # the latency scenario: the request waiting for its reply
        self.rt_seq = -1
        self.rt_ping = True
        self.rt_start = self.rt_last_in = 0
        self.rt: dict[str, list[int]] = {"ping": [], "targets": []}
        self.seg: dict[str, list[int]] = {"in": [], "notice": [], "reply": [], "out": []}

    # -- the encoders ----------------------------------------------------------------------
    def angle(self, finger: int, t: float) -> float:
        if self.still:
            return 0.0
        # Each finger sweeps +-0.4 rad at 1.3 Hz, phase-shifted: the PIDs always have work.
        return 0.4 * math.sin(2 * math.pi * 1.3 * t + finger)

    def set_encoders(self) -> None:
        """AS5600 analog: 10 % of 5 V at 0, 90 % at one turn; straight finger mid-band."""
        t = self.board.cycle / CPU_HZ
        for ch in range(5):
            turn = ((self.angle(ch, t) + math.pi) / (2 * math.pi)) % 1.0
            volts = 5.0 * (0.1 + 0.8 * turn)
            self.board.adc_volts[ch] = 0.0 if ch == self.broken_encoder else volts

    # -- the line ----------------------------------------------------------------------------
    def send(self, msg: m.Message) -> bytes:
        self.seq = (self.seq + 1) & 0x7F
        frame = encode_frame(self.seq, msg.ID, msg.encode())
        self.board.uart_write(frame)
        return frame

    def targets(self, t: float) -> m.SetTargets:
        raw = [lround(self.angle(f, t + 0.05) * 1e6) for f in range(5)]
        return m.SetTargets(
            kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=tuple(v * 1e-6 for v in raw)
        )

    def run_to(self, end: int) -> None:
        """Run up to cycle ``end`` (an instruction's cycles past), the encoders following."""
        while self.board.cycle < end:
            self.set_encoders()
            if self.board.run_to(min(end, self.board.cycle + CHUNK)) != 0:
                sys.exit(f"tick_bench: the simulated CPU stopped\n{self.board.log()}")
            self.take_output()

    def run_until(self, t_end: float) -> None:
        self.run_to(math.ceil(t_end * CPU_HZ))  # up, so that it always advances

    def take_output(self) -> None:
        data = self.board.uart_read()
        if not data:
            return
        times = iter(self.board.uart_frames())
        *complete, rest = (bytes(self.pending) + data).split(b"\x00")
        self.pending = bytearray(rest)
        for part in complete:
            start, end = next(times)
            for ev in decode_stream(part + b"\x00"):
                if isinstance(ev, Frame):
                    self.on_frame(ev, start, end)

    def on_frame(self, f: Frame, start: int, end: int) -> None:
        if self.rt_seq >= 0 and f.seq == self.rt_seq:
            self.rt["ping" if self.rt_ping else "targets"].append(end - self.rt_start)
            self.rt_seq = -1
            dispatched = self.board.profile(1 + DISPATCH)["last_entry"]
            if dispatched > self.rt_last_in:
                in_end = self.rt_last_in + self.frame_cycles
                self.seg["in"].append(in_end - self.rt_start)
                self.seg["notice"].append(dispatched - in_end)
                self.seg["reply"].append(start - dispatched)
                self.seg["out"].append(end - start)
        if f.msg_id == m.State.ID and f.seq & m.BOARD_SEQ_FLAG:
            self.state_frames += 1
            expected = m.BOARD_SEQ_FLAG | ((self.last_state_seq + 1) & (m.BOARD_SEQ_FLAG - 1))
            if self.last_state_seq >= 0 and f.seq != expected:
                self.state_gaps += 1
            self.last_state_seq = f.seq
        elif f.msg_id == m.Nack.ID:
            self.nacks += 1
        elif f.msg_id == m.Fault.ID:
            self.faults += 1
        elif f.msg_id == m.Stats.ID:
            self.stats = m.Stats.decode(f.body)

    @property
    def frame_cycles(self) -> int:
        return self.board.stats()["frame_cycles"]

    # -- the scenarios -----------------------------------------------------------------------
    def start(self, rate_hz: int) -> None:
        """Boot, then every finger into closed loop and the stream on."""
        self.run_until(0.1)
        self.send(m.Heartbeat())
        self.send(self.targets(0.1))
        self.send(modes(m.ControlMode.POSITION, 0.0))
        self.send(m.SetTelemetry(rate_hz=rate_hz))
        self.run_until(0.3)

    def measure(self, scenario: str, seconds: float) -> dict:
        b = self.board
        b.profile_function_slot(TICK, self.addr["tick"])
        b.profile_function_slot(LOOP, self.addr["loop"])
        b.profile_function_slot(DISPATCH, self.addr["dispatch"])
        b.profile_vector(TICK_VECTOR)
        b.profile_vector_requires(TICK)  # the timer interrupts that ran a tick
        self.start(1000 if scenario in ("moves", "latency", "heavy") else 500)
        self.send(m.ResetStats())
        self.run_until(0.31)
        b.profile_clear()
        b.rx_timing(clear=True)
        histogram = os.environ.get("UTRF_PC_PROFILE")
        hist_of = os.environ.get("UTRF_PC_PROFILE_OF", "tick")
        if histogram:
            b.pc_histogram({"tick": TICK, "loop": LOOP, "dispatch": DISPATCH}.get(hist_of, -1))
        sleep0, cycles0 = b.stats()["sleep_cycles"], b.cycle
        frames0, gaps0 = self.state_frames, self.state_gaps
        t0 = b.cycle / CPU_HZ
        t_end = t0 + seconds
        next_send = t0
        move_id = 0
        gap_phase = 0.0
        while b.cycle / CPU_HZ < t_end:
            t = b.cycle / CPU_HZ
            if scenario == "stress":
                if b.uart_pending() < 64:
                    self.send(self.targets(t))
                self.run_until(t + 0.0005)
            elif scenario == "moves":
                # A move of all five fingers every 0.4 s (0.3 s paths, ends alternating);
                # set_targets at 100 Hz in between would end them: heartbeats at 20 Hz instead.
                if t >= next_send:
                    if lround((next_send - t0) / 0.05 + 40e-6) % 8 == 0:
                        move_id += 1
                        v = 0.6 if move_id & 1 else -0.3
                        self.send(
                            m.Move(
                                move_id=move_id,
                                kind=m.TargetKind.JOINT2_ANGLE,
                                mask=ALL,
                                value=(v,) * 5,
                                duration=(0.3,) * 5,
                            )
                        )
                    else:
                        self.send(m.Heartbeat())
                    next_send += 0.05 + 40e-6
                self.run_until(min(next_send, t + 0.0005))
            elif scenario == "latency":
                # One request at a time, ping and set_targets in turn, each 0.5-3 ms after the
                # last reply (the run stops within a byte's time of its 0x00): the gap's step
                # is irrational, so the requests sample every phase of the tick and of the
                # stream evenly (a fixed gap would lock onto one phase).
                self.rt_ping = len(self.rt["ping"]) == len(self.rt["targets"])
                frame = self.send(m.Ping(token=0) if self.rt_ping else self.targets(t))
                self.rt_seq = self.seq
                self.rt_start = b.cycle + 1  # the line is idle: its first byte starts now
                self.rt_last_in = self.rt_start + (len(frame) - 1) * self.frame_cycles
                end = math.ceil(t_end * CPU_HZ)
                while self.rt_seq >= 0 and b.cycle < end:
                    self.set_encoders()
                    if b.run_plant_until(min(end, b.cycle + CHUNK), self.frame_cycles, 0):
                        sys.exit(f"tick_bench: the simulated CPU stopped\n{b.log()}")
                    self.take_output()
                gap_phase = math.fmod(gap_phase + 0.6180339887, 1.0)
                self.run_until(b.cycle / CPU_HZ + 0.0005 + 0.0025 * gap_phase)
            elif scenario == "heavy":
                if b.uart_pending() < 64:
                    move_id += 1
                    self.send(self.heavy_request(t, t >= next_send, move_id))
                    if t >= next_send:
                        next_send += 0.5
                self.run_until(t + 0.0005)
            elif scenario == "silent":
                self.run_until(t + 0.0005)
            else:
                if t >= next_send:
                    if scenario == "typical":
                        self.send(self.targets(t))
                        next_send += 0.005 + 4e-6  # the phase drifts 0.8 ms a second
                    else:
                        self.send(m.Heartbeat())
                        next_send += 0.05 + 40e-6  # 0.8 ms a second
                # Up to the next frame's time exactly: it starts then, at its own phase.
                self.run_until(min(next_send, t + 0.0005))
        if histogram:
            write_histogram(Path(histogram), b.pc_histogram_get(), f"{hist_of}, {scenario} row")
            b.pc_histogram(None)
        slept = b.stats()["sleep_cycles"] - sleep0
        rx = b.rx_timing()
        result = self.figures(scenario, seconds, b.cycle - cycles0, slept)
        result.update(
            rx_reads=rx["reads"],
            rx_wait_worst_cycles=rx["worst"],
            rx_wait_worst_at_s=round(rx["worst_at"] / CPU_HZ, 6),
            rx_wait_mean_cycles=round(rx["total"] / rx["reads"], 1) if rx["reads"] else 0.0,
            rx_waits_over_a_frame=rx["late"],
            rx_bytes_lost=rx["overruns"],
        )
        result["state_frames"] = self.state_frames - frames0
        result["state_seq_gaps"] = self.state_gaps - gaps0
        # Let the board work off what it has received, then ask for its counters. A lone 0x00
        # first ends whatever partial frame the board holds.
        self.rt_seq = -1
        self.run_until(b.cycle / CPU_HZ + 0.05)
        b.uart_write(b"\x00")
        self.send(m.GetStats())
        self.run_until(b.cycle / CPU_HZ + 0.02)
        if self.stats is None:
            sys.exit("tick_bench: no stats reply")
        s = self.stats
        result.update(
            ticks=s.ticks,
            tick_overruns=s.tick_overruns,
            tick_worst_us=lround(s.tick_worst * 1e6),
            tick_mean_us=lround(s.tick_mean * 1e6),
            rx_frames=s.rx_frames,
            rx_crc_errors=s.rx_crc_errors,
            rx_framing_errors=s.rx_framing_errors,
            rx_overruns=s.rx_overruns,
            uart_overruns=s.uart_overruns,
            uart_frame_errors=s.uart_frame_errors,
            nacks=s.nacks,
            tx_dropped=s.tx_dropped,
            fault_frames=self.faults,
        )
        return result

    def heavy_request(self, t: float, save: bool, k: int) -> m.Message:
        """The heavy row's next request: a save_config when due, else a five-finger move,
        ping, get_state, get_stats and heartbeat in turn."""
        if save:
            return m.SaveConfig()
        kind = k % 5
        if kind == 0:
            v = 0.5 if (k // 5) & 1 else -0.3
            return m.Move(
                move_id=(k // 5) & 0xFF,
                kind=m.TargetKind.JOINT2_ANGLE,
                mask=ALL,
                value=(v,) * 5,
                duration=(0.2,) * 5,
            )
        if kind == 1:
            return m.Ping(token=k & 0xFFFF)
        if kind == 2:
            return m.GetState()
        if kind == 3:
            return m.GetStats()
        return m.Heartbeat()

    def last_rt(self) -> int:
        return self.rt["ping" if self.rt_ping else "targets"][-1]

    def figures(self, scenario: str, seconds: float, cycles: int, slept: int) -> dict:
        b = self.board
        tick, loop, isr = b.profile(1 + TICK), b.profile(1 + LOOP), b.profile(0)
        n = tick["count"]
        out: dict = {
            "scenario": scenario,
            "seconds": seconds,
            "sim_ticks": n,
            "sim_tick_worst_cycles": tick["worst_incl"],
            "sim_tick_mean_cycles": round(tick["total_incl"] / n, 1) if n else 0.0,
            "sim_own_worst_cycles": tick["worst"],
            "sim_own_mean_cycles": round(tick["total"] / n, 1) if n else 0.0,
            "sim_nested_worst_cycles": tick["nested_worst"],
            "sim_nested_mean_cycles": round((tick["total_incl"] - tick["total"]) / n, 1)
            if n
            else 0.0,
            "sim_nested_interrupts": tick["nested"],
            "sim_isr_mean_cycles": round(isr["total_incl"] / isr["count"], 1)
            if isr["count"]
            else 0.0,
            "sim_isr_worst_cycles": isr["worst_incl"],
            "sim_isr_ticks": isr["count"],
            "loop_passes": loop["intervals"],
            "loop_worst_cycles": loop["period_worst"],
            "loop_worst_at_s": round(loop["period_worst_at"] / CPU_HZ, 6),
            "asleep": round(slept / cycles, 4),
        }
        if scenario == "latency":
            for name, key in (("ping", "ping"), ("targets", "targets")):
                v = self.rt[key]
                out[f"{name}_n"] = len(v)
                for q, label in ((0.5, "median"), (0.99, "p99"), (1.0, "max")):
                    out[f"{name}_{label}_us"] = percentile_us(v, q)
            for k, v in self.seg.items():
                if v:
                    out[f"seg_{k}_median_us"] = percentile_us(v, 0.5)
                    out[f"seg_{k}_p99_us"] = percentile_us(v, 0.99)
        return out

    # -- pins and tickdead -------------------------------------------------------------------
    def pins(self) -> dict:
        self.still = True
        self.run_until(0.05)
        out: dict = {"boot": self.board.pin_registers()}
        t = 0.05
        self.send(m.Heartbeat())
        # 80 ms a phase: the default slew limit (20 /s) takes the duty there within 50 ms.
        steps = (
            ("duty_plus", m.ControlMode.DUTY, 0.5, 0.08),
            ("duty_minus", m.ControlMode.DUTY, -0.5, 0.08),
            ("brake", m.ControlMode.BRAKE, 0.0, 0.02),
            ("coast", m.ControlMode.COAST, 0.0, 0.02),
        )
        for label, mode, duty, dt in steps:
            self.send(modes(mode, duty))
            t += dt
            self.run_until(t)
            out[label] = self.board.pin_registers()
        self.send(modes(m.ControlMode.DUTY, 0.5))
        t += 0.08
        self.run_until(t)
        self.broken_encoder = 2  # finger 2's encoder unplugged: its driver goes off
        t += 0.003
        self.run_until(t)
        out["encoder_fault"] = self.board.pin_registers()
        tccr2a, tccr2b, _, ocr2a = self.board.read_data(0xB0, 4)
        out["timer2"] = {
            "tccr2a": tccr2a,
            "tccr2b": tccr2b,
            "ocr2a": ocr2a,
            "timsk2": self.board.read_data(0x70, 1)[0],
        }
        out["ubrr0"] = int.from_bytes(self.board.read_data(0xC4, 2), "little")
        out["ucsr0a"] = self.board.read_data(0xC0, 1)[0]
        return out

    def tickdead(self, phase: float) -> dict:
        """The tick-alive rule, to the cycle: at 0.3 s + ``phase`` timer 2's clock stops
        (TCCR2B's clock select cleared, through the timer's own register hook, as the
        emulator's stop_tick_timer does); the time from the last tick's entry (and from the
        stop) until every STBY pin is low."""
        b = self.board
        b.profile_function_slot(TICK, self.addr["tick"])
        self.start(500)
        self.run_until(0.3 + phase)
        stop = b.cycle
        b.write_io(0xB1, b.read_data(0xB1, 1)[0] & ~0x07)
        last_tick = b.profile(1 + TICK)["last_entry"]
        while b.cycle < stop + CPU_HZ // 20:
            self.run_to(b.cycle + 1)
            if not any(f["stby"] for f in b.pin_registers()):
                return {
                    "scenario": "tickdead",
                    "from_stop_ms": round((b.cycle - stop) / CPU_HZ * 1e3, 4),
                    "from_last_tick_ms": round((b.cycle - last_tick) / CPU_HZ * 1e3, 4),
                }
        sys.exit("tick_bench: the motors stayed on 50 ms after the tick stopped")


def write_histogram(path: Path, cycles: Iterable[int], what: str) -> None:
    lines = [f"# byte address, cycles ({what})"]
    lines += [f"{2 * word:x} {int(c)}" for word, c in enumerate(cycles) if c]
    path.write_text("\n".join(lines) + "\n")


def modes(mode: m.ControlMode, duty: float) -> m.SetMode:
    return m.SetMode(mask=ALL, mode=(mode,) * 5, duty=(duty,) * 5, effort=(0.0,) * 5)


def percentile_us(values: list[int], q: float) -> float:
    """The value at rank round(q (n - 1)) of the sorted cycles, in µs (0 with none)."""
    if not values:
        return 0.0
    v = sorted(values)
    i = min(len(v) - 1, math.floor(q * (len(v) - 1) + 0.5))
    return round(v[i] / CPU_HZ * 1e6, 1)


def run(elf: Path, scenario: str, seconds: float) -> dict:
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; known: {', '.join(SCENARIOS)}")
    bench = Bench(elf)
    try:
        if scenario == "pins":
            return bench.pins()
        if scenario == "tickdead":
            return bench.tickdead(seconds)
        return bench.measure(scenario, seconds)
    finally:
        bench.board.close()


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 3 or args[1] not in SCENARIOS:
        print(f"usage: tick_bench <elf> {'|'.join(SCENARIOS)} <seconds>", file=sys.stderr)
        return 2
    print(json.dumps(run(Path(args[0]), args[1], float(args[2]))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
