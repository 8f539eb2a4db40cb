"""The twin's lockstep on one thread or two (``utrf.emulator.twin_threads`` chooses): the
same results to the bit, the plant's own clock in exact exchange periods, and the choice."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from utrf.emulator import EmulatedBoard, EmulatorError, twin_threads
from utrf.emulator._native import F_CPU_HZ
from utrf.hand.simlink import SimLink
from utrf.protocol import messages as m

ALL = 0b11111


def _moving_hold(board: EmulatedBoard) -> tuple[list[bytes], np.ndarray, float]:
    """Fingers driven by the firmware through MuJoCo, a hit and a blocked finger on the way:
    the telemetry's bytes, MuJoCo's state and the board's time."""
    frames: list[bytes] = []
    link = SimLink(board, on_telemetry=lambda t: frames.append(repr(t.message).encode()))
    link.handshake()
    link.request(m.ClearFaults(mask=ALL))
    link.request(m.SetTelemetry(rate_hz=200))
    targets = (0.3, 0.6, 0.9, 0.5, 0.2)
    link.request(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=ALL, value=targets))
    link.request(m.SetMode(mask=ALL, mode=(m.ControlMode.POSITION,) * 5, duty=(0.0,) * 5,
                           effort=(0.0,) * 5))  # fmt: skip
    link.sleep(0.25)
    board.hit_tip(1, (0.0, -0.2))
    board.block_finger(3, 0.3, direction="flexion")
    link.sleep(0.25)
    board.run_for(0.0123)  # ends between two exchanges
    link.sleep(0.05)
    t0 = link.now()  # the board running ahead of a client working beside it
    tips = list(link.sleep_each((t0 + 0.01 * k for k in range(1, 11)), lambda: board.tip[1]))
    frames += [np.asarray(tips).tobytes()]
    d = board.plant.data
    return frames, np.concatenate([d.qpos, d.qvel, board.motor_current.ravel()]), board.sim_time


def test_one_and_two_threads_give_the_same_run_to_the_bit(firmware_elf: Path) -> None:
    runs = []
    # two threads with the plant's thread spinning, and sleeping at once while a client works
    for threads, spin in ((1, True), (2, True), (2, False)):
        with EmulatedBoard(firmware_elf, realtime=False, seed=5, plant_threads=threads) as b:
            assert b.plant_threads == threads
            b._native.set_plant_spin(spin)
            runs.append(_moving_hold(b))
    # two threads on one core: the hand-over costs the MCU's thread more than the step, so it
    # steps the plant itself for stretches (lockstep.c), and the run is still the same
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cores)})  # this thread, and the threads it starts
    try:
        with EmulatedBoard(firmware_elf, realtime=False, seed=5, plant_threads=2) as b:
            runs.append(_moving_hold(b))
            inline = b._native.plant_inline_periods
    finally:
        os.sched_setaffinity(0, cores)
    assert 0 < inline < b.sim_time * 1000
    (f1, s1, t1) = runs[0]
    for f2, s2, t2 in runs[1:]:
        assert len(f1) > 50 and f1 == f2
        assert t1 == t2 and np.array_equal(s1, s2)
    assert np.ptp(s1[:10]) > 0.1  # the fingers moved: the comparison compared something


def test_on_one_core_the_hand_over_backs_off(firmware_elf: Path) -> None:
    """Two threads on one core: each try of the plant's thread wakes it and waits for the one
    core, so the stretches the MCU's thread steps itself double while the tries keep failing
    (lockstep.c): 4 s simulated, nearly every period inline (32-period stretches alone would
    leave 60-90 % of them inline)."""
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cores)})
    try:
        with EmulatedBoard(firmware_elf, realtime=False, seed=5, plant_threads=2) as b:
            b.run_for(4.0)
            periods = round(b.sim_time / b.exchange_period)
            inline = b._native.plant_inline_periods
    finally:
        os.sched_setaffinity(0, cores)
    assert inline > 0.95 * periods
    assert inline < periods  # the thread was tried


def test_the_plant_steps_exact_periods_on_its_own_clock(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False, plant_threads=2) as b:
        native = b._native
        period = round(b.exchange_period * F_CPU_HZ)
        b.run_for(0.5)
        b.run_for(0.0003)  # less than a period: the plant steps it, MuJoCo too
        b.run_until_output(0.02)
        assert 0 <= native.cycle - native.plant_cycle < 64  # the MCU's overshoot, carried
        # MuJoCo's clock is the plant's: exact periods and the partial one, no more
        assert b.plant.data.time == pytest.approx(native.plant_cycle / F_CPU_HZ, abs=1e-12)
        assert b.plant.model.opt.timestep == b.exchange_period / 2  # set back after it
        start = native.plant_cycle
        b.run_until_output(0.005, byte=256 - 1)  # whole exchanges on the plant's clock
        assert (native.plant_cycle - start) % period == 0 and native.plant_cycle > start


