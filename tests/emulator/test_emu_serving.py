"""The board in real time: served on a pty and on TCP to ordinary pyserial clients, paced to
the wall clock; shut down cleanly; bad requests refused with a clear error."""

from __future__ import annotations

import os
import shutil
import socket
import threading
import time
from pathlib import Path

import pytest
import serial

from utrf.emulator import EmulatedBoard, EmulatorError, check_elf
from utrf.emulator import board as board_module
from utrf.emulator.board import SERVE_BATCH_S


def open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def read_line(port: serial.SerialBase) -> bytes:
    line = port.readline()
    assert line.endswith(b"\n"), f"timed out: {line!r}"
    return line


def test_tcp_client_with_auto_reset_and_echo(fixture_elf: Path) -> None:
    with EmulatedBoard(fixture_elf) as board:
        assert board.url is not None and board.url.startswith("socket://127.0.0.1:")
        time.sleep(0.05)
        port = serial.serial_for_url(board.url, timeout=2.0)
        try:
            # opening the port resets the board, as the MEGA's DTR does: EXTRF
            assert read_line(port) == b"boot 2\n"
            assert board.clients == {"pty": False, "tcp": True}
            payload = bytes(range(256)) * 4
            port.write(b"u 7\n")  # 250 kbaud, where the fixture keeps up with a full echo
            assert read_line(port) == b"u\n"
            t0, s0 = time.monotonic(), board.sim_time
            port.write(f"e {len(payload)}\n".encode() + payload)
            got = port.read(len(payload))
            wall, sim = time.monotonic() - t0, board.sim_time - s0
            assert got == payload
            # 1031 frames of 40 µs in, the last echoed one frame later; the board keeps to
            # the wall clock (it may run behind, and catch up by up to 100 ms)
            # (sim_time moves at the end of a batch of exchanges; the last byte left during one)
            assert sim >= 1032 * 40e-6 - SERVE_BATCH_S
            assert wall >= sim - 0.1
            # a second client is turned away, told why, while the first is connected
            with socket.create_connection(("127.0.0.1", board.tcp_port), timeout=2.0) as other:
                other.settimeout(2.0)
                assert recv_line(other) == (
                    b"utrf busy: the emulator already has a host attached (a TCP client, on "
                    b"its socket); one host at a time\n"
                )
                assert other.recv(16) == b""
        finally:
            port.close()
        assert board.stats["clients"] == 1


def recv_line(sock: socket.socket) -> bytes:
    line = b""
    while not line.endswith(b"\n"):
        chunk = sock.recv(1)
        if not chunk:
            break
        line += chunk
    return line


def test_a_pulled_cable_hangs_up_on_the_client(fixture_elf: Path) -> None:
    with EmulatedBoard(fixture_elf, pty=False) as board:
        with socket.create_connection(("127.0.0.1", board.tcp_port), timeout=2.0) as client:
            client.settimeout(2.0)
            assert recv_line(client) == b"boot 2\n"
            board.drop_client()
            assert client.recv(16) == b""  # end of file
        assert board.clients == {"pty": False, "tcp": False}
        with socket.create_connection(("127.0.0.1", board.tcp_port), timeout=2.0) as again:
            again.settimeout(2.0)
            assert recv_line(again) == b"boot 2\n"  # plugged back in: reset again


def test_pty_client(fixture_elf: Path) -> None:
    with EmulatedBoard(fixture_elf) as board:
        assert board.pty_path is not None and os.path.exists(board.pty_path)
        with serial.Serial(board.pty_path, baudrate=1_000_000, timeout=2.0) as port:
            assert read_line(port) == b"boot 2\n"
            port.write(b"b\n")
            assert read_line(port) == b"b 2\n"
            port.write(b"z 100\n")
            assert port.read(100) == bytes(range(100))


def test_paced_to_the_wall_clock(fixture_elf: Path) -> None:
    """Never ahead of the wall clock (a slow machine may make it lag, not lead)."""
    with EmulatedBoard(fixture_elf, pty=False) as board:
        t0, s0 = time.monotonic(), board.sim_time
        board.run_for(0.5)
        wall = time.monotonic() - t0
        assert board.sim_time - s0 >= 0.5
        # A board that lagged before t0 (a starved thread) catches up by running ahead of
        # real time, at most the 0.1 s it keeps before it accepts the lag instead
        assert wall >= 0.5 - 0.1 - 2e-3
        assert board.realtime_factor < 1.01


