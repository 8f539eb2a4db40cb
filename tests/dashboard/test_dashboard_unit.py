"""The dashboard's parts without a browser: the settings' ranges, the token rule, the board's
clock on the host's, the decimation for the eye, who controls."""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from utrf.dashboard import settings
from utrf.dashboard.access import COOKIE, TokenGuard, needs_token
from utrf.dashboard.hub import READ_LINGER_S, DashboardHub, NotInControl, SampleRing
from utrf.dashboard.page import hand_turn
from utrf.hand.clock import WallClock
from utrf.hand.session import HandSession
from utrf.hand.state import FingerState, HandState
from utrf.hand.state_block import StateBlock
from utrf.protocol import messages as m
from utrf.protocol.link import Link
from utrf.protocol.transport import SerialTransport


def test_settings_take_the_protocols_ranges_and_name_every_problem() -> None:
    kp = next(s for s in settings.settings("gains") if s.name == "kp")
    assert (kp.lo, kp.hi, kp.unit) == (0.0, 1000.0, "1/rad")  # spec.toml's set_gains.kp
    assert settings.check("gains", {"kp": "12.5", "ki": 0}) == {"kp": 12.5, "ki": 0.0}
    with pytest.raises(settings.SettingsError) as exc:
        settings.check("gains", {"kp": 5000, "kd": "x", "spin": 1, "ki": math.nan})
    text = str(exc.value)
    assert "kp = 5000 is outside its range [0, 1000]" in text
    assert "kd = 'x' is not a number" in text and "spin is not a gains field" in text
    assert "ki = nan is outside" in text and text.endswith("(nothing was sent)")
    with pytest.raises(settings.SettingsError, match=r"theta2_min 1 must be below theta2_max 0\.5"):
        settings.check("limits", {"theta2_min": 1.0, "theta2_max": 0.5})


def test_the_token_is_needed_beyond_loopback_and_kept_in_a_cookie() -> None:
    assert not needs_token("127.0.0.1") and not needs_token("localhost")
    assert needs_token("0.0.0.0") and needs_token("127.0.0.2") and needs_token("192.168.1.5")
    seen: list[str] = []

    async def app(scope: Any, receive: Any, send: Any) -> None:
        seen.append(scope["path"])
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"page"})

    guard = TokenGuard(app, "tok")

    def call(query: bytes, cookie: bytes | None = None) -> list[dict]:
        sent: list[dict] = []
        headers = [(b"cookie", cookie)] if cookie else []
        scope = {"type": "http", "path": "/", "query_string": query, "headers": headers}

        async def send(msg: dict) -> None:
            sent.append(msg)

        asyncio.run(guard(scope, None, send))
        return sent

    refused = call(b"")
    assert refused[0]["status"] == 401 and b"no token" in refused[1]["body"]
    assert call(b"token=nope")[0]["status"] == 401 and not seen
    ok = call(b"token=tok")
    assert ok[0]["status"] == 200 and seen == ["/"]
    assert (b"set-cookie", f"{COOKIE}=tok; HttpOnly; SameSite=Strict; Path=/".encode()) in ok[0][
        "headers"
    ]
    assert call(b"", cookie=f"{COOKIE}=tok".encode())[0]["status"] == 200
    assert call(b"", cookie=f"{COOKIE}=bad".encode())[0]["status"] == 401


def state(board: float, host: float, theta: float = 0.0) -> HandState:
    f = FingerState(
        "index", 0, theta, theta, 0.1, 0.0, m.ControlMode.POSITION, m.FaultBits(0), 0, 0
    )
    return HandState(board_time=board, host_time=host, seq=0, fingers=(f,))


def block(board: float, host: float, theta: float = 0.0) -> StateBlock:
    """One sample as the Hand's reader hands it on (``Hand.on_states``)."""
    return StateBlock.of_states([state(board, host, theta)])


class FakeHand:
    """What the hub asks of a Hand before any command."""

    fingers = ("index",)
    telemetry_hz = 1000
    link: object = None  # no line (as a SimLink)

    def __init__(self) -> None:
        self.poses: dict[str, object] = {"fist": object()}
        self.callbacks: list = []
        self.pose_calls: list[str] = []

    def limits(self, i: int) -> SimpleNamespace:
        return SimpleNamespace(theta2_min=-0.2, theta2_max=1.5)

    def safety(self) -> m.Safety:
        return m.Safety(heartbeat_timeout=0.5, safe_action=m.SafeAction.HOLD)

    def on_states(self, cb: Any) -> Any:
        self.callbacks.append(cb)
        return lambda: self.callbacks.remove(cb)

    def pose(self, name: str, duration: Any, wait: bool) -> None:
        self.pose_calls.append(name)

    def state(self) -> list[SimpleNamespace]:
        return [SimpleNamespace(index=0, closed_loop=True)]

    def hold(self, fingers: list[int]) -> None:
        self.pose_calls.append(f"hold {fingers}")


