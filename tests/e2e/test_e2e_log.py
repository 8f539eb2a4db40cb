"""A run killed at any moment keeps every sample its Hand logged."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from utrf.datalog import read_log
from utrf.hand import log_columns

RUN = """
import sys
from utrf.emulator import EmulatedBoard
from utrf.hand import Hand
seen = 0
def count(st):
    global seen
    seen += 1
    if seen % 50 == 0:
        print(seen, flush=True)   # after the Hand has logged this sample
with EmulatedBoard(sys.argv[1], realtime=False) as board:
    with Hand.emulated(board, telemetry_hz=500, log_path=sys.argv[2]) as hand:
        hand.on_state(count)
        while True:
            hand.move([1.0] * 5, 0.5, wait=False)
            hand.move([0.2] * 5, 0.5, wait=False)
"""


def test_a_killed_run_keeps_every_logged_sample(firmware_elf: Path, tmp_path: Path) -> None:
    log = tmp_path / "run.csv"
    proc = subprocess.Popen(
        [sys.executable, "-c", RUN, str(firmware_elf), str(log)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        counts = []
        deadline = time.monotonic() + 60
        while len(counts) < 6 and time.monotonic() < deadline:
            line = proc.stdout.readline()  # type: ignore[union-attr]
            if not line:
                break
            counts.append(int(line))
        os.kill(proc.pid, signal.SIGKILL)  # no close(), no flush at exit
    finally:
        proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL and counts, "the run never got going"
    data = read_log(log, log_columns(("thumb", "index", "middle", "ring", "little")))
    assert len(data.rows) >= counts[-1]  # every sample acknowledged before the kill is there
    assert data.skipped <= 1  # at most the row the kill cut short
