"""The emulated board: the real firmware ELF on simavr, wired to the plant, served to clients.

This module holds the board's lifecycle (open, serve, close), its time (paced to the wall
clock, or driven: the lockstep with the plant in ``board_driven``), UART0, reset and the
EEPROM. Its driven time, faults (``board_faults``), plant knobs (``board_plant``) and views
into the MCU (``board_probes``) are mixins in their own modules; ``SimSerial`` is in
``sim_serial``. Every public name is importable from here. See ``README.md`` in this package
for the API and the time modes.
"""

from __future__ import annotations

import math
import os
import struct
import threading
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from utrf import artifacts
from utrf.emulator import _native, twin_threads
from utrf.emulator._native import F_CPU_HZ, HarnessError, NativeBoard
from utrf.emulator.board_driven import BoardDriven
from utrf.emulator.board_faults import BoardFaults
from utrf.emulator.board_plant import BoardPlant
from utrf.emulator.board_probes import BoardProbes
from utrf.emulator.board_types import (
    EEPROM_SIZE,
    RESET_FLAGS,
    VECTORS,
    CycleProfile,
    EmulatorError,
    PinState,
)
from utrf.emulator.build_faults import BuildFaults
from utrf.emulator.plant_params import PlantParams
from utrf.emulator.sim_serial import SimSerial
from utrf.models.geometry import HandGeometry

if TYPE_CHECKING:
    from utrf.emulator.mujoco_plant import MujocoPlant

# A checkout's `make firmware` output (relative: found from the working directory); with no
# ELF given, the board takes utrf.artifacts.firmware_elf() (this, or a cached build).
DEFAULT_ELF = artifacts.CHECKOUT_ELF
EXCHANGE_PERIOD_S = 1e-3  # one exchange per control tick; MuJoCo steps 0.5 ms twice
#: real time: simulated time the board thread runs per hold of the lock (sim_time moves by it)
SERVE_BATCH_S = 1e-3


def check_elf(path: Path) -> None:
    """Refuse, with a clear message, anything but an AVR ELF built for the atmega2560."""
    try:
        head = path.read_bytes()[:52]
    except FileNotFoundError:
        hint = " (run `make firmware`)" if path == DEFAULT_ELF else ""
        raise EmulatorError(f"firmware ELF {path} not found{hint}") from None
    except IsADirectoryError:
        raise EmulatorError(f"firmware ELF {path} is a directory") from None
    if len(head) < 52 or head[:4] != b"\x7fELF":
        raise EmulatorError(f"{path} is not an ELF file")
    if head[4] != 1 or head[5] != 1:
        raise EmulatorError(f"{path} is not a 32-bit little-endian ELF (not AVR)")
    machine, _, _, _, _, flags = struct.unpack_from("<HIIIII", head, 18)
    if machine != 83:
        raise EmulatorError(f"{path} is not an AVR program (ELF machine {machine}, AVR is 83)")
    if flags & 0x7F != 6:
        raise EmulatorError(
            f"{path} is built for AVR architecture avr{flags & 0x7F}; "
            "the ATmega2560 needs avr6 (-mmcu=atmega2560)"
        )


def _shutdown(stop: threading.Event, holder: dict) -> None:
    """Stop the thread and free the board; runs at close() or when the board is collected."""
    stop.set()
    thread = holder.get("thread")
    if thread is not None and thread is not threading.current_thread():
        thread.join(timeout=5.0)
    native = holder.pop("native", None)
    if native is not None:
        native.close()
    plant = holder.pop("plant", None)  # after the board that steps it
    if plant is not None:
        plant.close()


