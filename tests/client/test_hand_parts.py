"""`Hand` is composed of parts, not inherited from them (issue 23): each public method is one
part's method bound to that part, no part subclasses another, and the public API keeps every
name callers use."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hand_fake import HandBoard

from utrf.hand import Hand
from utrf.hand.configuration import HandConfiguration
from utrf.hand.control import HandControl
from utrf.hand.counters import HandCounters
from utrf.hand.lifecycle import HandLifecycle
from utrf.hand.motion import HandMotion
from utrf.hand.session import HandSession
from utrf.hand.telemetry import HandTelemetry
from utrf.hand.via import Via

PARTS = (
    HandSession,
    HandTelemetry,
    HandControl,
    HandMotion,
    HandConfiguration,
    HandLifecycle,
    HandCounters,
)
# What docs/hand.md, the CLI and the tests call on a Hand (the API before issue 23).
PUBLIC = """baudrate brake calibrate_zero clear_faults clock close closed coast connect emulated
faults_seen finger_config finger_index fingers forget_faults gains geometry hold identity
last_boot last_move latest limits link link_stats load_config motion move on_close on_fault
on_state ping pose poses reconnect reset_stats safety save_config set_finger_config
set_gains set_limits set_mode set_motion set_safety set_targets set_telemetry start_log
state stats stop_log telemetry_hz to_theta2 url wait_settled""".split()  # noqa: SIM905 (one name a line: 54)


@pytest.fixture
def hand() -> Iterator[Hand]:
    board = HandBoard()
    try:
        with Hand.connect(board.url, boot_wait_s=0, telemetry_hz=50) as h:
            yield h
    finally:
        board.close()


def test_no_part_inherits_from_another() -> None:
    for cls in (Hand, *PARTS):
        assert cls.__mro__ == (cls, object), f"{cls.__name__} inherits: {cls.__mro__}"


def test_each_public_method_is_one_parts_own(hand: Hand) -> None:
    vias = {name: v for name, v in vars(Hand).items() if isinstance(v, Via)}
    assert len(vias) > 30
    for name, via in vias.items():
        bound = getattr(hand, name)
        part = getattr(hand, via.part)
        assert type(part) in PARTS, f"Hand.{name} goes to {type(part).__name__}"
        assert bound.__self__ is part and bound.__func__ is via.method, name


def test_the_public_api_keeps_every_name(hand: Hand) -> None:
    missing = [name for name in PUBLIC if not hasattr(hand, name)]
    assert not missing, f"Hand lost {missing}"
    assert hand.fingers == ("thumb", "index", "middle", "ring", "little")
    assert hand.link is hand._session.link and hand.clock is hand._session.clock


def test_via_refuses_a_name_other_than_its_methods() -> None:
    via = Via("_motion", HandMotion.move)
    with pytest.raises(TypeError, match=r"Probe\.stop shows a method named move"):
        via.__set_name__(type("Probe", (), {}), "stop")


def test_help_shows_each_methods_signature_without_self() -> None:
    shown = repr(Hand.move)
    assert shown.startswith("HandMotion.move(targets") and "duration" in shown
    assert "self" not in repr(Hand.set_gains) and "finger" in repr(Hand.set_gains)
