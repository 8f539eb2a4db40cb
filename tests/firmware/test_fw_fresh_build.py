"""A fresh machine: the build must not read, while make parses, what the set-up installs.

On a machine without the Debian packages, `make test` runs tools/setup.sh (which installs the
Arduino core) after make has read its makefiles; a source list taken with $(wildcard) at
parse time was empty and the first run failed at avr-ar. Here the core's directory appears
only when a prerequisite recipe of the archive runs, as it does on a fresh machine.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DEBIAN_CORE = Path("/usr/share/arduino/hardware/arduino/avr")


@pytest.mark.slow
def test_core_archive_builds_from_a_directory_created_after_parsing(tmp_path: Path) -> None:
    if not (DEBIAN_CORE / "cores" / "arduino").is_dir():
        pytest.fail(f"{DEBIAN_CORE} is missing: run `make setup` (arduino-core-avr)")
    avr = tmp_path / "late" / "avr"
    build = tmp_path / "build"
    lib = build / "firmware" / "arduino-core" / "libarduino_core.a"
    late = tmp_path / "late.mk"
    # The stand-in for tools/setup.sh: a recipe that creates the core while make runs.
    late.write_text(
        f"{lib}: install-core-late\n"
        "install-core-late:\n"
        f"\tmkdir -p {avr.parent} && cp -r {DEBIAN_CORE} {avr}\n"
    )
    assert not avr.exists()
    proc = subprocess.run(
        ["make", "--no-print-directory", "-f", "Makefile", "-f", str(late),
         f"BUILD={build}", f"ARDUINO_AVR={avr}", str(lib)],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=240,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    members = subprocess.run(
        ["avr-ar", "t", str(lib)], capture_output=True, text=True, check=True
    ).stdout.split()
    sources = sorted(
        p.name for p in (avr / "cores" / "arduino").iterdir() if p.suffix in (".c", ".cpp", ".S")
    )
    assert sorted(n.removesuffix(".o") for n in members) == sources
    assert f"arduino core: {len(sources)} objects from {avr}/cores/arduino" in proc.stdout


def test_missing_core_is_one_clear_line(tmp_path: Path) -> None:
    proc = subprocess.run(
        ["make", "--no-print-directory", f"BUILD={tmp_path}", f"ARDUINO_AVR={tmp_path}/none",
         f"{tmp_path}/firmware/arduino-core/libarduino_core.a"],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=60,
    )  # fmt: skip
    assert proc.returncode != 0
    assert f"no Arduino core sources in {tmp_path}/none/cores/arduino" in proc.stderr
    assert "arduino-core-avr" in proc.stderr


def test_setup_installs_only_what_is_used() -> None:
    setup = (REPO / "tools" / "setup.sh").read_text()
    assert "doctest" not in setup
    assert shutil.which("bash")
