"""A fresh clone as a new user has it: ``make setup firmware emulator`` in one invocation (the
set-up installs MuJoCo during it: the harness must still be built with it), then the README's
shell commands as written, those that finish within a minute, against the emulated board.

The clone reuses the machine's Debian packages; its ``.venv`` is new (pip, from its cache)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

# Every command of the README's ``sh`` blocks, and how this test runs it: "run" (exits 0),
# "serve" (the emulator: started, its pty and URL taken for the commands after it), "watch"
# (runs until Ctrl-C: interrupted after a few seconds, exits 0), or a reason it is not run.
# A README command missing here fails the test: a new command is run, or says why not.
HOW = {
    "make demo": "run",
    "make test": "not run: the whole suite, minutes (this test is part of it)",
    "utrf poses": "run",
    "utrf emulate": "serve",
    "utrf pose shaka --port /dev/pts/N": "run",
    "utrf monitor --port /dev/pts/N": "watch",
    "utrf hil grasp-hold --emulated --object egg": "run",
    "make flash PORT=/dev/ttyACM0": "not run: needs the MEGA on /dev/ttyACM0",
}


def readme_commands(text: str) -> list[str]:
    """The commands of a Markdown file's ``sh`` blocks: comments dropped, continuations joined."""
    out: list[str] = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        pending = ""
        for line in block.splitlines():
            line = re.sub(r"\s+#.*$", "", line).rstrip()
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            pending += line.strip()
            if pending.endswith("\\"):
                pending = pending[:-1].rstrip() + " "
                continue
            out.append(pending)
            pending = ""
    return out


def test_readme_commands_are_found() -> None:
    text = "```sh\nmake demo   # set up\nutrf pose a \\\n  --port X  # where\n# a note\n```\n"
    assert readme_commands(text) == ["make demo", "utrf pose a --port X"]
    assert set(readme_commands((REPO / "README.md").read_text())) == set(HOW)


def _env(clone: Path) -> dict[str, str]:
    """A user's shell in the clone with its .venv activated: nothing of this test's make."""
    drop = ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "VIRTUAL_ENV", "PYTHONPATH")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    path = [p for p in env.get("PATH", "").split(os.pathsep) if ".venv" not in p]
    env["PATH"] = os.pathsep.join([str(clone / ".venv" / "bin"), *path])
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _sh(cmd: str, clone: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", cmd], cwd=clone, env=_env(clone), text=True,
                          capture_output=True, timeout=timeout)  # fmt: skip


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("UTRF_FRESH_CLONE") != "1",
    reason="a new .venv and the whole build take minutes: `make test-fresh-clone` (CI runs it)",
)
@pytest.mark.timeout(1800)  # a new .venv (pip) and the whole build: minutes on a loaded machine
def test_a_fresh_clone_sets_up_builds_and_runs_the_readme(tmp_path: Path) -> None:
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    r = _sh("make setup firmware emulator", clone, timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    built_with = (clone / "build" / "emulator" / "built-with.txt").read_text()
    assert "mujoco_include=none" not in built_with, built_with  # MuJoCo's headers were there
    assert "Sketch uses" in r.stdout  # the size against the chip
    r = _sh("make emulator", clone, timeout=120)  # up to date: nothing rebuilt
    assert r.returncode == 0 and " -shared " not in r.stdout, r.stdout

    commands = readme_commands((clone / "README.md").read_text())
    server = None
    try:
        for cmd in commands:
            how = HOW[cmd]
            if how.startswith("not run"):
                continue
            if how == "serve":
                server = subprocess.Popen(["bash", "-c", f"exec {cmd}"], cwd=clone,
                                          env=_env(clone), stdout=subprocess.PIPE, text=True,
                                          start_new_session=True)  # fmt: skip
                pty = _served_pty(server)
                continue
            run = cmd.replace("/dev/pts/N", pty) if "/dev/pts/N" in cmd else cmd
            if how == "watch":
                p = subprocess.Popen(["bash", "-c", f"exec {run}"], cwd=clone, env=_env(clone),
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)  # fmt: skip
                first = _line_with(p, "index")  # it shows the fingers, then Ctrl-C
                p.send_signal(signal.SIGINT)
                out, err = p.communicate(timeout=60)
                assert p.returncode in (0, 130) and "Traceback" not in err, (cmd, out, err)
                assert first, (cmd, out, err)
                continue
            r = _sh(run, clone, timeout=600)  # a minute of CPU; the machine may be loaded
            assert r.returncode == 0, (cmd, r.stdout[-3000:], r.stderr[-3000:])
            assert "Traceback" not in r.stderr, (cmd, r.stderr)
            if "grasp-hold" in cmd:  # no --out: it said where it wrote, and wrote there
                where = re.search(r"writing to (\S+)", r.stdout)
                assert where, r.stdout
                assert (clone / where.group(1) / "object_hold.png").exists()
    finally:
        if server is not None:
            server.send_signal(signal.SIGINT)
            try:
                server.wait(timeout=20)
            except subprocess.TimeoutExpired:
                server.kill()


def _line_with(proc: subprocess.Popen[str], text: str, timeout_s: float = 180) -> str:
    """The first line of ``proc``'s output holding ``text`` ('' if none came in time)."""
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if text in line:
            return line
        if not line and proc.poll() is not None:
            break
    return ""


def _served_pty(server: subprocess.Popen[str]) -> str:
    """The pty ``utrf emulate`` prints under its URL."""
    assert server.stdout is not None
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        line = server.stdout.readline()
        found = re.search(r"(/dev/pts/\d+)", line)
        if found:
            return found.group(1)
        if not line and server.poll() is not None:
            break
    raise AssertionError("utrf emulate printed no pty")
