"""ctypes binding of the C harness (``harness/utrf_sim.h``); one :class:`NativeBoard` per board.

The library is found by :func:`utrf.artifacts.harness_library`: ``UTRF_SIM_LIB``, a checkout's
``build/emulator/libutrf_sim.so`` (``make emulator``), or built on first use into the user's
cache from the harness sources the package ships. Nothing here is thread-safe: the caller
serialises calls on one board (``EmulatedBoard`` holds a lock).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any

import numpy as np

from utrf import artifacts

ABI = 10
F_CPU_HZ = 16_000_000
FINGERS = 5
PIN_FIELDS = 4  # duty, IN1, IN2, STBY
ADC_CHANNELS = 8


STATUS_NAMES = {0: "running", 1: "crashed", 2: "done"}
RESET_POWER_ON, RESET_PIN = 0, 1
TO_BOARD, TO_HOST = 0, 1

STAT_FIELDS = (
    "rx_host_bytes",
    "rx_uart_bytes",
    "rx_lost_disabled",
    "rx_dropped",
    "rx_corrupted",
    "rx_inserted",
    "rx_held",
    "tx_uart_bytes",
    "tx_dropped",
    "tx_corrupted",
    "tx_inserted",
    "tx_unheard",
    "tx_cut",
    "resets",
    "watchdog_resets",
    "last_reset_flags",
    "clients",
    "eeprom_writes",
    "frame_cycles",
    "adc_conversions",
    "late_interrupts",
    "rx_duplicated",
    "rx_burst_bytes",
    "tx_duplicated",
    "tx_burst_bytes",
    "stalls",
    "sleep_cycles",
    "quieted_timer_events",
)
PROFILE_FIELDS = (
    "count",
    "total",
    "worst",
    "best",
    "total_incl",
    "worst_incl",
    "last_entry",
    "period_sum",
    "intervals",
    "latency_sum",
    "latency_worst",
)


class HarnessError(RuntimeError):
    """The C harness is missing, stale, or refused a request."""


class _Stats(ctypes.Structure):
    _fields_ = [(name, ctypes.c_uint64) for name in STAT_FIELDS]


class _LineFaults(ctypes.Structure):
    _fields_ = [
        ("drop", ctypes.c_double),
        ("corrupt", ctypes.c_double),
        ("insert", ctypes.c_double),
        ("duplicate", ctypes.c_double),
        ("burst", ctypes.c_double),
        ("burst_min", ctypes.c_uint32),
        ("burst_max", ctypes.c_uint32),
    ]


_D = ctypes.c_double
_I32 = ctypes.c_int32


def _arr(kind: type, *shape: int) -> type:
    t: Any = kind  # ctypes array types are made by multiplying a type: no static type
    for n in reversed(shape):
        t = t * n
    return t


class PlantParamsC(ctypes.Structure):
    """``utrf_plant_params_t``: the plant's constants (utrf.emulator.plant fills it)."""

    _fields_ = [
        ("R", _arr(_D, 5, 3)),
        ("L", _arr(_D, 5, 3)),
        ("link_mass", _arr(_D, 5, 3)),
        ("com", _arr(_D, 5, 3)),
        ("tendon_stiffness", _arr(_D, 5)),
        ("coupling_compliance", _arr(_D, 5, 2)),
        ("rotary", _arr(_I32, 5)),
        ("q_limits", _arr(_D, 5, 2)),
        ("supply_v", _D),
        ("stall_force", _D),
        ("no_load_speed", _D),
        ("electrical_time_constant", _D),
        ("moving_mass", _D),
        ("coulomb_friction", _D),
        ("viscous_friction", _D),
        ("stroke", _arr(_D, 2)),
        ("enc_supply", _D),
        ("enc_offset", _D),
        ("enc_band", _arr(_D, 2)),
        ("enc_noise_v", _D),
        ("enc_unplugged_v", _D),
        ("enc_invert", _I32),
        ("enc_bits", _I32),
        ("joint_damping", _D),
        ("tendon_damping", _D),
        ("gravity", _arr(_D, 2)),
        ("max_substep", _D),
    ]