def test_the_boards_clock_is_followed_when_it_runs_at_another_pace() -> None:
    hand = FakeHand()
    hub = DashboardHub(hand)  # type: ignore[arg-type]
    rng = np.random.default_rng(1)
    # an emulated board at half speed: 1 s of board time takes 2 s; delays of 1-20 ms
    for k in range(3000):
        board = k * 1e-3
        hub._on_states(block(board, 100.0 + 2 * board + 0.001 + rng.exponential(0.004)))
    wall = hub.wall_time_of(2.999)
    assert abs(wall - (100.0 + 2 * 2.999 + 0.001)) < 0.003
    hub.close()


def test_the_hands_reader_takes_the_stream_in_batches_for_the_dashboard() -> None:
    hand = FakeHand()
    hand.link = link = Link(SerialTransport("loop://"), heartbeat_period_s=None)
    try:
        assert link.read_linger_s == 0.0  # a Link reads each frame as it comes
        hub = DashboardHub(hand)  # type: ignore[arg-type]
        assert link.read_linger_s == READ_LINGER_S > 0.0
        hub.close()
    finally:
        link.close()


def test_a_reopened_line_keeps_the_dashboards_linger() -> None:
    # Hand.reconnect after the line went away opens a new Link: it must read as the old one
    # did, or the dashboard's reader goes back to a read per frame
    first = Link(SerialTransport("loop://"), heartbeat_period_s=None)
    second = Link(SerialTransport("loop://"), heartbeat_period_s=None)
    try:
        session = HandSession(first, WallClock(), url="loop://")
        first.read_linger_s = READ_LINGER_S
        session.replace_link(second)
        assert session.link is second
        assert second.read_linger_s == READ_LINGER_S
    finally:
        first.close()
        second.close()


def test_the_ring_decimates_for_the_eye_and_keeps_the_newest() -> None:
    ring = SampleRing(1, 5000)
    for k in range(3000):
        ring.add(block(k * 1e-3, 0.0, theta=k * 1e-3))
    s = ring.series(2.0, points_per_s=25)
    assert s.board_time[-1] == pytest.approx(2.999)
    assert 49 <= len(s.board_time) <= 51  # 2 s at 25 a second
    np.testing.assert_allclose(np.diff(s.board_time), 0.04)
    np.testing.assert_array_equal(s.theta2[:, 0], s.board_time)


def test_the_rings_window_from_its_newest_samples_is_the_whole_rings() -> None:
    # the window looks at the samples its rate says it holds; a rate too low for the stream
    # (or a board clock at another pace) falls back to the whole ring: the same samples
    for rate in (1000.0, 100.0, 10_000.0):
        ring, whole = SampleRing(1, 5000, rate_hz=rate), SampleRing(1, 5000, rate_hz=1e9)
        for k in range(7000):  # wraps
            for r in (ring, whole):
                r.add(block(k * 1e-3, 0.0, theta=k * 1e-3))
        for seconds in (0.0, 0.05, 1.0, 2.0, 4.999, 10.0):
            np.testing.assert_array_equal(ring.clock(seconds)[0], whole.clock(seconds)[0])
            np.testing.assert_array_equal(
                ring.series(seconds, 25).theta2, whole.series(seconds, 25).theta2
            )


