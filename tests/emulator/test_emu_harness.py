"""The harness on its own test program (tests/emulator/fixtures/fixture.c), driven in
simulated time: UART timing and flow control, ADC, pins, watchdog, resets, EEPROM, line
faults, determinism, the cycle profiler, a crash."""

from __future__ import annotations

import math
import random
from pathlib import Path

import numpy as np
import pytest
from emu_helpers import QUIET, Console

from utrf.emulator import EmulatedBoard, EmulatorError, PlantParams
from utrf.emulator.board import RESET_FLAGS

# The harness's own tests run at a 250 us exchange (the MuJoCo plant's default is 1 ms, one
# per control tick): their timings are counted in exchanges of that size.
EXCHANGE = 250e-6
FRAME_S = 10e-6  # 8N1 at 1 Mbaud


@pytest.fixture
def board(fixture_elf: Path):
    with EmulatedBoard(
        fixture_elf, realtime=False, plant_params=QUIET, exchange_period=EXCHANGE
    ) as b:
        yield b


@pytest.fixture
def console(board: EmulatedBoard) -> Console:
    c = Console(board)
    assert c.line() == "boot 1"  # power-on: PORF
    return c


def echo_duration(board: EmulatedBoard, console: Console, payload: bytes) -> float:
    """Send "e N" and N bytes; return the simulated time until the last echoed byte."""
    port = console.port
    port.write(f"e {len(payload)}\n".encode() + payload)
    start = board.sim_time
    got = bytearray()
    while len(got) < len(payload) and board.sim_time - start < 1.0:
        board.run_for(20e-6)
        got += port.read(port.in_waiting)
    assert bytes(got) == payload
    return board.sim_time - start


class TestUart:
    def test_output_leaves_at_the_byte_rate(self, fixture_elf: Path) -> None:
        with EmulatedBoard(fixture_elf, realtime=False, exchange_period=20e-6) as board:
            console = Console(board)
            assert console.line() == "boot 1"
            console.port.write(b"z 300\n")
            arrivals = []
            got = bytearray()
            while len(got) < 300 and board.sim_time < 0.1:
                board.run_for(20e-6)
                new = console.port.read(console.port.in_waiting)
                arrivals += [board.sim_time] * len(new)
                got += new
            assert bytes(got) == bytes(i & 0xFF for i in range(300))
            # back to back at 1 Mbaud: 10 µs a byte (simavr alone would take 11)
            assert arrivals[-1] - arrivals[0] == pytest.approx(299 * FRAME_S, abs=40e-6)
            assert board.stats["frame_cycles"] == 160

    def test_round_trip_timing_follows_the_configured_baud(self, fixture_elf: Path) -> None:
        with EmulatedBoard(fixture_elf, realtime=False, exchange_period=20e-6) as board:
            console = Console(board)
            console.line()
            assert console.command("u 7") == "u"  # UBRR0 = 7, U2X: 250 kbaud
            frame = 10 * 8 * 8 / 16e6
            assert board.stats["frame_cycles"] == 10 * 8 * 8
            payload = random.Random(1).randbytes(100)
            elapsed = echo_duration(board, console, payload)
            # the command line and the payload in, the last byte echoed one frame later
            expected = (len(payload) + 6 + 1) * frame
            assert expected <= elapsed < expected + frame

    def test_a_busy_firmware_overruns_the_two_byte_receiver(
        self, board: EmulatedBoard, console: Console
    ) -> None:
        """The receive interrupt is off for 5 ms while 100 bytes arrive: the chip keeps two in
        its FIFO and one in the shift register (nothing starts after the last); the other 97
        are lost (DOR), as on an ATmega2560, where simavr alone would have queued 64."""
        console.port.write(b"x 5\n")
        board.run_for(0.5e-3)  # the command is read: the interrupt is off now
        board.rx_timing(clear=True)
        payload = bytes(range(1, 101))
        console.port.write(payload)
        assert console.line(timeout=0.1) == "x"
        stats, rx = board.stats, board.rx_timing()
        assert stats["rx_uart_bytes"] == stats["rx_host_bytes"] == 104
        assert stats["rx_overruns"] == rx["overruns"] == 97
        # the three kept bytes are read when the interrupt comes back, 5 ms after the first
        assert rx["reads"] == 3
        assert rx["worst"] > 4e-3 * 16e6 and rx["late"] == 3

    def test_bytes_read_in_time_wait_under_a_frame(self, board: EmulatedBoard) -> None:
        """Back-to-back bytes to a firmware that reads them (its echo and timer interrupts in
        between): each is read within two frames of its stop bit, none lost; the wait is timed
        from the end of the stop bit (a read 24 cycles after it), not from the start bit."""
        console = Console(board)
        assert console.line() == "boot 1"
        board.rx_timing(clear=True)
        payload = random.Random(2).randbytes(120)
        assert echo_duration(board, console, payload) > 0
        rx = board.rx_timing()
        assert rx["overruns"] == 0 and rx["reads"] == 120 + len("e 120\n")
        assert 0 < rx["worst"] < 2 * 160
        assert 20 <= rx["total"] / rx["reads"] < 80

    def test_bytes_sent_while_the_receiver_is_off_are_lost(self, board: EmulatedBoard) -> None:
        board.write(b"a\n")  # the fixture has not enabled its receiver yet at t = 0
        board.run_for(0.01)
        assert board.stats["rx_lost_disabled"] == 2
        assert board.read() == b"boot 1\n"


