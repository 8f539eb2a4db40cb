"""`utrf monitor` tells of bytes the board's UART lost (its stats' uart_overruns and
uart_frame_errors), read every few seconds."""

from __future__ import annotations

from dataclasses import replace

from utrf.cli import monitor
from utrf.protocol import messages as m

ZERO = m.Stats(**{f.name: 0 for f in m.Stats.FIELDS})


class _Board:
    def __init__(self, *stats: m.Stats) -> None:
        self.replies = list(stats)

    def stats(self) -> m.Stats:
        return self.replies.pop(0)


def test_a_line_when_the_uart_lost_bytes_and_none_otherwise() -> None:
    lost = replace(ZERO, uart_overruns=3, uart_frame_errors=1, rx_overruns=7)
    hand = _Board(ZERO, ZERO, lost)
    watch = monitor._Watch()
    assert monitor._board_losses(hand, watch) is None  # type: ignore[arg-type]  # the first read
    assert monitor._board_losses(hand, watch) is None  # type: ignore[arg-type]  # nothing new
    line = monitor._board_losses(hand, watch)  # type: ignore[arg-type]
    assert line is not None and "3 overruns, 1 frame errors" in line
    assert watch.board is lost
