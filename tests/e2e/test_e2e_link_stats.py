"""`Hand.link_stats()` on a clean line: no loss reported (issue 9 §6). A one-item queue that
nobody read once counted every frame received as dropped."""

from __future__ import annotations

import time
from pathlib import Path

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand


def test_a_clean_run_reports_no_telemetry_loss(firmware_elf: Path) -> None:
    with EmulatedBoard(firmware_elf, realtime=True, pty=False, seed=2) as board:
        assert board.url is not None
        with Hand.connect(board.url, telemetry_hz=200, boot_wait_s=0.5) as hand:
            seen: list[int] = []
            hand.on_state(lambda st: seen.append(st.seq))
            time.sleep(1.0)
            stats = hand.link_stats()
    assert stats.stream_frames >= 100 and len(seen) >= 100
    assert stats.telemetry_dropped == 0
    assert stats.stream_lost == 0
