"""tools/fw_profile.py: the awake cycles under the twin's traffic, mapped to the ELF's functions
(make profile-firmware, and the awake table of make bench-firmware)."""

from __future__ import annotations

import subprocess

import pytest
from fwsim import REPO

from tools import fw_profile

ELF = REPO / "build" / "firmware" / "utrf.elf"


@pytest.fixture(scope="module")
def profile() -> dict:
    subprocess.run(
        ["make", "--no-print-directory", "-s", "firmware", "emulator"],
        cwd=REPO,
        check=True,
        capture_output=True,
    )
    return fw_profile.awake(ELF, 0.3, 100)


def test_every_awake_cycle_is_a_functions_and_the_slept_ones_are_left_out(profile) -> None:
    # awake() raises when the slept cycles are not all at the sleep instruction; the rest add
    # up to the awake total, each in a named function of the ELF
    assert sum(profile["functions"].values()) == pytest.approx(profile["per_s"])
    assert "?" not in profile["functions"]
    assert 0.05 < profile["share"] < 0.95  # the idle sleep under the hold's traffic
    assert profile["per_s"] == pytest.approx(profile["share"] * fw_profile.CPU_HZ)


def test_the_tick_and_the_encoders_rounds_are_where_the_profile_puts_them(profile) -> None:
    f = profile["functions"]
    # 1 kHz ticks of five fingers: app::tick() is the largest part; the ADC interrupt runs
    # five conversions a tick
    assert max(f, key=f.get) == "utrf::app::tick()"
    assert f["utrf::app::tick()"] > 1000 * 1000  # more than 1,000 cycles a tick
    assert "__vector_29" in f and "__vector_13" in f
    assert fw_profile.label("__vector_29") == "__vector_29 (ADC interrupt)"


def test_one_functions_source_lines_are_listed(profile, capsys) -> None:
    addrs, names = fw_profile.symbols(ELF)
    fw_profile.lines(ELF, profile["hist"], "utrf::app::tick()", profile["sim_s"], addrs, names)
    out = capsys.readouterr().out
    assert "by source file" in out and "pid.h" in out


@pytest.mark.slow
def test_the_hold_with_the_plant_is_profiled_like_the_elf_alone(profile) -> None:
    # (the profile fixture builds the ELF and the harness) the grasp hold's run (the closing,
    # then 4 s of hold): every slept cycle found at a sleep instruction (awake() raises
    # otherwise), the rest in the ELF's functions; the moving, noisy encoders keep the tick
    # the largest part
    a = fw_profile.awake(ELF, 4.0, 100, plant=True)
    assert a["sim_s"] > 5.0  # the closing is counted
    assert "?" not in a["functions"]
    assert max(a["functions"], key=a["functions"].get) == "utrf::app::tick()"
    assert 0.05 < a["share"] < 0.95
