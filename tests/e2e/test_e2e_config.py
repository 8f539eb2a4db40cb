"""The Hand's configuration calls against the real firmware: each changes what it names and
nothing else, the board's checks come back as clear errors, and the host's own checks use
the limits the board holds."""

from __future__ import annotations

import dataclasses
import math

import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand, TargetError
from utrf.protocol import messages as M
from utrf.protocol.errors import NackError


def _fields(msg: M.Message) -> dict:
    return {f.name: getattr(msg, f.name) for f in type(msg).FIELDS}


def test_gains_change_only_what_is_named(hand: Hand) -> None:
    before = hand.gains("ring")
    after = hand.set_gains("ring", kp=5.5, max_duty=0.7)
    assert after.kp == pytest.approx(5.5) and after.max_duty == pytest.approx(0.7)
    changed = {k for k, v in _fields(after).items() if v != _fields(before)[k]}
    assert changed == {"kp", "max_duty"}
    assert hand.gains("index") == dataclasses.replace(before, finger=1)  # others untouched
    with pytest.raises(NackError, match="OUT_OF_RANGE"):  # the firmware's own check
        hand.set_gains("ring", pretension_duty=0.5, max_duty=0.4)
    assert hand.gains("ring") == after  # a refused request changed nothing


def test_limits_bound_moves_before_they_start(board: EmulatedBoard, hand: Hand) -> None:
    hand.set_limits("middle", theta2_max=1.0)
    before = board.stats["rx_uart_bytes"]
    with pytest.raises(TargetError, match=r"'middle' target 1\.200 rad.*\[-1\.65\d, 1\.000\]"):
        hand.move({"middle": 1.2}, 0.3)
    assert board.stats["rx_uart_bytes"] == before  # refused on the host: nothing sent
    hand.move({"middle": 0.95}, 0.3)
    with pytest.raises(NackError, match="BUSY"):  # not while a finger is driven
        hand.load_config("defaults")
    with pytest.raises(NackError, match="BUSY"):
        hand.set_finger_config("middle", encoder_invert=1)
    hand.brake()
    hand.load_config("defaults")
    assert hand.identity.config_status == M.ConfigStatus.DEFAULTS_BLANK  # the handshake's
    assert hand.limits("middle").theta2_max == pytest.approx(1.6535, abs=1e-3)
    hand.move({"middle": 1.2}, 0.3)  # the host follows the board's limits again


def test_calibrate_zero_takes_the_present_reading(board: EmulatedBoard, hand: Hand) -> None:
    # One ADC count is 2 pi / (0.8 * 1024) = 7.7 mrad of encoder angle; a reading is within
    # a count of quantisation plus about one of the encoder's seeded noise: 2 counts.
    lsb = 2 * math.pi / (0.8 * 1024)
    board.block_finger(4, 0.0)  # held straight: in COAST it would sag under gravity
    board.shift_encoder(4, 0.05)  # the magnet sits 0.05 rad off
    hand.clock.sleep(0.02)
    reading = hand.state()["little"].theta2
    assert board.theta2[4] == pytest.approx(0.0, abs=1e-3)
    assert reading == pytest.approx(0.05, abs=2 * lsb)
    old = hand.finger_config("little").encoder_offset
    hand.calibrate_zero("little")  # straight and idle: this reading is zero
    new = hand.finger_config("little").encoder_offset
    assert new - old == pytest.approx(0.05, abs=2 * lsb)
    hand.clock.sleep(0.02)
    assert hand.state()["little"].theta2 == pytest.approx(0.0, abs=2 * lsb)


def test_ping_and_stats(hand: Hand) -> None:
    rtt = hand.ping()  # simulated seconds
    assert 240e-6 <= rtt < 5e-3  # at least the two frames' time on the line
    stats = hand.stats()
    assert stats.rx_frames > 0 and stats.tick_overruns == 0
    hand.reset_stats()
    assert hand.stats().rx_frames <= 2
