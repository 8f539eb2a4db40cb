"""Python objects over the C harness: :class:`NativeBoard` (one per board) and
:class:`NativeMjPlant` (the MuJoCo plant's C side). The ABI they call (constants, structs,
signatures, loading the library) is in ``harness_abi``; its names are importable from here too.
Nothing here is thread-safe: the caller serialises calls on one board (``EmulatedBoard`` holds a
lock).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any

import numpy as np

from utrf.emulator.harness_abi import (
    ABI,
    ADC_CHANNELS,
    BEAT_BYTES,
    BEATS,
    F_CPU_HZ,
    FINGERS,
    FRAME_LOG,
    HITS,
    MARKS,
    MJ_LOADS,
    MJ_STATE_FIELDS,
    MOTOR_REG_FIELDS,
    PIN_FIELDS,
    PROFILE_FIELDS,
    RESET_PIN,
    RESET_POWER_ON,
    RX_TIMING_FIELDS,
    STAT_FIELDS,
    STATUS_NAMES,
    STOPS,
    TO_BOARD,
    TO_HOST,
    TRUTH,
    FingerRegsC,
    HarnessError,
    LineFaultsC,
    MjPlantParamsC,
    MjPlantStateC,
    ProfileC,
    RxTimingC,
    SimHitC,
    StatsC,
    library_path,
    load_library,
)

_DP = ctypes.POINTER(ctypes.c_double)


class _NativeStepper:
    """A C plant's handle, numpy views of its state, stepping, the encoder volts, freeing.
    ``_prefix`` names the C functions (``<prefix>_step`` ...)."""

    _prefix: str

    def _bind(
        self, lib: ctypes.CDLL, handle: int, fields: tuple[tuple[str, tuple[int, ...]], ...]
    ) -> None:
        self._lib = lib
        self._h: int | None = handle
        self._c = getattr(lib, f"{self._prefix}_state")(handle).contents
        self.state = {
            name: np.ctypeslib.as_array(getattr(self._c, name)) for name, shape in fields if shape
        }
        self._volts = np.zeros(FINGERS)
        self._step = getattr(lib, f"{self._prefix}_step")
        self._encoder_volts = getattr(lib, f"{self._prefix}_encoder_volts")

    @property
    def handle(self) -> int:
        if self._h is None:
            raise HarnessError("the plant is freed")
        return self._h

    @property
    def time(self) -> float:
        return float(self._c.time)

    def close(self) -> None:
        if self._h is not None:
            self.state = {k: v.copy() for k, v in self.state.items()}  # views outlive it
            getattr(self._lib, f"{self._prefix}_free")(self._h)
            self._h = None

    def step(self, dt: float, pins: np.ndarray | None) -> None:
        if pins is None:
            self._step(self.handle, dt, None)
            return
        block = np.ascontiguousarray(pins, dtype=np.float64)
        self._step(self.handle, dt, block.ctypes.data_as(_DP))

    def encoder_volts(self) -> np.ndarray:
        self._encoder_volts(self.handle, self._volts.ctypes.data_as(_DP))
        return self._volts.copy()

    def pulses(self) -> int:
        return int(getattr(self._lib, f"{self._prefix}_pulses")(self.handle))

    @staticmethod
    def _check_hit(rc: int, what: str) -> None:
        if rc == -2:
            raise HarnessError("too many hits under way at once (64)")
        if rc:
            raise HarnessError(f"bad hit: {what}")


class NativeMjPlant(_NativeStepper):
    """The MuJoCo plant's stepping in C (``utrf_mjplant_t``) over the caller's model and data."""

    _prefix = "utrf_mjplant"

    def __init__(
        self, libmujoco: str, model: int, data: int, params: MjPlantParamsC, seed: int
    ) -> None:
        lib = load_library()
        err = ctypes.create_string_buffer(1024)
        handle = lib.utrf_mjplant_new(
            libmujoco.encode(), model, data, ctypes.byref(params), seed & (2**64 - 1), err, 1024
        )
        if not handle:
            raise HarnessError(err.value.decode(errors="replace"))
        self._bind(lib, handle, MJ_STATE_FIELDS)
        self.state["load_body"][:] = -1

    def hit(self, body: int, site: int, impulse: np.ndarray, duration: float) -> None:
        rc = self._lib.utrf_mjplant_hit(self.handle, body, site, *map(float, impulse), duration)
        self._check_hit(rc, f"body {body}, duration {duration}")

    def truth_sites(self, sites: list[int]) -> None:
        """The sites whose world positions a run ahead's stops record (at most 5)."""
        arr = (ctypes.c_int32 * max(len(sites), 1))(*sites)
        if self._lib.utrf_mjplant_truth_sites(self.handle, arr, len(sites)):
            raise HarnessError(f"at most {FINGERS} truth sites, got {len(sites)}")


