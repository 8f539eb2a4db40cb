"""After JOINT_LIMIT the motors short-brake rather than coast: measured on the emulated board.

An outside force carries a finger past its limit (issue 13: coasting, a push carried the index
finger to 0.705 rad against a 0.3 rad limit). Both ways are run here on the real firmware:
its own choice (short brake) and coasting (the host sets COAST the moment the fault is
reported). A short brake puts no energy into the motor and cannot hold a steady force, but it
slows the finger several times, so it reaches the end of its stroke without the overshoot,
and a blow does not swing it back past its start. firmware/README.md quotes these runs.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand
from utrf.protocol import messages as M

INDEX = 1
STEP = 0.002  # s between samples


def pushed(elf: Path, *, coast: bool, force_n: float = 0.0, impulse_ns: float = 0.0) -> dict:
    """Index held at 0.25 rad under a 0.3 rad limit, then pushed toward flexion (+y at the tip):
    a steady force, or a blow. The angle's course for 0.6 s."""
    with EmulatedBoard(elf, realtime=False, seed=1) as board:
        hand = Hand.emulated(board, on_close="coast")
        hand.set_limits("index", theta2_max=0.3)
        hand.set_targets({"index": 0.25})
        hand.clock.sleep(0.5)
        if force_n:
            board.set_tip_force(INDEX, (0.0, force_n), ramp_s=0.05)
        else:
            board.hit_tip(INDEX, (0.0, impulse_ns))
        trace, coasted = [], False
        for _ in range(300):
            hand.clock.sleep(STEP)
            trace.append(float(board.theta2[INDEX]))
            if coast and not coasted and any(e.finger == "index" for e in hand.faults_seen):
                hand.coast("index")
                coasted = True
        st = hand.state()["index"]
        assert M.FaultBits.JOINT_LIMIT in st.faults
        assert st.mode == (M.ControlMode.COAST if coast else M.ControlMode.BRAKE)
    speeds = [(b - a) / STEP for a, b in itertools.pairwise(trace) if b >= 0.6 > a]
    return {"peak": max(trace), "end": trace[-1], "speed_at_0.6": speeds[0] if speeds else None}


@pytest.mark.parametrize("force_n", [4.0, 8.0])
def test_a_push_past_the_limit_is_slowed_by_the_brake(firmware_elf: Path, force_n: float) -> None:
    braked = pushed(firmware_elf, coast=False, force_n=force_n)
    coasted = pushed(firmware_elf, coast=True, force_n=force_n)
    # Measured (MuJoCo plant): 4 N: 1.5 against 8.6 rad/s at 0.6 rad, peak 0.698 against
    # 0.809 rad; 8 N: 3.7 against 12.7 rad/s, 0.705 against 0.821 rad. Both end at the
    # stroke's end.
    assert braked["speed_at_0.6"] < coasted["speed_at_0.6"] / 3
    assert braked["peak"] < coasted["peak"] - 0.08


def test_a_blow_past_the_limit_is_damped_by_the_brake(firmware_elf: Path) -> None:
    braked = pushed(firmware_elf, coast=False, impulse_ns=0.2)
    coasted = pushed(firmware_elf, coast=True, impulse_ns=0.2)
    # Measured (MuJoCo plant): braked, the finger comes to rest at 0.08 rad, near where it
    # started (0.25); coasting, the blow's bounces between the two tendons send both carriages
    # off, both tendons go slack and the finger falls on into flexion (1.54 rad after 0.6 s).
    # (On the analytic plant, whose tendons damp the bounces, it swung back to -0.35 rad.)
    assert braked["end"] > 0.0
    assert abs(coasted["end"] - 0.25) > abs(braked["end"] - 0.25) + 0.3
