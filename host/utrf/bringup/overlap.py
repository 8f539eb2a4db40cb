"""Two fingers' bring-up steps at once on one hand: each finger's steps run on its own thread,
and the threads take turns at the hand: only the thread holding the turn talks to the hand,
and it gives the turn up only while it waits on the hand's clock, in slices of at most
``SLICE_S`` of the clock. So on a driven board (simulated time, one thread may drive it) the
board runs for whichever finger waits, each finger's pulse is watched at least every slice as
when it runs alone, and a wait ends when the clock has passed its end (the other finger's
slices count). The fingers are mechanically independent; what crosses channels (the wiring's
cable check) is done before, one finger at a time (``procedure.bringup``).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

from utrf.hand import Hand

#: the longest a thread waits on the clock before the other takes its turn (s): the pulses'
#: own poll (``pulses.POLL_S``)
SLICE_S = 0.005

T = TypeVar("T")


class Stopped(Exception):
    """Raised in a finger's thread at its next wait when another finger's thread failed or
    the person pressed Ctrl-C: its pulse's own clean-up brakes its finger."""


class Turns:
    """Whose turn it is at the hand: first come, first served, handed on at each wait."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._queue: deque[int] = deque()
        self._holder: int | None = None
        self.stopped = False

    def take(self) -> None:
        me = threading.get_ident()
        with self._cond:
            self._queue.append(me)
            while self._holder is not None or self._queue[0] != me:
                self._cond.wait()
            self._queue.popleft()
            self._holder = me

    def give(self) -> None:
        with self._cond:
            self._holder = None
            self._cond.notify_all()

    def wait_queued(self, n: int) -> None:
        """Until ``n`` threads wait for a turn (each finger's thread is in line before the
        first one runs, so the turns alternate from the start)."""
        with self._cond:
            while len(self._queue) < n:
                self._cond.wait(0.01)

    def hand_on(self) -> None:
        """Let a waiting thread take a turn, then take one again."""
        self.give()
        self.take()
        if self.stopped:
            raise Stopped("stopped: another finger's bring-up failed or was interrupted")


@contextmanager
def taking_turns(hand: Hand, turns: Turns) -> Iterator[None]:
    """The hand's clock, while inside, waits in slices and hands the turn on between them."""
    clock = hand.clock
    sleep: Callable[[float], None] = clock.sleep

    def sliced(seconds: float) -> None:
        if seconds <= 0:
            return
        end = clock.now() + seconds
        while True:
            left = end - clock.now()
            if left <= SLICE_S / 10:
                break
            before = clock.now()
            sleep(min(SLICE_S, left))
            turns.hand_on()
            if clock.now() == before and end - clock.now() < SLICE_S:
                break  # less than the board's step is left: the clock will not move for it

    own = vars(clock).get("sleep")  # a sleep already put on the instance (a test's), kept
    clock.sleep = sliced  # type: ignore[method-assign]  # on this hand's clock alone, undone below
    try:
        yield
    finally:
        if own is None:
            del clock.sleep  # the class's method again
        else:
            clock.sleep = own  # type: ignore[method-assign]  # the test's own, put back


def apart_fingers(hand: Hand) -> Callable[[int, int], bool]:
    """Whether two fingers can never touch, whatever their angles: they flex in parallel
    planes further apart than their links are thick (``utrf.models.mjcf.never_touching``, the
    model's layout of the hand). The thumb, which closes across the palm, may touch the
    others."""
    from utrf.models.mjcf import FINGER_CONTYPE, never_touching  # MuJoCo: only when asked
    from utrf.models.mjcf_layout import load_layout

    apart = never_touching(hand.geometry, load_layout())
    return lambda i, j: bool(apart[i] & (FINGER_CONTYPE << j))


def run_overlapped(
    hand: Hand,
    jobs: Sequence[Callable[[], T]],
    width: int = 2,
) -> list[T]:
    """Run ``jobs`` (each one finger's steps) ``width`` at a time, taking turns at the hand;
    their results in order. The first failure (or Ctrl-C here) stops the others at their next
    wait and is raised once they have ended."""
    if width <= 1 or len(jobs) <= 1:
        return [job() for job in jobs]
    turns = Turns()
    results: dict[int, Any] = {}
    errors: list[BaseException] = []
    pending = deque(range(len(jobs)))

    def worker() -> None:
        turns.take()
        try:
            while pending and not turns.stopped:
                i = pending.popleft()
                results[i] = jobs[i]()
        except BaseException as exc:  # handed to the caller's thread
            if not isinstance(exc, Stopped):
                errors.append(exc)
            turns.stopped = True
        finally:
            turns.give()

    threads = [threading.Thread(target=worker, daemon=True) for _ in range(min(width, len(jobs)))]
    with taking_turns(hand, turns):
        held = False
        try:
            turns.take()  # held here until every finger's thread is in line
            held = True
            for th in threads:
                th.start()
            turns.wait_queued(len(threads))
            held = False
            turns.give()
            for th in threads:
                while th.is_alive():
                    th.join(0.05)
        except BaseException:  # Ctrl-C lands here: stop the fingers, then let it go on
            turns.stopped = True
            if held:
                turns.give()
            for th in threads:
                th.join()
            raise
    if errors:
        raise errors[0]
    return [results[i] for i in range(len(jobs))]
