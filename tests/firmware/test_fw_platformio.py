"""platformio.ini builds what `make firmware` builds, and the PlatformIO build links and runs.

PlatformIO cannot run here (it downloads its platform), so `make firmware-pio` reproduces its
atmelavr Arduino builder with Debian's avr-gcc: every file at -Os with -flto, the core archived
with avr-gcc-ar, a -flto -fuse-linker-plugin link, our sources with platformio.ini's
build_src_flags (firmware/firmware.mk). Link-time optimisation is what broke the build while
the interrupt handlers were assembly naming C variables only in their text (issue 9 §2).
"""

import configparser
import subprocess
from pathlib import Path

import pytest

from utrf.emulator import EmulatedBoard
from utrf.hand import Hand

ROOT = Path(__file__).resolve().parents[2]
# Flags that are the build system's business, not the code's: debug info and the sections
# the linker garbage-collects (PlatformIO adds both itself).
BUILD_SYSTEM_FLAGS = {"-g", "-ffunction-sections", "-fdata-sections"}
FLASH_TARGET = 64 * 1024  # firmware.mk FW_TARGET_FLASH
RAM_TARGET = 3 * 1024


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
    # ... and the PlatformIO-flag build below compiles our sources with exactly these.
    assert set(make_var("PIO_SRC_FLAGS")) == pio


def test_the_source_directory_is_the_firmwares() -> None:
    ini = configparser.ConfigParser()
    ini.read(ROOT / "platformio.ini")
    src = ROOT / ini["platformio"]["src_dir"]
    assert (src / "utrf_main.cpp").is_file()
    assert (src / "board_pins.h").is_file()


def sizes(elf: Path) -> dict[str, int]:
    out = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True)
    found = {}
    for line in out.stdout.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith(".") and parts[1].isdigit():
            found[parts[0]] = int(parts[1])
    return found


def defined(elf: Path) -> set[str]:
    """The global functions the image defines that the chip or the C runtime calls."""
    out = subprocess.run(["avr-nm", str(elf)], capture_output=True, text=True, check=True)
    names = {ln.split()[-1] for ln in out.stdout.splitlines() if " T " in ln}
    return {n for n in names if n.startswith("__vector_") or n in ("main", "__init")}


@pytest.fixture(scope="module")
def pio_elf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A clean PlatformIO-flag build into its own directory."""
    build = tmp_path_factory.mktemp("pio-build")
    r = subprocess.run(
        ["make", "--no-print-directory", "firmware-pio", "firmware", f"BUILD={build}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    # Every file went through link-time optimisation: the link had the plugin's work to do.
    assert "-flto -fuse-linker-plugin" in r.stdout
    return build / "firmware" / "pio" / "utrf.elf"


def test_the_platformio_flag_build_links_the_same_firmware(pio_elf: Path) -> None:
    reference = pio_elf.parent.parent / "utrf.elf"  # `make firmware` into the same BUILD
    # The same interrupt handlers (tick, UART receive and transmit, ADC, timer 0) and entry.
    assert defined(pio_elf) == defined(reference)
    assert {"__vector_13", "__vector_25", "__vector_26", "__vector_29"} <= defined(pio_elf)
    # Timer 0's overflow is the firmware's own handler (hal/avr, init() defined there): the
    # core's wiring.c object, with its handler and millis() state, is taken by neither link.
    for elf in (pio_elf, reference):
        assert "__vector_23" in defined(elf)
        symbols = subprocess.run(["avr-nm", str(elf)], capture_output=True, text=True, check=True)
        assert "timer0_millis" not in symbols.stdout
        assert "timer0_overflow_count" not in symbols.stdout
    pio, ref = sizes(pio_elf), sizes(reference)
    flash = pio[".text"] + pio.get(".data", 0)
    ram = pio.get(".data", 0) + pio.get(".bss", 0) + pio.get(".noinit", 0)
    ref_ram = ref.get(".data", 0) + ref.get(".bss", 0) + ref.get(".noinit", 0)
    assert flash <= FLASH_TARGET and ram <= RAM_TARGET
    # The same buffers and state: link-time optimisation may drop a few unused bytes, never a
    # buffer (the UART rings alone are 384 bytes).
    assert abs(ram - ref_ram) <= 64


def test_the_platformio_flag_build_runs_on_the_emulated_board(
    pio_elf: Path, firmware_elf: Path
) -> None:
    """It boots, answers identify and ping, streams state and holds a finger where told.
    (firmware_elf: the emulator's harness is built.)"""
    with EmulatedBoard(pio_elf, realtime=False, seed=3) as board, Hand.emulated(board) as hand:
        assert hand.identity.fw_major == 0
        assert hand.ping() > 0
        hand.clock.sleep(0.1)
        assert hand.latest is not None
        hand.set_targets({"index": 0.6})  # into POSITION
        hand.clock.sleep(1.0)
        index = hand.state()["index"]
        # held within four encoder counts (7.7 mrad each): against the plant's static friction
        # the default gains rest one to three counts off, depending on the build's timing
        assert abs(index.theta2 - 0.6) < 0.03
        assert index.faults == 0


def test_the_arduino_library_layout(tmp_path: Path) -> None:
    """Arduino IDE / arduino-cli users get the firmware as a library (firmware/ with
    library.properties, sources in src/, compiled recursively by the IDE) and an example
    sketch that adds nothing: the library defines setup() and loop()."""
    props = dict(
        ln.split("=", 1)
        for ln in (ROOT / "firmware" / "library.properties").read_text().splitlines()
        if "=" in ln
    )
    for key in ("name", "version", "author", "maintainer", "sentence", "category", "url"):
        assert props.get(key), key
    assert props["architectures"] == "avr"
    sketch = ROOT / "firmware" / "examples" / "utrf" / "utrf.ino"
    includes = [ln for ln in sketch.read_text().splitlines() if ln.startswith("#include")]
    assert includes == ["#include <utrf.h>"]
    assert (ROOT / "firmware" / "src" / "utrf.h").is_file()
    # The sketch compiled as the IDE does (Arduino.h first, the library's src on the path)
    # defines nothing, so it cannot clash with the library's setup() and loop().
    obj = tmp_path / "utrf.ino.o"
    subprocess.run(
        [
            "avr-g++",
            "-c",
            "-x",
            "c++",
            "-std=gnu++11",
            "-Os",
            "-mmcu=atmega2560",
            "-DF_CPU=16000000L",
            "-DARDUINO=10819",
            *make_var("FW_INC"),
            f"-I{ROOT / 'firmware' / 'src'}",
            "-include",
            "Arduino.h",
            "-o",
            str(obj),
            str(sketch),
        ],
        check=True,
        cwd=ROOT,
    )
    out = subprocess.run(["avr-nm", str(obj)], capture_output=True, text=True, check=True)
    assert " T " not in out.stdout
    main = (ROOT / "firmware" / "src" / "utrf_main.cpp").read_text()
    assert "void setup()" in main and "void loop()" in main
