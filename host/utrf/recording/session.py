"""A recording of a live :class:`~utrf.hand.Hand`: every telemetry sample and fault to MCAP.

The Hand's reader thread only queues each sample (``Hand.on_state``); a writer thread encodes
and writes them, so a slow disk never stalls the link. :meth:`Recording.stop` drains the
queue, reads the board's and the link's stream counters against those at the start and
writes them into the file with the recorder's own count (``RecordingSummary``).
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from utrf.hand.state import FaultEvent, HandState
from utrf.models.skeleton import HandSkeleton
from utrf.recording.mcap_recorder import McapRecorder, RecordingSummary

if TYPE_CHECKING:
    from utrf.hand import Hand

_STOP = object()


class Recording:
    """Records ``hand`` to ``path`` from now until :meth:`stop` (or the ``with`` block's end)."""

    def __init__(self, hand: Hand, path: str | Path, *, scene_hz: float = 30.0) -> None:
        if hand.telemetry_hz <= 0:
            raise ValueError("the hand's telemetry stream is off: set_telemetry(rate) first")
        self.hand = hand
        self._tx0 = hand.stats().tx_dropped
        self._lost0 = hand.link_stats().stream_lost
        self.recorder = McapRecorder(
            path,
            hand.fingers,
            rate_hz=hand.telemetry_hz,
            skeleton=HandSkeleton(hand.geometry),
            scene_hz=scene_hz,
        )
        self.path = self.recorder.path
        self._queue: queue.SimpleQueue[object] = queue.SimpleQueue()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._drain, name="utrf-recording", daemon=True)
        self._thread.start()
        self._unsubscribe = [hand.on_state(self._queue.put), hand.on_fault(self._queue.put)]
        self._summary: RecordingSummary | None = None

    @property
    def samples(self) -> int:
        return self.recorder.summary.samples

    def _drain(self) -> None:
        rec = self.recorder
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            try:
                if isinstance(item, HandState):
                    rec.write_state(item)
                elif isinstance(item, FaultEvent):
                    rec.write_fault(item)
            except BaseException as exc:  # kept and raised by stop(): nothing dies silently
                self.error = exc
                return

    def stop(self) -> RecordingSummary:
        """Stop, write the counters, close the file; returns what it holds and lost."""
        if self._summary is not None:
            return self._summary
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._queue.put(_STOP)
        self._thread.join()
        s = self.recorder.summary
        try:
            s.board_tx_dropped = self.hand.stats().tx_dropped - self._tx0
            s.link_stream_lost = self.hand.link_stats().stream_lost - self._lost0
        except Exception as exc:  # a board gone: the samples are kept all the same
            s.extra["counters_error"] = str(exc)
        self._summary = self.recorder.close()
        if self.error is not None:
            raise self.error
        return self._summary

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
