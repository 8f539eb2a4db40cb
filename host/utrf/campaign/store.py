"""A campaign's directory: its file, and its results as Parquet (pyarrow), one row per run.

    DIR/campaign.toml        the campaign as it was run (a different one is refused)
    DIR/runs/part-*.parquet  results as they come in, each part written whole or not at all
    DIR/runs/.token          this directory's token: a worker that reads it writes parts here
    DIR/results.parquet      every part in one file (written at the end, and by report)

Every row has ``run_key`` (a hash of the run's parameters), ``status`` (``ok`` or
``failed``), ``error`` (why it failed), ``compute_s`` and ``worker``; then the parameters
and what the kind measured. A run is done once its row is in a part: a campaign run again
skips it, so a killed campaign loses at most the runs that were in flight.

Parts are written by the workers that ran them (``write_part``), named by their runs' keys
(``part_name``): a task run twice (its worker lost after writing, a driver killed while it
ran) writes the same name with the same runs, so no run is ever stored twice. A worker that
does not see the directory (no shared file system) sends its rows to the driver, which
writes them the same way (``sees``).
"""

from __future__ import annotations

import hashlib
import os
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from utrf.campaign.sampling import words_of
from utrf.campaign.spec import Campaign, CampaignError

RESULTS = "results.parquet"
TOKEN = ".token"
_seen: dict[tuple[str, str], bool] = {}  # (parts directory, token) -> seen, per process


class Store:
    """Append-only results of one campaign in ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.parts = self.root / "runs"

    def claim(self, campaign: Campaign) -> str:
        """Make ``root`` this campaign's (refusing a directory of another campaign); returns
        the directory's token (``sees``)."""
        self.parts.mkdir(parents=True, exist_ok=True)
        copy = self.root / "campaign.toml"
        if copy.exists() and copy.read_text() != campaign.text:
            old = self.root / "campaign.toml"
            raise CampaignError(
                f"{self.root} holds another campaign ({old}); give a new output directory "
                "or run that campaign file"
            )
        if not copy.exists():
            _write_atomic(copy, campaign.text)
        token = self.parts / TOKEN
        if not token.exists():
            _write_atomic(token, uuid.uuid4().hex)
        return token.read_text()

    def part_files(self) -> list[Path]:
        return sorted(self.parts.glob("part-*.parquet")) if self.parts.is_dir() else []

    def done_words(self) -> np.ndarray:
        """The runs stored, as key words (``sampling.key_words``), sorted."""
        keys = [pq.read_table(p, columns=["run_key"]).column(0) for p in self.part_files()]
        if not keys:
            return np.zeros(0, dtype=np.uint64)
        return np.unique(words_of(pa.chunked_array(keys).to_numpy(zero_copy_only=False)))

    def append(self, table: pa.Table) -> Path | None:
        """Write ``table`` as a new part (named by its runs' keys); None for an empty table."""
        if table.num_rows == 0:
            return None
        return write_part(self.parts, table)

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


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def part_name(keys: Iterable[str]) -> str:
    """A part's name: a hash of its runs' keys (the same runs, the same name)."""
    digest = hashlib.blake2b("".join(keys).encode(), digest_size=10).hexdigest()
    return f"part-{digest}.parquet"


def write_part(parts: Path | str, table: pa.Table) -> Path:
    """``table`` as ``parts/part_name(its keys)``, written whole or not at all (a rename);
    written again by a task run twice, it is replaced by the same runs."""
    parts = Path(parts)
    parts.mkdir(parents=True, exist_ok=True)
    name = part_name(table.column("run_key").to_pylist())
    tmp = parts / f".{name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, parts / name)
    return parts / name


def sees(parts: str, token: str) -> bool:
    """Whether this process sees the campaign's ``parts`` directory (its token file holds
    ``token``): a worker on the driver's machine or on a shared file system. Checked once
    per process and campaign."""
    key = (parts, token)
    if key not in _seen:
        try:
            _seen[key] = (Path(parts) / TOKEN).read_text() == token
        except OSError:
            _seen[key] = False
    return _seen[key]


def columns_table(cols: Mapping[str, Any]) -> pa.Table:
    """Columns (numpy arrays, one per name) as a table; object columns through Python."""
    return pa.table({k: pa.array(v.tolist() if v.dtype == object else v) for k, v in cols.items()})


def rows_table(rows: list[Mapping[str, Any]]) -> pa.Table:
    """Rows (dicts) as a table; columns missing from some rows are nulls there."""
    names: list[str] = []
    for r in rows:
        names += [k for k in r if k not in names]
    return pa.Table.from_pylist([{k: r.get(k) for k in names} for r in rows])
