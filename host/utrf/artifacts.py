"""Where the firmware (ELF, HEX) and the emulator's harness library come from.

In order:

1. A path given explicitly (``--elf``, ``--hex``), or ``UTRF_FIRMWARE_ELF`` /
   ``UTRF_FIRMWARE_HEX`` / ``UTRF_SIM_LIB`` in the environment.
2. In a checkout (the current directory or one above it holds ``firmware/firmware.mk``):
   what ``make firmware`` and ``make emulator`` built under its ``build/``; missing, the
   error says which ``make`` target builds it.
3. Otherwise (an installed package): built on first use from the sources the wheel ships
   (``utrf/_firmware``: firmware/src and its makefiles; ``utrf/emulator/harness``) with the
   same makefiles, into ``$XDG_CACHE_HOME/utrf/<hash of the sources>/`` (``~/.cache`` by
   default), once per version of the sources. A missing tool is one line naming the Debian
   package that has it.

A board started without an explicit firmware says which it runs (:func:`describe_firmware`:
its build id and which of these it came from). A cached build's id is its sources' hash, so
two installs of the same sources report the same build.

No path here climbs from ``__file__`` into a repository: the packaged sources are package
data (``importlib.resources``), and a checkout is found from the working directory.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
from importlib import resources
from pathlib import Path

CHECKOUT_ELF = Path("build/firmware/utrf.elf")
CHECKOUT_HEX = Path("build/firmware/utrf.hex")
CHECKOUT_LIB = Path("build/emulator/libutrf_sim.so")
ARDUINO_CORE = Path("/usr/share/arduino/hardware/arduino/avr/cores/arduino")

# What the build needs, and the Debian package that has it (tools/setup.sh installs them all).
APT_ALL = "gcc-avr avr-libc binutils-avr arduino-core-avr simavr libsimavr-dev libelf-dev"
_FIRMWARE_TOOLS = {"make": "make", "avr-g++": "gcc-avr", "avr-gcc": "gcc-avr",
                   "avr-ar": "binutils-avr", "avr-objcopy": "binutils-avr"}  # fmt: skip
_HARNESS_TOOLS = {"make": "make", "cc": "gcc"}
_HARNESS_FILES = {Path("/usr/include/simavr/sim_avr.h"): "libsimavr-dev",
                  Path("/usr/include/libelf.h"): "libelf-dev"}  # fmt: skip


class ArtifactError(RuntimeError):
    """The firmware or the harness library is missing and cannot be built; says what to do."""


def checkout_root(start: Path | None = None) -> Path | None:
    """The checkout holding the working directory (or ``start``), if any."""
    here = (start or Path.cwd()).resolve()
    for d in (here, *here.parents):
        if (d / "firmware" / "firmware.mk").is_file() and (d / "host" / "utrf").is_dir():
            return d
    return None


def packaged_sources() -> tuple[Path, Path]:
    """The firmware directory and the harness directory shipped in the package."""
    pkg = Path(str(resources.files("utrf")))
    return pkg / "_firmware", pkg / "emulator" / "harness"


def cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "utrf"


def _source_hash(fw_dir: Path, harness_dir: Path) -> str:
    """The sources' hash, and the MuJoCo the harness is built against (its headers come from
    the mujoco package: installed or upgraded later, the harness is built anew)."""
    h = hashlib.sha256()
    h.update(f"mujoco {_mujoco_version()}\0".encode())
    for root in (fw_dir, harness_dir):
        files = [*root.glob("*.mk"), *root.glob("src/**/*.[ch]*"), *root.glob("*.[ch]")]
        for p in sorted(set(files)):
            h.update(str(p.relative_to(root)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def _mujoco_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("mujoco")
    except metadata.PackageNotFoundError:
        return "none"


def _check_tools(tools: dict[str, str], files: dict[Path, str], what: str) -> None:
    for tool, package in tools.items():
        if shutil.which(tool) is None:
            raise ArtifactError(
                f"cannot build {what}: {tool} not found: install Debian's {package} "
                f"(all the toolchain: sudo apt-get install {APT_ALL})"
            )
    for path, package in files.items():
        if not path.exists():
            raise ArtifactError(
                f"cannot build {what}: {path} not found: install Debian's {package} "
                f"(all the toolchain: sudo apt-get install {APT_ALL})"
            )


def _cached(relative: Path, what: str, tools: dict[str, str], files: dict[Path, str]) -> Path:
    """Build ``relative`` (under the cache) from the packaged sources, once per version."""
    fw_dir, harness_dir = packaged_sources()
    if not (fw_dir / "firmware.mk").is_file():
        raise ArtifactError(
            f"cannot build {what}: the package holds no firmware sources ({fw_dir}): "
            "reinstall utrf, or pass the file explicitly"
        )
    out = cache_root() / _source_hash(fw_dir, harness_dir)
    target = out / relative
    if target.is_file():
        return target
    _check_tools(tools, files, what)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # two first uses at once build once
        if target.is_file():
            return target
        print(f"utrf: building {what} into {out} (once)", flush=True)
        cmd = ["make", "-s", "--no-print-directory",
               "-f", str(fw_dir / "firmware.mk"), "-f", str(harness_dir / "harness.mk"),
               f"FW_DIR={fw_dir}", f"EMU_DIR={harness_dir}", f"BUILD={out}",
               f"FW_GIT_ID={out.name[:8]}",  # the build id: the cache's hash of the sources
               f"PY={sys.executable}",  # harness.mk asks it for MuJoCo's headers
               str(target)]  # fmt: skip
        proc = subprocess.run(cmd, cwd=out, capture_output=True, text=True, check=False)
        if proc.returncode or not target.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            raise ArtifactError(f"building {what} failed: {tail[0]} (in {out})")
    return target


def _resolve(env: str, checkout_rel: Path, make_target: str, what: str) -> Path:
    if os.environ.get(env):
        return Path(os.environ[env])
    root = checkout_root()
    if root is not None:
        path = root / checkout_rel
        if not path.is_file():
            raise ArtifactError(f"{what} {path} not found (run `make {make_target}`)")
        return path
    tools = _FIRMWARE_TOOLS if make_target == "firmware" else _HARNESS_TOOLS
    files = {ARDUINO_CORE: "arduino-core-avr"} if make_target == "firmware" else _HARNESS_FILES
    return _cached(checkout_rel.relative_to("build"), what, tools, files)


def firmware_elf() -> Path:
    """The firmware ELF to emulate."""
    return _resolve("UTRF_FIRMWARE_ELF", CHECKOUT_ELF, "firmware", "firmware ELF")


def firmware_hex() -> Path:
    """The firmware HEX to flash."""
    return _resolve("UTRF_FIRMWARE_HEX", CHECKOUT_HEX, "firmware", "firmware HEX")


def harness_library() -> Path:
    """The emulator's simavr harness (a shared library loaded with ctypes)."""
    return _resolve("UTRF_SIM_LIB", CHECKOUT_LIB, "emulator", "the emulator's harness library")


