"""loop() sleeps when it has nothing to do, and never while work waits.

hal::idle() (the AVR: sleep mode idle until the next interrupt, so the CPU stops instead of
spinning and simavr skips the idle cycles) is called at the end of a loop() pass with no reply
pending and no EEPROM write under way; it sleeps only when no received byte waits. The host
layer counts the sleeps it would take.
"""

from __future__ import annotations

from fwsim import Sim, m

from utrf.protocol.framing import encode_frame


def sleeps(sim: Sim) -> int:
    return sim.status().idle_sleeps


def test_an_idle_board_sleeps_every_pass(sim: Sim) -> None:
    before = sleeps(sim)
    sim.loop(10)
    assert sleeps(sim) == before + 10


def test_no_sleep_while_received_bytes_wait(sim: Sim) -> None:
    # Three requests at once: a pass answers one (a reply holds the input until it is sent),
    # so the passes that leave bytes behind do not sleep; the last one does.
    frames = b"".join(
        encode_frame(10 + k, m.Heartbeat.ID, m.Heartbeat().encode()) for k in range(3)
    )
    sim.send_raw(frames)
    before = sleeps(sim)
    sim.loop(1)
    assert sleeps(sim) == before
    sim.loop(1)
    assert sleeps(sim) == before
    sim.loop(1)
    assert sleeps(sim) == before + 1
    assert [r.seq for r in sim.take(m.Ack)] == [10, 11, 12]  # every request answered


def test_no_sleep_while_saving_the_configuration(sim: Sim) -> None:
    seq = sim.send(m.SaveConfig())
    sim.loop(1)
    assert sim.status().saving
    before = sleeps(sim)
    sim.loop(3)
    assert sleeps(sim) == before
    for _ in range(5000):  # until the image is written and acknowledged
        sim.run(1)
        if any(r.seq == seq for r in sim.frames):
            break
    assert [r.seq for r in sim.take(m.Ack)] == [seq]
    before = sleeps(sim)
    sim.loop(1)
    assert sleeps(sim) == before + 1  # done: idle again