class NativeBoard:
    """One simavr board. ``pins`` and ``adc_volts`` are numpy views of the harness's memory."""

    def __init__(self, elf: Path, seed: int) -> None:
        self._lib = load_library()
        err = ctypes.create_string_buffer(1024)
        handle = self._lib.utrf_sim_open(str(elf).encode(), seed & (2**64 - 1), err, len(err))
        if not handle:
            raise HarnessError(err.value.decode(errors="replace") or f"cannot load {elf}")
        self._h: int | None = handle
        pins = self._lib.utrf_sim_pins(handle)
        self.pins = np.ctypeslib.as_array(pins, shape=(FINGERS, 2, PIN_FIELDS))
        self.adc_volts = np.ctypeslib.as_array(
            self._lib.utrf_sim_adc_volts(handle), shape=(ADC_CHANNELS,)
        )
        self._run_to = self._lib.utrf_sim_run_to
        self._u8buf = (ctypes.c_uint8 * 65536)()
        self._marks = ((ctypes.c_uint64 * MARKS)(), (ctypes.c_uint64 * MARKS)())

    @property
    def handle(self) -> int:
        if self._h is None:
            raise HarnessError("the board is closed")
        return self._h

    def close(self) -> None:
        if self._h is not None:
            self.pins = np.zeros((FINGERS, 2, PIN_FIELDS))
            self.adc_volts = np.zeros(ADC_CHANNELS)
            self._lib.utrf_sim_close(self._h)
            self._h = None

    # -- running ----------------------------------------------------------------------------
    def run_to(self, cycle: int) -> int:
        return self._run_to(self._h, cycle)

    def attach_plant(self, plant: NativeMjPlant | None) -> None:
        self._lib.utrf_sim_attach_mjplant(self.handle, None if plant is None else plant.handle)

    def run_plant(self, cycle: int, period: int) -> int:
        return self._lib.utrf_sim_run_plant(self._h, cycle, period)

    def run_plant_until(self, cycle: int, period: int, wake: int) -> int:
        return self._lib.utrf_sim_run_plant_until(self._h, cycle, period, wake)

    def ahead_start(self, cycle: int, period: int, wake: int) -> None:
        """``run_plant_until`` on the harness's own thread, marking each period in which
        ``wake`` came instead of stopping there; returns at once (``ahead_join`` waits)."""
        if self._lib.utrf_sim_ahead_start(self.handle, cycle, period, wake):
            raise HarnessError("the board's run-ahead thread could not start (or one runs)")

    def ahead_join(self) -> int:
        """Wait for the run ahead; its status."""
        return int(self._lib.utrf_sim_ahead_join(self.handle))

    def ahead_marks(self) -> tuple[list[int], list[int]]:
        """After the join: the output's bytes not yet read up to each marked period, and the
        MCU's cycle at that period's end."""
        n = self._lib.utrf_sim_ahead_marks(self.handle, self._marks[0], self._marks[1], MARKS)
        return list(self._marks[0][:n]), list(self._marks[1][:n])

    def ahead_stops(
        self, targets: list[int], t0: float, hits: list[tuple[float, int, int, Any, float]]
    ) -> None:
        """Stops for the next run ahead (its last target the run's): at each, the hits due
        ((at, body, site, world impulse, duration); due at ``cycle / F_CPU_HZ - t0 >= at``)
        are applied and the plant's truth recorded (``ahead_stops_done``)."""
        if len(targets) > STOPS or len(hits) > HITS:
            raise HarnessError(f"at most {STOPS} stops and {HITS} hits a run, got "
                               f"{len(targets)} and {len(hits)}")  # fmt: skip
        cycles = (ctypes.c_uint64 * max(len(targets), 1))(*targets)
        chits = (SimHitC * max(len(hits), 1))()
        for c, (at, body, site, imp, duration) in zip(chits, hits, strict=False):
            c.at, c.body, c.site, c.duration = at, body, site, duration
            c.impulse[:] = [float(x) for x in imp]
        if self._lib.utrf_sim_ahead_stops(self.handle, cycles, len(targets), t0, chits, len(hits)):
            raise HarnessError("stops not rising, or a run ahead is under way")
        self._stop_hits = len(hits)

    def ahead_stops_done(self) -> tuple[list[int], np.ndarray, list[int]]:
        """After the join: the stops' MCU cycles, their truths (n, TRUTH) and each hit's stop
        (-1: not applied)."""
        cycles = (ctypes.c_uint64 * STOPS)()
        truth = np.zeros((STOPS, TRUTH))
        at = (ctypes.c_int32 * HITS)()
        n = self._lib.utrf_sim_ahead_stops_done(
            self.handle, cycles, truth.ctypes.data_as(_DP), at, STOPS
        )
        return list(cycles[:n]), truth[:n], list(at[: getattr(self, "_stop_hits", 0)])

    def ahead_beats(
        self,
        frames: list[tuple[int, bytes]],
        due: float,
        period: float,
        acks: set[int],
        kinds: bytes,
    ) -> None:
        """Heartbeats for the next run ahead with stops (``(seq, frame)`` each, the next due
        at ``due``, a ``period`` after each sent or each ack of ``acks`` heard; ``kinds``: per
        message id, 1 the stream, 2 an ack, 0 anything else)."""
        if len(frames) > BEATS or any(len(f) > BEAT_BYTES for _, f in frames) or len(kinds) != 256:
            raise HarnessError(f"at most {BEATS} heartbeats of {BEAT_BYTES} bytes a run")
        n = len(frames)
        buf = (ctypes.c_uint8 * (BEATS * BEAT_BYTES))()
        lens = (ctypes.c_uint8 * BEATS)()
        seqs = (ctypes.c_uint8 * BEATS)()
        for i, (seq, frame) in enumerate(frames):
            buf[i * BEAT_BYTES : i * BEAT_BYTES + len(frame)] = list(frame)
            lens[i], seqs[i] = len(frame), seq
        mask = (ctypes.c_uint8 * 16)()
        for seq in acks:
            mask[seq >> 3] |= 1 << (seq & 7)
        ckinds = (ctypes.c_uint8 * 256).from_buffer_copy(kinds)
        if self._lib.utrf_sim_ahead_beats(
            self.handle, buf, lens, seqs, n, due, period, mask, ckinds
        ):
            raise HarnessError("heartbeats refused: too many, or a run ahead is under way")

    def ahead_beats_done(self) -> tuple[list[int], list[float]]:
        """After the join: the heartbeats sent, their cycles and the due times they went for."""
        cycles = (ctypes.c_uint64 * BEATS)()
        dues = (ctypes.c_double * BEATS)()
        n = self._lib.utrf_sim_ahead_beats_done(self.handle, cycles, dues, BEATS)
        return list(cycles[:n]), list(dues[:n])

    def ahead_beats_next(self) -> tuple[float, set[int]] | None:
        """After the join: the next heartbeat's due time and the seqs whose acks still count,
        as the harness's rule stands (None: heartbeats off, or the rule frozen)."""
        due = ctypes.c_double(0.0)
        mask = (ctypes.c_uint8 * 16)()
        if self._lib.utrf_sim_ahead_beats_next(self.handle, ctypes.byref(due), mask):
            return None
        return due.value, {k for k in range(128) if mask[k >> 3] >> (k & 7) & 1}

    def ahead_send(self, data: bytes, at_s: float) -> None:
        """Write ``data`` to UART0 at the first period's end whose time reaches ``at_s``."""
        buf = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
        if self._lib.utrf_sim_ahead_send(self.handle, buf, len(data), at_s):
            raise HarnessError(f"{len(data)} bytes cannot wait for their time (or a run is on)")

    def ahead_sent(self) -> tuple[int, int]:
        """The cycle the waiting bytes went at (0: not yet) and how many the UART took."""
        taken = ctypes.c_size_t(0)
        cycle = self._lib.utrf_sim_ahead_sent(self.handle, ctypes.byref(taken))
        return int(cycle), int(taken.value)

    @property
    def plant_cycle(self) -> int:
        """The plant's clock: where the next exchange period starts."""
        return int(self._lib.utrf_sim_plant_cycle(self._h))

    @property
    def plant_threads(self) -> int:
        return int(self._lib.utrf_sim_plant_threads(self._h))

    def set_plant_threads(self, threads: int) -> None:
        rc = self._lib.utrf_sim_set_plant_threads(self._h, threads)
        if rc == -1:
            raise HarnessError(f"the plant steps on 1 or 2 threads, not {threads!r}")
        if rc:
            raise HarnessError("the plant's thread could not start")

    @property
    def plant_inline_periods(self) -> int:
        """With two twin threads: the periods the MCU's thread stepped the plant itself."""
        return int(self._lib.utrf_sim_plant_inline_periods(self._h))

    @property
    def plant_wait_s(self) -> float:
        """With two twin threads: how long the MCU's thread waited for the plant's (s)."""
        return int(self._lib.utrf_sim_plant_wait_ns(self._h)) / 1e9

    def set_plant_spin(self, spin: bool) -> None:
        """With two twin threads: whether the plant's thread spins before it sleeps."""
        self._lib.utrf_sim_set_plant_spin(self._h, int(bool(spin)))

    @property
    def cycle(self) -> int:
        return self._lib.utrf_sim_cycle(self.handle)

    @property
    def status(self) -> int:
        return self._lib.utrf_sim_status(self.handle)

    @property
    def pc(self) -> int:
        return self._lib.utrf_sim_pc(self.handle)

    def jump(self, addr: int, interrupts: int = -1) -> bool:
        return self._lib.utrf_sim_jump(self.handle, addr, interrupts) == 0

    def jump_at(self, at: int, addr: int, interrupts: int = -1) -> bool:
        return self._lib.utrf_sim_jump_at(self.handle, at, addr, interrupts) == 0

    def flash_word(self, addr: int) -> int:
        return self._lib.utrf_sim_flash_word(self.handle, addr)

    def refresh_pins(self) -> None:
        self._lib.utrf_sim_refresh_pins(self.handle)

    # -- UART -------------------------------------------------------------------------------
    def uart_write(self, data: bytes) -> int:
        return self._lib.utrf_sim_uart_write(self.handle, data, len(data))

    def uart_read(self, limit: int = 65536) -> bytes:
        n = self._lib.utrf_sim_uart_read(self.handle, self._u8buf, min(limit, len(self._u8buf)))
        return bytes(self._u8buf[:n])

    def uart_pending(self) -> int:
        return self._lib.utrf_sim_uart_pending(self.handle)

    def set_capture(self, on: bool) -> None:
        self._lib.utrf_sim_set_capture(self.handle, int(on))

    def serve_pty(self) -> str:
        buf = ctypes.create_string_buffer(256)
        rc = self._lib.utrf_sim_serve_pty(self.handle, buf, len(buf))
        if rc < 0:
            raise HarnessError(f"cannot open a pty: {os.strerror(-rc)}")
        return buf.value.decode()

    def serve_tcp(self, host: str, port: int) -> int:
        rc = self._lib.utrf_sim_serve_tcp(self.handle, host.encode(), port)
        if rc < 0:
            raise HarnessError(f"cannot listen on {host}:{port}: {os.strerror(-rc)}")
        return rc

    def set_auto_reset(self, on: bool) -> None:
        self._lib.utrf_sim_set_auto_reset(self.handle, int(on))

    @property
    def clients(self) -> int:
        return self._lib.utrf_sim_clients(self.handle)

    def drop_client(self) -> None:
        self._lib.utrf_sim_drop_client(self.handle)

    def set_line_faults(
        self,
        direction: int,
        drop: float,
        corrupt: float,
        insert: float,
        duplicate: float = 0.0,
        burst: float = 0.0,
        burst_length: tuple[int, int] = (8, 32),
    ) -> None:
        f = LineFaultsC(drop, corrupt, insert, duplicate, burst, *burst_length)
        if self._lib.utrf_sim_set_line_faults(self.handle, direction, ctypes.byref(f)):
            raise HarnessError(
                "line fault probabilities must lie in [0, 1] (insert and duplicate < 1), "
                "a burst's length 1 <= min <= max"
            )

    def stall_vector(self, vector: int, cycles: int, count: int) -> None:
        if self._lib.utrf_sim_stall_vector(self.handle, vector, cycles, count):
            raise HarnessError(f"interrupt vector {vector} does not exist on the atmega2560")

    def stalls_left(self) -> int:
        return self._lib.utrf_sim_stalls_left(self.handle)

    def write_io(self, address: int, value: int) -> None:
        if self._lib.utrf_sim_write_io(self.handle, address, value):
            raise HarnessError(f"{address:#x} is not an I/O register")

    def set_quiet_timers(self, on: bool) -> None:
        self._lib.utrf_sim_set_quiet_timers(self.handle, int(on))

    def poke(self, address: int, value: int) -> None:
        if self._lib.utrf_sim_poke(self.handle, address, value):
            raise HarnessError(f"{address:#x} is outside the data space")

    def inject(self, direction: int, data: bytes) -> int:
        return self._lib.utrf_sim_inject(self.handle, direction, data, len(data))

    # -- board ------------------------------------------------------------------------------
    def reset(self, cause: int, hold_cycles: int = 0) -> None:
        self._lib.utrf_sim_reset(self.handle, cause, hold_cycles)

    def set_auto_reset_hold(self, hold_cycles: int) -> None:
        self._lib.utrf_sim_set_auto_reset_hold(self.handle, hold_cycles)

    def eeprom(self) -> bytes:
        n = self._lib.utrf_sim_eeprom_size(self.handle)
        buf = (ctypes.c_uint8 * n)()
        if self._lib.utrf_sim_eeprom_get(self.handle, buf, n):
            raise HarnessError("cannot read the EEPROM")
        return bytes(buf)

    def set_eeprom(self, data: bytes) -> None:
        if self._lib.utrf_sim_eeprom_set(self.handle, data, len(data)):
            raise HarnessError(f"EEPROM image of {len(data)} bytes does not fit")

    @property
    def eeprom_size(self) -> int:
        return self._lib.utrf_sim_eeprom_size(self.handle)

    def stats(self) -> dict[str, int]:
        s = StatsC()
        self._lib.utrf_sim_stats(self.handle, ctypes.byref(s))
        return {name: int(getattr(s, name)) for name in STAT_FIELDS}

    def rx_timing(self, clear: bool = False) -> dict[str, int]:
        """The receive path since the last clear: bytes read from UDR0 (``reads``), their
        waits from the end of the stop bit to the read (``total``, ``worst`` and its cycle
        ``worst_at``, in cycles; ``late``: over one frame), bytes lost to the two-byte FIFO
        (``overruns``, DOR0) and frame errors (FE0). ``clear`` starts it again."""
        t = RxTimingC()
        self._lib.utrf_sim_rx_timing(self.handle, ctypes.byref(t), int(clear))
        return {name: int(getattr(t, name)) for name in RX_TIMING_FIELDS}

    def profile_vector(self, vector: int) -> None:
        if self._lib.utrf_sim_profile_vector(self.handle, vector):
            raise HarnessError(f"interrupt vector {vector} does not exist on the atmega2560")

    def profile_function(self, address: int) -> None:
        if self._lib.utrf_sim_profile_function(self.handle, address):
            raise HarnessError(f"{address:#x} is not a code address")

    def profile_function_slot(self, slot: int, address: int) -> None:
        if self._lib.utrf_sim_profile_function_slot(self.handle, slot, address):
            raise HarnessError(f"slot {slot} or address {address:#x} is not valid")

    def profile_vector_requires(self, slot: int) -> None:
        if self._lib.utrf_sim_profile_vector_requires(self.handle, slot):
            raise HarnessError(f"no function profile slot {slot}")

    def profile_clear(self) -> None:
        self._lib.utrf_sim_profile_clear(self.handle)

    def pc_histogram(self, slot: int | None) -> None:
        """Count cycles per program address from now on: every instruction's (slot -1), or
        function slot ``slot``'s own work; None stops."""
        if self._lib.utrf_sim_pc_histogram(self.handle, -2 if slot is None else slot):
            raise HarnessError(f"no function profile slot {slot}")

    def pc_histogram_get(self) -> np.ndarray:
        """Cycles per program word (index = byte address / 2); empty when off."""
        n = self._lib.utrf_sim_pc_histogram_get(self.handle, None, 0)
        out = np.zeros(n, dtype=np.uint64)
        if n:
            self._lib.utrf_sim_pc_histogram_get(
                self.handle, out.ctypes.data_as(ctypes.POINTER(ctypes.c_uint64)), n
            )
        return out

    def uart_frames(self) -> list[tuple[int, int]]:
        """The captured frames' wire times since the last call: (first byte's start, 0x00's
        stop bit end), in cycles."""
        starts, ends = (ctypes.c_uint64 * FRAME_LOG)(), (ctypes.c_uint64 * FRAME_LOG)()
        n = self._lib.utrf_sim_uart_frames(self.handle, starts, ends, FRAME_LOG)
        return list(zip(starts[:n], ends[:n], strict=True))

    def pin_registers(self) -> list[dict[str, object]]:
        """Per finger: ``stby``, ``stby_out`` and motors ``a``, ``b`` as register fields."""
        regs = (FingerRegsC * FINGERS)()
        self._lib.utrf_sim_pin_registers(self.handle, regs)
        return [
            {
                "stby": int(f.stby),
                "stby_out": int(f.stby_out),
                **{
                    side: {name: int(getattr(f.motor[k], name)) for name in MOTOR_REG_FIELDS}
                    for k, side in enumerate("ab")
                },
            }
            for f in regs
        ]

    def profile(self, which: int) -> dict[str, int]:
        p = ProfileC()
        self._lib.utrf_sim_profile_get(self.handle, which, ctypes.byref(p))
        return {name: int(getattr(p, name)) for name in PROFILE_FIELDS}

    def log(self) -> str:
        buf = ctypes.create_string_buffer(4096)
        self._lib.utrf_sim_log(self.handle, buf, len(buf))
        return buf.value.decode(errors="replace")

    def symbol(self, name: str) -> int | None:
        addr = self._lib.utrf_sim_symbol(self.handle, name.encode())
        return None if addr < 0 else int(addr)

    def read_data(self, address: int, size: int) -> bytes:
        buf = (ctypes.c_uint8 * size)()
        if self._lib.utrf_sim_read_data(self.handle, address, buf, size):
            raise HarnessError(f"data space {address:#x}+{size} is outside the ATmega2560's")
        return bytes(buf)


__all__ = [
    "ABI",
    "ADC_CHANNELS",
    "FINGERS",
    "F_CPU_HZ",
    "MJ_LOADS",
    "MJ_STATE_FIELDS",
    "PIN_FIELDS",
    "PROFILE_FIELDS",
    "RESET_PIN",
    "RESET_POWER_ON",
    "STATUS_NAMES",
    "STAT_FIELDS",
    "TO_BOARD",
    "TO_HOST",
    "HarnessError",
    "LineFaultsC",
    "MjPlantParamsC",
    "MjPlantStateC",
    "NativeBoard",
    "NativeMjPlant",
    "ProfileC",
    "StatsC",
    "library_path",
    "load_library",
]
