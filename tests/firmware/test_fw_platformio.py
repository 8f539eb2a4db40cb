"""platformio.ini builds what `make firmware` builds: the same board, sources and flags.

PlatformIO cannot run here (it downloads its toolchain), so this reads both files: the
flags the Makefile really uses (asked of make) against the ones platformio.ini gives.
"""

import configparser
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# Flags that are the build system's business, not the code's: debug info and the sections
# the linker garbage-collects (PlatformIO adds both itself).
BUILD_SYSTEM_FLAGS = {"-g", "-ffunction-sections", "-fdata-sections"}


def make_var(name: str) -> list[str]:
    out = subprocess.run(
        ["make", "-s", "--no-print-directory", "--eval", "print-%: ; @echo $($*)", f"print-{name}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.split()


def pio_env() -> configparser.SectionProxy:
    ini = configparser.ConfigParser()
    ini.read(ROOT / "platformio.ini")
    return ini["env:megaatmega2560"]


def test_the_env_targets_the_mega_with_arduino() -> None:
    env = pio_env()
    assert env["board"] == "megaatmega2560"
    assert env["framework"] == "arduino"
    assert env["platform"] == "atmelavr"


def test_our_sources_get_the_makefiles_flags() -> None:
    made = {
        f
        for var in ("FW_OPT", "FW_CXXSTD", "FW_WARN", "FW_DEFS")
        for f in make_var(var)
        if f not in BUILD_SYSTEM_FLAGS
    }
    pio = set(pio_env()["build_src_flags"].split())
    assert pio == made


def test_the_source_directory_is_the_firmwares() -> None:
    ini = configparser.ConfigParser()
    ini.read(ROOT / "platformio.ini")
    src = ROOT / ini["platformio"]["src_dir"]
    assert (src / "utrf_main.cpp").is_file()
    assert (src / "board_pins.h").is_file()
