"""The wiring tables people read agree with the one definition, firmware/src/board_pins.h."""

from __future__ import annotations

import re

import pytest
from fwsim import REPO

NAMES = ("thumb", "index", "middle", "ring", "little")


def pins_from_header() -> list[list[str]]:
    """Each finger's row as the tables write it, built from board_pins.h's initialisers."""
    text = (REPO / "firmware" / "src" / "board_pins.h").read_text()
    body = text[text.index("UTRF_FINGER_PINS[UTRF_FINGER_COUNT] = {") :]
    pin = r"\{'([A-L])', (\d), (\d+)\}"
    motor = r"\{\{(\d), '([ABC])', " + pin + r"\}, " + pin + ", " + pin + r"\}"
    finger = r"\{" + motor + r",\s*" + motor + r",\s*" + pin + r", (\d)\}"
    rows = []
    for f in re.finditer(finger, body):
        g = f.groups()

        def d(port: str, bit: str, num: str) -> str:
            return f"D{num} (P{port}{bit})"

        def pwm(timer: str, ch: str, port: str, bit: str, num: str) -> str:
            return f"D{num} (OC{timer}{ch}, P{port}{bit})"

        rows.append(
            [
                pwm(*g[0:5]),
                d(*g[5:8]),
                d(*g[8:11]),
                pwm(*g[11:16]),
                d(*g[16:19]),
                d(*g[19:22]),
                d(*g[22:25]),
                f"A{g[25]}",
            ]
        )
    assert len(rows) == 5
    return rows


def table_rows(path: str) -> list[list[str]]:
    rows = []
    for line in (REPO / path).read_text().splitlines():
        m = re.match(r"\|\s*(\d) (\w+)\s*\|(.*)\|\s*$", line)
        if m and m.group(2) in NAMES:
            rows.append([c.strip() for c in m.group(3).split("|")])
    return rows


@pytest.mark.parametrize("path", ["firmware/README.md", "docs/architecture.md"])
def test_wiring_table_matches_board_pins(path: str) -> None:
    assert table_rows(path) == pins_from_header()
