"""The runs a sampler makes of a campaign's parameters, as columns, and each run's key.

grid: every combination of the lists and of each range's ``steps`` points; random: uniform
draws; lhs: a Latin hypercube (``scipy.stats.qmc.LatinHypercube``), a list's values drawn
as equal strata of the same unit interval. Seeded by the campaign's seed, so a campaign run
again makes the same runs (what resuming relies on). Optuna asks for its runs one by one
(``utrf.campaign.search``).
"""

from __future__ import annotations

import hashlib
import itertools
import math

import numpy as np
from scipy.stats import qmc

from utrf.campaign.spec import Campaign, Param, Range

Columns = dict[str, np.ndarray]


def _range_points(r: Range, u: np.ndarray) -> np.ndarray:
    """Unit-interval draws mapped onto the range."""
    if r.log:
        out = np.exp(math.log(r.low) + u * (math.log(r.high) - math.log(r.low)))
    else:
        out = r.low + u * (r.high - r.low)
    return np.floor(out + 0.5) if r.integer else out


def _grid_values(p: Param) -> np.ndarray:
    if p.values is not None:
        return np.asarray(p.values)
    assert p.range is not None and p.range.steps is not None  # spec checks grids
    return _range_points(p.range, np.linspace(0.0, 1.0, p.range.steps))


def grid_size(campaign: Campaign) -> int:
    return math.prod(len(_grid_values(p)) for p in campaign.params)


def columns(campaign: Campaign) -> Columns:
    """Every run of the campaign's sampler, one array per parameter (equal lengths); each
    sampled row once with every combination of the ``cross`` parameters' values."""
    crossed = [p for p in campaign.params if p.name in campaign.cross]
    cols = _sampled(campaign, [p for p in campaign.params if p.name not in campaign.cross])
    if not crossed:
        return cols
    n = row_count(cols) if cols else 1
    combos = list(itertools.product(*(p.values or () for p in crossed)))
    out = {k: np.tile(v, len(combos)) for k, v in cols.items()}
    for j, p in enumerate(crossed):
        out[p.name] = np.repeat(np.asarray([c[j] for c in combos]), n)
    return out


def _sampled(campaign: Campaign, params: list[Param]) -> Columns:
    if not params:
        return {}
    if campaign.method == "grid":
        axes = [_grid_values(p) for p in params]
        index = np.array(list(itertools.product(*(range(len(a)) for a in axes))), dtype=np.intp)
        index = index.reshape(-1, len(axes))
        return {p.name: axes[i][index[:, i]] for i, p in enumerate(params)}
    n = campaign.samples
    free = [p for p in params if not p.fixed]
    if campaign.method == "lhs" and free:
        unit = qmc.LatinHypercube(d=len(free), seed=campaign.seed).random(n)
    else:
        unit = np.random.default_rng(campaign.seed).random((n, len(free)))
    out: Columns = {}
    for p in params:
        if p.fixed:
            assert p.values is not None
            out[p.name] = np.full(n, p.values[0])
            continue
        u = unit[:, free.index(p)]
        if p.range is not None:
            out[p.name] = _range_points(p.range, u)
        else:
            assert p.values is not None
            choices = np.asarray(p.values)
            out[p.name] = choices[np.minimum((u * len(choices)).astype(np.intp), len(choices) - 1)]
    return out


def row_count(cols: Columns) -> int:
    return len(next(iter(cols.values()))) if cols else 0


_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def _mix(h: np.ndarray) -> np.ndarray:
    """splitmix64's finaliser: every input bit moves about half the output bits."""
    h = h ^ (h >> np.uint64(30))
    h = h * _M1
    h = h ^ (h >> np.uint64(27))
    h = h * _M2
    return h ^ (h >> np.uint64(31))


def _digest64(text: str) -> int:
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little")


def key_words(cols: Columns, salt: str) -> np.ndarray:
    """Each run's key as a 64-bit word: a hash of its parameters (names and values: numbers
    as their float64 bits, text through BLAKE2b) and ``salt`` (the kind and its options).
    Vectorised (a million runs in well under a second); the same run in another campaign
    file has the same key."""
    names = sorted(cols)
    n = row_count(cols)
    h = np.full(n, _digest64(salt + "|" + ",".join(names)), dtype=np.uint64)
    with np.errstate(over="ignore"):
        for name in names:
            col = cols[name]
            if col.dtype.kind in "iufb":
                words = np.ascontiguousarray(col, dtype=np.float64).view(np.uint64)
            else:
                uniq, inverse = np.unique(col.astype(str), return_inverse=True)
                words = np.array([_digest64(u) for u in uniq], dtype=np.uint64)[inverse]
            h = _mix(h ^ words)
    return h


def hex_keys(words: np.ndarray) -> np.ndarray:
    """Key words as the ``run_key`` column's 16 hex digits (what the results hold)."""
    raw = np.ascontiguousarray(words, dtype=">u8").tobytes().hex()
    return np.frombuffer(raw.encode("ascii"), dtype="S16").astype("U16")


def words_of(keys: list[str] | np.ndarray) -> np.ndarray:
    """``hex_keys`` undone: the results' run keys as words (to skip the runs done)."""
    text = "".join(np.asarray(keys, dtype="U16").tolist())
    return np.frombuffer(bytes.fromhex(text), dtype=">u8").astype(np.uint64)


def run_keys(cols: Columns, salt: str) -> np.ndarray:
    """Each run's key (``key_words``) as 16 hex digits."""
    return hex_keys(key_words(cols, salt))


def row(cols: Columns, i: int) -> dict[str, object]:
    """Run ``i``'s parameters as plain Python values."""
    return {k: v[i].item() if hasattr(v[i], "item") else v[i] for k, v in cols.items()}
