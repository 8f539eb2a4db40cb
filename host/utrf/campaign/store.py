"""A campaign's directory: its file, and its results as Parquet (pyarrow), one row per run.

    DIR/campaign.toml        the campaign as it was run (a different one is refused)
    DIR/runs/part-*.parquet  results as they come in, each part written whole or not at all
    DIR/results.parquet      every part in one file (written at the end, and by report)

Every row has ``run_key`` (a hash of the run's parameters), ``status`` (``ok`` or
``failed``), ``error`` (why it failed), ``compute_s`` and ``worker``; then the parameters
and what the kind measured. A run is done once its row is in a part: a campaign run again
skips it, so a killed campaign loses at most the runs that were in flight.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from utrf.campaign.spec import Campaign, CampaignError

RESULTS = "results.parquet"


class Store:
    """Append-only results of one campaign in ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.parts = self.root / "runs"

    def claim(self, campaign: Campaign) -> None:
        """Make ``root`` this campaign's (refusing a directory of another campaign)."""
        self.parts.mkdir(parents=True, exist_ok=True)
        copy = self.root / "campaign.toml"
        if copy.exists() and copy.read_text() != campaign.text:
            old = self.root / "campaign.toml"
            raise CampaignError(
                f"{self.root} holds another campaign ({old}); give a new output directory "
                "or run that campaign file"
            )
        if not copy.exists():
            tmp = copy.with_name(".campaign.toml.tmp")
            tmp.write_text(campaign.text)
            tmp.replace(copy)

    def part_files(self) -> list[Path]:
        return sorted(self.parts.glob("part-*.parquet")) if self.parts.is_dir() else []

    def done_keys(self) -> set[str]:
        keys: set[str] = set()
        for part in self.part_files():
            keys.update(pq.read_table(part, columns=["run_key"]).column(0).to_pylist())
        return keys

    def append(self, table: pa.Table) -> Path | None:
        """Write ``table`` as a new part, atomically; None for an empty table."""
        if table.num_rows == 0:
            return None
        self.parts.mkdir(parents=True, exist_ok=True)
        name = f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
        tmp = self.parts / f".{name}.tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, self.parts / name)
        return self.parts / name

    def read(self, columns: Iterable[str] | None = None) -> pa.Table:
        """Every run so far, in one table (parts with other columns are unified; a run
        written twice, which the engine never does, would show up twice)."""
        tables = [pq.read_table(p) for p in self.part_files()]
        if not tables:
            return pa.table({"run_key": pa.array([], pa.string())})
        table = pa.concat_tables(tables, promote_options="default")
        return table.select(list(columns)) if columns is not None else table

    def consolidate(self) -> Path:
        """``results.parquet``: every part in one file, for pandas, polars or DuckDB."""
        path = self.root / RESULTS
        tmp = path.with_name(f".{RESULTS}.tmp")
        pq.write_table(self.read(), tmp)
        os.replace(tmp, path)
        return path


def columns_table(cols: Mapping[str, Any]) -> pa.Table:
    """Columns (numpy arrays, one per name) as a table; object columns through Python."""
    return pa.table({k: pa.array(v.tolist() if v.dtype == object else v) for k, v in cols.items()})


def rows_table(rows: list[Mapping[str, Any]]) -> pa.Table:
    """Rows (dicts) as a table; columns missing from some rows are nulls there."""
    names: list[str] = []
    for r in rows:
        names += [k for k in r if k not in names]
    return pa.Table.from_pylist([{k: r.get(k) for k in names} for r in rows])