PLANT_STATE_FIELDS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("time", ()),
    ("q", (5,)),
    ("qd", (5,)),
    ("x", (5, 2)),
    ("xd", (5, 2)),
    ("current", (5, 2)),
    ("tension", (5, 2)),
    ("drive_mode", (5, 2)),
    ("drive_duty", (5, 2)),
    ("tip_force", (5, 2)),
    ("tip_goal", (5, 2)),
    ("tip_rate", (5,)),
    ("applied_force", (5, 2)),
    ("coupling_stretch", (5, 2)),
    ("q_ext", (5,)),
    ("block", (5, 2)),
    ("plugged", (5,)),
    ("unplugged_v", (5,)),
    ("encoder_shift", (5,)),
)


class PlantStateC(ctypes.Structure):
    """``utrf_plant_state_t``: the plant's state, read and written in place."""

    _fields_ = [(name, _arr(_D, *shape) if shape else _D) for name, shape in PLANT_STATE_FIELDS]


MJ_LOADS = 16


class MjPlantParamsC(ctypes.Structure):
    """``utrf_mjplant_params_t``: indices into the MuJoCo model and the motors' constants."""

    _fields_ = [
        ("actuator", _arr(_I32, 5, 2)),
        ("dof", _arr(_I32, 5, 2)),
        ("gear", _arr(_D, 5, 2)),
        ("j2_qpos", _arr(_I32, 5)),
        ("supply_v", _D),
        ("force_constant", _D),
        ("resistance", _D),
        ("electrical_time_constant", _D),
        ("stall_force", _D),
        ("enc_supply", _D),
        ("enc_offset", _D),
        ("enc_band", _arr(_D, 2)),
        ("enc_noise_v", _D),
        ("enc_unplugged_v", _D),
        ("enc_invert", _I32),
        ("enc_bits", _I32),
    ]


MJ_STATE_FIELDS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("time", ()),
    ("current", (5, 2)),
    ("drive_mode", (5, 2)),
    ("drive_duty", (5, 2)),
    ("plugged", (5,)),
    ("unplugged_v", (5,)),
    ("encoder_shift", (5,)),
    ("load_body", (MJ_LOADS,)),
    ("load_site", (MJ_LOADS,)),
    ("load_force", (MJ_LOADS, 3)),
)


class MjPlantStateC(ctypes.Structure):
    _fields_ = [(name, _arr(_D, *shape) if shape else _D) for name, shape in MJ_STATE_FIELDS]


class _Profile(ctypes.Structure):
    _fields_ = [(name, ctypes.c_uint64) for name in PROFILE_FIELDS]


_lib: ctypes.CDLL | None = None


def library_path() -> Path:
    try:
        return artifacts.harness_library()
    except artifacts.ArtifactError as exc:
        raise HarnessError(str(exc)) from None


def _check_fresh(path: Path) -> None:
    if not path.is_file():
        raise HarnessError(
            f"the emulator's harness library {path} is missing: run `make emulator` "
            "(or `make test`) in the repository"
        )
    root = artifacts.checkout_root()
    if os.environ.get("UTRF_SIM_LIB") or root is None or not path.is_relative_to(root):
        return  # the cache is keyed by its sources' hash: never stale
    harness = root / "host" / "utrf" / "emulator" / "harness"
    sources = [*harness.glob("*.c"), *harness.glob("*.h")]
    pins = root / "firmware" / "src" / "board_pins.h"
    if pins.is_file():
        sources.append(pins)
    newest = max((p.stat().st_mtime for p in sources), default=0.0)
    if newest > path.stat().st_mtime:
        raise HarnessError(
            f"the emulator's harness library {path} is older than its sources: run `make emulator`"
        )


