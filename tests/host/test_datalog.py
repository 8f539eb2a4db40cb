import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from utrf.datalog import CsvLog, LogFormatError, read_log

COLS = ("t", "a", "b")


def test_rows_round_trip(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    with CsvLog(p, COLS) as log:
        log.write([0.0, 1.5, "x"])
        log.write({"t": 0.1, "a": -2.0, "b": "y"})
    data = read_log(p, COLS)
    assert data.skipped == 0
    assert data.column("a") == [1.5, -2.0]
    assert data.column("b") == ["x", "y"]


def test_reopening_appends_under_the_same_header(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    with CsvLog(p, COLS) as log:
        log.write([0, 1, 2])
    with CsvLog(p, COLS) as log:
        log.write([1, 3, 4])
    assert p.read_text().count("t,a,b") == 1
    assert read_log(p).column("t") == [0.0, 1.0]


def test_a_different_header_is_refused_not_mixed(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    with CsvLog(p, COLS) as log:
        log.write([0, 1, 2])
    with pytest.raises(LogFormatError, match="columns"):
        CsvLog(p, ("t", "a"))
    assert read_log(p).column("t") == [0.0]


def test_bad_rows_are_refused(tmp_path: Path) -> None:
    with CsvLog(tmp_path / "log.csv", COLS) as log:
        with pytest.raises(ValueError, match="3 columns"):
            log.write([1, 2])
        with pytest.raises(ValueError, match="lacks"):
            log.write({"t": 1})


def test_a_half_written_row_is_skipped_and_the_next_append_is_clean(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    p.write_text("t,a,b\n0,1,2\n1,3")  # a writer killed mid-row
    data = read_log(p)
    assert data.skipped == 1 and data.column("t") == [0.0]
    with CsvLog(p, COLS) as log:
        log.write([2, 5, 6])
    data = read_log(p)
    assert data.column("t") == [0.0, 2.0]
    assert data.skipped == 0  # the cut row, never a whole sample, was dropped on reopening
    assert p.read_text() == "t,a,b\n0,1,2\n2,5,6\n"


def test_a_row_cut_inside_its_last_field_is_not_read_as_a_shortened_value(
    tmp_path: Path,
) -> None:
    p = tmp_path / "log.csv"
    p.write_text("t,a,b\n0,1,2\n1,3,4")  # killed while writing b = 45: full width, cut value
    with CsvLog(p, COLS) as log:
        log.write([2, 5, 6])
    data = read_log(p)
    assert data.column("b") == [2.0, 6.0]
    assert data.skipped == 0


def test_a_log_cut_inside_its_first_row_gets_its_header_again(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    p.write_text("t,a,b")  # killed before the header's newline
    with CsvLog(p, COLS) as log:
        log.write([1, 2, 3])
    assert read_log(p, COLS).column("t") == [1.0]


def test_a_killed_writer_keeps_every_row_it_wrote(tmp_path: Path) -> None:
    p = tmp_path / "log.csv"
    code = (
        "import sys, time\n"
        "from utrf.datalog import CsvLog\n"
        f"log = CsvLog({str(p)!r}, ('i', 'x'))\n"
        "i = 0\n"
        "while True:\n"
        "    log.write([i, i * 0.5]); print(i, flush=True); i += 1; time.sleep(0.001)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    last = -1
    deadline = time.monotonic() + 20
    while last < 200 and time.monotonic() < deadline:
        last = int(proc.stdout.readline())
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    data = read_log(p)
    got = [int(v) for v in data.column("i")]
    # Every row the writer reported written is on disk, in order, with nothing invented.
    assert got[: last + 1] == list(range(last + 1))
    assert got == list(range(len(got)))


def test_a_slow_disk_does_not_hold_up_the_writer(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The periodic fsync runs beside the writer; close() waits for it and syncs the rest."""
    synced: list[int] = []
    real_fsync = os.fsync

    def slow_fsync(fd: int) -> None:
        time.sleep(0.3)
        real_fsync(fd)
        synced.append(fd)

    monkeypatch.setattr(os, "fsync", slow_fsync)
    log = CsvLog(tmp_path / "log.csv", ["a"], fsync_period_s=0.0)
    t0 = time.monotonic()
    for i in range(20):  # every row is due a sync; at most one runs at a time
        log.write([i])
    assert time.monotonic() - t0 < 0.25
    log.close()
    assert len(synced) >= 2  # the periodic one, then close()'s own
    assert [r["a"] for r in read_log(tmp_path / "log.csv").rows] == list(range(20))
