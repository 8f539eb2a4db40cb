""":meth:`SimLink.sleep_each <utrf.hand.simlink.SimLink.sleep_each>` with the stops in C, in
batches (:meth:`SimLink.stops_each`): the fast path beside the general one, the same samples.

``sleep_each`` stops the board at every end for ``take()`` (Python reads the plant, hits it)
and starts it again: thousands of stops a hold, the board standing still at each. Here the
caller says beforehand what ``take()`` does to the plant (:class:`Stops`: the hits, each with
its time) and what it reads (the plant's truth: the tips, the motors' currents), and the
harness does it at each end (``EmulatedBoard.run_ahead_stops``), so the board runs through
several ends in one run ahead while the caller works on the last batch's. The heartbeats
go out at the engine's times within a batch: the harness keeps the engine's rule (the next
a period after the later of the last one sent and the last ack heard) and frames the output
to hear the acks (``utrf_sim_ahead_beats``); the engine is told of each after the join, and
a test of its own keeps the two in step (the due time each went for is the engine's). A
batch ends where the general path could decide otherwise: at a frame the harness cannot
place (a boot, a damaged frame: the next stop), at the end that may be the caller's last,
and at :data:`~utrf.emulator.harness_abi.STOPS` ends. Every end is one a run ahead to it would
reach, to the cycle (a test compares the two paths' holds byte for byte); where the general
path would not run ahead (a plain sleep) or a run ends short (a crash, its marks full), that
end is taken the general way.
"""

from __future__ import annotations

from bisect import bisect_left
from collections import deque
from collections.abc import Callable, Generator, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from utrf.emulator.board_driven import Beats
from utrf.emulator.board_types import EmulatorError
from utrf.emulator.harness_abi import BEATS, F_CPU_HZ, HITS, STOPS
from utrf.protocol import messages as m
from utrf.protocol.engine import HEARTBEAT_SEQS_KEPT, SEQ_MASK, STREAM_IDS, Engine
from utrf.protocol.framing import encode_frame

if TYPE_CHECKING:
    from utrf.hand.simlink import SimLink

T = TypeVar("T")
#: per message id, what the harness's heartbeat rule makes of a frame: 1 the stream (with the
#: board's seq flag; the boot is not: it stops the heartbeats), 2 an ack, 0 anything else
KINDS = bytes(
    1 if i in STREAM_IDS and i != m.Boot.ID else 2 if i == m.Ack.ID else 0 for i in range(256)
)
#: how far past an exchange's end the MCU may stop (cycles): it ends at the first instruction
#: boundary there, a few cycles on (an interrupt's entry at most); a stop past it is an error
OVERSHOOT_BOUND = 1_000


@dataclass
class Stops:
    """What ``take()`` does at each end, for the harness to do: ``hits`` (time from ``t0``,
    body, site, world impulse N s, duration s; rising time) each applied at the first end
    whose ``now - t0`` reaches its time; ``made(now, truth, hits)`` gives what ``take()``
    would have (None: the end is the last), from the time, the truth the end recorded and
    how many hits were applied there; an end whose ``now - t0`` passes ``last_s`` must be
    its last."""

    t0: float
    hits: list[tuple[float, int, int, Any, float]]
    last_s: float
    made: Callable[[float, np.ndarray, int], Any]
    applied: int = 0  # hits applied so far


@dataclass
class _Batch:
    """A run ahead under way through ``ends`` (their ``targets``)."""

    ends: list[float]
    targets: list[int]
    beats: list[tuple[int, bytes]]  # the heartbeats the harness may send, in order