def test_adc_values_reach_the_firmware(board: EmulatedBoard, console: Console) -> None:
    angles = [-1.2, -0.4, 0.0, 0.7, 1.5]
    for finger, theta2 in enumerate(angles):
        board.plant.set_theta2(finger, theta2)
    board.unplug_encoder(4, volts=1.0)
    board.run_for(1e-3)
    volts = board.adc_volts
    assert volts[4] == 1.0
    reading = [int(v) for v in console.command("a").split()[1:]]
    # the datasheet's ideal converter with AVcc = 5 V as the reference: the nearest code
    assert reading[:5] == [ideal_adc(v) for v in volts]
    assert reading[5:] == [0, 0, 0]
    assert reading[0] < reading[1] < reading[2] < reading[3]
    assert board.stats["adc_conversions"] == 8


def ideal_adc(volts: float, vref: float = 5.0) -> int:
    """The ATmega2560 datasheet's ideal 10-bit converter ("ADC Accuracy Definitions"): the
    first transition at 0.5 LSB, the last 1.5 LSB below Vref, so each code reads the inputs
    within half an LSB of code * Vref / 1024."""
    return min(max(math.floor(volts * 1024 / vref + 0.5), 0), 1023)


# (input in LSB of 5 V / 1024, code): the datasheet's transitions, and inputs past either end
TRANSITIONS = [
    (0.0, 0),
    (0.49, 0),
    (0.51, 1),
    (511.49, 511),
    (511.51, 512),
    (1022.49, 1022),
    (1022.51, 1023),
    (1023.99, 1023),
    (1024.0, 1023),
]


def test_the_adc_is_the_datasheets_ideal_converter(board: EmulatedBoard, console: Console) -> None:
    """Each code stands for the inputs within half an LSB of it (a floor would read every
    input half an LSB low: 3.8 mrad of Joint-2 angle). Probed on an unplugged input, whose
    voltage the plant sets exactly."""
    lsb = 5.0 / 1024
    for x, code in TRANSITIONS:
        board.unplug_encoder(2, volts=x * lsb)
        board.run_for(1e-3)
        assert int(console.command("a").split()[3]) == code, f"{x} LSB"


def test_a_conversion_samples_at_its_start(board: EmulatedBoard, console: Console) -> None:
    """The ADC holds the value its conversion started with (104 µs at clk/128)."""
    board.plant.set_theta2(0, 1.0)
    console.port.write(b"a\n")
    # run until the first conversion has started, then move the finger
    while board.stats["adc_conversions"] == 0:
        board.run_for(board.exchange_period)
    started_with = ideal_adc(board.adc_volts[0])
    board.plant.set_theta2(0, -1.0)
    assert int(console.line().split()[1]) == started_with


CHANNELS = [(f, c) for f in range(5) for c in range(2)]


