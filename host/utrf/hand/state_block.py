"""Telemetry samples as arrays: the run of ``state`` samples one read of the line brought, for a
consumer of the fast stream that needs no :class:`~utrf.hand.state.HandState` per sample (the
dashboard's ring at 1 kHz). ``Hand.on_states`` delivers them; which way a block is built
(from the messages, or from HandStates when something needs those anyway) is chosen in one
place, ``HandTelemetry.on_frames``, and a test compares the two."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from utrf.hand.state import HandState
from utrf.protocol import messages as m

#: the rows of :attr:`StateBlock.values`, in order
FIELDS = ("theta2", "target", "duty_a", "duty_b")


@dataclass(frozen=True, slots=True)
class StateBlock:
    """``n`` consecutive samples: board times (s, unwrapped), host receive times (s), and per
    sample and finger the Joint-2 angle and target (rad) and the duties (fractions); ``last``
    is the newest sample as a HandState (its modes, faults and tips too)."""

    board_time: np.ndarray  # (n,)
    host_time: np.ndarray  # (n,)
    values: np.ndarray  # (n, 4, fingers): FIELDS
    last: HandState

    def __len__(self) -> int:
        return len(self.board_time)

    @property
    def theta2(self) -> np.ndarray:
        return self.values[:, 0]

    @property
    def target(self) -> np.ndarray:
        return self.values[:, 1]

    @property
    def duty_a(self) -> np.ndarray:
        return self.values[:, 2]

    @property
    def duty_b(self) -> np.ndarray:
        return self.values[:, 3]

    @classmethod
    def of_states(cls, states: Sequence[HandState]) -> StateBlock:
        """The general way: from HandStates already built (what a per-sample consumer gets)."""
        values = np.array(
            [[[getattr(f, name) for f in st.fingers] for name in FIELDS] for st in states],
            dtype=float,
        )
        return cls(
            np.array([st.board_time for st in states], dtype=float),
            np.array([st.host_time for st in states], dtype=float),
            values,
            states[-1],
        )

    @classmethod
    def of_messages(
        cls,
        msgs: Sequence[m.State],
        board_time: Sequence[float],
        host_time: float,
        last: HandState,
    ) -> StateBlock:
        """The fast way: from the decoded messages, one array for the lot (no FingerState per
        sample); ``board_time`` unwrapped, one ``host_time`` for the read that brought them."""
        n = len(last.fingers)
        rows = np.array(
            [msg.theta2[:n] + msg.target[:n] + msg.duty_a[:n] + msg.duty_b[:n] for msg in msgs],
            dtype=float,
        )
        return cls(
            np.array(board_time, dtype=float),
            np.full(len(msgs), host_time),
            rows.reshape(len(msgs), len(FIELDS), n),
            last,
        )
