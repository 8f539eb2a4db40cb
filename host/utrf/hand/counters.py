"""The board's and the host's link and timing counters, and one timed round trip."""

from __future__ import annotations

from utrf.hand.session import HandSession
from utrf.protocol import messages as m
from utrf.protocol.link import LinkStats


class HandCounters:
    """Counters of both ends (a part of :class:`~utrf.hand.Hand`)."""

    def __init__(self, session: HandSession) -> None:
        self._session = session

    def stats(self) -> m.Stats:
        """The board's link and timing counters."""
        return self._session.request(m.GetStats())

    def reset_stats(self) -> None:
        self._session.request(m.ResetStats())

    def link_stats(self) -> LinkStats:
        """The host side's counters (frames, retries, CRC errors, stream frames lost...)."""
        return self._session.link.stats()

    def ping(self) -> float:
        """One round trip (s): wall clock, or simulated time on a driven board."""
        clock = self._session.clock
        t0 = clock.now()
        self._session.request(m.Ping(token=0x55AA))
        return clock.now() - t0