@pytest.mark.parametrize(("finger", "channel"), CHANNELS)
def test_pwm_direction_and_standby_readback(
    board: EmulatedBoard, console: Console, finger: int, channel: int
) -> None:
    assert console.command(f"o {finger} {channel} 199 2") == "o"  # non-inverting
    assert console.command(f"i {finger} {channel} 1 0") == "i"
    assert console.command(f"s {finger} 1") == "s"
    pins = board.pins
    expected = np.zeros((5, 2))
    expected[finger, channel] = 200 / 800  # fast PWM: OCR + 1 of TOP + 1 counts
    np.testing.assert_allclose(pins.duty, expected)
    assert pins.in1.sum() == 1 and pins.in1[finger, channel]
    assert not pins.in2.any()
    assert pins.stby.tolist() == [f == finger for f in range(5)]
    board.run_for(1e-3)
    assert board.drive[finger][channel] == ("forward", 0.25)

    console.command(f"o {finger} {channel} 199 3")  # inverting
    assert board.pins.duty[finger, channel] == pytest.approx(0.75)
    console.command(f"i {finger} {channel} 0 1")
    board.run_for(1e-3)
    assert board.drive[finger][channel] == ("reverse", -0.75)
    console.command(f"o {finger} {channel} 199 0")  # disconnected: the pin is its PORT bit, low
    assert board.pins.duty[finger, channel] == 0.0
    console.command(f"s {finger} 0")
    board.run_for(1e-3)
    assert board.drive[finger][channel] == ("coast", 0.0)


def test_an_interrupt_enabled_with_its_flag_set_runs(
    board: EmulatedBoard, console: Console
) -> None:
    """A compare match while the tick is masked runs the handler as soon as it is unmasked."""
    board.profile_interrupt("TIMER2_COMPA")
    board.run_for(0.01)
    assert board.profile()["interrupt"].worst_latency < 300  # a few instructions
    assert console.command("m") == "m 1"
    assert board.stats["late_interrupts"] == 1
    # masked for 24,000 cycles, a compare match came 8,000 to 24,000 cycles before the unmask
    assert 8000 < board.profile()["interrupt"].worst_latency < 24000


def test_driven_pins_move_the_plant(board: EmulatedBoard, console: Console) -> None:
    console.command("o 2 0 599 2")
    console.command("i 2 0 1 0")
    console.command("s 2 1")
    board.run_for(0.1)
    assert board.theta2[2] > 0.2
    assert board.motor_current[2, 0] > 0.0
    assert np.abs(board.theta2[[0, 1, 3, 4]]).max() == 0.0


