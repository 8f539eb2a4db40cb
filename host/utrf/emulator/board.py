"""The emulated board: the real firmware ELF on simavr, wired to the plant, served to clients.

See ``README.md`` in this package for the API and the time modes.
"""

from __future__ import annotations

import math
import os
import struct
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from utrf import artifacts
from utrf.emulator import _native
from utrf.emulator._native import F_CPU_HZ, HarnessError, NativeBoard
from utrf.emulator.plant import DRIVE_NAMES, HandPlant, PlantParams
from utrf.models.geometry import HandGeometry

if TYPE_CHECKING:
    from utrf.emulator.mujoco_plant import MujocoPlant

# A checkout's `make firmware` output (relative: found from the working directory); with no
# ELF given, the board takes utrf.artifacts.firmware_elf() (this, or a cached build).
DEFAULT_ELF = artifacts.CHECKOUT_ELF
EXCHANGE_PERIOD_S = 250e-6
MUJOCO_EXCHANGE_PERIOD_S = 1e-3  # the MJCF's own timestep: one mj_step per exchange
#: real time: simulated time the board thread runs per hold of the lock (sim_time moves by it)
SERVE_BATCH_S = 1e-3
EEPROM_SIZE = 4096

# MCUSR bits, and the order in which the protocol's ResetCause reports them.
RESET_FLAGS = {
    "power_on": 0x01,
    "reset_pin": 0x02,
    "brown_out": 0x04,
    "watchdog": 0x08,
    "jtag": 0x10,
}

# Interrupt vectors of the ATmega2560 (datasheet Table 14-1, numbering from 0 = RESET).
VECTORS = {
    "INT4": 5,
    "INT5": 6,
    "WDT": 12,
    "TIMER2_COMPA": 13,
    "TIMER2_COMPB": 14,
    "TIMER2_OVF": 15,
    "TIMER1_COMPA": 17,
    "TIMER1_OVF": 20,
    "TIMER0_COMPA": 21,
    "TIMER0_OVF": 23,
    "USART0_RX": 25,
    "USART0_UDRE": 26,
    "USART0_TX": 27,
    "ADC": 29,
    "EE_READY": 30,
}


# Registers the board's faults touch (ATmega2560 datasheet, data-space addresses).
_TCCR2B, _CS2_MASK = 0xB1, 0x07
_ADCSRA, _ADEN, _ADSC = 0x7A, 0x80, 0x40

_CLI = 0x94F8  # cli
_RJMP_SELF = 0xCFFF  # rjmp . (to itself)


class EmulatorError(RuntimeError):
    """A request the emulated board cannot honour; the message says what to do."""


@dataclass(frozen=True)
class CycleProfile:
    """Cycles spent in an interrupt handler or a function, per call.

    ``mean``/``worst``/``best`` leave out interrupts that nest inside; ``*_incl`` count them.
    ``period`` is the mean interval between entries; ``load`` and ``worst_load`` divide by it
    (the fraction of the CPU the code takes). For an interrupt, ``latency`` and
    ``worst_latency`` count the cycles from its flag being raised to its handler's entry (long
    when the firmware masks it)."""

    calls: int
    mean: float
    worst: int
    best: int
    mean_incl: float
    worst_incl: int
    period: float
    latency: float = math.nan  # interrupt: mean cycles from its flag to its entry
    worst_latency: int = 0

    @property
    def load(self) -> float:
        return self.mean / self.period if self.period else math.nan

    @property
    def worst_load(self) -> float:
        return self.worst / self.period if self.period else math.nan

    @classmethod
    def from_native(cls, p: dict[str, int]) -> CycleProfile:
        n = p["count"]
        return cls(
            calls=n,
            mean=p["total"] / n if n else math.nan,
            worst=p["worst"],
            best=p["best"],
            mean_incl=p["total_incl"] / n if n else math.nan,
            worst_incl=p["worst_incl"],
            period=p["period_sum"] / p["intervals"] if p["intervals"] else math.nan,
            latency=p["latency_sum"] / n if n else math.nan,
            worst_latency=p["latency_worst"],
        )


