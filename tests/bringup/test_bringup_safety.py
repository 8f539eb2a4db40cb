"""A bring-up stopped at any moment (Ctrl-C, an error, the host process killed) leaves every
motor off and the saved configuration as it was; and from the board's own telemetry, it never
commands more than its duty bound nor pushes against a stop longer than its stall rule."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from bringup_helpers import Built

from utrf.bringup import Bounds, bringup, procedure
from utrf.emulator import EmulatedBoard
from utrf.hand import Hand

INDEX = 1


def _motors_off(board: EmulatedBoard) -> bool:
    return all(mode in ("coast", "brake") for a, b in board.drive for mode in (a[0], b[0]))


def _config(hand: Hand, f: int) -> tuple[object, ...]:
    return (hand.finger_config(f), hand.limits(f), hand.gains(f), hand.motion(f))


def _kill_at(hand: Hand, board_time: float) -> None:
    """Ctrl-C once the board's clock passes ``board_time``: raised from the hand's clock, so
    it lands wherever the bring-up waits (mid-pulse, mid-search, mid-check)."""
    sleep = hand.clock.sleep

    def sleep_then_kill(seconds: float) -> None:
        sleep(seconds)
        if hand.state().board_time >= board_time:
            raise KeyboardInterrupt

    hand.clock.sleep = sleep_then_kill  # type: ignore[method-assign]


@pytest.mark.parametrize("at_s", [0.6, 3.0])  # in the wiring pulses; in the stop search
def test_ctrl_c_leaves_motors_off_and_the_saved_config(built: Built, at_s: float) -> None:
    with built() as (board, hand):
        eeprom, before = board.eeprom, _config(hand, INDEX)
        _kill_at(hand, hand.state().board_time + at_s)
        with pytest.raises(KeyboardInterrupt):
            bringup(hand, fingers=[INDEX], confirm=lambda text: True)
        assert _motors_off(board)
        assert board.eeprom == eeprom
        assert _config(hand, INDEX) == before  # the running configuration is the saved one


def test_a_killed_host_leaves_the_motors_off(built: Built, monkeypatch: pytest.MonkeyPatch) -> None:
    """No clean-up at all (the process killed mid-pulse): the board's host-silence rule, set to
    COAST for the bring-up, turns the motors off by itself."""
    monkeypatch.setattr(procedure, "_safe_stop", lambda hand: None)
    with built() as (board, hand):
        eeprom = board.eeprom
        _kill_at(hand, hand.state().board_time + 0.7)
        with pytest.raises(KeyboardInterrupt):
            bringup(hand, fingers=[INDEX])
        board.run_for(1.0)  # nobody talks to it any more
        assert _motors_off(board)
        assert board.eeprom == eeprom


def _longest_push_without_motion(
    t: np.ndarray, th: np.ndarray, push: np.ndarray, motion: float
) -> float:
    """The longest time the finger was driven (a duty difference) and moved less than
    ``motion`` over it: how long it pushed against a stop."""
    longest, start = 0.0, None
    for i in range(len(t)):
        if not push[i]:
            start = None
            continue
        if start is None or abs(th[i] - th[start]) > motion:
            start = i
        longest = max(longest, t[i] - t[start])
    return longest


@pytest.mark.slow
def test_a_whole_finger_is_brought_up_saved_and_then_left_alone(
    built: Built, tmp_path: Path
) -> None:
    bounds = Bounds()
    with built("invert-magnet:1", "magnet-offset:1=0.3") as (board, hand):
        eeprom = board.eeprom
        first = bringup(hand, tmp_path / "first", fingers=[INDEX], confirm=lambda text: True)
        assert [f.kind for f in first.findings] == ["encoder-inverted", "magnet-offset"]
        assert first.saved and board.eeprom != eeprom
        assert hand.finger_config(INDEX).encoder_invert == 1
        tuned = first.fingers[0].checks[-1]
        assert tuned.rms_rad < math.radians(1.5), tuned
        # the board's telemetry: never above the duty bound, never pushing on a stop longer
        # than the stall rule the bring-up gives the board
        tel = json.loads((tmp_path / "first" / "telemetry.json").read_text())
        t = np.array(tel["board_time_s"])
        a, b = np.array(tel["duty_a"])[:, INDEX], np.array(tel["duty_b"])[:, INDEX]
        assert max(np.max(np.abs(a)), np.max(np.abs(b))) <= bounds.duty + 1 / 128
        th = np.array(tel["theta2_rad"])[:, INDEX]
        push = np.abs(a - b) > 0.05
        assert _longest_push_without_motion(t, th, push, 0.02) <= bounds.board_stall_s
        assert (tmp_path / "first" / "report.md").exists()
        assert (tmp_path / "first" / "index.png").exists()
        saved = board.eeprom
        again = bringup(hand, fingers=[INDEX], confirm=lambda text: True)
        assert again.unchanged and not again.saved, (again.message, again.changes)
        assert "nothing to change" in again.message
        assert board.eeprom == saved


@pytest.mark.slow
def test_a_bring_up_resumes_after_the_fingers_done(built: Built, tmp_path: Path) -> None:
    steps: list[str] = []

    def stop_at_index(text: str) -> None:
        steps.append(text)
        if text.startswith("index"):
            raise KeyboardInterrupt

    with built("invert-magnet:0") as (board, hand):
        with pytest.raises(KeyboardInterrupt):
            bringup(hand, tmp_path, fingers=[0, 1], upto="wiring", on_step=stop_at_index)
        assert _motors_off(board)
        steps.clear()
        result = bringup(
            hand, tmp_path, fingers=[0, 1], upto="wiring", on_step=steps.append, resume=True
        )
    assert "thumb: done before (resumed)" in steps
    assert not any(s.startswith("thumb: wiring") for s in steps)
    assert [f.kind for f in result.fingers[0].findings] == ["encoder-inverted"]  # from the file
    assert [r.name for r in result.fingers] == ["thumb", "index"]