class TestResets:
    def test_watchdog_resets_a_firmware_that_stops_feeding_it(
        self, board: EmulatedBoard, console: Console
    ) -> None:
        assert console.command("d") == "d"
        start = board.sim_time
        assert console.line(timeout=0.5) == f"boot {RESET_FLAGS['watchdog']}"
        # WDTO_250MS: 32768 cycles of the 128 kHz watchdog oscillator
        assert 0.25 < board.sim_time - start < 0.27
        assert board.reset_cause == "watchdog"
        assert board.stats["watchdog_resets"] == 1
        assert console.command("b") == "b 8"

    def test_a_watchdog_reset_at_a_runs_end_ends_the_run(self, board: EmulatedBoard) -> None:
        """Asleep, simavr skips to one cycle past the next event: a run ends at its time all
        the same (simavr skipped on past it to the tick, 1 ms), and when the watchdog's reset
        comes due just before a run's end, the reset, which clears every timer, ends the run
        (it ran for ever)."""
        console = Console(board)
        assert console.line() == "boot 1"
        assert console.command("S") == "S"  # asleep, the watchdog no longer fed: 250 ms
        start = board.sim_time
        while board.stats["resets"] == 0 and board.sim_time - start < 0.3:
            before = board.sim_time
            board.run_for(50e-6)  # run ends everywhere between two of the tick's wake-ups
            assert board.sim_time - before < 60e-6
        assert board.stats["resets"] == 1 and board.reset_cause == "watchdog"
        assert console.line() == f"boot {RESET_FLAGS['watchdog']}"

    @pytest.mark.parametrize(("cause", "flags"), [("reset_pin", 2), ("power_on", 1)])
    def test_reset_on_request(
        self, board: EmulatedBoard, console: Console, cause: str, flags: int
    ) -> None:
        board.reset(cause)
        assert console.line() == f"boot {flags}"
        assert board.reset_cause == cause
        assert board.stats["resets"] == 1

    def test_held_in_reset(self, board: EmulatedBoard, console: Console) -> None:
        console.command("s 2 1")
        board.reset(hold=0.05)
        start = board.sim_time
        board.run_for(0.04)
        assert not board.pins.stby.any()  # the pins float while held: the drivers are off
        assert console.line(timeout=0.1) == "boot 2"
        assert board.sim_time - start >= 0.05

    @pytest.mark.timeout(30)
    def test_a_timed_read_ends_on_a_board_held_in_reset(self, board: EmulatedBoard) -> None:
        """Held in reset, time moves in whole exchanges, so a read's deadline can fall on
        one exactly: float rounding then left a sliver too short to run, and the read spun."""
        board.reset(hold=30.0)
        port = board.serial()
        for i in range(40):
            port.timeout = (0.2, 0.1, 0.05, 0.3, 0.15)[i % 5]
            start = board.sim_time
            assert port.read(1) == b""
            late = board.sim_time - start - port.timeout
            assert -1e-9 < late < board.exchange_period  # the timeout, to the next exchange

    def test_a_reset_cuts_the_transmission(self, board: EmulatedBoard, console: Console) -> None:
        console.port.write(b"z 200\n")
        board.run_for(0.5e-3)  # a few dozen bytes out of 200
        board.reset()
        board.run_for(0.01)
        out = console.port.read(1000)
        sent = out[: out.index(b"boot 2\n")]
        assert 10 < len(sent) < 100
        assert sent == bytes(range(len(sent)))  # whole bytes, then nothing but the boot line
        assert out[len(sent) :] == b"boot 2\n"
        assert board.stats["tx_cut"] >= 1

    def test_a_crash_stops_the_core_until_reset(
        self, board: EmulatedBoard, console: Console
    ) -> None:
        console.port.write(b"c\n")
        board.run_for(0.01)
        assert board.status == "crashed"
        assert board.crash_pc is not None
        assert "out of ram" in board.log
        t = board.sim_time
        board.run_for(0.01)
        assert board.sim_time == pytest.approx(t + 0.01)  # time goes on around it
        board.reset()
        assert board.status == "running"
        assert console.line() == "boot 2"


class TestEeprom:
    def test_persisted_across_runs(self, fixture_elf: Path, tmp_path: Path) -> None:
        path = tmp_path / "eeprom.bin"
        with EmulatedBoard(fixture_elf, realtime=False, eeprom_path=path) as board:
            console = Console(board)
            console.line()
            for addr, value in ((0, 17), (1000, 42), (4095, 99)):
                assert console.command(f"w {addr} {value}") == "w"
            board.run_for(0.01)
            assert board.stats["eeprom_writes"] == 3
        image = path.read_bytes()
        assert len(image) == 4096
        assert (image[0], image[1000], image[4095]) == (17, 42, 99)
        assert image.count(0xFF) == 4093
        with EmulatedBoard(fixture_elf, realtime=False, eeprom_path=path) as board:
            console = Console(board)
            console.line()
            assert console.command("r 1000") == "r 1000 42"
            assert console.command("r 1001") == "r 1001 255"

    def test_a_byte_takes_3_4_ms_to_program(self, fixture_elf: Path) -> None:
        board = EmulatedBoard(fixture_elf, realtime=False, exchange_period=20e-6)
        console = Console(board)
        console.line()
        port = console.port
        port.write(b"w 5 1\nw 6 2\n")
        assert console.line() == "w"
        first = board.sim_time
        assert console.line() == "w"  # waited for the first byte's programming time
        assert 3.4e-3 <= board.sim_time - first < 3.6e-3
        assert console.command("r 6") == "r 6 2"
        board.close()

    def test_bad_image_is_refused(self, fixture_elf: Path, tmp_path: Path) -> None:
        path = tmp_path / "big.bin"
        path.write_bytes(b"\0" * 5000)
        with pytest.raises(Exception, match="5000 bytes"):
            EmulatedBoard(fixture_elf, realtime=False, eeprom_path=path)


