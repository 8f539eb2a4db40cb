"""The emulated board in a child process (``utrf emulate``), driven through its stdin.

In one process, a real-time board's thread shares the interpreter with its client (a
``Link``, a ``Hand``, a test): they take turns with it. ``BoardProcess`` runs
``utrf emulate --json`` in a process of its own, so each has an interpreter and a crash or a
stall of either leaves the other standing. Faults
go in as ``utrf emulate``'s stdin commands (``utrf emulate --help`` lists them; angles there
are in degrees); ``state()`` returns the hand's true state.

    with BoardProcess() as board:
        with Link.open(board.url) as link:
            ...
        board.command("unplug 2")
        print(board.state()["theta2_rad"])
"""

from __future__ import annotations

import contextlib
import json
import queue
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

from utrf.emulator.board import EmulatorError


class BoardProcess:
    """``utrf emulate`` as a child process. ``url``, ``pty_path`` once started; ``command``,
    ``state``; ``close()`` (or the context manager) stops it and returns its last report."""

    def __init__(
        self,
        elf: str | Path | None = None,
        *,
        seed: int = 0,
        hand: str | Path | None = None,
        eeprom_path: str | Path | None = None,
        speed: float | None = 1.0,
        tcp_port: int = 0,
        pty: bool = True,
        auto_reset: bool = True,
        auto_reset_hold: float = 0.1,
        args: tuple[str, ...] = (),
        startup_timeout: float = 30.0,
    ) -> None:
        cmd = [sys.executable, "-m", "utrf", "emulate", "--json", "--status-interval", "0"]
        cmd += ["--seed", str(seed), "--port", str(tcp_port)]
        cmd += ["--speed", "max" if speed is None else str(speed)]
        cmd += ["--auto-reset-hold", str(auto_reset_hold)]
        if elf is not None:
            cmd += ["--elf", str(elf)]
        if hand is not None:
            cmd += ["--hand", str(hand)]
        if eeprom_path is not None:
            cmd += ["--eeprom", str(eeprom_path)]
        if not pty:
            cmd.append("--no-pty")
        if not auto_reset:
            cmd.append("--no-auto-reset")
        cmd += list(args)
        self._proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        self._events: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self._lock = threading.Lock()
        self.final: dict[str, Any] | None = None
        self._reader = threading.Thread(target=self._read, name="utrf-board-process", daemon=True)
        self._reader.start()
        try:
            first = self._next(startup_timeout)
        except BaseException:
            self.close()
            raise
        if first.get("event") != "serving":
            self.close()
            raise EmulatorError(f"utrf emulate did not start: {first}")
        self.url: str | None = first.get("url")
        self.pty_path: str | None = first.get("pty")
        self.elf = Path(first["elf"])

    def _read(self) -> None:
        assert self._proc.stdout is not None
        for line in self._proc.stdout:
            try:
                self._events.put(json.loads(line))
            except json.JSONDecodeError:
                self._events.put({"event": "text", "text": line.rstrip("\n")})
        self._events.put(None)  # the process closed its output

    def _next(self, timeout: float) -> dict[str, Any]:
        try:
            event = self._events.get(timeout=timeout)
        except queue.Empty:
            raise EmulatorError(f"utrf emulate said nothing for {timeout} s") from None
        if event is None:
            self._proc.wait(timeout=10)
            err = self._proc.stderr.read() if self._proc.stderr else ""
            raise EmulatorError(
                f"utrf emulate exited with code {self._proc.returncode}: {err.strip()}"
            )
        return event

    @property
    def alive(self) -> bool:
        return self._proc.poll() is None

    def command(self, line: str, timeout: float = 10.0) -> dict[str, Any]:
        """Send one stdin command (e.g. ``"reset"``, ``"unplug 2"``, ``"block 1 30"``) and
        return its reply event; EmulatorError for an ``error`` reply."""
        if "\n" in line:
            raise EmulatorError("one command at a time (no newline)")
        with self._lock:
            if not self.alive or self._proc.stdin is None:
                raise EmulatorError("the board process has stopped")
            self._proc.stdin.write(line + "\n")
            self._proc.stdin.flush()
            reply = self._next(timeout)
        if reply.get("event") == "error":
            raise EmulatorError(f"utrf emulate refused {line!r}")
        return reply

    def state(self) -> dict[str, Any]:
        """The hand's true state, SI: ``sim_time_s``, ``theta_rad``, ``theta2_rad``,
        ``tension_n``, ``current_a``, ``drive``, ``adc_volts``, ``status``."""
        return self.command("state")

    def status(self) -> dict[str, Any]:
        """``sim_time_s``, ``realtime_factor``, ``capacity``, ``clients``, ``resets``, ..."""
        return self.command("status")

    def close(self, timeout: float = 10.0) -> dict[str, Any] | None:
        """Stop the board (it saves its EEPROM file, if any) and return its last report."""
        if self._proc.poll() is None:
            try:
                with self._lock:
                    if self._proc.stdin is not None:
                        self._proc.stdin.write("quit\n")
                        self._proc.stdin.flush()
                self._proc.wait(timeout=timeout)
            except (OSError, subprocess.TimeoutExpired):
                self._proc.terminate()
                try:
                    self._proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    self._proc.kill()
                    self._proc.wait()
        self._reader.join(timeout=5)
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                break
            if event and event.get("event") == "stopped":
                self.final = event
        for stream in (self._proc.stdin, self._proc.stdout, self._proc.stderr):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()
        return self.final

    def __enter__(self) -> BoardProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
