"""Hand against a scripted fake board over TCP: what the emulated firmware cannot be made to
do (lost replies, arbitrary nacks, a bootloader's silence, a board of another spec) and the
client's own logic (targets and their errors, trajectories, settling, logs, closing)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hand_fake import HAND, HandBoard

from utrf.datalog import read_log
from utrf.hand import (
    FingerFaultError,
    Hand,
    NotControlledError,
    NotSettledError,
    TargetError,
    log_columns,
)
from utrf.hand.state import BOARD_CLOCK_WRAP_S, BoardClock
from utrf.protocol import messages as M
from utrf.protocol.errors import (
    BoardResetError,
    NackError,
    ReplyTimeout,
    SchemaMismatchError,
)


@pytest.fixture
def board() -> Iterator[HandBoard]:
    b = HandBoard()
    yield b
    b.close()


@pytest.fixture
def hand(board: HandBoard) -> Iterator[Hand]:
    with Hand.connect(board.url, boot_wait_s=0, telemetry_hz=100) as h:
        yield h


# --- connecting -------------------------------------------------------------------------


def test_connect_waits_out_the_boot_then_handshakes_and_starts_telemetry() -> None:
    board = HandBoard(boot_on_connect=True)
    try:
        t0 = time.monotonic()
        with Hand.connect(board.url, boot_wait_s=2.0, telemetry_hz=50) as hand:
            took = time.monotonic() - t0
            # It waited for the boot instead of asking into the bootloader's silence.
            assert board.unheard == 0 and 0.25 < took < 3.0
            assert hand.identity.reset_cause == M.ResetCause.RESET_PIN
            assert board.requests(M.SetTelemetry)[0] == M.SetTelemetry(rate_hz=50)
            assert len(board.requests(M.GetLimits)) == 5
            hand.state()  # usable: the boot seen before the handshake raised nothing
    finally:
        board.close()


def test_schema_mismatch_names_both_versions_and_hashes(board: HandBoard) -> None:
    board.identity = M.Identity(
        **{**_fields(board.identity), "protocol_version": 7, "schema_hash": 0x0BADF00D}
    )
    with pytest.raises(SchemaMismatchError) as info:
        Hand.connect(board.url, boot_wait_s=0)
    text = str(info.value)
    assert "version 7 (schema 0x0BADF00D)" in text
    assert f"version {M.PROTOCOL_VERSION} (schema 0x{M.SCHEMA_HASH:08X})" in text


def _fields(msg: M.Message) -> dict:
    return {f.name: getattr(msg, f.name) for f in type(msg).FIELDS}


def test_a_board_that_never_answers_times_out() -> None:
    board = HandBoard()
    board.on(M.Identify.ID, lambda f: None)
    try:
        t0 = time.monotonic()
        with pytest.raises(ReplyTimeout, match="identify"):
            Hand.connect(board.url, boot_wait_s=0, handshake_timeout_s=0.5)
        assert 0.45 < time.monotonic() - t0 < 3.0
        assert len(board.requests(M.Identify)) >= 3  # asked again and again meanwhile
    finally:
        board.close()


# --- requests that fail -----------------------------------------------------------------


def test_lost_replies_are_retried_then_reported(board: HandBoard, hand: Hand) -> None:
    drops = {"left": 2}

    def flaky(frame):  # the first two set_targets get no answer
        if drops["left"]:
            drops["left"] -= 1
            return None
        return [(frame.seq, M.Ack(frame.msg_id))]

    board.on(M.SetTargets.ID, flaky)
    hand.set_targets({"index": 0.5}, enable=False)
    sent = board.requests(M.SetTargets)
    assert len(sent) == 3 and sent[0] == sent[2]  # resent with the same bytes
    assert hand.link_stats().retries == 2
    board.on(M.SetTargets.ID, lambda f: None)
    with pytest.raises(ReplyTimeout, match="set_targets after 9 attempt"):
        hand.set_targets({"index": 0.6}, enable=False)


def test_out_of_range_target_is_a_target_error_naming_the_finger(
    board: HandBoard, hand: Hand
) -> None:
    with pytest.raises(TargetError, match=r"'ring'.*theta2 = 2\.5 rad.*limits"):
        hand.set_targets({"ring": 2.5})
    with pytest.raises(TargetError, match=r"'thumb'.*flexion = -0.2.*0\.\.1"):
        hand.set_targets({"thumb": -0.2}, kind="flexion")
    # move checks before it sends anything
    before = len(board.received)
    with pytest.raises(TargetError, match=r"move: finger 'little' target 3\.000 rad"):
        hand.move({"little": 3.0})
    assert len(board.received) == before


def test_a_faulted_finger_is_named_with_its_faults(board: HandBoard, hand: Hand) -> None:
    board.latch(2, M.FaultBits.STALL)
    with pytest.raises(FingerFaultError, match="middle: STALL"):
        hand.set_mode("position", "middle")
    with pytest.raises(FingerFaultError, match=r"move: .*middle: STALL"):
        hand.move({"middle": 0.3}, 0.1)
    hand.clear_faults("middle")
    hand.move({"middle": 0.3}, 0.1)


def test_other_nacks_surface_as_nack_errors(board: HandBoard, hand: Hand) -> None:
    board.on(M.SaveConfig.ID, lambda f: [(f.seq, M.Nack(f.msg_id, M.ErrorCode.BUSY, 0xFF))])
    with pytest.raises(NackError, match="save_config refused: BUSY"):
        hand.save_config()


def test_bad_input_is_refused_with_what_was_wrong(hand: Hand) -> None:
    with pytest.raises(TargetError, match="no finger named 'pinky'; fingers are"):
        hand.set_targets({"pinky": 0.1})
    with pytest.raises(TargetError, match=r"finger index 5 is outside 0\.\.4"):
        hand.set_targets({5: 0.1})
    with pytest.raises(TargetError, match="3 targets for 5 fingers"):
        hand.set_targets([0.1, 0.2, 0.3])
    with pytest.raises(TargetError, match="target of index is nan"):
        hand.set_targets({"index": math.nan})
    with pytest.raises(TargetError, match="kind must be one of"):
        hand.set_targets({"index": 0.1}, kind="degrees")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown control mode 'hover'"):
        hand.set_mode("hover")
    with pytest.raises(ValueError, match="effort of index must lie in"):
        hand.set_mode("grasp", "index", effort=1.5)
    with pytest.raises(ValueError, match="duration must be"):
        hand.move({"index": 0.1}, duration=-1)
    with pytest.raises(ValueError, match=r"duration must be a number of seconds in \[0, 60\]"):
        hand.move({"index": 0.1}, duration=61)
    with pytest.raises(KeyError, match="no pose named 'vulcan'"):
        hand.pose("vulcan")
    with pytest.raises(TypeError, match=r"unknown field.*'kq'"):
        hand.set_gains("index", kq=1.0)


# --- targets, trajectories, settling -----------------------------------------------------


def test_targets_by_name_index_and_kind(board: HandBoard, hand: Hand) -> None:
    g = HAND.fingers[1].geometry
    hand.set_targets({"index": 0.004}, kind="q")
    hand.set_targets({3: 0.5}, kind="flexion")
    sent = board.requests(M.SetTargets)
    assert sent[0].kind == M.TargetKind.TENDON_Q and sent[0].mask == 0b00010
    assert sent[0].value[1] == pytest.approx(0.004, abs=1e-6)
    assert sent[1].kind == M.TargetKind.FLEXION and sent[1].mask == 0b01000
    # enable: both fingers went to POSITION, and the board holds the converted targets
    st = hand.state()
    assert st["index"].mode == M.ControlMode.POSITION
    assert st["index"].target == pytest.approx(0.004 / g.guide_radii_m[1], abs=1e-3)
    assert st[3].target == pytest.approx(hand.to_theta2("ring", 0.5, "flexion"), abs=1e-3)


def test_move_is_one_command_timed_by_the_board(board: HandBoard, hand: Hand) -> None:
    hand.move({"thumb": 0.2, "middle": -0.3}, 0.1)  # a known start, settled
    n0 = len(board.requests(M.SetTargets))
    moves0 = len(board.requests(M.Move))
    result = hand.move({"thumb": 0.5, "middle": 0.0}, 0.6, wait=False)
    (sent,) = board.requests(M.Move)[moves0:]
    assert len(board.requests(M.SetTargets)) == n0  # in closed loop already: no step first
    assert sent.kind == M.TargetKind.JOINT2_ANGLE and sent.mask == 0b00101
    assert sent.value[0] == pytest.approx(0.5, abs=1e-6)
    assert sent.value[2] == pytest.approx(0.0, abs=1e-6)
    assert sent.duration == (0.6, 0.0, 0.6, 0.0, 0.0)
    assert result.duration == {"thumb": 0.6, "middle": 0.6} and result.stretched == ()
    assert hand.last_move == result
    # waiting lasts until the board's clock passes the paths' end
    t0 = time.monotonic()
    hand.move({"thumb": 0.8}, 0.4)
    assert time.monotonic() - t0 >= 0.4
    # a path faster than the finger's limits is stretched, and the result names it
    result = hand.move({"thumb": -0.7, "index": 0.1}, 0.5, wait=False)
    assert result.stretched == ("thumb",)
    assert result.duration["thumb"] == pytest.approx(1.875 * 1.5 / board.max_speed, abs=1e-3)
    assert result.duration["index"] == 0.5
    assert "thumb 2.344 s" in result.describe()
    assert board.requests(M.Move)[-1].move_id != board.requests(M.Move)[-2].move_id


def test_move_holds_an_idle_finger_before_its_path(board: HandBoard, hand: Hand) -> None:
    with board.lock:
        board.theta2[3] = 0.25  # in COAST, resting bent
    hand.move({"ring": 0.6}, 0.2, wait=False)
    (hold,) = board.requests(M.SetTargets)
    assert hold.mask == 0b01000 and hold.value[3] == pytest.approx(0.25, abs=1e-4)
    # its motors were off: first its tendons taken up at the pretension (DUTY 0), then held
    take_up, mode = board.requests(M.SetMode)
    assert take_up.mask == 0b01000 and take_up.mode[3] == M.ControlMode.DUTY
    assert take_up.duty[3] == 0.0
    assert mode.mask == 0b01000 and mode.mode[3] == M.ControlMode.POSITION
    assert board.received[-1].msg_id == M.Move.ID  # the move goes last


def test_wait_settled_names_the_finger_and_how_far(board: HandBoard, hand: Hand) -> None:
    board.stuck[4] = 0.25  # the little finger stops at 0.25 rad
    with pytest.raises(NotSettledError) as info:
        hand.move({"little": 0.85, "index": 0.4}, 0.1, timeout=0.4)
    err = info.value
    assert set(err.errors) == {"little"}
    assert err.errors["little"] == pytest.approx(0.6, abs=2e-3)
    assert "little is 0.600 rad (34.4 deg) short of its target" in str(err)


def test_wait_settled_raises_when_a_finger_faults_or_lets_go(board: HandBoard, hand: Hand) -> None:
    board.stuck[0] = 0.0
    hand.move({"thumb": 0.8}, 0.05, wait=False)
    board.latch(0, M.FaultBits.ENCODER_RANGE)
    with pytest.raises(FingerFaultError, match="thumb: ENCODER_RANGE"):
        hand.wait_settled(timeout=1.0)
    hand.clear_faults()
    hand.move({"index": 0.3}, 0.05)
    with board.lock:
        board.mode[1] = M.ControlMode.COAST
    with pytest.raises(NotControlledError, match="index is in COAST"):
        hand.wait_settled(timeout=1.0, fingers="index")


def test_pose_uses_the_library_and_grasp_mode(board: HandBoard, hand: Hand) -> None:
    pose = hand.pose("shaka", duration=0.1)
    st = hand.state()
    np.testing.assert_allclose(st.target, pose.theta2(HAND), atol=1e-4)
    assert set(st[i].mode for i in range(5)) == {M.ControlMode.POSITION}
    hand.pose("open", duration=0.1)
    n = len(board.requests(M.SetMode))
    grasp = hand.pose("grasp-egg", duration=0.1)  # closes thumb, index, middle, ring
    (modes,) = board.requests(M.SetMode)[n:]  # the little finger already holds position
    assert modes.mask == 0b01111
    assert modes.mode[:4] == (M.ControlMode.GRASP,) * 4
    assert modes.effort[:4] == (pytest.approx(grasp.grasp.effort),) * 4
    st = hand.state()
    assert [f.mode for f in st][4:] == [M.ControlMode.POSITION]


# --- telemetry, log, closing -------------------------------------------------------------


def test_unsubscribe_waits_for_a_call_under_way_and_stops_the_next(hand: Hand) -> None:
    import threading

    entered, release = threading.Event(), threading.Event()
    calls: list[float] = []

    def slow(state) -> None:
        calls.append(state.board_time)
        if len(calls) == 1:
            entered.set()
            release.wait(5)

    unsubscribe = hand.on_state(slow)
    assert entered.wait(5)
    done = threading.Thread(target=unsubscribe)
    done.start()
    done.join(0.2)
    assert done.is_alive()  # a call is under way: unsubscribe waits for it
    release.set()
    done.join(5)
    assert not done.is_alive()
    n = len(calls)
    time.sleep(0.1)  # the stream goes on
    assert len(calls) == n == 1


def test_telemetry_reaches_callbacks_and_the_log(tmp_path: Path, board: HandBoard) -> None:
    path = tmp_path / "run.csv"
    seen = []
    with Hand.connect(board.url, boot_wait_s=0, telemetry_hz=200, log_path=path) as hand:
        unsubscribe = hand.on_state(seen.append)
        hand.move({"index": 0.7}, 0.05)
        time.sleep(0.2)
        unsubscribe()
        n = len(seen)
        time.sleep(0.05)
        assert len(seen) == n  # unsubscribed
    data = read_log(path, log_columns(hand.fingers))
    assert len(data.rows) >= n >= 30 and data.skipped == 0
    moving = [r for r in data.rows if r["index_mode"] == "POSITION"]
    assert moving[-1]["index_theta2_rad"] == pytest.approx(0.7, abs=1e-3)
    assert data.rows[-1]["index_mode"] in ("POSITION", "BRAKE")  # close() brakes, then stops
    seqs = [r["seq"] for r in data.rows]
    assert all(s >= 128 for s in seqs)  # stream frames
    times = np.array(data.column("board_time_s"), dtype=float)
    assert np.all(np.diff(times) >= 0)


def test_close_leaves_the_hand_braked_and_silent(board: HandBoard) -> None:
    with Hand.connect(board.url, boot_wait_s=0) as hand:
        hand.move({"index": 0.5}, 0.05)
    last_mode = board.requests(M.SetMode)[-1]
    assert last_mode.mask == 0b11111 and last_mode.mode == (M.ControlMode.BRAKE,) * 5
    assert board.requests(M.SetTelemetry)[-1].rate_hz == 0
    with pytest.raises(Exception, match="closed"):
        hand.state()


@pytest.mark.parametrize(("on_close", "mode"), [("coast", M.ControlMode.COAST), ("hold", None)])
def test_close_modes(board: HandBoard, on_close: str, mode: M.ControlMode | None) -> None:
    with Hand.connect(board.url, boot_wait_s=0, on_close=on_close) as hand:  # type: ignore[arg-type]
        hand.move({"index": 0.5}, 0.05)
    modes = board.requests(M.SetMode)
    if mode is None:
        assert modes[-1].mode[1] == M.ControlMode.POSITION  # left holding
    else:
        assert modes[-1].mode == (mode,) * 5


def test_a_reset_makes_the_next_call_raise_until_reconnect(board: HandBoard, hand: Hand) -> None:
    hand.move({"index": 0.5}, 0.05)
    board.boot(M.ResetCause.WATCHDOG)
    time.sleep(0.1)
    with pytest.raises(BoardResetError, match="WATCHDOG"):
        hand.wait_settled(timeout=0.5)  # noticed from telemetry, without a request
    with pytest.raises(BoardResetError):
        hand.state()
    n = len(board.requests(M.SetTelemetry))
    hand.reconnect()
    assert len(board.requests(M.SetTelemetry)) == n + 1  # telemetry restarted
    hand.state()


def test_board_clock_unwraps_and_restarts() -> None:
    clock = BoardClock()
    assert clock.unwrap(4294.0) == 4294.0
    assert clock.unwrap(0.5) == pytest.approx(0.5 + BOARD_CLOCK_WRAP_S)
    assert clock.unwrap(1.0) == pytest.approx(1.0 + BOARD_CLOCK_WRAP_S)
    clock.restart()
    assert clock.unwrap(0.01) == 0.01


def test_tip_model_interpolates_as_numpy_does_to_the_bit() -> None:
    """The tips of every telemetry sample come from a plain-float interpolation (its fast
    path); numpy's np.interp on the same table is the general twin it must equal."""
    import numpy as np

    from utrf.hand.state import TipModel
    from utrf.models.geometry import HandGeometry

    model = TipModel(HandGeometry.default())
    grid, xs, ys = model._tables[1]
    rng = np.random.default_rng(3)
    values = [*rng.uniform(grid[0] - 0.5, grid[-1] + 0.5, 2000), *grid[:40], grid[-1]]
    for v in values:
        assert model.tip(1, v) == (float(np.interp(v, grid, xs)), float(np.interp(v, grid, ys)))
    nan_x, _ = model.tip(0, math.nan)
    assert math.isnan(nan_x)
    assert model.tips([0.1, 0.2, 0.3, 0.4, 0.5]) == (
        [model.tip(i, t)[0] for i, t in enumerate([0.1, 0.2, 0.3, 0.4, 0.5])],
        [model.tip(i, t)[1] for i, t in enumerate([0.1, 0.2, 0.3, 0.4, 0.5])],
    )


