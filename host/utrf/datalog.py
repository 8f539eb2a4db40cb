"""Append-safe CSV logs for telemetry and bench runs.

Every row is written and flushed to the kernel as it arrives, so a run killed at any moment
keeps every sample it took; an fsync every ``fsync_period_s`` bounds the loss on power
failure. The periodic fsync runs in a thread of its own, so a slow disk does not hold up the
run that writes (an emulated run writes ten times faster than real time); ``close()`` waits
for it and syncs the rest. Reopening a log appends to it when the header matches. A row cut
short by a kill is skipped, and counted, by :func:`read_log`; reopening the log drops it (it
was never a whole sample, and a row cut inside its last field would otherwise read as a full
row with a shortened number).
"""

from __future__ import annotations

import csv
import io
import math
import os
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType


class LogFormatError(ValueError):
    """A log file whose header does not match what is being written or read."""


class CsvLog:
    """A CSV file opened for appending rows of fixed columns."""

    def __init__(
        self, path: str | Path, columns: Sequence[str], *, fsync_period_s: float = 1.0
    ) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        if len(set(self.columns)) != len(self.columns) or not self.columns:
            raise ValueError(f"columns must be unique and non-empty, got {columns!r}")
        self._fsync_period = fsync_period_s
        self.path.parent.mkdir(parents=True, exist_ok=True)
        existing = self.path.exists() and self.path.stat().st_size > 0
        if existing:
            with self.path.open("rb") as f:
                header = f.readline().decode("utf-8", "replace").rstrip("\r\n")
            found = next(csv.reader([header]), [])
            if tuple(found) != self.columns:
                raise LogFormatError(
                    f"{self.path}: existing log has columns {found}, not {list(self.columns)}; "
                    "write to a new file"
                )
            _drop_cut_row(self.path)
            existing = self.path.stat().st_size > 0  # not if all there was, was a cut header
        self._file = self.path.open("a", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file, lineterminator="\n")
        if not existing:
            self._writer.writerow(self.columns)
        self._file.flush()
        self._last_sync = time.monotonic()
        self._syncing: threading.Thread | None = None
        self.rows_written = 0

    def write(self, row: Mapping[str, object] | Sequence[object]) -> None:
        if isinstance(row, Mapping):
            missing = [c for c in self.columns if c not in row]
            if missing:
                raise ValueError(f"{self.path}: row lacks column(s) {missing}")
            values = [row[c] for c in self.columns]
        else:
            values = list(row)
            if len(values) != len(self.columns):
                raise ValueError(
                    f"{self.path}: row has {len(values)} values for {len(self.columns)} columns"
                )
        self._writer.writerow(values)
        self._written()

    def write_line(self, line: str) -> None:
        """A row its caller formatted as :meth:`write` would write it (fields needing no
        quotes, comma-separated, ending in a newline): the fast path of a log written at
        every sample; the caller keeps a test comparing the two."""
        if line.count(",") != len(self.columns) - 1 or not line.endswith("\n"):
            raise ValueError(f"{self.path}: a line of {len(self.columns)} fields, got {line!r}")
        self._file.write(line)
        self._written()

    def _written(self) -> None:
        """A row is out: flushed to the kernel, counted, an fsync started when one is due."""
        self._file.flush()
        self.rows_written += 1
        now = time.monotonic()
        if now - self._last_sync >= self._fsync_period and not self._sync_running():
            self._syncing = threading.Thread(
                target=os.fsync, args=(self._file.fileno(),), name="csvlog-fsync", daemon=True
            )
            self._syncing.start()
            self._last_sync = now

    def _sync_running(self) -> bool:
        return self._syncing is not None and self._syncing.is_alive()

    def close(self) -> None:
        if not self._file.closed:
            self._file.flush()
            if self._syncing is not None:
                self._syncing.join()  # before the descriptor goes
            os.fsync(self._file.fileno())
            self._file.close()

    def __enter__(self) -> CsvLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _drop_cut_row(path: Path, chunk: int = 1 << 16) -> None:
    """Truncate a file that does not end in a newline back to its last one."""
    with path.open("r+b") as f:
        end = f.seek(0, os.SEEK_END)
        pos = end
        while pos > 0:
            start = max(0, pos - chunk)
            f.seek(start)
            block = f.read(pos - start)
            if pos == end and block.endswith(b"\n"):
                return  # ends clean
            nl = block.rfind(b"\n")
            if nl >= 0:
                f.truncate(start + nl + 1)
                return
            pos = start
        f.truncate(0)  # not one whole line


@dataclass(frozen=True)
class LogData:
    columns: tuple[str, ...]
    rows: list[dict[str, float | str]]
    skipped: int  # rows cut short (a killed writer) or malformed

    def column(self, name: str) -> list[float | str]:
        if name not in self.columns:
            raise KeyError(f"no column {name!r}; columns are {list(self.columns)}")
        return [r[name] for r in self.rows]


def _value(text: str) -> float | str:
    try:
        v = float(text)
    except ValueError:
        return text
    return v if math.isfinite(v) or text.lower() in ("nan", "inf", "-inf") else text


def read_log(path: str | Path, columns: Sequence[str] | None = None) -> LogData:
    """All complete rows of a log; numbers as float. Rows of the wrong width are skipped."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    reader = csv.reader(io.StringIO(text))
    header = tuple(next(reader, ()))
    if not header:
        raise LogFormatError(f"{path}: empty log, no header")
    if columns is not None and header != tuple(columns):
        raise LogFormatError(f"{path}: columns are {list(header)}, expected {list(columns)}")
    complete_text = text if text.endswith("\n") else text[: text.rfind("\n") + 1]
    lines = list(csv.reader(io.StringIO(complete_text)))[1:]
    skipped = 0 if text.endswith("\n") else 1
    rows = []
    for line in lines:
        if len(line) != len(header):
            skipped += 1
            continue
        rows.append({c: _value(v) for c, v in zip(header, line, strict=True)})
    return LogData(columns=header, rows=rows, skipped=skipped)


def read_rows(path: str | Path, columns: Sequence[str]) -> list[dict[str, float | str]]:
    """The complete rows of a log that a killed writer may have left: none when the file is
    missing or its header was cut short (a kill before the first row); else :func:`read_log`'s
    rows. A whole header of other columns is still an error."""
    path = Path(path)
    if not path.exists():
        return []
    with path.open("rb") as f:
        first = f.readline()
    if not first.endswith(b"\n"):
        return []  # the header itself was cut: not one row was written
    return read_log(path, columns).rows