def test_a_board_run_alone_takes_the_plant_up_from_where_it_is(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False) as b:
        b.run_for(0.01)
        t = b.plant.data.time
        b._native.run_to(b._native.cycle + 8000)  # the MCU alone: the plant skips it
        b._cycle = b._native.cycle  # (the board's own calls keep this)
        assert b._native.plant_cycle == b._native.cycle
        b.run_for(0.001)
        assert b.plant.data.time == pytest.approx(t + 0.001, abs=1e-12)


def test_a_forked_child_steps_on_a_thread_of_its_own(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False, plant_threads=2) as b:
        b.run_for(0.01)
        pid = os.fork()
        if pid == 0:  # the parent's plant thread is not in the child
            try:
                b.run_for(0.01)
                os._exit(0 if b.plant.data.time > 0.0195 else 3)
            finally:
                os._exit(4)
        deadline = time.monotonic() + 60
        while (done := os.waitpid(pid, os.WNOHANG))[0] == 0:
            if time.monotonic() > deadline:
                os.kill(pid, 9)
                pytest.fail("the forked child hung waiting for a plant thread it does not have")
            time.sleep(0.05)
        assert os.waitstatus_to_exitcode(done[1]) == 0
        b.run_for(0.01)  # the parent's thread still serves the parent
        assert b.plant.data.time == pytest.approx(0.02, abs=1e-3)


def test_the_choice_argument_environment_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(twin_threads.ENV, raising=False)
    monkeypatch.setattr(twin_threads, "usable_cores", lambda: 3)
    assert twin_threads.plant_threads() == 2
    assert twin_threads.plant_threads(paced=True) == 1  # paced to the wall clock: time to spare
    assert twin_threads.plant_threads(1) == 1
    monkeypatch.setattr(twin_threads, "usable_cores", lambda: 2)  # the MCU's and the plant's
    assert twin_threads.plant_threads() == 2
    monkeypatch.setattr(twin_threads, "usable_cores", lambda: 1)
    assert twin_threads.plant_threads() == 1
    assert twin_threads.plant_threads(2) == 2  # asked for: given
    monkeypatch.setenv(twin_threads.ENV, "2")
    assert twin_threads.plant_threads() == 2
    assert twin_threads.plant_threads(1) == 1  # the argument wins over the environment
    monkeypatch.setenv(twin_threads.ENV, "two")
    with pytest.raises(EmulatorError, match="UTRF_TWIN_THREADS must be 1 or 2, got 'two'"):
        twin_threads.plant_threads()
    monkeypatch.setenv(twin_threads.ENV, "3")
    with pytest.raises(EmulatorError, match="UTRF_TWIN_THREADS must be 1 or 2, got 3"):
        twin_threads.plant_threads()
    with pytest.raises(EmulatorError, match="plant_threads must be 1 or 2, got 0"):
        twin_threads.plant_threads(0)


def test_the_plant_thread_spins_only_with_a_core_for_each(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(twin_threads, "usable_cores", lambda: 3)
    assert twin_threads.plant_spins()
    monkeypatch.setattr(twin_threads, "usable_cores", lambda: 2)  # MCU, plant, client on two
    assert not twin_threads.plant_spins()


def test_a_client_beside_the_board_has_the_plant_stepped_on_the_mcus_thread(
    firmware_elf: Path,
) -> None:
    """Where the plant's thread sleeps at once while a client works beside the board (fewer
    than three cores), the MCU's thread steps every period of a run ahead itself until the
    client joins; a run on the caller's own thread hands its periods over."""
    with EmulatedBoard(firmware_elf, realtime=False, plant_threads=2) as b:
        native = b._native
        native.set_plant_spin(False)
        b.run_for(0.02)  # the caller's own run: no client beside, the plant's thread steps
        handed = 20 - native.plant_inline_periods
        assert handed > 0
        before = native.plant_inline_periods
        b.run_ahead(0.02)  # 20 periods: a few ms of wall time, not joined for 2 s
        time.sleep(2.0)
        run = b.run_ahead_join()
        assert run.done
        assert native.plant_inline_periods - before == 20
        native.set_plant_spin(True)  # a core for each: the plant's thread steps them
        before = native.plant_inline_periods
        b.run_ahead(0.02)
        time.sleep(2.0)
        b.run_ahead_join()
        assert native.plant_inline_periods - before < 20