def test_finger_state_fast_path_equals_the_dataclass() -> None:
    """Each sample's fingers are built with their slots set directly (the fast path); the
    frozen dataclass's own constructor is the general twin: equal, frozen, every field set."""
    import dataclasses

    from utrf.hand.state import FingerState, _finger_state

    args = ("ring", 3, 0.1, 0.2, -0.3, 0.4, M.ControlMode.GRASP, M.FaultBits.STALL, 0.05, -0.01)
    fast, general = _finger_state(*args), FingerState(*args)
    assert fast == general
    assert dataclasses.astuple(fast) == args
    assert fast.error == general.error and fast.closed_loop
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.theta2 = 0.0  # type: ignore[misc]


def test_each_sample_takes_the_modes_and_faults_of_the_status_it_is_given() -> None:
    """from_message keeps the last status's modes and faults as enums (samples come at
    1 kHz, a status rarely): a new status, or none, must still be the one a sample shows."""
    from utrf.hand.state import HandState

    names = ("thumb", "index", "middle", "ring", "little")
    msg = M.State(board_time=1.0, status_seq=2, theta2=(0.1,) * 5, target=(0.2,) * 5,
                  duty_a=(0.3,) * 5, duty_b=(0.0,) * 5)  # fmt: skip
    hold = M.Status(change=2, mode=(M.ControlMode.POSITION,) * 5, faults=(M.FaultBits(0),) * 5)
    stall = M.Status(
        change=3,
        mode=(M.ControlMode.BRAKE, *(M.ControlMode.POSITION,) * 4),
        faults=(M.FaultBits.STALL, *(M.FaultBits(0),) * 4),
    )
    for status, mode, faults in [
        (hold, M.ControlMode.POSITION, 0),
        (hold, M.ControlMode.POSITION, 0),
        (stall, M.ControlMode.BRAKE, M.FaultBits.STALL),
        (None, M.ControlMode.COAST, 0),
        (hold, M.ControlMode.POSITION, 0),
    ]:
        st = HandState.from_message(msg, names, status)
        assert (st[0].mode, int(st[0].faults)) == (mode, int(faults))
        assert type(st[0].mode) is M.ControlMode and type(st[0].faults) is M.FaultBits
        assert st[1].mode == (M.ControlMode.COAST if status is None else M.ControlMode.POSITION)
        assert st.status_current == (status is hold)
    three = HandState.from_message(msg, names[:3], stall)  # fewer fingers, same status
    assert [f.mode for f in three] == [M.ControlMode.BRAKE, *(M.ControlMode.POSITION,) * 2]