@dataclass(frozen=True)
class PinState:
    """What the TB6612FNGs see, per finger (axis 0) and channel (axis 1: motor A, motor B)."""

    duty: np.ndarray  # PWM duty at the driver's PWM input, 0..1
    in1: np.ndarray  # bool
    in2: np.ndarray  # bool
    stby: np.ndarray  # bool, per finger

    @classmethod
    def from_block(cls, block: np.ndarray) -> PinState:
        return cls(
            duty=block[..., 0].copy(),
            in1=block[..., 1] > 0.5,
            in2=block[..., 2] > 0.5,
            stby=block[:, 0, 3] > 0.5,
        )


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


class EmulatedBoard:
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
        plant: str | HandPlant | Any = "analytic",
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
        if exchange_period is None:  # MuJoCo steps once per exchange: its own 1 ms step
            exchange_period = (
                MUJOCO_EXCHANGE_PERIOD_S
                if plant == "mujoco" or hasattr(plant, "set_timestep")
                else EXCHANGE_PERIOD_S
            )
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
        self.realtime = bool(realtime)
        self.speed = None if speed is None else float(speed)
        self.seed = int(seed)
        self.eeprom_path = Path(eeprom_path) if eeprom_path is not None else None
        self.plant: HandPlant | MujocoPlant
        if plant == "analytic":
            self.plant = HandPlant(hand, plant_params, seed)
        elif plant == "mujoco":
            from utrf.emulator.mujoco_plant import MujocoPlant  # imports MuJoCo only when asked

            self.plant = MujocoPlant(hand, plant_params, seed, timestep=exchange_period)
        elif isinstance(plant, str):
            raise EmulatorError(f"plant must be 'analytic', 'mujoco' or a plant, got {plant!r}")
        else:
            self.plant = plant
        if hasattr(self.plant, "set_timestep"):  # MuJoCo steps once per exchange
            self.plant.set_timestep(round(exchange_period * F_CPU_HZ) / F_CPU_HZ)
        self._lock = threading.RLock()
        self._tick = threading.Condition()
        self._stop = threading.Event()
        self._holder: dict = {}
        self._holder["plant"] = self.plant
        self._native = NativeBoard(self.elf, self.seed)
        self._holder["native"] = self._native
        self._native.attach_plant(self.plant.native)
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
    def sim_time(self) -> float:
        """Simulated seconds since power-on (the MCU's cycle count / 16 MHz)."""
        return self._cycle / F_CPU_HZ

    def _run_plant(self, target: int) -> None:
        """Run in lockstep with the plant up to cycle ``target``, all in C: each exchange
        period the MCU runs with the encoders as the plant had them at its start, then the
        plant runs the same period with the pins as the MCU had set them at its start."""
        status = self._native.run_plant(target, self._period_cycles)
        self._cycle = self._native.cycle
        if status != self._status:
            self._status = status
            self.crash_pc = self._native.pc if status == 1 else None

    def _exchange(self) -> None:
        """One lockstep period."""
        self._run_plant(self._cycle + self._period_cycles)

    def _run_driven(
        self, seconds: float, until: Callable[[EmulatedBoard], bool] | None = None
    ) -> bool:
        target = self._cycle + round(seconds * F_CPU_HZ)
        t0 = time.perf_counter()
        try:
            if until is None:
                while self._cycle < target:  # one call; again only if a crash stopped it
                    self._run_plant(target)
                return False
            while self._cycle < target:  # the predicate is judged between exchanges
                self._exchange()
                if until(self):
                    return True
            return False
        finally:
            dt = time.perf_counter() - t0
            self._busy += dt
            self._driven_wall += dt

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
                self._run_plant(self._cycle + batch * self._period_cycles)
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

    # -- faults ----------------------------------------------------------------------------------
    def unplug_encoder(self, finger: int, volts: float | None = None) -> None:
        """Finger's Joint-2 encoder disconnected: its ADC input reads ``volts`` (default 0 V)."""
        with self._lock:
            self.plant.unplug_encoder(finger, volts)

    def plug_encoder(self, finger: int) -> None:
        with self._lock:
            self.plant.plug_encoder(finger)

    def block_finger(
        self, finger: int, theta2: float | None = None, direction: str = "both"
    ) -> None:
        """Block a finger at a Joint-2 angle (rad; default where it is): ``both`` jams it,
        ``flexion`` puts an obstacle in its way. Its motor stalls against the block."""
        with self._lock:
            self.plant.block(finger, theta2, direction)

    def unblock_finger(self, finger: int) -> None:
        with self._lock:
            self.plant.unblock(finger)

    def shift_encoder(self, finger: int, radians: float) -> None:
        """The finger's encoder magnet slips: from now its reading is off by ``radians`` (a
        sudden jump of the measured Joint-2 angle; 0 puts it back)."""
        with self._lock:
            self.plant.shift_encoder(finger, radians)

    def set_tip_force(self, finger: int, force_n: tuple[float, float], ramp_s: float = 0.0) -> None:
        """A steady force (Fx, Fy) in N at a fingertip, finger frame (y toward flexion; the
        bench's gravity is −y), reached over ``ramp_s`` s; (0, 0) removes it. The motor and the
        controller feel it through the coupling (``HandPlant.set_tip_force``)."""
        with self._lock:
            self.plant.set_tip_force(finger, force_n, ramp_s)

    def hang_payload(self, finger: int, mass_kg: float, ramp_s: float = 0.0) -> None:
        """Hang ``mass_kg`` from a fingertip (its weight along −y of the finger frame, the
        bench's gravity), lowered in over ``ramp_s`` s; 0 removes it."""
        if not (isinstance(mass_kg, int | float) and math.isfinite(mass_kg) and mass_kg >= 0):
            raise EmulatorError(f"a payload must be a mass >= 0 kg, got {mass_kg!r}")
        g = -self.plant.params.gravity_m_s2[1] if self.plant.params.gravity_m_s2[1] else 9.81
        self.set_tip_force(finger, (0.0, -float(mass_kg) * g), ramp_s)

    def hit_tip(
        self, finger: int, impulse_ns: tuple[float, float], duration_s: float = 5e-3
    ) -> None:
        """A hammer hit: a force pulse at the tip carrying ``impulse_ns`` (Jx, Jy) in N s,
        finger frame, over ``duration_s`` from now."""
        with self._lock:
            self.plant.hit(finger, impulse_ns, duration_s)

    @property
    def tip(self) -> np.ndarray:
        """True fingertips (m), shape (5, 2), each in its finger's frame, with the coupling
        tendons' stretch under tip loads: what a perfect tracker would read."""
        with self._lock:
            return self.plant.tip

    @property
    def tip_force(self) -> np.ndarray:
        """The tip force applied over the last step (N), shape (5, 2), pulses included."""
        with self._lock:
            return self.plant.applied_force.copy()

    def drop_client(self) -> None:
        """Hang up on the TCP client, as a pulled USB cable would (it reads end-of-file)."""
        with self._lock:
            self._board().drop_client()

    def set_line_faults(
        self,
        direction: str = "both",
        *,
        drop: float = 0.0,
        corrupt: float = 0.0,
        insert: float = 0.0,
        duplicate: float = 0.0,
        burst: float = 0.0,
        burst_length: tuple[int, int] = (8, 32),
    ) -> None:
        """Serial line faults, as probabilities per byte, seeded (reproducible when driven):
        ``drop`` it, ``corrupt`` it (one bit flipped), ``insert`` a random byte before it,
        ``duplicate`` it (sent twice), or start a ``burst`` of noise there that replaces it and
        the bytes after it, ``burst_length`` = (min, max) bytes in all, uniformly. ``direction``:
        "to_board", "to_host", "both". All zero: a clean line. Counted in ``stats``
        (``rx_dropped``, ``tx_duplicated``, ``rx_burst_bytes``, ...)."""
        dirs: dict[str, tuple[int, ...]] = {
            "to_board": (_native.TO_BOARD,),
            "to_host": (_native.TO_HOST,),
        }
        dirs["both"] = dirs["to_board"] + dirs["to_host"]
        if direction not in dirs:
            raise EmulatorError(f"direction must be one of {list(dirs)}, got {direction!r}")
        probs = (
            ("drop", drop),
            ("corrupt", corrupt),
            ("insert", insert),
            ("duplicate", duplicate),
            ("burst", burst),
        )
        for name, p in probs:
            below_one = name in ("insert", "duplicate")
            if not (isinstance(p, int | float) and 0.0 <= p <= 1.0) or (below_one and p >= 1):
                bound = "[0, 1)" if below_one else "[0, 1]"
                raise EmulatorError(f"{name} must be a probability in {bound}, got {p!r}")
        try:
            lo, hi = (int(n) for n in burst_length)
        except (TypeError, ValueError):
            raise EmulatorError(
                f"burst_length must be (min, max) bytes, got {burst_length!r}"
            ) from None
        if not 1 <= lo <= hi <= 65536:
            raise EmulatorError(
                f"burst_length must be (min, max) with 1 <= min <= max, got {burst_length!r}"
            )
        with self._lock:
            for d in dirs[direction]:
                self._board().set_line_faults(
                    d, float(drop), float(corrupt), float(insert), float(duplicate),
                    float(burst), (lo, hi),
                )  # fmt: skip

    def inject_noise(self, data: bytes | int, direction: str = "to_board") -> None:
        """Put a burst of bytes on the line (an int: that many random bytes from the seed)."""
        if isinstance(data, int):
            if data < 0:
                raise EmulatorError(f"noise burst length must be >= 0, got {data}")
            data = (
                np.random.default_rng([self.seed, int(self._cycle)])
                .integers(0, 256, data, dtype=np.uint8)
                .tobytes()
            )
        d = {"to_board": _native.TO_BOARD, "to_host": _native.TO_HOST}.get(direction)
        if d is None:
            raise EmulatorError(f"direction must be 'to_board' or 'to_host', got {direction!r}")
        with self._lock:
            self._board().inject(d, bytes(data))

    def slow_tick(self, extra_s: float, count: int | None = 1) -> None:
        """A slow control tick: each of the next ``count`` timer-2 compare interrupts (the 1 kHz
        tick; None: every one until called again with 0) takes ``extra_s`` seconds longer, as
        if the handler ran that many more cycles (the timers run on meanwhile). Past one tick
        period (1 ms) the next compare comes before the tick ends: the firmware latches
        OVERRUN. ``extra_s`` 0 or ``count`` 0 ends it. ``stats["stalls"]`` counts the slow
        ticks."""
        self.stall_interrupt("TIMER2_COMPA", extra_s, count)

    def stall_interrupt(self, vector: int | str, extra_s: float, count: int | None = 1) -> None:
        """Make ``count`` entries of an interrupt handler (name as in :data:`VECTORS` or number;
        None: every entry) last ``extra_s`` seconds longer. See :meth:`slow_tick`."""
        if isinstance(vector, str):
            if vector not in VECTORS:
                raise EmulatorError(f"unknown vector {vector!r}; known: {sorted(VECTORS)}")
            vector = VECTORS[vector]
        if not (isinstance(extra_s, int | float) and math.isfinite(extra_s) and 0 <= extra_s <= 10):
            raise EmulatorError(f"extra_s must be a duration in [0, 10] s, got {extra_s!r}")
        if count is not None and (
            isinstance(count, bool) or not isinstance(count, int) or count < 0
        ):
            raise EmulatorError(f"count must be an int >= 0 or None (every entry), got {count!r}")
        cycles = round(extra_s * F_CPU_HZ)
        with self._lock:
            self._board().stall_vector(int(vector), cycles, -1 if count is None else count)

    @property
    def slow_ticks_left(self) -> int | None:
        """Slow ticks still to come (None: every tick is slow; 0: none)."""
        with self._lock:
            left = self._board().stalls_left()
        return None if left < 0 else left

    def stop_tick_timer(self) -> None:
        """The tick's timer stops: timer 2's clock select is cleared (TCCR2B's CS22..CS20, as a
        glitch on the register would), so no compare interrupt comes; everything else runs,
        ``loop()`` included, which finds no tick for 20 ms (the tick-alive rule: every motor
        off, the watchdog resets the board). The firmware's own set-up after the reset
        starts the timer again; nothing else does."""
        with self._lock:
            board = self._board()
            tccr2b = board.read_data(_TCCR2B, 1)[0]
            board.write_io(_TCCR2B, tccr2b & ~_CS2_MASK)

    def stop_adc(self) -> None:
        """The ADC stops: ADEN is cleared under the conversion in progress, which then never
        completes; the firmware's sampling round waits for it, the encoder readings go stale
        (after 3 ticks: ENCODER_RANGE on every finger, motors off). It stays stopped until
        :meth:`restart_adc` or a reset (the firmware enables the ADC at start)."""
        with self._lock:
            board = self._board()
            adcsra = board.read_data(_ADCSRA, 1)[0]
            board.poke(_ADCSRA, adcsra & ~_ADEN)

    def restart_adc(self) -> None:
        """Undo :meth:`stop_adc`: enable the ADC and redo the conversion it lost, so the
        firmware's round goes on."""
        with self._lock:
            board = self._board()
            adcsra = board.read_data(_ADCSRA, 1)[0]
            if adcsra & _ADEN:
                return
            board.poke(_ADCSRA, (adcsra | _ADEN) & ~_ADSC)
            board.write_io(_ADCSRA, adcsra | _ADEN | _ADSC)

    def hang_firmware(self, interrupts: bool = True) -> None:
        """Hang the firmware in a self-loop, as a bug that never returns would. With
        ``interrupts`` on, ``loop()`` hangs at its next start (no lock held, no interrupt
        under way) and the timer interrupts go on, so the firmware's own tick sees ``loop()``
        stop; off, the CPU stops where it stands with interrupts disabled. Either way only the
        watchdog gets the board back. The self-loop is libgcc's ``_exit``: ``cli``, then
        ``__stop_program: rjmp .``."""
        with self._lock:
            board = self._board()
            exit_, loop = board.symbol("_exit"), board.symbol("loop")
            if exit_ is None or (interrupts and loop is None):
                raise EmulatorError("the ELF lacks the _exit or loop symbol to hang it with")
            words = (board.flash_word(exit_), board.flash_word(exit_ + 2))
            if words != (_CLI, _RJMP_SELF):
                raise EmulatorError(
                    f"_exit at {exit_:#x} is not 'cli; rjmp .' (words {words[0]:#06x} "
                    f"{words[1]:#06x})"
                )
            if interrupts and loop is not None:  # (loop is known when interrupts: see above)
                done = board.jump_at(loop, exit_ + 2, 1)
            else:
                done = board.jump(exit_, -1)
            if not done:
                raise EmulatorError(f"_exit at {exit_:#x} or loop is not a flash address")

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

    @property
    def theta(self) -> np.ndarray:
        """True relative joint angles θ1..θ3 (rad), shape (5, 3)."""
        with self._lock:
            return self.plant.theta

    @property
    def theta2(self) -> np.ndarray:
        with self._lock:
            return self.plant.theta2

    @property
    def tendon_tension(self) -> np.ndarray:
        """Tendon 1 (flexor) and Tendon 4 (extensor) tensions (N), shape (5, 2)."""
        with self._lock:
            return self.plant.tension.copy()

    @property
    def motor_current(self) -> np.ndarray:
        """Motor A and B currents (A), shape (5, 2)."""
        with self._lock:
            return self.plant.current.copy()

    @property
    def pins(self) -> PinState:
        """The driver inputs as the firmware has set them, now."""
        with self._lock:
            return PinState.from_block(self._board().pins)

    @property
    def drive(self) -> list[tuple[tuple[str, float], tuple[str, float]]]:
        """Per finger, (mode, signed duty) of motors A and B as the plant applies them."""
        with self._lock:
            return [
                (
                    (DRIVE_NAMES[int(modes[0])], float(duties[0])),
                    (DRIVE_NAMES[int(modes[1])], float(duties[1])),
                )
                for modes, duties in zip(self.plant.drive_mode, self.plant.drive_duty, strict=True)
            ]

    @property
    def adc_volts(self) -> np.ndarray:
        """The voltages on ADC0..4 (the encoders' outputs) as the firmware samples them now."""
        with self._lock:
            return self._board().adc_volts[:5].copy()

    @property
    def stats(self) -> dict[str, int]:
        """Harness counters (bytes each way, line faults, resets, clients, EEPROM writes...)."""
        with self._lock:
            return self._board().stats()

    @property
    def reset_flags(self) -> set[str]:
        """MCUSR's reset flags as the firmware finds them after the last reset."""
        flags = self.stats["last_reset_flags"]
        return {name for name, bit in RESET_FLAGS.items() if flags & bit}

    @property
    def reset_cause(self) -> str:
        """The highest-priority reset flag (the protocol's ResetCause order), or ``unknown``."""
        flags = self.reset_flags
        return next((name for name in RESET_FLAGS if name in flags), "unknown")

    @property
    def log(self) -> str:
        """simavr's recent errors and warnings for this board."""
        with self._lock:
            return self._board().log()

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

    # -- profiling -------------------------------------------------------------------------------
    def profile_interrupt(self, vector: int | str | None) -> None:
        """Start counting cycles in an interrupt handler (number or name, e.g. TIMER2_COMPA;
        None stops). Figures restart from zero."""
        if isinstance(vector, str):
            if vector not in VECTORS:
                raise EmulatorError(f"unknown vector {vector!r}; known: {sorted(VECTORS)}")
            vector = VECTORS[vector]
        with self._lock:
            self._board().profile_vector(0 if vector is None else int(vector))

    def profile_function(self, function: str | int | None) -> None:
        """Start counting cycles in a function (ELF symbol or byte address; None stops)."""
        with self._lock:
            if function is None:
                self._board().profile_function(-1)
                return
            addr = self.symbol(function) if isinstance(function, str) else int(function)
            if addr is None:
                raise EmulatorError(f"no symbol {function!r} in {self.elf}")
            self._board().profile_function(addr)

    def profile(self) -> dict[str, CycleProfile]:
        """The running profiles: ``interrupt`` and ``function``."""
        with self._lock:
            b = self._board()
            return {
                "interrupt": CycleProfile.from_native(b.profile(0)),
                "function": CycleProfile.from_native(b.profile(1)),
            }

    def symbol(self, name: str) -> int | None:
        """An ELF symbol's address (data symbols: SRAM address, without avr-gcc's 0x800000)."""
        with self._lock:
            addr = self._board().symbol(name)
        if addr is not None and addr >= 0x800000:
            addr -= 0x800000
        return addr

    def read_ram(self, address: int | str, size: int) -> bytes:
        """Bytes of the data space (registers and SRAM) at an address or a data symbol."""
        if isinstance(address, str):
            addr = self.symbol(address)
            if addr is None:
                raise EmulatorError(f"no symbol {address!r} in {self.elf}")
            address = addr
        with self._lock:
            return self._board().read_data(int(address), int(size))


