"""Recordings (MCAP) and telemetry CSV logs to Parquet: one row per sample, the CSV log's SI
column names (``index_theta2_rad``, ``board_time_s``...), each column's unit in its field
metadata (``unit``) and all of them in the file's (``utrf.units``, JSON), so pandas, polars
and pyarrow read them without a converter."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from utrf.datalog import read_log
from utrf.hand.telemetry_log import FINGER_FIELDS
from utrf.recording import schemas


class ExportError(ValueError):
    """A file that cannot be exported; the message names it and why."""


def _finger_names_of(columns: Sequence[str]) -> list[str]:
    suffix = "_" + FINGER_FIELDS[0]
    return [c[: -len(suffix)] for c in columns if c.endswith(suffix)]


def _column_type(column: str) -> pa.DataType:
    if column.endswith("_mode"):
        return pa.string()
    if column == "seq" or column.endswith("_faults"):
        return pa.int64()
    return pa.float64()


def table_of(rows: dict[str, list[object]], source: str) -> pa.Table:
    """The columns as an Arrow table with SI units in its metadata."""
    names = _finger_names_of(list(rows))
    units = schemas.column_units(names)
    if list(rows) != list(units):
        raise ExportError(f"{source}: columns {list(rows)} are not a telemetry log's")
    fields = [
        pa.field(c, _column_type(c), metadata={"unit": units[c]} if units[c] else None)
        for c in units
    ]
    meta = {
        "utrf.units": json.dumps(units),
        "utrf.fingers": json.dumps(names),
        "utrf.source": source,
    }
    return pa.Table.from_pydict(rows, schema=pa.schema(fields, metadata=meta))


def rows_from_csv(path: Path) -> dict[str, list[object]]:
    log = read_log(path)
    out: dict[str, list[object]] = {c: [] for c in log.columns}
    for row in log.rows:
        for c in log.columns:
            v = row[c]
            if c == "seq" or c.endswith("_faults"):
                empty = v == "" or (isinstance(v, float) and math.isnan(v))
                out[c].append(None if empty else int(v))
            else:
                out[c].append(str(v) if c.endswith("_mode") else v)
    return out


def rows_from_mcap(path: Path) -> dict[str, list[object]]:
    from mcap.reader import make_reader

    out: dict[str, list[object]] | None = None
    with path.open("rb") as f:
        reader = make_reader(f)
        for _schema, _channel, message in reader.iter_messages(topics=[schemas.STATE_TOPIC]):
            doc = json.loads(message.data)
            if out is None:
                columns = schemas.column_units(list(doc["fingers"]))
                out = {c: [] for c in columns}
            out["host_time_s"].append(doc["host_time_s"])
            out["board_time_s"].append(doc["board_time_s"])
            out["seq"].append(None if doc["seq"] < 0 else doc["seq"])
            for name, finger in doc["fingers"].items():
                for field in FINGER_FIELDS:
                    out[f"{name}_{field}"].append(finger[field])
    if out is None:
        raise ExportError(f"{path}: no {schemas.STATE_TOPIC} messages: not a utrf recording")
    return out


def export_parquet(source: str | Path, dest: str | Path) -> pa.Table:
    """``source`` (``.mcap`` recording or ``.csv`` telemetry log) to ``dest`` (Parquet)."""
    source = Path(source)
    if not source.exists():
        raise ExportError(f"{source}: no such file")
    kind = source.suffix.lower()
    if kind == ".mcap":
        rows = rows_from_mcap(source)
    elif kind == ".csv":
        rows = rows_from_csv(source)
    else:
        raise ExportError(f"{source}: expected a .mcap recording or a .csv telemetry log")
    table = table_of(rows, source.name)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, dest)
    return table
