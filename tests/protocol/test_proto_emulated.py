"""The protocol on the real firmware (the emulated board, driven, simulated time): the 1 kHz
stream whole while five fingers move; and safe resend: over a noisy line, every command ends
in a definite answer, replies lost on the way are answered again from the board's reply
cache, and nothing is applied that was not sent."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand
from utrf.protocol import messages as M

RES = M.State.FIELDS[3].scale  # the board's angle count, rad


def test_commands_over_a_noisy_line_get_a_definite_answer_applied_once(
    firmware_elf: Path,
) -> None:
    rng = np.random.default_rng(5)
    with (
        EmulatedBoard(firmware_elf, realtime=False, seed=5) as board,
        Hand.emulated(board, telemetry_hz=100) as hand,
    ):
        link = hand.link
        link.request(M.SetMode(0b11111, (M.ControlMode.BRAKE,) * 5, (0,) * 5, (0,) * 5))
        # About 1e-2 per byte, both ways: a third of the exchanges touched.
        board.set_line_faults("both", corrupt=0.004, drop=0.003, insert=0.003)
        sent = []
        for i in range(120):
            values = tuple(float(v) for v in rng.uniform(0.0, 1.0, 5))
            link.request(M.SetTargets(M.TargetKind.JOINT2_ANGLE, 0b11111, values))
            sent.append(values)
            if i % 8 == 0:
                link.request(M.SetSafety(heartbeat_timeout=0.5 + 0.01 * (i % 5), safe_action=0))
        board.set_line_faults("both")
        stats = link.request(M.GetStats())
        targets = link.request(M.GetState()).target
        safety = link.request(M.GetSafety())
        ls = hand.link_stats()
    assert ls.retries > 10  # the noise was real
    assert stats.rx_repeats > 0  # and lost replies were answered from the cache
    assert stats.rx_crc_errors > 0
    # the board holds the last targets sent, at its resolution, and the last safety
    on_wire = M.SetTargets.decode(
        M.SetTargets(M.TargetKind.JOINT2_ANGLE, 0b11111, sent[-1]).encode()
    ).value  # the µrad the line carried
    assert targets == tuple(round(v / RES) * RES for v in on_wire)
    assert safety.heartbeat_timeout == 0.5 + 0.01 * (112 % 5)


def test_the_1khz_stream_is_whole_while_five_fingers_move(firmware_elf: Path) -> None:
    with (
        EmulatedBoard(firmware_elf, realtime=False, seed=2) as board,
        Hand.emulated(board, telemetry_hz=M.MAX_TELEMETRY_HZ) as hand,
    ):
        assert M.MAX_TELEMETRY_HZ == 1000
        seqs: list[int] = []
        hand.link.add_telemetry_callback(lambda item: seqs.append(item.seq))
        hand.reset_stats()
        s0 = hand.link_stats()
        # the board runs the moves (core/path.h); the waits read the stream and poll the line
        hand.move([1.0] * 5, 0.6, wait=True)
        hand.move([0.3] * 5, 0.6, wait=True)
        s1 = hand.link_stats()
        fw = hand.stats()
        # up to here: closing the Hand brakes the fingers, and the status frame that reports
        # it takes a seq of the same counter without being a state frame
        got = list(seqs)
    assert len(got) > 1150  # 1.2 s of frames
    # every board frame's seq follows the one before: nothing lost on the way or skipped
    assert all((b - a) % 128 == 1 for a, b in itertools.pairwise(got))
    assert s1.stream_lost == s0.stream_lost
    assert fw.tx_dropped == 0