def stops_each(
    link: SimLink, ends: Iterable[float], take: Callable[[], T | None], stops: Stops
) -> Generator[T, None, None]:
    """The batches; see the module. Each batch's samples are made and yielded while the next
    batch runs (the engine takes a batch's frames first: the next one's heartbeat hangs on
    them), as ``sleep_each`` works on a sample while the board runs to the next."""
    upcoming: deque[float] = deque()
    it = iter(ends)

    def peek(k: int) -> float | None:
        while len(upcoming) <= k:
            nxt = next(it, None)
            if nxt is None:
                return None
            upcoming.append(nxt)
        return upcoming[k]

    def general() -> T | None:
        """The next end the general way: the board sleeps to it, then the sample is taken."""
        end = upcoming.popleft()
        link.sleep(end - link.now())
        return take()

    batch = _start(link, peek, upcoming, stops)
    try:
        while batch is not None or peek(0) is not None:
            if batch is None:  # the general way, for this end
                link._deliver_arrived()
                value = general()
                if value is None:
                    return
                yield value
                batch = _start(link, peek, upcoming, stops)
                continue
            joined = _join(link, batch, stops)
            cycles, truths, applied = joined.cycles, joined.truths, joined.applied
            done = joined.done
            for end in reversed(batch.ends[len(cycles) :]):  # not reached: taken again
                upcoming.appendleft(end)
            last = bool(cycles) and cycles[-1] / F_CPU_HZ - stops.t0 > stops.last_s
            go_on = done and not last
            carried = joined.carried if go_on else None
            if carried is not None:
                # the next batch starts before the engine takes this one's frames: the
                # harness's heartbeat rule carries on (its state is the engine's after them)
                nxt = _start(link, peek, upcoming, stops, carried)
                _take(link, batch, joined)
                _check_carried(link, carried)
            else:
                _take(link, batch, joined)
                nxt = _start(link, peek, upcoming, stops) if go_on else None
            batch = nxt
            for k, cycle in enumerate(cycles):
                now = cycle / F_CPU_HZ
                link._deliver_arrived(now)
                value = stops.made(now, truths[k], applied[k])
                if value is None:
                    return
                yield value
            link._deliver_arrived()
            if not done:  # short (a crash, the marks full): the next end the general way
                value = general()
                if value is None:
                    return
                yield value
                batch = _start(link, peek, upcoming, stops)
    finally:  # what the board ran reaches the engine and the callbacks, a caller stopping too
        if batch is not None:
            _take(link, batch, _join(link, batch, stops))
        link._deliver_arrived()


@dataclass
class _Carried:
    """The harness's heartbeat rule after a batch, before the engine has taken its frames:
    the next due time, the seqs whose acks count, the engine's next seq once it is told of
    the batch's heartbeats."""

    due: float
    awaited: set[int]
    seq: int


@dataclass
class _Joined:
    """A batch joined, its frames not yet taken by the engine (``_take``)."""

    cycles: list[int]
    truths: np.ndarray
    applied: list[int]
    done: bool
    sent: list[int]
    dues: list[float]
    carried: _Carried | None


def _start(
    link: SimLink,
    peek: Callable[[int], float | None],
    upcoming: deque[float],
    stops: Stops,
    carried: _Carried | None = None,
) -> _Batch | None:
    """The next batch started on the board (its ends taken off ``upcoming``), or None where
    the general path would not run ahead to the next end. ``carried``: the heartbeats from
    the harness's rule, the last batch's frames not yet taken (else from the engine's)."""
    plan = _plan(link, peek, stops, carried)
    if plan is None:
        return None
    targets, beats = plan
    hits = stops.hits[stops.applied : stops.applied + HITS]
    link.board.run_ahead_stops(targets, stops.t0, hits, beats=beats)
    return _Batch([upcoming.popleft() for _ in targets], targets, beats[0] if beats else [])


def _join(link: SimLink, batch: _Batch, stops: Stops) -> _Joined:
    """Wait for a batch: its stops' cycles, truths and hits applied at each (counted in
    ``stops``), whether it reached its end, the heartbeats it sent and where the harness's
    rule stands. Its frames wait, cut at the marks and stamped there, for ``_take``."""
    board = link.board
    run = board.run_ahead_join()
    cycles, truths, hit_stop = board.run_ahead_stops_done()
    sent, dues = board.run_ahead_beats_done()
    rule = board.run_ahead_beats_next() if batch.beats else None
    data = board.read()
    for cycle, target in zip(cycles, batch.targets, strict=False):
        if not 0 <= cycle - target <= OVERSHOOT_BOUND:  # the plan assumed it: say so
            raise EmulatorError(
                f"a stop ended {cycle - target} cycles past its exchange's end (planned "
                f"within {OVERSHOOT_BOUND}): the batched samples may differ from sleep_each's"
            )
    at = 0
    for n, t in run.marks:
        link._arrived.append((data[at:n], t))
        at = n
    link._arrived.append((data[at:], link.now()))
    applied = [sum(1 for s in hit_stop if s == k) for k in range(len(cycles))]
    stops.applied += sum(applied)
    carried = None
    if rule is not None and link._heartbeat is None:
        carried = _Carried(rule[0], rule[1], (link._engine._seq + len(sent)) & SEQ_MASK)
    return _Joined(cycles, truths, applied, run.done, sent, dues, carried)


def _take(link: SimLink, batch: _Batch, joined: _Joined) -> None:
    """The engine takes a joined batch's frames, told of its heartbeats among them."""
    _heartbeats(link, batch, joined.cycles, joined.sent, joined.dues)
    link._take_arrived()


def _check_carried(link: SimLink, carried: _Carried) -> None:
    """The engine, having taken the frames, stands where the harness's rule said it would
    (the next batch was planned from the rule): say so if not."""
    engine = link._engine
    if (
        engine.heartbeat_due() != carried.due
        or set(engine._heartbeat_seqs) != carried.awaited
        or engine._seq != carried.seq
    ):
        raise EmulatorError(
            f"the harness's heartbeat rule stood at {carried.due!r} awaiting "
            f"{sorted(carried.awaited)}, the engine's at {engine.heartbeat_due()!r} awaiting "
            f"{sorted(engine._heartbeat_seqs)}: the batched samples may differ from sleep_each's"
        )


