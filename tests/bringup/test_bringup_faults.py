"""Each build fault of the twin, alone on the index finger: the bring-up names it, says
whether the configuration fixes it, and proposes the fix (only the steps that find it run:
the wiring faults stop after the wiring, the stops' after the stops)."""

from __future__ import annotations

import pytest
from bringup_helpers import Built

from utrf.bringup import bringup

INDEX = 1

# (build fault, the step that finds it, the finding's kind, fixable by configuration)
CASES = [
    ("swap-leads:1", "wiring", "leads-swapped", True),
    ("swap-lead-a:1", "wiring", "lead-a-swapped", False),
    ("invert-magnet:1", "wiring", "encoder-inverted", True),
    ("swap-cables:1,2", "wiring", "cable-swap", False),
    ("swap-encoders:1,2", "wiring", "cable-swap", False),
    ("unpowered:1", "wiring", "no-motion", False),
    ("unplugged:1", "wiring", "encoder-signal", False),
    ("magnet-offset:1=0.4", "stops", "magnet-offset", True),
    ("narrow-range:1=1.3", "stops", "narrow-range", True),
    ("slow-motor:1=0.45", "plant", "slow-motor", True),
    # the slowest the campaign draws: seen only by the wiring's longest pulse at the duty bound,
    # its stops by a search of more legs
    ("slow-motor:1=0.32", "plant", "slow-motor", True),
    # from its steps from rest: a weaker motor comes up to speed later than the model's
    ("weak-motor:1=0.3", "plant", "weak-motor", True),
    ("friction:1=8", "plant", "friction", True),
    # late from rest too (6.5 and 3 times the model's lag), but its friction duty is far beyond
    # what a weak motor's lag explains
    ("friction:1=11", "plant", "friction", True),
    # more than the duty bound moves through the travel: the closing search sticks at once (a
    # jam); it ends with the motors off and nothing saved
    ("friction:1=14", "stops", "friction", False),
    # Joint 2 loose between its strands: driven at one duty, its reading goes back (it swings)
    # before any plant step (on the merged firmware its steps from rest read 7.6 times the
    # model's lag both ways, which named a weak motor when the plant came first)
    ("slack:1=0.0015", "plant", "slack", False),
    # the reading turns further between the stops than the joint can
    ("off-centre:1=0.3", "stops", "not-monotonic", False),
    # the other phase: the reading's span short by twice its error (not a narrow range nor a
    # turned magnet), its speed slowest mid-travel: the opening leg runs past the middle
    ("off-centre:1=-0.4", "plant", "not-monotonic", False),
]


def _kinds(result: object) -> list[str]:
    return [f.kind for f in result.findings]  # type: ignore[attr-defined]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fault", "upto", "kind", "fixable"),
    CASES,
    ids=[c[0] for c in CASES],
)
def test_a_build_fault_is_named(
    built: Built, fault: str, upto: str, kind: str, fixable: bool
) -> None:
    with built(fault) as (board, hand):
        eeprom = board.eeprom
        result = bringup(hand, fingers=[INDEX], upto=upto, confirm=lambda text: True)
        assert _kinds(result) == [kind], [str(f) for f in result.findings]
        assert result.findings[0].fixable is fixable
        assert result.ok is fixable
        if not fixable:  # nothing saved, the motors off
            assert not result.saved and "NOT saved" in result.message
            assert board.eeprom == eeprom
            assert all(mode in ("coast", "brake") for a, b in board.drive for mode in (a[0], b[0]))


def test_the_model_build_has_nothing_to_name(built: Built) -> None:
    with built() as (_, hand):
        result = bringup(hand, fingers=[INDEX], upto="wiring")
    assert result.findings == []
    assert result.fingers[0].config.finger_config == {"encoder_invert": 0, "motor_invert": 0}


def test_an_inverted_magnet_is_fixed_by_the_configuration(built: Built) -> None:
    with built("invert-magnet:1") as (_, hand):
        result = bringup(hand, fingers=[INDEX], upto="wiring")
    assert _kinds(result) == ["encoder-inverted"]
    assert result.fingers[0].config.finger_config["encoder_invert"] == 1


@pytest.mark.slow
def test_slack_on_the_thumb_is_named(built: Built) -> None:
    """The thumb's stiff strands blew the twin up when a slack strand was undamped (MuJoCo's
    "Nan, Inf or huge value in QACC"; named no-motion or lead-b-swapped); a slack strand now
    acts only while taut. Its closing search pauses mid-travel (Joint 2 waits on its strand)
    and goes on when driven again: slack, not a jam."""
    with built("slack:0=0.0019") as (_, hand):
        result = bringup(hand, fingers=[0], upto="plant")
    assert _kinds(result) == ["slack"], [str(f) for f in result.findings]
    assert not result.ok