class TestLineFaults:
    def test_drop_everything_to_the_board(self, board: EmulatedBoard, console: Console) -> None:
        board.set_line_faults("to_board", drop=1.0)
        console.port.write(b"b\n")
        board.run_for(0.01)
        assert console.port.in_waiting == 0
        assert board.stats["rx_dropped"] == 2
        board.set_line_faults("to_board")  # clean again
        assert console.command("b") == "b 1"

    def test_corruption_flips_one_bit_per_byte(
        self, board: EmulatedBoard, console: Console
    ) -> None:
        payload = bytes(range(64))
        console.port.write(b"e 64\n")
        board.run_for(1e-3)
        board.set_line_faults("to_host", corrupt=1.0)
        console.port.write(payload)
        got = console.port.read(64)
        assert [bin(a ^ b).count("1") for a, b in zip(got, payload, strict=True)] == [1] * 64
        assert board.stats["tx_corrupted"] == 64

    def test_insertion_and_injected_noise(self, board: EmulatedBoard, console: Console) -> None:
        console.port.write(b"e 8\n")
        board.run_for(1e-3)
        board.inject_noise(b"12345678", direction="to_board")  # noise the fixture echoes
        assert console.port.read(8) == b"12345678"
        board.set_line_faults("to_host", insert=0.5)
        console.port.write(b"e 100\n" + bytes(100))
        board.run_for(5e-3)
        out = console.port.read(1000)
        inserted = board.stats["tx_inserted"]
        assert 20 < inserted < 80
        assert len(out) == 100 + inserted

    def test_bad_probabilities_are_refused(self, board: EmulatedBoard) -> None:
        with pytest.raises(Exception, match="drop must be a probability"):
            board.set_line_faults(drop=1.5)
        with pytest.raises(Exception, match="direction"):
            board.set_line_faults("sideways", drop=0.1)


def scripted_run(fixture_elf: Path, seed: int) -> tuple[bytes, np.ndarray, np.ndarray]:
    plant = PlantParams()  # gravity and encoder noise on
    with EmulatedBoard(fixture_elf, seed=seed, realtime=False, plant_params=plant) as board:
        board.set_line_faults("to_host", corrupt=0.05)
        board.run_for(0.005)
        for cmd in (b"o 1 0 499 2\n", b"i 1 0 1 0\n", b"s 1 1\n", b"a\n", b"e 50\n"):
            board.write(cmd)
            board.run_for(0.002)
        board.write(bytes(range(50)))
        board.run_for(0.05)
        board.write(b"a\n")
        board.run_for(0.01)
        return board.read(), board.theta.copy(), board.adc_volts


def test_a_run_is_determined_by_its_seed(fixture_elf: Path) -> None:
    out1, theta1, adc1 = scripted_run(fixture_elf, seed=3)
    out2, theta2, adc2 = scripted_run(fixture_elf, seed=3)
    out3, _, _ = scripted_run(fixture_elf, seed=4)
    assert out1 == out2 and np.array_equal(theta1, theta2) and np.array_equal(adc1, adc2)
    assert out1 != out3  # other line faults and encoder noise
    assert theta1[1, 1] > 0.05  # the run did drive finger 1


def test_a_quiet_timer_counts_as_a_running_one(fixture_elf: Path) -> None:
    """Timer 1's events are left out (harness/timers.c: no interrupt of it is on), yet TCNT1
    reads what the running timer gives, at any time: simavr counts from the last overflow,
    which the harness moves along the timer's period grid before the read."""

    def counts(quiet: bool) -> list[int]:
        with EmulatedBoard(fixture_elf, realtime=False, plant_params=QUIET) as board:
            board._native.set_quiet_timers(quiet)
            console = Console(board)
            assert console.line() == "boot 1"
            out = []
            for wait in (0.0, 13e-6, 1.003e-3, 0.25):
                board.run_for(wait)
                out.append(int(console.command("n").split()[1]))
            stats = board.stats
            assert (stats["quieted_timer_events"] > 0) == quiet
            return out

    quiet, loud = counts(True), counts(False)
    assert quiet == loud
    assert all(0 <= n < 800 for n in quiet) and len(set(quiet)) > 1


