"""The watchdog bounds a hard hang: the real firmware on the emulated board.

A hang with interrupts off stops everything the firmware does: the PWM hardware keeps each
motor at its last duty, STBY high, until the watchdog resets the board. Its period (30 ms,
hal/avr) is that window; it was 120 ms (128 ms measured), in which a finger at half duty moved
0.146 rad (issue 13: 0.155 rad). firmware/README.md quotes these runs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand

INDEX = 1


def motors_off(board: EmulatedBoard, finger: int) -> bool:
    pins = board.pins
    return (not pins.stby[finger]) and bool(np.all(pins.duty[finger] == 0))


def hang_driving(board: EmulatedBoard, hand: Hand, interrupts: bool) -> tuple[float, float]:
    """Index at half duty, moving; the firmware hangs. (hang time, angle then)."""
    hand.set_mode("duty", "index", duty=0.5)
    hand.clock.sleep(0.2)
    assert not motors_off(board, INDEX)
    board.hang_firmware(interrupts=interrupts)
    return board.sim_time, float(board.theta2[INDEX])


def test_a_hang_with_interrupts_off_is_cut_short_by_the_watchdog(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False, seed=1) as board:
        hand = Hand.emulated(board, on_close="coast")
        hung_at, theta = hang_driving(board, hand, interrupts=False)
        assert board.run_until(lambda b: b.reset_cause == "watchdog", timeout=0.3)
        window = board.sim_time - hung_at
        moved = float(board.theta2[INDEX]) - theta
        assert window <= 0.034  # WDTO_30MS: 4K cycles of 128 kHz = 32 ms (and the last feed)
        assert abs(moved) < 0.05  # 0.0365 rad measured (0.146 in the 128 ms window before)
        assert all(motors_off(board, f) for f in range(5))  # the reset board drives nothing


def test_a_hung_loop_is_stopped_by_the_firmware_before_the_watchdog(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False, seed=1) as board:
        hand = Hand.emulated(board, on_close="coast")
        hung_at, _ = hang_driving(board, hand, interrupts=True)
        # The tick still runs: the loop-alive rule (20 ticks) turns the motors off and marks
        # the hang, then the watchdog resets the board.
        assert board.run_until(lambda b: all(motors_off(b, f) for f in range(5)), timeout=0.1)
        assert board.sim_time - hung_at < 0.025
        assert board.reset_cause != "watchdog"
        assert board.run_until(lambda b: b.reset_cause == "watchdog", timeout=0.1)
        assert board.sim_time - hung_at <= 0.034
