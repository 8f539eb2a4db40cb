"""What every page of the dashboard shares: the Hand, the stream's recent samples, which page
controls, the commands and the recording. No web code here (the pages are
:mod:`utrf.dashboard.page`): this is the part the tests and the benchmarks drive directly too.

The Hand's reader thread only copies each read's samples into a ring (``Hand.on_states``: as
arrays, no HandState per sample); the pages read it decimated for the eye. Every command runs
on one worker thread, one at a time, through the Hand's public API, and only for the page in
control: a page that is not gets :class:`NotInControl` and nothing is sent. When the page in
control goes, the fingers under closed-loop control hold where they are (no finger is left
moving), and the next page to ask takes control. If the server itself stops, the board's
host-silence rule (``Hand.safety``) latches HOST_TIMEOUT and applies its safe action.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import contextlib
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from utrf.dashboard import settings as settings_
from utrf.hand import Hand, HandState
from utrf.hand.state_block import StateBlock
from utrf.protocol import messages as m
from utrf.protocol.link import Link
from utrf.recording import schemas

T = TypeVar("T")

#: a page in control whose connection drops holds the fingers unless back within this (s)
LOST_GRACE_S = 1.0
#: seconds of samples kept for the plots
WINDOW_S = 10.0
#: the board's clock is mapped to the host's over this many seconds of samples
OFFSET_WINDOW_S = 2.0
#: the Hand's reader waits this long after each read (s), so one read carries many frames of
#: the 1 kHz stream; a page about to update ends the wait (``Link.read_soon``: the sample it
#: sends is as fresh as without it), and a command's reply is read at once
#: (``Link.read_linger_s``)
READ_LINGER_S = 0.02


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class NotInControl(RuntimeError):
    """A command from a page that does not control the hand (nothing was sent)."""


@dataclass(frozen=True)
class Series:
    """Samples decimated for the eye: board times (s) and, per finger, the Joint-2 angle and
    setpoint (rad) and the duties (fractions)."""

    board_time: np.ndarray  # (n,)
    theta2: np.ndarray  # (n, fingers)
    target: np.ndarray
    duty_a: np.ndarray
    duty_b: np.ndarray


class SampleRing:
    """The last ``WINDOW_S`` of samples in preallocated arrays (written by the reader thread)."""

    def __init__(self, fingers: int, capacity: int, rate_hz: float | None = None) -> None:
        self.capacity = capacity
        # samples a second of board time (the board stamps each with its own clock): a window
        # looks only at the newest samples it can hold, not the whole ring
        self.rate_hz = rate_hz if rate_hz else capacity / WINDOW_S
        self._t = np.zeros(capacity)  # board time
        self._host = np.zeros(capacity)  # host receive time
        self.fingers = fingers
        # theta2, target, duty_a, duty_b, each per finger (StateBlock.values)
        self._v = np.zeros((capacity, 4, fingers))
        self._n = 0  # samples ever written
        self._lock = threading.Lock()

    def add(self, block: StateBlock) -> None:
        """A read's samples (on the Hand's reader thread), all at once."""
        total = len(block)
        skip = max(total - self.capacity, 0)  # only the newest fit
        t, host, v = block.board_time[skip:], block.host_time[skip:], block.values[skip:]
        k = total - skip
        with self._lock:
            i = (self._n + skip) % self.capacity
            j = min(i + k, self.capacity)  # to the ring's end, the rest from its start
            self._t[i:j], self._host[i:j], self._v[i:j] = t[: j - i], host[: j - i], v[: j - i]
            rest = k - (j - i)
            if rest:
                self._t[:rest], self._host[:rest] = t[-rest:], host[-rest:]
                self._v[:rest] = v[-rest:]
            self._n += total

    @property
    def count(self) -> int:
        return self._n

    def _last(self, seconds: float) -> np.ndarray:
        """Ring indices of the samples of the last ``seconds`` of board time, oldest first
        (the caller holds the lock)."""
        n = min(self._n, self.capacity)
        k = min(n, math.ceil(1.25 * seconds * self.rate_hz) + 16)  # what the window should hold
        idx = np.arange(self._n - k, self._n) % self.capacity
        if k < n and self._t[idx[0]] >= self._t[idx[-1]] - seconds:  # it reaches further back
            idx = np.arange(self._n - n, self._n) % self.capacity
        if n:
            idx = idx[self._t[idx] >= self._t[idx[-1]] - seconds]
        return idx

    def clock(self, seconds: float) -> tuple[np.ndarray, np.ndarray]:
        """(board times, host receive times) of the last ``seconds`` of samples."""
        with self._lock:
            idx = self._last(seconds)
            return self._t[idx], self._host[idx]

    def series(self, seconds: float, points_per_s: float) -> Series:
        """The last ``seconds`` at most ``points_per_s`` (every k-th sample, newest kept)."""
        with self._lock:
            idx = self._last(seconds)
            if len(idx) > 1:
                t0, t1 = self._t[idx[0]], self._t[idx[-1]]
                dt = (t1 - t0) / (len(idx) - 1)
                step = max(1, round(1.0 / (points_per_s * dt))) if dt > 0 else 1
                idx = idx[len(idx) - 1 :: -step][::-1]
            t = self._t[idx]
            v = self._v[idx]
        return Series(t, v[:, 0], v[:, 1], v[:, 2], v[:, 3])


class DashboardHub:
    """One Hand for all the pages of a dashboard."""

    def __init__(
        self, hand: Hand, *, record_dir: str | Path = ".", hold_after_s: float = LOST_GRACE_S
    ) -> None:
        self.hand = hand
        self.fingers = hand.fingers
        rate = max(hand.telemetry_hz, 1)
        self.ring = SampleRing(len(self.fingers), int(WINDOW_S * rate) + 1, rate)
        self.latest: HandState | None = None
        self._lock = threading.Lock()
        self._controller: str | None = None
        self.watchers: set[str] = set()  # pages open (connected or not)
        self._connected: set[str] = set()
        self._losses: dict[str, int] = {}  # each page's lost connections, counted
        self.hold_after_s = hold_after_s
        self.sent: collections.Counter[str] = collections.Counter()  # commands sent, by name
        self.pushed: collections.Counter[str] = collections.Counter()  # page updates, by kind
        self.record_dir = Path(record_dir)
        self.recording: Any = None  # utrf.recording.session.Recording while recording
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="utrf-dash")
        self.limits = [hand.limits(i) for i in range(len(self.fingers))]
        self.safety = hand.safety()
        self.pose_names = list(hand.poses)
        # pages waiting for the next sample (their event loop, its future): woken by the
        # reader thread, so an update sends a sample the moment it arrives
        self._waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future[None]]] = []
        self._waiters_lock = threading.Lock()
        self._unsubscribe = hand.on_states(self._on_states)
        if isinstance(hand.link, Link):  # a line (a SimLink reads none)
            hand.link.read_linger_s = READ_LINGER_S

    # --- the stream -----------------------------------------------------------------------------

    def _on_states(self, block: StateBlock) -> None:
        self.ring.add(block)
        self.latest = block.last
        if self._waiters:
            with self._waiters_lock:
                waiters, self._waiters = self._waiters, []
            for loop, future in waiters:
                with contextlib.suppress(RuntimeError):  # its loop closed (the server stops)
                    loop.call_soon_threadsafe(_wake, future)

    async def next_sample(self, timeout_s: float) -> bool:
        """Wait for the next sample to arrive (at most ``timeout_s``): an update that starts
        here sends a sample as fresh as the reader gives, not one a timer's phase aged.
        Returns whether one came."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[None] = loop.create_future()
        with self._waiters_lock:
            self._waiters.append((loop, future))
        link = self.hand.link
        if isinstance(link, Link):  # the reader's linger ends: the newest is read now
            link.read_soon()
        try:
            await asyncio.wait_for(future, timeout_s)
        except TimeoutError:
            with self._waiters_lock:
                if (loop, future) in self._waiters:
                    self._waiters.remove((loop, future))
            return False
        return True

    def wall_time_of(self, board_time: float) -> float:
        """When the board took a sample, on the host's wall clock, from its board time: the
        lower envelope of (board time, host receive time) over the last ``OFFSET_WINDOW_S``,
        through the least-delayed sample of each half of the window (so a board clock that
        runs at another pace than the host's, as an emulated board under load does, is
        followed; a sample's delay to the host is then what it took beyond the quickest)."""
        board, host = self.ring.clock(OFFSET_WINDOW_S)
        if len(board) < 2:
            return math.nan
        half = len(board) // 2
        delay = host - board
        if half < 1 or board[-1] - board[0] < OFFSET_WINDOW_S / 4:
            return board_time + float(delay.min())
        i = int(np.argmin(delay[:half]))
        j = half + int(np.argmin(delay[half:]))
        slope = (host[j] - host[i]) / (board[j] - board[i]) if board[j] > board[i] else 1.0
        return float(host[i] + slope * (board_time - board[i]))

    # --- who controls ---------------------------------------------------------------------------

    @property
    def controller(self) -> str | None:
        return self._controller

    def join(self, page: str) -> bool:
        """A page opens: it controls if none does. Returns whether it controls."""
        with self._lock:
            self.watchers.add(page)
            self._connected.add(page)
            self._losses[page] = self._losses.get(page, 0) + 1  # a pending hold is void
            if self._controller is None:
                self._controller = page
            return self._controller == page

    def lost(self, page: str) -> None:
        """A page's connection dropped (closed, or a blip): if it controls and is not back
        within ``hold_after_s``, the fingers in closed loop hold where they are then. It keeps
        control should it come back."""
        with self._lock:
            self._connected.discard(page)
            if self._controller != page:
                return
            self._losses[page] = loss = self._losses.get(page, 0) + 1
        timer = threading.Timer(self.hold_after_s, self._hold_if_gone, (page, loss))
        timer.daemon = True
        timer.start()

    def _hold_if_gone(self, page: str, loss: int) -> None:
        """The fingers held, once per loss, if the page is still away (and nobody else took
        control meanwhile)."""
        with self._lock:
            gone = (
                page not in self._connected
                and self._controller in (page, None)
                and self._losses.get(page) == loss
            )
        if gone:
            self._pool.submit(self._hold_all)

    def leave(self, page: str) -> None:
        """A page is gone for good (its connection dropped first: :meth:`lost` held the
        fingers): it no longer controls."""
        with self._lock:
            self.watchers.discard(page)
            self._connected.discard(page)
            if self._controller == page:
                self._controller = None

    def take_control(self, page: str) -> bool:
        with self._lock:
            if self._controller is None and page in self.watchers:
                self._controller = page
            return self._controller == page

    def _hold_all(self) -> None:
        st = self.hand.state()
        closed = [f.index for f in st if f.closed_loop]
        if closed:
            self.hand.hold(closed)
            self.sent["hold"] += 1

    # --- commands -------------------------------------------------------------------------------

    def _run(self, page: str, name: str, fn: Callable[[], T]) -> concurrent.futures.Future[T]:
        if self._controller != page:
            raise NotInControl("another page controls the hand: this one watches")

        def job() -> T:
            self.sent[name] += 1
            return fn()

        return self._pool.submit(job)

    def pose(
        self, page: str, name: str, duration: float | None = None
    ) -> concurrent.futures.Future:
        """One board-side move to a pose of the library (as ``Hand.pose``), not waited for."""
        if name not in self.pose_names:
            raise KeyError(f"no pose named {name!r}")
        return self._run(page, "pose", lambda: self.hand.pose(name, duration, wait=False))

    def move_finger(
        self, page: str, finger: int, theta2: float, duration: float = 0.3
    ) -> concurrent.futures.Future:
        """One finger to a Joint-2 angle (rad) in one board-side move, not waited for."""
        lim = self.limits[finger]
        theta2 = min(max(theta2, lim.theta2_min), lim.theta2_max)
        return self._run(
            page, "move", lambda: self.hand.move({finger: theta2}, duration, wait=False)
        )

    def clear_faults(self, page: str, finger: int) -> concurrent.futures.Future:
        return self._run(page, "clear_faults", lambda: self.hand.clear_faults(finger))

    def read_settings(self, group: str, finger: int) -> dict[str, float]:
        msg = {"gains": self.hand.gains, "limits": self.hand.limits, "motion": self.hand.motion}[
            group
        ](finger)
        return {s.name: float(getattr(msg, s.name)) for s in settings_.settings(group)}

    def apply_settings(
        self, page: str, group: str, finger: int, values: Mapping[str, object]
    ) -> concurrent.futures.Future:
        """Check ``values`` against the protocol's ranges (SettingsError: nothing sent), then
        set them (``Hand.set_gains``, ``set_limits``, ``set_motion``)."""
        checked = settings_.check(group, values)
        if self._controller != page:
            raise NotInControl("another page controls the hand: this one watches")
        setter = {
            "gains": self.hand.set_gains,
            "limits": self.hand.set_limits,
            "motion": self.hand.set_motion,
        }[group]

        def apply() -> Any:
            out = setter(finger, **checked)
            if isinstance(out, m.Limits):
                self.limits[finger] = out
            return out

        return self._run(page, f"set_{group}", apply)

    def save_eeprom(self, page: str) -> concurrent.futures.Future:
        return self._run(page, "save_config", self.hand.save_config)

    # --- recording ------------------------------------------------------------------------------

    def start_recording(self, page: str) -> Path:
        from utrf.recording.session import Recording

        if self._controller != page:
            raise NotInControl("another page controls the hand: this one watches")
        if self.recording is not None:
            return Path(self.recording.path)
        name = time.strftime("utrf-%Y%m%d-%H%M%S.mcap")
        self.recording = self._pool.submit(Recording, self.hand, self.record_dir / name).result()
        self.sent["record"] += 1
        return Path(self.recording.path)

    def stop_recording(self, page: str) -> Any:
        if self._controller != page:
            raise NotInControl("another page controls the hand: this one watches")
        rec, self.recording = self.recording, None
        return None if rec is None else self._pool.submit(rec.stop).result()

    # --- a summary for /api/status --------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        st = self.latest
        out: dict[str, Any] = {
            "controller": self._controller is not None,
            "pages": len(self.watchers),
            "samples": self.ring.count,
            "sent": dict(self.sent),
            "pushed": dict(self.pushed),
            "recording": None if self.recording is None else str(self.recording.path),
            "heartbeat_timeout_s": self.safety.heartbeat_timeout,
            "safe_action": m.SafeAction(self.safety.safe_action).name,
        }
        if st is not None:
            out["board_time_s"] = st.board_time
            out["fingers"] = {f.name: schemas.finger_fields(f) for f in st}
        return out

    def close(self) -> None:
        self._unsubscribe()
        if self.recording is not None:
            rec, self.recording = self.recording, None
            rec.stop()
        self._pool.shutdown(wait=True)
