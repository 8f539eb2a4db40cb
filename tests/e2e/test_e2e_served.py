"""The real-time path, as a user meets it: the emulated board served on a TCP port (as a MEGA
on its USB serial port), a Hand or the `utrf` command connecting over `socket://`, riding out
the auto-reset, a pulled cable, and the demo writing its files."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.datalog import read_log
from utrf.emulator import EmulatedBoard
from utrf.hand import DEFAULT_TOLERANCE, Hand, log_columns
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary
from utrf.protocol import messages as M
from utrf.protocol.errors import DisconnectedError

LIBRARY = PoseLibrary.load(include_user=False)


@pytest.fixture
def served(firmware_elf: Path) -> Iterator[EmulatedBoard]:
    with EmulatedBoard(firmware_elf, realtime=True, pty=False, seed=5) as b:
        yield b


@pytest.fixture(autouse=True)
def no_user_poses(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UTRF_POSES", str(tmp_path / "none.toml"))


def test_connect_rides_out_a_bootloaders_delay(firmware_elf: Path) -> None:
    # A stock MEGA's bootloader keeps the board silent about 1 s after the port opens.
    with EmulatedBoard(firmware_elf, realtime=True, pty=False, auto_reset_hold=1.0) as board:
        t0 = time.monotonic()
        with Hand.connect(board.url) as hand:
            assert time.monotonic() - t0 > 1.0
            assert hand.identity.reset_cause == M.ResetCause.RESET_PIN
            assert hand.last_boot is not None
            assert board.stats["rx_lost_disabled"] == 0  # nothing was sent into the reset
            hand.pose("shaka", duration=0.5)
            goal = LIBRARY["shaka"].theta2(hand.geometry)
            np.testing.assert_allclose(board.theta2, goal, atol=DEFAULT_TOLERANCE + 0.01)


def test_a_pulled_cable_raises_and_reconnect_recovers(served: EmulatedBoard) -> None:
    with Hand.connect(served.url) as hand:
        hand.pose("fist", duration=0.4)
        served.drop_client()
        time.sleep(0.1)
        with pytest.raises(DisconnectedError):
            hand.set_targets({"index": 0.3})
        identity = hand.reconnect()  # a new connection: the auto-reset, a new handshake
        assert identity.reset_cause == M.ResetCause.RESET_PIN
        assert [f.mode for f in hand.state()] == [M.ControlMode.COAST] * 5
        hand.pose("open", duration=0.4)


def test_utrf_pose_settles_and_leaves_the_pose_standing(
    served: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["pose", "rock-and-roll", "--port", served.url, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    goal = LIBRARY["rock-and-roll"].theta2(HandGeometry.default())
    assert out["settled"] is True
    got = [out["fingers"][n]["theta2_rad"] for n in ("thumb", "index", "middle", "ring", "little")]
    # read just after settling: within the tolerance, give or take an ADC count (7.7 mrad)
    np.testing.assert_allclose(got, goal, atol=DEFAULT_TOLERANCE + 0.008)
    # --then hold (the default): after the command (and its goodbye) the board holds the pose
    # by itself, past its host timeout
    served.run_for(1.0)
    np.testing.assert_allclose(served.theta2, goal, atol=DEFAULT_TOLERANCE + 0.02)


def test_utrf_pose_says_why_it_did_not_settle(
    served: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    served.block_finger(2, 0.4, direction="flexion")
    # (a generous timeout: the stall ends it as soon as the firmware latches it, and a busy
    # machine may run the board slower than the wall clock)
    assert main(["pose", "fist", "--port", served.url, "--timeout", "8"]) == 1
    err = capsys.readouterr().err
    assert "utrf pose: error:" in err and "middle: STALL" in err


def test_utrf_monitor_prints_and_logs(
    served: EmulatedBoard, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "monitor.csv"
    argv = ["monitor", "--port", served.url, "--duration", "1.2", "--every", "0.5"]
    assert main([*argv, "--rate", "100", "--log", str(log)]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("t=")]
    assert len(lines) >= 2 and "thumb" in lines[0] and "°" in lines[0]
    data = read_log(log, log_columns(("thumb", "index", "middle", "ring", "little")))
    assert len(data.rows) >= 30 and data.skipped == 0
    times = np.array(data.column("board_time_s"), dtype=float)
    np.testing.assert_allclose(np.diff(times), 0.01, atol=1e-6)  # every 100 Hz sample logged
    assert {r["thumb_mode"] for r in data.rows} == {"COAST"}  # the monitor moved nothing


def test_utrf_monitor_says_when_the_board_resets_and_carries_on(
    served: EmulatedBoard, capsys: pytest.CaptureFixture[str]
) -> None:
    def reset_once_monitored() -> None:  # 0.4 s (simulated) into the monitor's connection
        if served.wait_until(lambda b: b.clients["tcp"], timeout=10.0):
            served.run_for(0.4)
            served.reset()

    resetter = threading.Thread(target=reset_once_monitored, daemon=True)
    resetter.start()
    # 4 s of wall clock: room for a board that a busy machine runs slower than real time
    argv = ["monitor", "--port", served.url, "--duration", "4", "--every", "0.25"]
    assert main(argv) == 0
    resetter.join(timeout=5.0)
    assert served.stats["resets"] >= 2  # the auto-reset of the connection, then ours
    out = capsys.readouterr().out
    assert "the board reset (RESET_PIN): handshaking again" in out
    after = out.split("handshaking again", 1)[1]
    assert sum(line.startswith("t=") for line in after.splitlines()) >= 2  # the stream is back


def test_utrf_demo_writes_its_pictures_and_plot(
    firmware_elf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "demo"
    argv = ["demo", "--out", str(out), "--sequence", "open,shaka", "--duration", "0.5"]
    assert main([*argv, "--hold", "0.2", "--speed", "max", "--no-live"]) == 0
    printed = capsys.readouterr().out
    files = [out / "pose-01-open.png", out / "pose-02-shaka.png", out / "trajectories.png"]
    for f in files:
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f.stat().st_size > 20_000
        assert str(f) in printed  # it says where they are
    data = read_log(out / "telemetry.csv")
    times = np.array(data.column("board_time_s"), dtype=float)
    assert len(times) > 100 and np.all(np.diff(times) > 0)
    assert "every pose settled" in printed