def _exchanges(seconds: float, period: float, plain: float | None) -> int | None:
    """The exchanges ``sleep_each`` runs ahead for ``seconds`` (None: it sleeps plainly)."""
    if seconds < period / 2 or (plain is not None and seconds > plain):
        return None
    return max(round(seconds / period), 1)


def _plan(
    link: SimLink,
    peek: Callable[[int], float | None],
    stops: Stops,
    carried: _Carried | None = None,
) -> tuple[list[int], Beats | None] | None:
    """The next batch's stops (cycles) and its heartbeat, or None where the general path would
    not run ahead to the next end; the heartbeats from ``carried`` where given."""
    board, engine = link.board, link._engine
    period = board.exchange_period
    if carried is None:
        link._take_arrived()  # the heartbeat's due time counts every ack that came
    if link._heartbeat is not None:
        return None  # one made and not sent (a run ended short): the general way sends it
    due = engine.heartbeat_due() if carried is None else carried.due
    hb = engine.heartbeat_period_s
    plain = min(hb / 2, link.pump_interval_s) if hb is not None else None
    now = link.now()
    lo = hi = now  # where the MCU stands at the stop before (known exactly at the first)
    plant = board.plant_cycle
    # the first hit the harness is not given: the batch ends before it could fall due
    unheld = stops.hits[stops.applied + HITS][0] if len(stops.hits) > stops.applied + HITS else None
    targets: list[int] = []
    k = 0
    while len(targets) < STOPS:
        end = peek(k)
        if end is None:
            break
        counts = {_exchanges(end - at, period, plain) for at in (lo, hi)}
        n = counts.pop()
        if counts or n is None:  # the MCU's few cycles past the stop could change it, or
            break  # sleep_each would not run ahead here
        target = board.exchanges_after(plant, n * period)
        if unheld is not None and (target + OVERSHOOT_BOUND) / F_CPU_HZ - stops.t0 >= unheld:
            break  # a hit beyond the harness's list may fall due here
        targets.append(target)
        k += 1
        if (target + OVERSHOOT_BOUND) / F_CPU_HZ - stops.t0 > stops.last_s:
            break  # this end may be the last: nothing runs past it
        plant = target
        lo, hi = target / F_CPU_HZ, (target + OVERSHOOT_BOUND) / F_CPU_HZ
    if not targets:
        return None
    if due is None or hb is None:
        return targets, None
    # the engine forgets seqs beyond its count
    awaited = set(engine._heartbeat_seqs) if carried is None else carried.awaited
    n = max(min(BEATS, HEARTBEAT_SEQS_KEPT - len(awaited)), 0)
    frames = next_heartbeats(engine, n, None if carried is None else carried.seq)
    return targets, (frames, due, hb, awaited, KINDS)


def next_heartbeats(engine: Engine, n: int, seq: int | None = None) -> list[tuple[int, bytes]]:
    """The next ``n`` heartbeats' (seq, frame) as ``engine.heartbeat()`` will make them if
    nothing else is sent first (its seq read here, or ``seq``: no other driver needs it)."""
    first = engine._seq if seq is None else seq
    return [
        (s, encode_frame(s, m.Heartbeat.ID)) for s in ((first + i) & SEQ_MASK for i in range(n))
    ]


def _heartbeats(
    link: SimLink, batch: _Batch, cycles: list[int], sent: list[int], dues: list[float]
) -> None:
    """The engine told of the heartbeats the harness sent, each after the frames that came
    before its stretch of the run (where ``sleep_each`` decided it) and checked against them:
    the due time it went for is the engine's, its frame the one the engine makes."""
    engine = link._engine
    for beat, (cycle, due) in enumerate(zip(sent, dues, strict=True)):
        k = bisect_left(cycles, cycle)  # its stretch: the first stop at or past it
        start = cycles[k - 1] / F_CPU_HZ if k else -float("inf")
        n = next((i for i, (_, t) in enumerate(link._arrived) if t > start), len(link._arrived))
        for data, t in link._arrived[:n]:
            link._items += engine.receive(data, t)
        del link._arrived[:n]
        tx = engine.heartbeat(due) if engine.heartbeat_due() == due else None
        if tx is None or tx.data != batch.beats[beat][1]:
            raise EmulatorError(
                f"the harness sent a heartbeat at {cycle / F_CPU_HZ:.6f} s for {due:.6f} s, "
                f"the engine's next was due at {engine.heartbeat_due()}: the batched "
                "samples may differ from sleep_each's"
            )
        engine.sent(tx, cycle / F_CPU_HZ)