def test_twice_real_time_when_asked(fixture_elf: Path) -> None:
    with EmulatedBoard(fixture_elf, pty=False, speed=2.0) as board:
        t0, s0 = time.monotonic(), board.sim_time
        board.run_for(0.4)
        # sim_time moves a batch at a time, and the pacing lets the board run up to 1 ms of
        # wall time ahead: the wall time may be short by that much
        assert time.monotonic() - t0 >= 0.2 - 2e-3 - SERVE_BATCH_S / 2 - 1e-3
        assert board.sim_time - s0 >= 0.4


def test_a_failure_in_the_board_thread_reaches_the_caller(fixture_elf: Path) -> None:
    with EmulatedBoard(fixture_elf, pty=False) as board:

        def broken(cycle: int, period: int) -> int:
            raise ValueError("plant exploded")

        board._native.run_plant = broken  # type: ignore[method-assign]
        with pytest.raises(EmulatorError, match="plant exploded"):
            board.run_for(0.1)
        assert isinstance(board.failure, ValueError)


def test_clean_shutdown(fixture_elf: Path) -> None:
    before = open_fds()
    board = EmulatedBoard(fixture_elf)
    port, pty = board.tcp_port, board.pty_path
    assert any(t.name == "utrf-board" for t in threading.enumerate())
    board.close()
    board.close()  # idempotent
    assert board.closed
    assert not any(t.name == "utrf-board" and t.is_alive() for t in threading.enumerate())
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=1.0)
    assert pty is not None and not os.path.exists(pty)
    assert open_fds() <= before
    with pytest.raises(EmulatorError, match="closed"):
        board.reset()


def test_collected_board_frees_its_ports(fixture_elf: Path) -> None:
    import gc

    board = EmulatedBoard(fixture_elf, realtime=False, serve=True)
    port = board.tcp_port
    del board
    gc.collect()
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", port), timeout=1.0)


class TestBadInput:
    def test_missing_default_firmware_says_how_to_build_it(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setattr(board_module, "DEFAULT_ELF", tmp_path / "utrf.elf")
        with pytest.raises(EmulatorError, match="run `make firmware`"):
            check_elf(board_module.DEFAULT_ELF)

    def test_not_an_elf(self, tmp_path: Path) -> None:
        bad = tmp_path / "x.elf"
        bad.write_bytes(b"hello world" * 10)
        with pytest.raises(EmulatorError, match="not an ELF"):
            EmulatedBoard(bad, realtime=False)

    def test_not_an_avr_program(self) -> None:
        with pytest.raises(EmulatorError, match=r"not an AVR|not a 32-bit"):
            EmulatedBoard(shutil.which("sh"), realtime=False)

    def test_not_built_for_the_atmega2560(self, fixture_elf: Path, tmp_path: Path) -> None:
        data = bytearray(fixture_elf.read_bytes())
        data[36] = (data[36] & 0x80) | 5  # e_flags: avr5 (atmega328p and friends)
        other = tmp_path / "avr5.elf"
        other.write_bytes(bytes(data))
        with pytest.raises(EmulatorError, match="avr6"):
            EmulatedBoard(other, realtime=False)

    @pytest.mark.parametrize(
        ("kwargs", "needle"),
        [
            ({"speed": 0}, "speed"),
            ({"exchange_period": 1.0}, "exchange_period"),
            ({"tcp_port": 70000}, "tcp_port"),
        ],
    )
    def test_bad_arguments(self, fixture_elf: Path, kwargs: dict, needle: str) -> None:
        with pytest.raises(EmulatorError, match=needle):
            EmulatedBoard(fixture_elf, realtime=False, **kwargs)

    def test_driven_only_calls_are_refused_in_real_time(self, fixture_elf: Path) -> None:
        with EmulatedBoard(fixture_elf, pty=False) as board:
            with pytest.raises(EmulatorError, match="realtime=False"):
                board.serial()
            with pytest.raises(EmulatorError, match="capture"):
                board.read()

    def test_tcp_port_in_use(self, fixture_elf: Path) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            s.listen()
            with pytest.raises(Exception, match="cannot listen"):
                EmulatedBoard(fixture_elf, pty=False, tcp_port=s.getsockname()[1])