def load_library() -> ctypes.CDLL:
    """Load (once) and type the harness library."""
    global _lib
    if _lib is not None:
        return _lib
    path = library_path()
    _check_fresh(path)
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise HarnessError(
            f"cannot load {path}: {exc} (is libsimavr installed? `make setup`)"
        ) from exc
    if lib.utrf_sim_abi() != ABI:
        raise HarnessError(
            f"{path} speaks harness ABI {lib.utrf_sim_abi()}, this package {ABI}: "
            "run `make emulator`"
        )
    p, u8p = ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint8)
    sigs: dict[str, tuple[Any, list[Any]]] = {
        "utrf_sim_open": (p, [ctypes.c_char_p, ctypes.c_uint64, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_sim_close": (None, [p]),
        "utrf_sim_run_to": (ctypes.c_int, [p, ctypes.c_uint64]),
        "utrf_sim_cycle": (ctypes.c_uint64, [p]),
        "utrf_sim_status": (ctypes.c_int, [p]),
        "utrf_sim_pc": (ctypes.c_uint32, [p]),
        "utrf_sim_jump": (ctypes.c_int, [p, ctypes.c_uint32, ctypes.c_int]),
        "utrf_sim_flash_word": (ctypes.c_int32, [p, ctypes.c_uint32]),
        "utrf_sim_jump_at": (ctypes.c_int, [p, ctypes.c_uint32, ctypes.c_uint32, ctypes.c_int]),
        "utrf_sim_adc_volts": (ctypes.POINTER(ctypes.c_double), [p]),
        "utrf_sim_pins": (ctypes.POINTER(ctypes.c_double), [p]),
        "utrf_sim_refresh_pins": (None, [p]),
        "utrf_sim_read_data": (ctypes.c_int, [p, ctypes.c_uint32, u8p, ctypes.c_size_t]),
        "utrf_sim_symbol": (ctypes.c_int64, [p, ctypes.c_char_p]),
        "utrf_sim_uart_write": (ctypes.c_size_t, [p, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_sim_uart_read": (ctypes.c_size_t, [p, u8p, ctypes.c_size_t]),
        "utrf_sim_uart_pending": (ctypes.c_size_t, [p]),
        "utrf_sim_set_capture": (None, [p, ctypes.c_int]),
        "utrf_sim_serve_pty": (ctypes.c_int, [p, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_sim_serve_tcp": (ctypes.c_int, [p, ctypes.c_char_p, ctypes.c_int]),
        "utrf_sim_set_auto_reset": (None, [p, ctypes.c_int]),
        "utrf_sim_clients": (ctypes.c_int, [p]),
        "utrf_sim_drop_client": (None, [p]),
        "utrf_sim_set_line_faults": (
            ctypes.c_int,
            [p, ctypes.c_int, ctypes.POINTER(_LineFaults)],
        ),
        "utrf_sim_stall_vector": (
            ctypes.c_int,
            [p, ctypes.c_int, ctypes.c_uint64, ctypes.c_int64],
        ),
        "utrf_sim_stalls_left": (ctypes.c_int64, [p]),
        "utrf_sim_write_io": (ctypes.c_int, [p, ctypes.c_uint32, ctypes.c_uint8]),
        "utrf_sim_poke": (ctypes.c_int, [p, ctypes.c_uint32, ctypes.c_uint8]),
        "utrf_sim_set_quiet_timers": (None, [p, ctypes.c_int]),
        "utrf_sim_inject": (ctypes.c_size_t, [p, ctypes.c_int, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_sim_reset": (None, [p, ctypes.c_int, ctypes.c_uint64]),
        "utrf_sim_set_auto_reset_hold": (None, [p, ctypes.c_uint64]),
        "utrf_sim_eeprom_size": (ctypes.c_size_t, [p]),
        "utrf_sim_eeprom_get": (ctypes.c_int, [p, u8p, ctypes.c_size_t]),
        "utrf_sim_eeprom_set": (ctypes.c_int, [p, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_sim_stats": (None, [p, ctypes.POINTER(_Stats)]),
        "utrf_sim_profile_vector": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_profile_function": (ctypes.c_int, [p, ctypes.c_int64]),
        "utrf_sim_profile_get": (None, [p, ctypes.c_int, ctypes.POINTER(_Profile)]),
        "utrf_sim_log": (ctypes.c_size_t, [p, ctypes.c_char_p, ctypes.c_size_t]),
        "utrf_plant_new": (p, [ctypes.POINTER(PlantParamsC), ctypes.c_uint64]),
        "utrf_plant_free": (None, [p]),
        "utrf_plant_state": (ctypes.POINTER(PlantStateC), [p]),
        "utrf_plant_refresh": (None, [p]),
        "utrf_plant_inertia": (ctypes.c_double, [p, ctypes.c_int]),
        "utrf_plant_step": (None, [p, ctypes.c_double, ctypes.POINTER(ctypes.c_double)]),
        "utrf_plant_encoder_volts": (None, [p, ctypes.POINTER(ctypes.c_double)]),
        "utrf_plant_decode": (None, [p, ctypes.POINTER(ctypes.c_double)]),
        "utrf_plant_hit": (
            ctypes.c_int,
            [p, ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_double],
        ),
        "utrf_plant_pulses": (ctypes.c_int, [p]),
        "utrf_sim_attach_plant": (None, [p, p]),
        "utrf_mjplant_new": (
            p,
            [
                ctypes.c_char_p,
                p,
                p,
                ctypes.POINTER(MjPlantParamsC),
                ctypes.c_uint64,
                ctypes.c_char_p,
                ctypes.c_size_t,
            ],
        ),
        "utrf_mjplant_free": (None, [p]),
        "utrf_mjplant_state": (ctypes.POINTER(MjPlantStateC), [p]),
        "utrf_mjplant_step": (None, [p, ctypes.c_double, ctypes.POINTER(ctypes.c_double)]),
        "utrf_mjplant_encoder_volts": (None, [p, ctypes.POINTER(ctypes.c_double)]),
        "utrf_mjplant_hit": (
            ctypes.c_int,
            [p, ctypes.c_int, ctypes.c_int] + [ctypes.c_double] * 4,
        ),
        "utrf_mjplant_pulses": (ctypes.c_int, [p]),
        "utrf_sim_attach_mjplant": (None, [p, p]),
        "utrf_sim_run_plant": (ctypes.c_int, [p, ctypes.c_uint64, ctypes.c_uint64]),
    }
    for name, (restype, argtypes) in sigs.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    _lib = lib
    return lib


_DP = ctypes.POINTER(ctypes.c_double)


class NativePlant:
    """One C plant (``utrf_plant_t``). ``state`` holds numpy views of its state, by field."""

    def __init__(self, params: PlantParamsC, seed: int) -> None:
        self._lib = load_library()
        handle = self._lib.utrf_plant_new(ctypes.byref(params), seed & (2**64 - 1))
        if not handle:
            raise HarnessError("out of memory for the plant")
        self._h: int | None = handle
        self._c = self._lib.utrf_plant_state(handle).contents
        self.state = {
            name: np.ctypeslib.as_array(getattr(self._c, name))
            for name, shape in PLANT_STATE_FIELDS
            if shape
        }
        self._volts = np.zeros(FINGERS)
        self._step = self._lib.utrf_plant_step

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
            self._lib.utrf_plant_free(self._h)
            self._h = None

    def step(self, dt: float, pins: np.ndarray | None) -> None:
        if pins is None:
            self._step(self.handle, dt, None)
            return
        block = np.ascontiguousarray(pins, dtype=np.float64)
        self._step(self.handle, dt, block.ctypes.data_as(_DP))

    def decode(self, pins: np.ndarray) -> None:
        block = np.ascontiguousarray(pins, dtype=np.float64)
        self._lib.utrf_plant_decode(self.handle, block.ctypes.data_as(_DP))

    def encoder_volts(self) -> np.ndarray:
        self._lib.utrf_plant_encoder_volts(self.handle, self._volts.ctypes.data_as(_DP))
        return self._volts.copy()

    def refresh(self) -> None:
        self._lib.utrf_plant_refresh(self.handle)

    def inertia(self, finger: int) -> float:
        return self._lib.utrf_plant_inertia(self.handle, finger)

    def hit(self, finger: int, jx: float, jy: float, duration: float) -> None:
        rc = self._lib.utrf_plant_hit(self.handle, finger, jx, jy, duration)
        if rc == -2:
            raise HarnessError("too many hits under way at once (64)")
        if rc:
            raise HarnessError(f"bad hit: finger {finger}, duration {duration}")

    def pulses(self) -> int:
        return self._lib.utrf_plant_pulses(self.handle)


class NativeMjPlant:
    """The MuJoCo plant's stepping in C (``utrf_mjplant_t``) over the caller's model and data."""

    def __init__(
        self, libmujoco: str, model: int, data: int, params: MjPlantParamsC, seed: int
    ) -> None:
        self._lib = load_library()
        err = ctypes.create_string_buffer(1024)
        handle = self._lib.utrf_mjplant_new(
            libmujoco.encode(), model, data, ctypes.byref(params), seed & (2**64 - 1), err, 1024
        )
        if not handle:
            raise HarnessError(err.value.decode(errors="replace"))
        self._h: int | None = handle
        self._c = self._lib.utrf_mjplant_state(handle).contents
        self.state = {
            name: np.ctypeslib.as_array(getattr(self._c, name))
            for name, shape in MJ_STATE_FIELDS
            if shape
        }
        self.state["load_body"][:] = -1
        self._volts = np.zeros(FINGERS)

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
            self.state = {k: v.copy() for k, v in self.state.items()}
            self._lib.utrf_mjplant_free(self._h)
            self._h = None

    def step(self, dt: float, pins: np.ndarray | None) -> None:
        if pins is None:
            self._lib.utrf_mjplant_step(self.handle, dt, None)
            return
        block = np.ascontiguousarray(pins, dtype=np.float64)
        self._lib.utrf_mjplant_step(self.handle, dt, block.ctypes.data_as(_DP))

    def encoder_volts(self) -> np.ndarray:
        self._lib.utrf_mjplant_encoder_volts(self.handle, self._volts.ctypes.data_as(_DP))
        return self._volts.copy()

    def hit(self, body: int, site: int, impulse: np.ndarray, duration: float) -> None:
        rc = self._lib.utrf_mjplant_hit(self.handle, body, site, *map(float, impulse), duration)
        if rc == -2:
            raise HarnessError("too many hits under way at once (64)")
        if rc:
            raise HarnessError(f"bad hit: body {body}, duration {duration}")

    def pulses(self) -> int:
        return self._lib.utrf_mjplant_pulses(self.handle)


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

    def attach_plant(self, plant: NativePlant | NativeMjPlant | None) -> None:
        if isinstance(plant, NativeMjPlant):
            self._lib.utrf_sim_attach_mjplant(self.handle, plant.handle)
        else:
            self._lib.utrf_sim_attach_plant(self.handle, None if plant is None else plant.handle)

    def run_plant(self, cycle: int, period: int) -> int:
        return self._lib.utrf_sim_run_plant(self._h, cycle, period)

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
        f = _LineFaults(drop, corrupt, insert, duplicate, burst, *burst_length)
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
        s = _Stats()
        self._lib.utrf_sim_stats(self.handle, ctypes.byref(s))
        return {name: int(getattr(s, name)) for name in STAT_FIELDS}

    def profile_vector(self, vector: int) -> None:
        if self._lib.utrf_sim_profile_vector(self.handle, vector):
            raise HarnessError(f"interrupt vector {vector} does not exist on the atmega2560")

    def profile_function(self, address: int) -> None:
        if self._lib.utrf_sim_profile_function(self.handle, address):
            raise HarnessError(f"{address:#x} is not a code address")

    def profile(self, which: int) -> dict[str, int]:
        p = _Profile()
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
