"""The emulator's public fault-injection API for the board itself (a slow tick, a stopped
tick timer, a stopped ADC) and the line faults added for the noisy-line tests (duplicated
bytes, bursts), each seen as the real firmware sees it, in simulated time."""

from __future__ import annotations

from pathlib import Path

import pytest
from emu_helpers import QUIET, LinkClient, ready_client

from utrf.emulator import EmulatedBoard, EmulatorError
from utrf.protocol import messages as m

ALL = 0b11111
TICK_S = 1e-3


@pytest.fixture
def client(board: EmulatedBoard) -> LinkClient:
    return ready_client(board)[0]


def drive_all(client: LinkClient, duty: float = 0.3) -> None:
    reply = client.request(
        m.SetMode(mask=ALL, mode=(m.ControlMode.DUTY,) * 5, duty=(duty,) * 5, effort=(0.0,) * 5)
    )
    assert isinstance(reply, m.Ack), reply
    client.run(0.02)
    client.stream.clear()


def motors_on(board: EmulatedBoard) -> bool:
    return bool(board.pins.stby.any())


def test_a_slow_tick_latches_overrun_and_stops_the_motors(
    board: EmulatedBoard, client: LinkClient
) -> None:
    drive_all(client)
    assert motors_on(board)
    board.slow_tick(1.5 * TICK_S, count=1)
    t0 = board.sim_time
    assert board.run_until(lambda b: not motors_on(b), timeout=0.05)
    # the slow tick itself, then the tick that finds the overrun
    assert board.sim_time - t0 <= 1.5 * TICK_S + 2 * TICK_S + board.exchange_period
    assert board.stats["stalls"] == 1
    assert board.slow_ticks_left == 0
    status = client.request(m.GetStatus())
    assert all(m.FaultBits.OVERRUN in f for f in status.faults)
    assert client.request(m.GetStats()).tick_overruns >= 1


def test_a_tick_shorter_than_its_period_is_no_overrun(
    board: EmulatedBoard, client: LinkClient
) -> None:
    drive_all(client)
    board.slow_tick(0.3 * TICK_S, count=None)  # every tick, but within its period
    client.run(0.05)
    assert board.slow_ticks_left is None
    assert board.stats["stalls"] >= 45
    assert not any(client.request(m.GetStatus()).faults)
    assert motors_on(board)
    board.slow_tick(0.0)
    assert board.slow_ticks_left == 0


def test_a_stopped_tick_timer_stops_the_motors_and_the_watchdog_resets(
    board: EmulatedBoard, client: LinkClient
) -> None:
    drive_all(client)
    resets = board.stats["resets"]
    board.stop_tick_timer()
    t0 = board.sim_time
    assert board.run_until(lambda b: not motors_on(b), timeout=0.1)
    off = board.sim_time - t0
    assert 0.018 <= off <= 0.020 + 2 * TICK_S  # the tick-alive rule: 20 ms
    assert board.run_until(lambda b: b.stats["resets"] > resets, timeout=0.3)
    assert board.reset_cause == "watchdog"
    boot = client.wait_boot()
    assert boot is not None
    client.run(0.05)  # the firmware's set-up started the timer again: ticks run
    assert client.request(m.GetStats()).ticks > 0


def test_a_stopped_adc_goes_stale_and_restarts(board: EmulatedBoard, client: LinkClient) -> None:
    drive_all(client)
    board.stop_adc()
    t0 = board.sim_time
    assert board.run_until(lambda b: not motors_on(b), timeout=0.05)
    assert board.sim_time - t0 <= 5 * TICK_S  # stale after 3 ticks, off in that tick
    status = client.request(m.GetStatus())
    assert all(m.FaultBits.ENCODER_RANGE in f for f in status.faults)
    conversions = board.stats["adc_conversions"]
    client.run(0.02)
    assert board.stats["adc_conversions"] == conversions  # nothing samples any more
    board.restart_adc()
    client.run(0.02)
    assert board.stats["adc_conversions"] > conversions + 50
    assert isinstance(client.request(m.ClearFaults(mask=ALL)), m.Ack)
    client.run(0.01)
    assert not any(client.request(m.GetStatus()).faults)


def test_duplicated_and_burst_bytes_are_counted_and_seeded(firmware_elf: Path) -> None:
    def run(seed: int) -> tuple[dict[str, int], bytes]:
        with EmulatedBoard(firmware_elf, realtime=False, seed=seed, plant_params=QUIET) as b:
            c = LinkClient(b)
            c.wait_boot()
            c.request(m.SetTelemetry(rate_hz=500))
            b.set_line_faults("to_host", duplicate=0.01, burst=0.001, burst_length=(8, 32))
            b.run_for(0.2)
            return b.stats, b.read()

    stats, out = run(7)
    assert stats["tx_duplicated"] > 0
    assert stats["tx_burst_bytes"] >= 8
    assert stats["rx_duplicated"] == stats["rx_burst_bytes"] == 0
    assert run(7)[1] == out  # the same faults for the same seed
    assert run(8)[1] != out


def test_duplicated_bytes_to_the_board_reach_it_twice(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=False, plant_params=QUIET) as b:
        c = LinkClient(b)
        c.wait_boot()
        before = b.stats
        b.set_line_faults("to_board", duplicate=0.2)
        b.write(bytes(range(1, 101)))  # not frames: the decoder drops them
        b.run_for(0.01)
        after = b.stats
        dup = after["rx_duplicated"] - before["rx_duplicated"]
        assert dup > 5
        assert after["rx_uart_bytes"] - before["rx_uart_bytes"] == 100 + dup


def test_bad_fault_arguments_are_refused_by_name(board: EmulatedBoard) -> None:
    with pytest.raises(EmulatorError, match="duplicate"):
        board.set_line_faults(duplicate=1.0)
    with pytest.raises(EmulatorError, match="burst_length"):
        board.set_line_faults(burst=0.01, burst_length=(0, 4))
    with pytest.raises(EmulatorError, match="extra_s"):
        board.slow_tick(-1e-3)
    with pytest.raises(EmulatorError, match="count"):
        board.slow_tick(1e-3, count=-2)
    with pytest.raises(EmulatorError, match="unknown vector"):
        board.stall_interrupt("TIMER9", 1e-3)