def test_a_reads_block_fills_the_ring_as_its_samples_one_by_one() -> None:
    # blocks of any size, across the ring's end, and one larger than the ring
    rng = np.random.default_rng(2)
    one, many = SampleRing(1, 100), SampleRing(1, 100)
    k = 0
    for size in [*rng.integers(1, 40, 20), 250, 3]:
        states = [state(j * 1e-3, 5.0 + j, theta=j * 1e-3) for j in range(k, k + size)]
        for st in states:
            one.add(StateBlock.of_states([st]))
        many.add(StateBlock.of_states(states))
        k += size
        assert one.count == many.count == k
        for a, b in zip(one.clock(1.0), many.clock(1.0), strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(one.series(1.0, 1000).theta2, many.series(1.0, 1000).theta2)


def test_an_update_asks_the_reader_for_the_newest_at_once() -> None:
    hand = FakeHand()
    hand.link = link = Link(SerialTransport("loop://"), heartbeat_period_s=None)
    asked: list[bool] = []
    link.read_soon = lambda: asked.append(True)  # type: ignore[method-assign]
    try:
        hub = DashboardHub(hand)  # type: ignore[arg-type]
        assert not asyncio.run(hub.next_sample(0.01)) and asked == [True]
        hub.close()
    finally:
        link.close()


def test_the_ring_keeps_each_fingers_fields_apart() -> None:
    ring = SampleRing(3, 100)
    mode = m.ControlMode.POSITION
    for k in range(10):
        fingers = tuple(
            FingerState("f", i, k + i, 10 * (k + i), 0.1 * i, 0.01 * i, mode, m.FaultBits(0), 0, 0)
            for i in range(3)
        )
        ring.add(StateBlock.of_states([HandState(k * 1e-3, 0.0, k, fingers)]))
    s = ring.series(1.0, points_per_s=1000)
    assert s.theta2.shape == (10, 3)
    k = np.arange(10)[:, None]
    i = np.arange(3)[None, :]
    np.testing.assert_allclose(s.theta2, k + i)
    np.testing.assert_allclose(s.target, 10 * (k + i))
    np.testing.assert_allclose(s.duty_a, np.broadcast_to(0.1 * i, (10, 3)))
    np.testing.assert_allclose(s.duty_b, np.broadcast_to(0.01 * i, (10, 3)))


def test_an_update_waits_for_the_next_sample_from_the_readers_thread() -> None:
    hub = DashboardHub(FakeHand())  # type: ignore[arg-type]

    async def run() -> tuple[bool, bool, float]:
        quiet = await hub.next_sample(0.02)  # no sample: it gives up at its timeout
        assert not hub._waiters  # and leaves no waiter behind
        loop = asyncio.get_running_loop()
        # a sample from another thread (the Hand's reader) wakes it at once
        loop.call_later(
            0.05, lambda: threading.Thread(target=hub._on_states, args=(block(1.0, 2.0),)).start()
        )
        t0 = time.monotonic()
        woken = await hub.next_sample(10.0)
        return quiet, woken, time.monotonic() - t0

    quiet, woken, waited = asyncio.run(run())
    assert not quiet and woken and waited < 5.0 and hub.latest is not None
    assert hub.latest.board_time == 1.0 and not hub._waiters
    # a page's wait left behind on a loop since closed (the server stopping) costs the
    # reader's thread nothing
    loop = asyncio.new_event_loop()
    hub._waiters.append((loop, loop.create_future()))
    loop.close()
    hub._on_states(block(1.001, 2.001))
    assert not hub._waiters and hub.latest.board_time == 1.001
    hub.close()


def test_the_3d_hand_and_the_charts_take_turns_after_the_numbers() -> None:
    last, drawn = False, []
    for _ in range(6):  # both due at every update: they alternate
        draw = hand_turn(True, True, last)
        drawn.append(draw)
        last = draw
    assert drawn == [True, False, True, False, True, False]
    assert hand_turn(True, False, True) and not hand_turn(False, True, False)


def test_one_page_controls_the_others_watch() -> None:
    hand = FakeHand()
    hub = DashboardHub(hand)  # type: ignore[arg-type]
    assert hub.join("a") and not hub.join("b")
    with pytest.raises(NotInControl):
        hub.pose("b", "fist")
    assert not hub.take_control("b")  # a still controls
    hub.pose("a", "fist").result()
    assert hand.pose_calls == ["fist"] and hub.sent["pose"] == 1
    hub.leave("a")
    assert hub.take_control("b") and hub.controller == "b"
    hub.close()


def test_a_page_in_control_that_goes_holds_the_fingers_unless_it_comes_back() -> None:
    hand = FakeHand()
    hub = DashboardHub(hand, hold_after_s=0.05)  # type: ignore[arg-type]
    assert hub.join("a") and not hub.join("b")
    hub.lost("b")  # a watcher going holds nothing
    hub.lost("a")
    hub.join("a")  # back within the grace: nothing held
    time.sleep(0.3)
    assert hand.pose_calls == []
    hub.lost("a")  # gone: held once, however long it stays away
    time.sleep(0.3)
    hub.leave("a")
    hub.close()
    assert hand.pose_calls == ["hold [0]"] and hub.controller is None


def test_the_status_and_the_recording_name_a_fingers_fields_alike(tmp_path: Any) -> None:
    from utrf.recording import schemas
    from utrf.recording.mcap_recorder import McapRecorder

    hub = DashboardHub(FakeHand())  # type: ignore[arg-type]
    hub._on_states(block(1.0, 2.0, theta=0.25))
    finger = hub.status()["fingers"]["index"]
    hub.close()
    assert tuple(finger) == tuple(schemas.FIELD_UNITS) and finger["theta2_rad"] == 0.25
    rec = McapRecorder(tmp_path / "r.mcap", ("index",), rate_hz=1000)
    rec.write_state(state(1.0, 2.0, theta=0.25))
    rec.close()
    from mcap.reader import make_reader

    with (tmp_path / "r.mcap").open("rb") as f:
        docs = [
            json.loads(msg.data)
            for _, ch, msg in make_reader(f).iter_messages()
            if ch.topic == schemas.STATE_TOPIC
        ]
    assert docs[0]["fingers"]["index"] == finger


def test_the_ring_keeps_the_host_times_for_the_clock() -> None:
    ring = SampleRing(1, 100)
    for k in range(250):  # wraps twice
        ring.add(block(k * 1e-3, 10.0 + k * 1e-3))
    board, host = ring.clock(0.0495)
    np.testing.assert_allclose(board, np.arange(200, 250) * 1e-3)
    np.testing.assert_allclose(host - board, 10.0)