class SimSerial:
    """A pyserial-like port into a driven :class:`EmulatedBoard`: ``read`` runs the simulation
    until the bytes arrive or ``timeout`` *simulated* seconds pass (None: no limit).

    Implements what a protocol client uses: ``read``, ``read_until``, ``write``, ``flush``,
    ``in_waiting``, ``reset_input_buffer``, ``timeout``, ``is_open``, ``close``."""

    def __init__(self, board: EmulatedBoard, timeout: float | None = 1.0) -> None:
        self.board = board
        self.timeout = timeout
        self._buffer = bytearray()
        self.is_open = True

    def _pull(self) -> None:
        self._buffer += self.board.read()

    def _run_until(self, done: Callable[[], bool]) -> None:
        """Run one exchange period at a time (the finest step the board has) until done or
        the deadline. Within half a cycle of it counts as there: when time lands on the
        deadline, float rounding can leave a sliver no exchange runs, and the read would spin."""
        deadline = math.inf if self.timeout is None else self.board.sim_time + self.timeout
        step = self.board.exchange_period
        self._pull()
        while not done() and deadline - self.board.sim_time > 0.5 / F_CPU_HZ:
            self.board.run_for(step)
            self._pull()

    def read(self, size: int = 1) -> bytes:
        self._check_open()
        self._run_until(lambda: len(self._buffer) >= size)
        out = bytes(self._buffer[:size])
        del self._buffer[:size]
        return out

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        self._check_open()

        def found() -> bool:
            return expected in self._buffer or (size is not None and len(self._buffer) >= size)

        self._run_until(found)
        i = self._buffer.find(expected)
        end = len(self._buffer) if i < 0 else i + len(expected)
        if size is not None:
            end = min(end, size)
        out = bytes(self._buffer[:end])
        del self._buffer[:end]
        return out

    def write(self, data: bytes) -> int:
        self._check_open()
        return self.board.write(bytes(data))

    def flush(self) -> None:
        """Run until every byte written has gone out on the wire."""
        self._check_open()
        while self.board.uart_pending:
            self.board.run_for(1e-3)

    @property
    def in_waiting(self) -> int:
        self._pull()
        return len(self._buffer)

    def reset_input_buffer(self) -> None:
        self._pull()
        self._buffer.clear()

    def reset_output_buffer(self) -> None:
        """Bytes already queued are on the wire; nothing to drop."""

    def close(self) -> None:
        self.is_open = False

    def _check_open(self) -> None:
        if not self.is_open:
            raise EmulatorError("the port is closed")

    def __enter__(self) -> SimSerial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "DEFAULT_ELF",
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
