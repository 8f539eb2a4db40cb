"""The stream in blocks (``Hand.on_states``): a read's samples taken as arrays (the fast path,
no HandState per sample) equal what the per-sample path gives (the general twin, taken when
an ``on_state`` callback or the log needs each HandState), and a Link hands a read's frames
on together."""

from __future__ import annotations

import random
import time
from types import SimpleNamespace

import numpy as np
from hand_fake import HandBoard

from utrf.hand import Hand
from utrf.hand.state_block import StateBlock
from utrf.hand.telemetry import HandTelemetry
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as M
from utrf.protocol.engine import Telemetry

NAMES = ("thumb", "index", "middle", "ring", "little")


def stream(n: int, seed: int = 1) -> list[Telemetry]:
    """``n`` state samples (the board's ms clock wrapping among them), a status and a fault
    amid them, as the reader would hand them on."""
    rng = random.Random(seed)
    items = []
    for k in range(n):
        ms = (65_500 + k) % 65_536  # wraps after 36 samples
        msg = M.State(
            board_time=ms * 1e-3,
            status_seq=1 if k < n // 2 else 2,
            theta2=tuple(rng.uniform(-0.2, 1.5) for _ in range(5)),
            target=tuple(rng.uniform(-0.2, 1.5) for _ in range(5)),
            duty_a=tuple(rng.randint(-128, 127) / 128 for _ in range(5)),
            duty_b=tuple(rng.randint(-128, 127) / 128 for _ in range(5)),
        )
        # as decoded from the wire (the values at the board's resolution)
        items.append(Telemetry(M.State.decode(msg.encode()), 0x80 | (k % 128), 0.0))
        if k == n // 2:
            status = M.Status(
                change=2,
                mode=(M.ControlMode.POSITION,) * 5,
                faults=(M.FaultBits.STALL, *(M.FaultBits(0),) * 4),
            )
            items.append(Telemetry(status, 0x80, 0.0))
        if k == n // 3:
            fault = M.Fault(board_time=1.0, finger=0, new_faults=M.FaultBits.STALL,
                            faults=(M.FaultBits.STALL, *(M.FaultBits(0),) * 4))  # fmt: skip
            items.append(Telemetry(fault, 0x81, 0.0))
    return items


def telemetry() -> HandTelemetry:
    session = SimpleNamespace(clock=SimpleNamespace(timestamp=lambda: 7.0))
    return HandTelemetry(session, HandGeometry.default(), NAMES, 1000)  # type: ignore[arg-type]


def take(items: list[Telemetry], per_sample: bool, reads: list[int]) -> tuple:
    """Feed ``items`` in reads of these sizes; the blocks, faults and latest state seen."""
    tel = telemetry()
    blocks: list[StateBlock] = []
    faults: list = []
    tel.on_states(blocks.append)
    tel.on_fault(faults.append)
    states: list = []
    if per_sample:  # a per-sample consumer: the general path
        tel.on_state(states.append)
    i = 0
    for size in reads:
        tel.on_frames(items[i : i + size])
        i += size
    assert i == len(items)
    return blocks, faults, tel.latest, states


def test_state_blocks_fast_path_equals_the_general() -> None:
    items = stream(120)
    rng = random.Random(3)
    reads = []
    left = len(items)
    while left:
        reads.append(min(left, rng.randint(1, 30)))
        left -= reads[-1]
    fast, fast_faults, fast_latest, none = take(items, False, reads)
    general, general_faults, general_latest, states = take(items, True, reads)
    assert not none and len(states) == 120  # the general path built every HandState
    assert fast_latest == general_latest == states[-1]
    assert fast_faults == general_faults and len(fast_faults) == 1
    # the same blocks (a status or fault between samples ends one), sample for sample
    assert [len(b) for b in fast] == [len(b) for b in general]
    assert sum(len(b) for b in fast) == 120
    for a, b in zip(fast, general, strict=True):
        np.testing.assert_array_equal(a.board_time, b.board_time)
        np.testing.assert_array_equal(a.host_time, b.host_time)
        np.testing.assert_array_equal(a.values, b.values)
        assert a.last == b.last
    board_time = np.concatenate([b.board_time for b in fast])
    np.testing.assert_allclose(np.diff(board_time), 1e-3)  # unwrapped over the clock's wrap
    theta2 = np.concatenate([b.theta2 for b in fast])
    np.testing.assert_array_equal(theta2, [[f.theta2 for f in st] for st in states])
    # the status that came mid-stream is the one the newest sample shows
    assert fast_latest.fingers[0].faults == M.FaultBits.STALL and fast_latest.status_current


def test_a_link_hands_a_reads_frames_on_together() -> None:
    board = HandBoard()
    try:
        with Hand.connect(board.url, boot_wait_s=0, telemetry_hz=500) as hand:
            hand.link.read_linger_s = 0.02  # type: ignore[attr-defined]
            blocks: list[StateBlock] = []
            off = hand.on_states(blocks.append)
            deadline = time.monotonic() + 10.0  # the emulated board is slower on a busy machine
            while sum(len(b) for b in blocks) <= 50 and time.monotonic() < deadline:
                time.sleep(0.1)
            off()
            n = [len(b) for b in blocks]
            assert sum(n) > 50 and max(n) > 1  # several samples a read
            t = np.concatenate([b.board_time for b in blocks])
            assert np.all(np.diff(t) > 0)  # every sample once, in order
            assert hand.latest is not None and hand.latest.board_time >= t[-1]
    finally:
        board.close()