def firmware_build_id(elf: Path) -> int | None:
    """The build id compiled into ``elf`` (identify's ``build_id``), from the ``build_id.h``
    its build wrote beside it; None when there is none (an ELF from elsewhere)."""
    try:
        text = (elf.parent / "build_id.h").read_text()
    except OSError:
        return None
    for word in text.split():
        if word.startswith("0x") and word.endswith("UL"):
            return int(word[2:-2], 16)
    return None


def describe_firmware(elf: Path, given: bool = False) -> str:
    """Which firmware ``elf`` is, in words: its build id and where it came from (given
    explicitly, ``UTRF_FIRMWARE_ELF``, this checkout's build, or the user's cache built from
    the packaged sources)."""
    build = firmware_build_id(elf)
    ident = f"build {build:08x}" if build is not None else "build id unknown"
    env = os.environ.get("UTRF_FIRMWARE_ELF")
    root = checkout_root()
    if given:
        origin = "given explicitly"
    elif env and Path(env).resolve() == elf.resolve():
        origin = "from UTRF_FIRMWARE_ELF"
    elif root is not None and (root / CHECKOUT_ELF).resolve() == elf.resolve():
        origin = f"this checkout's `make firmware` ({root})"
    elif cache_root().resolve() in elf.resolve().parents:
        origin = (
            f"built from the sources packaged with utrf {_version()} and cached in "
            f"{elf.parent.parent} (pass --elf or set UTRF_FIRMWARE_ELF for another)"
        )
    else:
        origin = "the default"
    return f"{elf} ({ident}, {origin})"


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("utrf")
    except metadata.PackageNotFoundError:
        return "(not installed)"
