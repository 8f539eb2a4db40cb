"""The firmware as built for the MEGA 2560: the build itself, and the ELF on simavr.

- the build is warning-free and within its flash and RAM targets;
- the core's arithmetic gives the same results on the AVR (its multiplies, 16-bit
  int) as in the host build the other tests use;
- the pins and timers follow board_pins.h through every mode (the emulator's contract);
- the tick runs on time under protocol traffic, and the firmware's own timing agrees with the
  simulator's cycle count (tools.tick_bench, on the emulator's harness).
"""

from __future__ import annotations

import ctypes
import re
import subprocess
from pathlib import Path

import pytest
from fwsim import REPO

from tools import tick_bench

ELF = REPO / "build" / "firmware" / "utrf.elf"
CHECK_ELF = REPO / "build" / "firmware" / "check" / "core_check.elf"
FLASH_TARGET = 64 * 1024  # firmware.mk FW_TARGET_FLASH
RAM_TARGET = 3 * 1024


@pytest.fixture(scope="module")
def built() -> None:
    subprocess.run(
        ["make", "--no-print-directory", "-s", "firmware", "firmware-check", "emulator"],
        cwd=REPO,
        check=True,
        capture_output=True,
    )


def section_sizes(elf: Path) -> dict[str, int]:
    out = subprocess.run(
        ["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    sizes = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith(".") and parts[1].isdigit():
            sizes[parts[0]] = int(parts[1])
    return sizes


def test_mega_build_is_warning_free_and_within_targets(tmp_path: Path) -> None:
    """A clean build into an empty directory: every file compiled, every warning seen."""
    r = subprocess.run(
        ["make", "--no-print-directory", "-j2", "firmware", f"BUILD={tmp_path}"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    ours = [
        ln for ln in (r.stdout + r.stderr).splitlines() if "warning:" in ln and "firmware/" in ln
    ]
    assert ours == []
    sizes = section_sizes(tmp_path / "firmware" / "utrf.elf")
    flash = sizes[".text"] + sizes.get(".data", 0)
    ram = sizes.get(".data", 0) + sizes.get(".bss", 0) + sizes.get(".noinit", 0)
    assert flash <= FLASH_TARGET
    assert ram <= RAM_TARGET
    # The build prints what it measured: against the chip as the Arduino IDE does (its
    # integer percentages; the MEGA's 256 KB less the 8 KB bootloader, 8 KB of RAM), then
    # against the project's budgets.
    assert (
        f"Sketch uses {flash} bytes ({100 * flash // 253952}%) of program storage space. "
        "Maximum is 253952 bytes." in r.stdout
    )
    assert (
        f"Global variables use {ram} bytes ({100 * ram // 8192}%) of dynamic memory, leaving "
        f"{8192 - ram} bytes for local variables. Maximum is 8192 bytes." in r.stdout
    )
    assert re.search(rf"budgets: flash {flash} bytes .*static RAM {ram} bytes", r.stdout)
    assert "kinematics table:" in r.stdout
    assert (tmp_path / "firmware" / "utrf.hex").stat().st_size > flash


def test_core_arithmetic_is_the_same_on_the_avr(built, fwlib: ctypes.CDLL) -> None:
    r = subprocess.run(
        ["simavr", "-m", "atmega2560", "-f", "16000000", str(CHECK_ELF)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    found = re.search(r"CORE_CHECK ([0-9a-f]{8})", r.stdout + r.stderr)
    assert found, r.stdout + r.stderr
    fwlib.fw_core_check.restype = ctypes.c_uint32
    assert int(found.group(1), 16) == fwlib.fw_core_check()


def test_product_slices_from_byte_products_are_exact(fwlib: ctypes.CDLL) -> None:
    """The tick's P, D and filter take slices of a 16 x 16 product from its four 8 x 8 pieces
    (fixed.h, ProdSU): every slice equals the one of the 32-bit product, on a sweep of a
    against b and at their edges; and a gain of each shift applied with its saturation equals
    the 32-bit product shifted (the core check above shows the AVR computes the same)."""
    fwlib.fw_product_mismatches.restype = ctypes.c_uint32
    assert fwlib.fw_product_mismatches() == 0


@pytest.fixture(scope="module")
def pins(built) -> dict:
    return tick_bench.run(ELF, "pins", 0)


def test_pwm_timers_are_fast_pwm_mode_14_at_20_khz(pins: dict) -> None:
    for finger in pins["boot"]:
        for motor in (finger["a"], finger["b"]):
            assert (motor["wgm"], motor["icr"], motor["cs"]) == (14, 799, 1)
            assert motor["outputs"] == 1 and finger["stby_out"] == 1


def test_timer2_ticks_at_1_khz_and_uart_runs_at_1_mbaud(pins: dict) -> None:
    t2 = pins["timer2"]
    assert t2["tccr2a"] == 0x02  # CTC
    assert t2["tccr2b"] == 0x04  # clk/64
    assert t2["ocr2a"] == 249  # 16 MHz / 64 / 250 = 1 kHz
    assert t2["timsk2"] & 0x02
    assert pins["ubrr0"] == 1 and pins["ucsr0a"] & 0x02  # U2X: 16 MHz / 8 / 2 = 1 Mbaud


def test_boot_and_coast_leave_every_driver_off(pins: dict) -> None:
    for phase in ("boot", "coast"):
        for finger in pins[phase]:
            assert finger["stby"] == 0
            for motor in (finger["a"], finger["b"]):
                assert (motor["com"], motor["in1"], motor["in2"], motor["pwm_pin"]) == (0, 0, 0, 0)


@pytest.mark.parametrize("phase,flexor,extensor", [("duty_plus", 479, 79), ("duty_minus", 79, 479)])
def test_duty_drives_both_tendons_forward(pins: dict, phase: str, flexor: int, extensor: int):
    """Antagonistic, duty +-0.5: the working side at 0.6, the other at the 0.1 pretension."""
    for finger in pins[phase]:
        assert finger["stby"] == 1
        for motor, ocr in ((finger["a"], flexor), (finger["b"], extensor)):
            assert motor["com"] == 2  # non-inverting compare output connected
            assert motor["ocr"] == ocr  # duty = (OCR + 1) / 800
            assert (motor["in1"], motor["in2"]) == (1, 0)  # forward: pull


def test_brake_shorts_both_channels(pins: dict) -> None:
    for finger in pins["brake"]:
        assert finger["stby"] == 1
        for motor in (finger["a"], finger["b"]):
            assert (motor["com"], motor["in1"], motor["in2"], motor["pwm_pin"]) == (0, 1, 1, 0)


def test_an_unplugged_encoder_turns_its_driver_off(pins: dict) -> None:
    for f, finger in enumerate(pins["encoder_fault"]):
        if f == 2:
            assert finger["stby"] == 0
            assert finger["a"]["com"] == 0 and finger["b"]["com"] == 0
        else:
            assert finger["stby"] == 1 and finger["a"]["com"] == 2


def test_tick_runs_on_time_under_traffic_and_its_timing_is_true(built) -> None:
    s = tick_bench.run(ELF, "typical", 0.4)
    assert s["tick_overruns"] == 0
    # 1 kHz: reset_stats at 0.30 s, 0.4 s of traffic from 0.31 s, 50 ms to drain, get_stats at
    # about 0.76 s.
    assert abs(s["ticks"] - 460) <= 10
    assert s["rx_frames"] >= 75 and s["rx_crc_errors"] == 0 and s["nacks"] == 0
    assert s["state_frames"] + s["tx_dropped"] >= 195  # 500 Hz, each sent or counted
    assert s["fault_frames"] == 0
    # The firmware's own measurement (timer 2 and timer 1) against simavr's cycle count of
    # app::tick(): the firmware's window holds that call and a little bookkeeping around it.
    worst_fw = s["tick_worst_us"] * 16
    assert s["sim_tick_worst_cycles"] - 8 <= worst_fw <= s["sim_tick_worst_cycles"] + 120
