"""The hand's fingers by name or number: a finger key checked against the hand file's names,
a set of fingers, and the wire's finger bitmask."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from utrf.hand.errors import TargetError
from utrf.protocol import messages as m

FingerKey = int | str
#: the wire's mask of every finger
ALL_FINGERS = (1 << m.FINGER_COUNT) - 1


def finger_mask(idx: Iterable[int]) -> int:
    """The wire's finger bitmask (bit i: finger i) of finger indices."""
    return sum(1 << i for i in set(idx))


class Fingers:
    """The finger names of the hand file, in the wire's order (0 thumb .. 4 little)."""

    def __init__(self, names: Iterable[str]) -> None:
        self.names: tuple[str, ...] = tuple(names)
        if len(self.names) != m.FINGER_COUNT:
            raise ValueError(
                f"the protocol drives {m.FINGER_COUNT} fingers; the hand file has {len(self.names)}"
            )

    def __len__(self) -> int:
        return len(self.names)

    def index(self, key: FingerKey) -> int:
        """0..4 for a finger name or index; TargetError naming the choices otherwise."""
        if isinstance(key, bool):
            raise TargetError(f"finger must be a name or an index, got {key!r}")
        if isinstance(key, int | np.integer):
            if 0 <= int(key) < len(self.names):
                return int(key)
            raise TargetError(f"finger index {key} is outside 0..{len(self.names) - 1}")
        if isinstance(key, str):
            if key in self.names:
                return self.names.index(key)
            if key.isdigit():
                return self.index(int(key))
            raise TargetError(f"no finger named {key!r}; fingers are {list(self.names)}")
        raise TargetError(f"finger must be a name or an index, got {key!r}")

    def select(self, fingers: Iterable[FingerKey] | FingerKey | None) -> list[int]:
        """The sorted indices of some fingers (None: all of them)."""
        if fingers is None:
            return list(range(len(self.names)))
        if isinstance(fingers, int | str):
            return [self.index(fingers)]
        out = sorted({self.index(f) for f in fingers})
        if not out:
            raise TargetError("no fingers given")
        return out
