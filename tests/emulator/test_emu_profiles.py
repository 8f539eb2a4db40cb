"""The harness's cycle profiles and output frame log, at its C interface (what
tools/tick_bench.py and `make bench-firmware` measure the firmware's tick with): several
function slots at once, an interrupt's RETI counted as its own, the vector's calls that ran a
function, the clear that keeps calls under way, the interrupts nested in a call, and the wire
times of each frame the board sends."""

from __future__ import annotations

import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from utrf.emulator._native import NativeBoard
from utrf.protocol import messages as m
from utrf.protocol.framing import encode_frame

MS = 16_000  # cycles
TICK_VECTOR = 13  # TIMER2_COMPA


@pytest.fixture
def native(fixture_elf: Path) -> Iterator[NativeBoard]:
    b = NativeBoard(fixture_elf, seed=0)
    b.set_capture(True)
    b.run_to(10 * MS)  # booted
    b.uart_write(b"k 1000\n")  # the tick's ISR busy-waits 4,000 cycles
    b.run_to(b.cycle + 10 * MS)
    yield b
    b.close()


def test_one_interrupt_seen_by_its_vector_and_as_a_function(native: NativeBoard) -> None:
    """The vector's call runs from the jump to its vector to the end of its RETI; the handler
    as a function from its first instruction (after the vector table's 3-cycle JMP) to the
    same end: exactly 3 cycles apart, call by call. (simavr signals the return before it adds
    the RETI's 5 cycles: ended at the signal, the vector's calls would be 2 cycles shorter than
    the function's. And the handler's own RETI is not an interrupt nested in it.)"""
    handler = native.symbol("__vector_13")
    assert handler is not None
    native.profile_vector(TICK_VECTOR)
    native.profile_function_slot(0, handler)
    native.profile_function_slot(2, handler)
    native.profile_vector_requires(0)
    native.run_to(native.cycle + 100 * MS)
    vec, fn, same = native.profile(0), native.profile(1), native.profile(3)
    assert fn == same  # two slots on one function agree
    assert vec["count"] == fn["count"] >= 99
    assert vec["total_incl"] - fn["total_incl"] == 3 * fn["count"]
    assert vec["worst_incl"] - fn["worst_incl"] == 3 and vec["best"] - fn["best"] == 3
    assert fn["nested"] == 0 and fn["total"] == fn["total_incl"]  # nothing nests in it
    assert 4000 < fn["worst"] < 4150
    assert fn["period_worst"] >= fn["period_sum"] / fn["intervals"] > 15_900
    assert fn["last_entry"] - fn["period_worst_at"] >= fn["period_worst"]


def test_a_vector_counts_only_the_calls_that_ran_the_required_function(
    native: NativeBoard,
) -> None:
    main = native.symbol("main")
    assert main is not None
    native.profile_vector(TICK_VECTOR)
    native.profile_function_slot(1, main)  # never returns, never called in the interrupt
    native.profile_vector_requires(1)
    native.run_to(native.cycle + 20 * MS)
    assert native.profile(0)["count"] == 0
    native.profile_vector_requires(-1)
    native.run_to(native.cycle + 20 * MS)
    assert native.profile(0)["count"] >= 19


def test_clear_keeps_the_call_under_way_and_the_last_entry(native: NativeBoard) -> None:
    handler = native.symbol("__vector_13")
    assert handler is not None
    native.profile_function_slot(0, handler)
    native.run_to(native.cycle + 10 * MS)
    # stop inside a call: 1,000 cycles after an entry
    entry = native.profile(1)["last_entry"]
    native.run_to(entry + MS + 1000)
    entry = native.profile(1)["last_entry"]
    assert native.cycle - entry < 4000
    native.profile_clear()
    cleared = native.profile(1)
    assert cleared["count"] == cleared["intervals"] == 0 and cleared["last_entry"] == entry
    native.run_to(native.cycle + 4000)
    after = native.profile(1)
    assert after["count"] == 1 and after["worst"] > 4000  # the whole call, not its remainder


