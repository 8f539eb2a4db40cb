"""The package as a user installs it (issue 9 §4): a wheel built from this checkout, installed
(not editable) into a fresh venv, run from a directory that is not a checkout. It finds no
repository: the firmware and the emulator's harness are built on first use from the sources
the wheel ships, into the user's cache; a missing tool is one line naming its package."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A venv holding the wheel (no network: build and install without isolation, the
    dependencies from this interpreter's site-packages through a .pth file)."""
    root = tmp_path_factory.mktemp("installed")
    src = root / "src"
    files = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=REPO, capture_output=True, check=True,
    ).stdout.split(b"\0")  # fmt: skip
    for name in filter(None, files):
        rel = Path(os.fsdecode(name))
        if not (REPO / rel).exists() and not (REPO / rel).is_symlink():
            continue  # deleted, not yet committed
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        if (REPO / rel).is_symlink():
            (src / rel).symlink_to(os.readlink(REPO / rel))
        else:
            shutil.copy2(REPO / rel, src / rel)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(root / "wheel"),
                    str(src)], check=True, capture_output=True)  # fmt: skip
    (wheel,) = (root / "wheel").glob("utrf-*.whl")
    venv = root / "venv"
    base = Path(getattr(sys, "_base_executable", sys.executable))
    subprocess.run([str(base), "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    (Path(purelib) / "utrf-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([*pip, "--python", str(python), "install", "--no-deps", "--no-index",
                    str(wheel)], check=True, capture_output=True)  # fmt: skip
    yield venv


def _env(root: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("UTRF_")}
    env["XDG_CACHE_HOME"] = str(root / "cache")
    env.update(extra)
    return env


@pytest.mark.slow
def test_installed_package_emulates_poses_and_flashes_from_anywhere(
    installed: Path, tmp_path: Path
) -> None:
    utrf = str(installed / "bin" / "utrf")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = _env(tmp_path)
    urls = tmp_path / "urls"
    emulate = subprocess.Popen(
        [utrf, "emulate", "--url-file", str(urls), "--duration", "60", "--no-commands",
         "--status-interval", "0"],
        cwd=elsewhere, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 45  # the first use builds the firmware and the harness
        while not urls.exists() and emulate.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert urls.exists(), emulate.communicate(timeout=5)[0] if emulate.poll() else "no URL"
        url = urls.read_text().split()[0]
        assert url.startswith("socket://")
        pose = subprocess.run(
            [utrf, "pose", "shaka", "--port", url, "--duration", "0.5"],
            cwd=elsewhere, env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert pose.returncode == 0, pose.stdout + pose.stderr
        assert "settled: shaka" in pose.stdout
    finally:
        emulate.terminate()
        out = emulate.communicate(timeout=10)[0]
    cache = tmp_path / "cache" / "utrf"
    (built,) = cache.iterdir()
    assert f"building firmware ELF into {built} (once)" in out
    assert f"serving: firmware {built / 'firmware' / 'utrf.elf'}" in out
    # it says which firmware: the build id (the sources' hash) and that it is the cached build
    assert f"(build {built.name[:8]}, built from the sources packaged with utrf" in out
    assert (built / "emulator" / "libutrf_sim.so").is_file()

    flash = subprocess.run(
        [utrf, "flash", "--port", "/dev/ttyACM0", "--dry-run"],
        cwd=elsewhere, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert flash.returncode == 0, flash.stderr
    assert f"flash:w:{built / 'firmware' / 'utrf.hex'}:i" in flash.stdout
    assert not list(elsewhere.iterdir())  # nothing written where it ran


@pytest.mark.slow
def test_installed_package_names_a_missing_tool_in_one_line(
    installed: Path, tmp_path: Path
) -> None:
    bin_dir = tmp_path / "bin"  # a PATH with make but no AVR toolchain
    bin_dir.mkdir()
    make = shutil.which("make")
    assert make is not None
    (bin_dir / "make").symlink_to(make)
    env = _env(tmp_path, PATH=str(bin_dir))
    for argv in (["emulate", "--duration", "1"], ["hil", "grasp-hold", "--emulated", "--out", "o"]):
        proc = subprocess.run(
            [str(installed / "bin" / "utrf"), *argv],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "avr-g++ not found: install Debian's gcc-avr" in lines[0]
        assert not (tmp_path / "o").exists()


def test_no_path_climbs_from_the_package_into_a_repository() -> None:
    climbing = re.compile(r"__file__\)?(\.resolve\(\))?\.(parents\[|parent\.parent)")
    offenders = [
        f"{p.relative_to(REPO)}:{n}"
        for p in (REPO / "host" / "utrf").rglob("*.py")
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if climbing.search(line)
    ]
    assert offenders == []
