"""Geometry schema: loading, the documented default, and errors that name the field."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from utrf.models.geometry import FingerGeometry, GeometryError, HandGeometry

GOOD = """
[finger]
link_lengths_m = [0.070, 0.055, 0.045]
guide_radii_m = [0.010, 0.008, 0.006]
tendon_diameter_m = 0.001
tendon_youngs_modulus_pa = 200e9
actuating_tendon_length_m = 0.100
link_masses_kg = [0.012, 0.009, 0.006]
link_com_fraction = [0.5, 0.5, 0.5]
theta1_range_deg = [-90, 90]
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "f.toml"
    p.write_text(text)
    return p


def test_default_is_the_documented_170_mm_finger() -> None:
    g = FingerGeometry.default()
    # 0.545 mm = 0.322 % of the finger's length in the paper: about 170 mm.
    assert g.total_length_m == pytest.approx(0.545e-3 / 0.00322, rel=0.01)
    assert g.theta1_range_rad == pytest.approx((-math.pi / 2, math.pi / 2))


def test_file_round_trips_through_to_dict(tmp_path: Path) -> None:
    g = FingerGeometry.from_toml(_write(tmp_path, GOOD))
    assert FingerGeometry.from_dict(g.to_dict()) == g


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        (
            "guide_radii_m = [0.010, 0.008, 0.006]",
            "guide_radii_m = [0.040, 0.035, 0.006]",
            "R1 + R2",
        ),
        (
            "guide_radii_m = [0.010, 0.008, 0.006]",
            "guide_radii_m = [0.010, 0.030, 0.030]",
            "R2 + R3",
        ),
        (
            "link_lengths_m = [0.070, 0.055, 0.045]",
            "link_lengths_m = [0.070, -0.05, 0.045]",
            "link_lengths_m[1]",
        ),
        ("tendon_diameter_m = 0.001", "tendon_diameter_m = 0", "tendon_diameter_m"),
        (
            "link_com_fraction = [0.5, 0.5, 0.5]",
            "link_com_fraction = [0.5, 1.5, 0.5]",
            "link_com_fraction",
        ),
        ("theta1_range_deg = [-90, 90]", "theta1_range_deg = [90, -90]", "theta1_range_deg"),
        (
            "tendon_youngs_modulus_pa = 200e9",
            "tendon_youngs_modulus_pa = 'steel'",
            "tendon_youngs_modulus_pa",
        ),
        (
            "link_masses_kg = [0.012, 0.009, 0.006]",
            "link_masses_kg = [0.012, 0.009]",
            "link_masses_kg",
        ),
    ],
)
def test_bad_values_name_the_field(tmp_path: Path, old: str, new: str, field: str) -> None:
    assert old in GOOD
    with pytest.raises(GeometryError, match=field.replace("[", r"\[").replace("+", r"\+")):
        FingerGeometry.from_toml(_write(tmp_path, GOOD.replace(old, new)))


def test_missing_and_unknown_keys_are_named(tmp_path: Path) -> None:
    with pytest.raises(GeometryError, match=r"missing key.*tendon_diameter_m"):
        FingerGeometry.from_toml(_write(tmp_path, GOOD.replace("tendon_diameter_m = 0.001", "")))
    with pytest.raises(GeometryError, match=r"unknown key.*colour"):
        FingerGeometry.from_toml(_write(tmp_path, GOOD + "colour = 'red'\n"))


def test_unreadable_files_say_why(tmp_path: Path) -> None:
    with pytest.raises(GeometryError, match="no such geometry file"):
        FingerGeometry.from_toml(tmp_path / "absent.toml")
    with pytest.raises(GeometryError, match="not valid TOML"):
        FingerGeometry.from_toml(_write(tmp_path, "[finger\n"))
    with pytest.raises(GeometryError, match=r"needs a \[finger\] table"):
        FingerGeometry.from_toml(_write(tmp_path, "[hand]\nname = 'x'\n"))


def test_default_hand_has_five_fingers_and_a_different_thumb() -> None:
    hand = HandGeometry.default()
    assert [f.name for f in hand.fingers] == ["thumb", "index", "middle", "ring", "little"]
    assert hand.fingers[0].geometry != hand.fingers[1].geometry
    assert hand.fingers[1].geometry == FingerGeometry.default()
    assert hand.index("ring") == 3
    with pytest.raises(KeyError, match="pinky"):
        hand.index("pinky")


def test_derived_ranges_follow_the_coupling() -> None:
    g = FingerGeometry.default()
    lo, hi = g.q_range_m
    assert lo == -hi
    assert hi == pytest.approx(g.guide_radii_m[0] * math.pi / 2)
    assert g.theta2_range_rad[1] == pytest.approx(hi / g.guide_radii_m[1])
    assert g.tendon_area_m2 == pytest.approx(math.pi * 0.25e-6)