def test_interrupts_nested_in_the_firmware_tick_are_counted_apart(firmware_elf: Path) -> None:
    """The real firmware re-enables interrupts in its tick: the UART's receive interrupt, one a
    byte, nests in it. Each nested call is left out of the tick's own cycles and counted."""
    b = NativeBoard(firmware_elf, seed=0)
    try:
        b.set_capture(True)
        b.run_to(100 * MS)
        tick = next(
            int(a, 16)
            for a, name in (line.split(" ", 1) for line in _symbols(firmware_elf))
            if name == "utrf::app::tick()"
        )
        b.profile_function_slot(0, tick)
        frame = encode_frame(1, m.Heartbeat.ID, m.Heartbeat().encode())
        for _ in range(200):  # heartbeats back to back: the line never rests
            b.uart_write(frame)
        b.run_to(b.cycle + 20 * MS)
        p = b.profile(1)
        assert p["count"] == pytest.approx(20, abs=1)
        assert p["nested"] > 0
        nested = p["total_incl"] - p["total"]
        # each nested receive interrupt costs tens of cycles, none more than a byte's time
        assert 20 * p["nested"] < nested < 160 * p["nested"]
        assert nested / p["count"] <= p["nested_worst"] <= p["worst_incl"] - p["best"]
    finally:
        b.close()


def _symbols(elf: Path) -> list[str]:
    nm = subprocess.run(["avr-nm", "-C", str(elf)], capture_output=True, text=True, check=True)
    return [" ".join((ln.split()[0], ln.split(" ", 2)[2])) for ln in nm.stdout.splitlines()]


def test_the_frame_log_gives_each_frame_its_wire_times(firmware_elf: Path) -> None:
    b = NativeBoard(firmware_elf, seed=0)
    try:
        b.set_capture(True)
        b.run_to(100 * MS)
        b.uart_read()
        b.uart_frames()
        sent = b.cycle
        ping = encode_frame(5, m.Ping.ID, m.Ping(token=7).encode())
        b.uart_write(ping)
        b.run_to(sent + 5 * MS)
        out, frames = b.uart_read(), b.uart_frames()
        assert len(frames) == out.count(0)  # one entry per 0x00
        frame_cycles = b.stats()["frame_cycles"]
        assert frame_cycles == 160  # 8N1 at 1 Mbaud
        pong = out.split(b"\x00")[0] + b"\x00"  # nothing else was asked for
        start, end = frames[0]
        # the pong starts after the ping is in; its bytes take a frame time each, at least
        assert sent + len(ping) * frame_cycles < start < end <= b.cycle
        assert len(pong) * frame_cycles <= end - start < len(pong) * frame_cycles + MS
        b.set_capture(False)  # off: the log is emptied with the capture
        assert b.uart_frames() == []
    finally:
        b.close()


def test_the_pc_histogram_counts_every_cycle_or_a_functions_own(native: NativeBoard) -> None:
    handler = native.symbol("__vector_13")
    assert handler is not None
    native.pc_histogram(-1)  # every instruction: each cycle of the run, at some address
    start = native.cycle
    native.run_to(start + 20 * MS)
    every = native.pc_histogram_get()
    assert int(every.sum()) == native.cycle - start
    native.profile_function_slot(0, handler)
    native.pc_histogram(0)  # the handler's own work only: its calls' cycles, where they went
    native.run_to(native.cycle + 20 * MS)
    own, calls = native.pc_histogram_get(), native.profile(1)
    assert calls["count"] >= 19
    # every completed call's cycles, and those of a call under way at the end
    assert calls["total"] <= int(own.sum()) < calls["total"] + calls["worst"]
    words = np.flatnonzero(own)
    assert words.min() * 2 >= handler  # all in the handler (and the delay loop inlined in it)
    native.pc_histogram(None)
    assert native.pc_histogram_get().size == 0