class TestRunUntilOutput:
    """``run_until_output``: in C from one awaited byte to the next (a frame's end for the
    protocol's clients), stopping where a look after every exchange would have."""

    @staticmethod
    def counting(board: EmulatedBoard) -> None:
        assert Console(board).line() == "boot 1"
        board.write(b"z 300\n")  # bytes 0, 1, ..., 255, 0, ..., 43: 10 us apart

    def test_it_stops_where_a_look_every_exchange_would(self, fixture_elf: Path) -> None:
        seen = bytearray()

        def has_200(b: EmulatedBoard) -> bool:
            seen.extend(b.read())
            return 200 in seen

        stops = []
        for wait in ("every exchange", "in C"):
            with EmulatedBoard(
                fixture_elf, realtime=False, plant_params=QUIET, exchange_period=EXCHANGE
            ) as board:
                self.counting(board)
                start = board.sim_time
                if wait == "in C":
                    assert board.run_until_output(1.0, byte=200)
                    seen[:] = board.read()
                else:
                    seen.clear()
                    assert board.run_until(has_200, timeout=1.0)
                stops.append((board.sim_time, bytes(seen)))
                period = board.exchange_period
        assert stops[0] == stops[1]
        at, out = stops[0]
        per = round(period / FRAME_S)  # the bytes an exchange carries
        assert 200 in out[-per - 1 :]  # the rest of its exchange came too
        assert 2e-3 < at - start < 2.1e-3 + period  # 200 bytes of 10 us after the echo

    def test_until_decides_at_each_awaited_byte(self, board: EmulatedBoard) -> None:
        self.counting(board)
        period = board.exchange_period
        start = board.sim_time
        looks: list[tuple[float, bytes]] = []

        def look() -> bool:
            looks.append((board.sim_time, board.read()))
            return False

        assert not board.run_until_output(0.01 + period / 3, look, byte=0)
        # whole exchanges, the last one past the time asked (and an instruction's cycles past
        # that); a look at each 0x00 only
        whole = math.ceil(0.01 / period + 1 / 3) * period
        assert board.sim_time - start == pytest.approx(whole, abs=1e-6)
        assert len(looks) == 2
        per = round(period / FRAME_S)
        assert all(0 in out[-per - 1 :] for _, out in looks)  # in the last exchange's bytes
        # 256 bytes apart, each look at the end of its byte's exchange
        assert abs(looks[1][0] - looks[0][0] - 256 * FRAME_S) < period + 1e-6

    def test_it_needs_a_driven_capturing_board(self, fixture_elf: Path) -> None:
        with EmulatedBoard(fixture_elf, realtime=False, capture=False) as board:
            with pytest.raises(EmulatorError, match="capture"):
                board.run_until_output(0.01)
            with pytest.raises(EmulatorError, match="byte"):
                board.run_until_output(0.01, byte=256)


class TestProfiler:
    def test_interrupt_cycles(self, board: EmulatedBoard, console: Console) -> None:
        console.command("k 1000")  # the tick ISR busy-waits 1000 x 4 cycles
        board.profile_interrupt("TIMER2_COMPA")
        board.run_for(0.1)
        prof = board.profile()["interrupt"]
        assert 98 <= prof.calls <= 100
        assert 4000 < prof.mean < 4150
        assert prof.worst - prof.best < 40
        assert prof.period == pytest.approx(16000, rel=1e-3)  # 1 kHz
        assert 0.25 < prof.load < 0.26  # a quarter of the CPU
        console.command("k 0")
        board.profile_interrupt(13)
        board.run_for(0.05)
        assert board.profile()["interrupt"].mean < 150

    def test_function_cycles(self, board: EmulatedBoard, console: Console) -> None:
        console.command("k 500")
        board.profile_function("__vector_13")
        board.run_for(0.05)
        prof = board.profile()["function"]
        assert prof.calls >= 49
        assert 2000 < prof.mean < 2150

    def test_unknown_names_are_refused(self, board: EmulatedBoard) -> None:
        with pytest.raises(Exception, match="unknown vector"):
            board.profile_interrupt("TIMER9")
        with pytest.raises(Exception, match="no symbol"):
            board.profile_function("no_such_function")


def test_ram_and_symbols(board: EmulatedBoard, console: Console) -> None:
    addr = board.symbol("mcusr_saved")
    assert addr is not None and 0x200 <= addr < 0x2200
    assert board.read_ram("mcusr_saved", 1) == b"\x01"
    assert math.isnan(board.profile()["interrupt"].mean)