class EmulatedBoard(BoardDriven, BoardFaults, BoardPlant, BoardProbes):
    """The firmware ELF on an emulated ATmega2560 driving the plant model of the hand.

    ``realtime=True`` (the default) starts a thread that runs the board paced to the wall
    clock (``speed`` times real time; ``speed=None``: as fast as it goes) and serves UART0 on
    a pty and on ``socket://127.0.0.1:PORT``. ``realtime=False`` runs only when asked
    (``run_for``, ``run_until``, ``serial()``), as fast as the CPU allows, and is then
    reproducible for a seed. Use it as a context manager or call ``close()``.
    """

    def __init__(
        self,
        elf: str | Path | None = None,
        hand: HandGeometry | str | Path | None = None,
        seed: int = 0,
        realtime: bool = True,
        eeprom_path: str | Path | None = None,
        *,
        plant_params: PlantParams | None = None,
        speed: float | None = 1.0,
        serve: bool | None = None,
        tcp_port: int = 0,
        pty: bool = True,
        auto_reset: bool = True,
        auto_reset_hold: float = 0.1,
        capture: bool | None = None,
        exchange_period: float | None = None,
        plant: str | MujocoPlant = "mujoco",
        build: BuildFaults | None = None,
        plant_threads: int | None = None,
    ) -> None:
        if elf is None:
            try:
                elf = artifacts.firmware_elf()
            except artifacts.ArtifactError as exc:
                raise EmulatorError(str(exc)) from None
        self.elf = Path(elf)
        check_elf(self.elf)
        if speed is not None and not (isinstance(speed, int | float) and speed > 0):
            raise EmulatorError(
                f"speed must be a factor > 0 or None (as fast as possible), got {speed!r}"
            )
        if exchange_period is None:  # one exchange per 1 ms control tick
            exchange_period = EXCHANGE_PERIOD_S
        if not (isinstance(exchange_period, int | float) and 1e-5 <= exchange_period <= 1e-2):
            raise EmulatorError(
                f"exchange_period must lie in [10 µs, 10 ms], got {exchange_period!r}"
            )
        if not (isinstance(auto_reset_hold, int | float) and 0 <= auto_reset_hold <= 10):
            raise EmulatorError(f"auto_reset_hold must lie in [0, 10] s, got {auto_reset_hold!r}")
        if not isinstance(tcp_port, int) or not 0 <= tcp_port <= 65535:
            raise EmulatorError(f"tcp_port must be 0..65535 (0: any free port), got {tcp_port!r}")
        if isinstance(hand, str | Path):
            hand = HandGeometry.from_toml(hand)
        threads = twin_threads.plant_threads(plant_threads, paced=realtime and speed is not None)
        self.realtime = bool(realtime)
        self.speed = None if speed is None else float(speed)
        self.seed = int(seed)
        self.eeprom_path = Path(eeprom_path) if eeprom_path is not None else None
        self.plant: MujocoPlant
        if plant == "mujoco":
            from utrf.emulator.mujoco_plant import MujocoPlant  # imports MuJoCo only when asked

            self.plant = MujocoPlant(hand, plant_params, seed, timestep=exchange_period)
        elif isinstance(plant, str):
            raise EmulatorError(f"plant must be 'mujoco' or a MujocoPlant, got {plant!r}")
        else:
            self.plant = plant
        #: how this hand was built (build faults, hidden from the wire): build_faults.py
        self.build = build if build is not None else BuildFaults()
        self.build.apply(self.plant)
        # MuJoCo cuts the exchange into its steps
        self.plant.set_timestep(round(exchange_period * F_CPU_HZ) / F_CPU_HZ)
        self._lock = threading.RLock()
        self._ahead: int | None = None  # a run ahead's target while one is under way
        self._tick = threading.Condition()
        self._stop = threading.Event()
        self._holder: dict = {}
        self._holder["plant"] = self.plant
        self._native = NativeBoard(self.elf, self.seed)
        self._holder["native"] = self._native
        self._native.attach_plant(self.plant.native)
        self._native.set_plant_threads(threads)
        self._native.set_plant_spin(twin_threads.plant_spins())
        self._finalizer = weakref.finalize(self, _shutdown, self._stop, self._holder)
        try:
            if self.eeprom_path is not None and self.eeprom_path.exists():
                self._load_eeprom(self.eeprom_path)
            self._period_cycles = max(1, round(exchange_period * F_CPU_HZ))
            self._cycle = self._native.cycle
            self._native.adc_volts[:5] = self.plant.encoder_volts()
            self._status = 0
            self.crash_pc: int | None = None
            self.failure: BaseException | None = None  # what stopped the board thread
            self._capture = (not self.realtime) if capture is None else bool(capture)
            self._native.set_capture(self._capture)
            self._native.set_auto_reset(auto_reset)
            self._native.set_auto_reset_hold(round(auto_reset_hold * F_CPU_HZ))
            self.pty_path: str | None = None
            self.tcp_port: int | None = None
            if serve if serve is not None else self.realtime:
                if pty:
                    self.pty_path = self._native.serve_pty()
                self.tcp_port = self._native.serve_tcp("127.0.0.1", tcp_port)
            self._wall_start = time.perf_counter()
            self._busy = 0.0
            self._driven_wall = 0.0
            self._lag_events = 0
            if self.realtime:
                thread = threading.Thread(
                    target=self._serve_forever, name="utrf-board", daemon=True
                )
                self._holder["thread"] = thread
                thread.start()
        except BaseException:
            self.close()
            raise

    # -- lifetime --------------------------------------------------------------------------------
    def __enter__(self) -> EmulatedBoard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the board, save the EEPROM to ``eeprom_path`` (when given), free the ports."""
        if not self._finalizer.alive:
            return
        self._stop.set()
        if self._ahead is not None:
            self.run_ahead_join()
        thread = self._holder.get("thread")
        if thread is not None:
            thread.join(timeout=5.0)
        with self._lock:
            if self.eeprom_path is not None and "native" in self._holder:
                self.save_eeprom()
            self._finalizer()

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def _board(self) -> NativeBoard:
        if not self._finalizer.alive:
            raise EmulatorError("the emulated board is closed")
        if self._ahead is not None:
            raise EmulatorError("the board is running ahead on its thread: join it first")
        return self._native

    # -- where to connect -----------------------------------------------------------------------
    @property
    def url(self) -> str | None:
        """pyserial URL of the TCP port (``socket://127.0.0.1:PORT``), None when not served."""
        return None if self.tcp_port is None else f"socket://127.0.0.1:{self.tcp_port}"

    @property
    def urls(self) -> list[str]:
        return [u for u in (self.url, self.pty_path) if u]

    @property
    def clients(self) -> dict[str, bool]:
        c = self._board().clients
        return {"pty": bool(c & 1), "tcp": bool(c & 2)}

    # -- time ------------------------------------------------------------------------------------
    @property
    def exchange_period(self) -> float:
        """Simulated seconds between two exchanges of pins and ADC values with the plant."""
        return self._period_cycles / F_CPU_HZ

    @property
    def plant_threads(self) -> int:
        """1: the plant steps after the MCU on one thread; 2: on a thread of its own while
        the MCU runs (``utrf.emulator.twin_threads`` chooses; the same results)."""
        return self._board().plant_threads

    @property
    def sim_time(self) -> float:
        """Simulated seconds since power-on (the MCU's cycle count / 16 MHz)."""
        return self._cycle / F_CPU_HZ

    def run_for(self, seconds: float) -> None:
        """Advance the simulation by ``seconds``: at once when driven, and by waiting for the
        board thread in real time."""
        if not (isinstance(seconds, int | float) and math.isfinite(seconds) and seconds >= 0):
            raise EmulatorError(f"seconds must be a finite number >= 0, got {seconds!r}")
        if not self.realtime:
            with self._lock:
                self._board()
                self._run_driven(seconds)
            return
        self.wait_until(lambda b: True, timeout=None, after=seconds)

    def run_until(self, predicate: Callable[[EmulatedBoard], bool], timeout: float) -> bool:
        """Run (driven) or wait (real time) until ``predicate(board)`` holds, at most ``timeout``
        simulated seconds. Returns whether it held. The predicate runs between exchanges."""
        if not (isinstance(timeout, int | float) and timeout >= 0):
            raise EmulatorError(f"timeout must be a number >= 0, got {timeout!r}")
        if not self.realtime:
            with self._lock:
                self._board()
                if predicate(self):
                    return True
                return self._run_driven(timeout, predicate)
        return self.wait_until(predicate, timeout=timeout)

    def wait_until(
        self, predicate: Callable[[EmulatedBoard], bool], timeout: float | None, after: float = 0.0
    ) -> bool:
        """Real-time mode: block until ``predicate`` holds with at least ``after`` simulated
        seconds gone, or ``timeout`` simulated seconds passed."""
        if not self.realtime:
            raise EmulatorError("wait_until needs realtime=True; use run_until when driven")
        start = self.sim_time
        deadline = math.inf if timeout is None else start + max(timeout, after)
        while True:
            with self._lock:
                self._board()
                now = self.sim_time
                if now - start >= after and predicate(self):
                    return True
            if now >= deadline:
                return False
            if self.failure is not None:
                raise EmulatorError(f"the board stopped: {self.failure!r}") from self.failure
            thread = self._holder.get("thread")
            if thread is None or not thread.is_alive():
                raise EmulatorError("the board thread has stopped")
            with self._tick:
                self._tick.wait(0.05)

    def _serve_forever(self) -> None:
        try:
            self._pace()
        except BaseException as exc:  # kept for the caller: run_for and wait_until raise it
            self.failure = exc
            with self._tick:
                self._tick.notify_all()

    def _pace(self) -> None:
        batch = max(1, round(SERVE_BATCH_S / (self._period_cycles / F_CPU_HZ)))
        wall0, sim0 = time.perf_counter(), self.sim_time
        while not self._stop.is_set():
            t0 = time.perf_counter()
            with self._lock:
                if not self._finalizer.alive:
                    return
                self._run_plant(self._exchanges_on(batch))
                sim = self.sim_time
            t1 = time.perf_counter()
            self._busy += t1 - t0
            with self._tick:
                self._tick.notify_all()
            if self.speed is None:
                time.sleep(0)  # let other threads have the interpreter
                continue
            ahead = (sim - sim0) / self.speed - (t1 - wall0)
            if ahead > 1e-3:
                self._stop.wait(ahead)
            elif ahead < -0.1:
                # Too slow to keep up: accept the lag rather than race to catch up later.
                self._lag_events += 1
                wall0, sim0 = t1, sim

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second: since start in real time (about ``speed``
        when the machine keeps up), or while running when driven."""
        wall = (time.perf_counter() - self._wall_start) if self.realtime else self._driven_wall
        return self.sim_time / wall if wall > 0 else math.nan

    @property
    def busy_seconds(self) -> float:
        """Wall-clock seconds spent running the board (sleeps while pacing left out)."""
        return self._busy

    @property
    def capacity(self) -> float:
        """Simulated seconds per wall-clock second of work: how fast the board could run."""
        return self.sim_time / self._busy if self._busy > 0 else math.nan

    @property
    def lag_events(self) -> int:
        """Times the real-time board fell more than 100 ms behind the wall clock."""
        return self._lag_events

    # -- UART0 in-process -------------------------------------------------------------------------
    def write(self, data: bytes) -> int:
        """Send bytes to the board's UART0 (they go out at its baud rate from now on)."""
        data = bytes(data)
        with self._lock:
            n = self._board().uart_write(data)
        if n < len(data):
            raise EmulatorError(
                f"the UART queue is full: {len(data) - n} of {len(data)} bytes refused"
            )
        return n

    def read(self, size: int = -1) -> bytes:
        """Bytes the board has sent (with ``capture``, the default when driven)."""
        if not self._capture:
            raise EmulatorError(
                "this board does not capture its output (capture=False): "
                f"connect to {self.url or self.pty_path} instead"
            )
        with self._lock:
            return self._board().uart_read(65536 if size < 0 else size)

    @property
    def uart_pending(self) -> int:
        """Bytes written to the board that have not yet gone out on the wire."""
        with self._lock:
            return self._board().uart_pending()

    def serial(self, timeout: float | None = 1.0) -> SimSerial:
        """A pyserial-like port on this driven board whose timeouts are simulated seconds."""
        if self.realtime:
            raise EmulatorError("serial() needs realtime=False; in real time use board.url")
        if not self._capture:
            raise EmulatorError("serial() needs capture=True")
        return SimSerial(self, timeout)

    # -- reset -----------------------------------------------------------------------------------
    def reset(self, cause: str = "reset_pin", hold: float = 0.0) -> None:
        """Reset the board: ``reset_pin`` (EXTRF, as the USB-serial auto-reset or the button;
        SRAM kept) or ``power_on`` (PORF;
        SRAM cleared). The EEPROM survives both. ``hold``: seconds it stays in reset (pins
        floating, firmware not running) before starting."""
        causes = {"reset_pin": _native.RESET_PIN, "power_on": _native.RESET_POWER_ON}
        if cause not in causes:
            raise EmulatorError(f"cause must be 'reset_pin' or 'power_on', got {cause!r}")
        if not (isinstance(hold, int | float) and 0 <= hold <= 60):
            raise EmulatorError(f"hold must lie in [0, 60] s, got {hold!r}")
        with self._lock:
            self._board().reset(causes[cause], round(hold * F_CPU_HZ))
            self._status = 0
            self.crash_pc = None

    # -- observation -----------------------------------------------------------------------------
    @property
    def status(self) -> str:
        """``running``, ``crashed`` (simavr stopped the core; ``reset()`` recovers) or ``done``."""
        return _native.STATUS_NAMES[self._status]

    # -- EEPROM ----------------------------------------------------------------------------------
    @property
    def eeprom(self) -> bytes:
        with self._lock:
            return self._board().eeprom()

    def _load_eeprom(self, path: Path) -> None:
        data = path.read_bytes()
        if len(data) > EEPROM_SIZE:
            raise EmulatorError(
                f"{path}: {len(data)} bytes, the ATmega2560's EEPROM holds {EEPROM_SIZE}"
            )
        self._native.set_eeprom(data + b"\xff" * (EEPROM_SIZE - len(data)))

    def load_eeprom(self, path: str | Path) -> None:
        """Replace the EEPROM with a file's bytes (shorter files are padded with erased 0xFF)."""
        with self._lock:
            self._board()
            self._load_eeprom(Path(path))

    def save_eeprom(self, path: str | Path | None = None) -> Path:
        """Write the EEPROM's 4096 bytes to ``path`` (default ``eeprom_path``), atomically."""
        target = Path(path) if path is not None else self.eeprom_path
        if target is None:
            raise EmulatorError("save_eeprom needs a path (no eeprom_path was given)")
        data = self.eeprom
        tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, target)
        return target


__all__ = [
    "DEFAULT_ELF",
    "EEPROM_SIZE",
    "RESET_FLAGS",
    "SERVE_BATCH_S",
    "VECTORS",
    "CycleProfile",
    "EmulatedBoard",
    "EmulatorError",
    "HarnessError",
    "PinState",
    "SimSerial",
    "check_elf",
]
