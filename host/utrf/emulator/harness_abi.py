"""The C harness's ABI (``harness/utrf_sim.h``) for ctypes: its constants, its structs, the
signature of every function, and loading the library (:func:`load_library`, once).

The library is found by :func:`utrf.artifacts.harness_library`: ``UTRF_SIM_LIB``, a checkout's
``build/emulator/libutrf_sim.so`` (``make emulator``), or built on first use into the user's
cache from the harness sources the package ships. The wrappers over it are in ``_native``.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any

from utrf import artifacts

ABI = 20
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
    "rx_overruns",
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
    "rx_frame_errors",
)
RX_TIMING_FIELDS = ("reads", "total", "worst", "worst_at", "late", "overruns", "frame_errors")
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
    "nested",
    "nested_worst",
    "period_worst",
    "period_worst_at",
)
FUNCTION_PROFILES = 3  # function slots; profile(which): 0 the vector, 1 + k slot k
FRAME_LOG = 4096
MARKS = 256  # UTRF_SIM_MARKS: the periods a run ahead marks at most
STOPS = 64  # UTRF_SIM_STOPS: the stops one run ahead passes through at most
HITS = 16  # UTRF_SIM_HITS: the hits one run ahead's stops apply at most
TRUTH = 32  # UTRF_SIM_TRUTH: the doubles a stop records of the plant
BEATS = 16  # UTRF_SIM_BEATS: the heartbeats one run ahead with stops sends at most
BEAT_BYTES = 16  # UTRF_SIM_BEAT_BYTES: a heartbeat frame's room
MOTOR_REG_FIELDS = ("com", "ocr", "icr", "wgm", "cs", "in1", "in2", "pwm_pin", "outputs")


class HarnessError(RuntimeError):
    """The C harness is missing, stale, or refused a request."""


class StatsC(ctypes.Structure):
    """``utrf_sim_stats_t``: the harness counters, one per ``STAT_FIELDS``."""

    _fields_ = [(name, ctypes.c_uint64) for name in STAT_FIELDS]


class RxTimingC(ctypes.Structure):
    """``utrf_sim_rx_timing_t``: the receive path's waits, one per ``RX_TIMING_FIELDS``."""

    _fields_ = [(name, ctypes.c_uint64) for name in RX_TIMING_FIELDS]


class SimHitC(ctypes.Structure):
    """``utrf_sim_hit_t``: a hit a run ahead's stops apply at its time."""

    _fields_ = [
        ("at", ctypes.c_double),
        ("body", ctypes.c_int32),
        ("site", ctypes.c_int32),
        ("impulse", ctypes.c_double * 3),
        ("duration", ctypes.c_double),
    ]


class LineFaultsC(ctypes.Structure):
    """``utrf_line_faults_t``: one direction's line-fault probabilities."""

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


# The encoder's constants in the plant's parameter struct (utrf_sim.h).
_ENCODER_FIELDS = [
    ("enc_supply", _D),
    ("enc_offset", _D),
    ("enc_band", _arr(_D, 2)),
    ("enc_noise_v", _D),
    ("enc_unplugged_v", _D),
    ("enc_invert", _I32),
    ("enc_bits", _I32),
]


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
        *_ENCODER_FIELDS,
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
    ("load_from", (MJ_LOADS, 3)),
    ("load_t0", (MJ_LOADS,)),
    ("load_t1", (MJ_LOADS,)),
    ("build_motor_from", (5,)),
    ("build_lead", (5, 2)),
    ("build_powered", (5, 2)),
    ("build_k_scale", (5, 2)),
    ("build_r_scale", (5, 2)),
    ("build_encoder_from", (5,)),
    ("build_encoder_invert", (5,)),
    ("build_encoder_offset", (5,)),
    ("build_encoder_eccentric", (5,)),
)


class MjPlantStateC(ctypes.Structure):
    _fields_ = [(name, _arr(_D, *shape) if shape else _D) for name, shape in MJ_STATE_FIELDS]


class ProfileC(ctypes.Structure):
    """``utrf_profile_t``: cycle counts of a profiled interrupt or function."""

    _fields_ = [(name, ctypes.c_uint64) for name in PROFILE_FIELDS]


class MotorRegsC(ctypes.Structure):
    """``utrf_sim_motor_regs_t``: one motor's driver pins as registers."""

    _fields_ = [(name, ctypes.c_uint32) for name in MOTOR_REG_FIELDS]


class FingerRegsC(ctypes.Structure):
    """``utrf_sim_finger_regs_t``: a finger's two motors and STBY."""

    _fields_ = [
        ("motor", MotorRegsC * 2),
        ("stby", ctypes.c_uint32),
        ("stby_out", ctypes.c_uint32),
    ]


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
    u64p = ctypes.POINTER(ctypes.c_uint64)
    _dp = ctypes.POINTER(ctypes.c_double)
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
            [p, ctypes.c_int, ctypes.POINTER(LineFaultsC)],
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
        "utrf_sim_stats": (None, [p, ctypes.POINTER(StatsC)]),
        "utrf_sim_rx_timing": (None, [p, ctypes.POINTER(RxTimingC), ctypes.c_int]),
        "utrf_sim_profile_vector": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_profile_function": (ctypes.c_int, [p, ctypes.c_int64]),
        "utrf_sim_profile_function_slot": (ctypes.c_int, [p, ctypes.c_int, ctypes.c_int64]),
        "utrf_sim_profile_get": (None, [p, ctypes.c_int, ctypes.POINTER(ProfileC)]),
        "utrf_sim_profile_vector_requires": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_profile_clear": (None, [p]),
        "utrf_sim_pc_histogram": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_pc_histogram_get": (ctypes.c_size_t, [p, u64p, ctypes.c_size_t]),
        "utrf_sim_uart_frames": (ctypes.c_size_t, [p, u64p, u64p, ctypes.c_size_t]),
        "utrf_sim_pin_registers": (None, [p, ctypes.POINTER(FingerRegsC)]),
        "utrf_sim_log": (ctypes.c_size_t, [p, ctypes.c_char_p, ctypes.c_size_t]),
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
        "utrf_sim_run_plant_until": (
            ctypes.c_int,
            [p, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_int],
        ),
        "utrf_sim_plant_cycle": (ctypes.c_uint64, [p]),
        "utrf_sim_set_plant_threads": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_plant_threads": (ctypes.c_int, [p]),
        "utrf_sim_set_plant_spin": (ctypes.c_int, [p, ctypes.c_int]),
        "utrf_sim_plant_inline_periods": (ctypes.c_uint64, [p]),
        "utrf_sim_plant_wait_ns": (ctypes.c_uint64, [p]),
        "utrf_sim_ahead_start": (
            ctypes.c_int,
            [p, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_int],
        ),
        "utrf_sim_ahead_join": (ctypes.c_int, [p]),
        "utrf_sim_ahead_running": (ctypes.c_int, [p]),
        "utrf_sim_ahead_marks": (ctypes.c_size_t, [p, u64p, u64p, ctypes.c_size_t]),
        "utrf_sim_ahead_send": (ctypes.c_int, [p, u8p, ctypes.c_size_t, ctypes.c_double]),
        "utrf_sim_ahead_sent": (ctypes.c_uint64, [p, ctypes.POINTER(ctypes.c_size_t)]),
        "utrf_sim_ahead_stops": (
            ctypes.c_int,
            [p, u64p, ctypes.c_size_t, ctypes.c_double, ctypes.POINTER(SimHitC), ctypes.c_size_t],
        ),
        "utrf_sim_ahead_stops_done": (
            ctypes.c_size_t,
            [p, u64p, _dp, ctypes.POINTER(ctypes.c_int32), ctypes.c_size_t],
        ),
        "utrf_sim_ahead_beats": (
            ctypes.c_int,
            [p, u8p, u8p, u8p, ctypes.c_size_t, ctypes.c_double, ctypes.c_double, u8p, u8p],
        ),
        "utrf_sim_ahead_beats_done": (ctypes.c_size_t, [p, u64p, _dp, ctypes.c_size_t]),
        "utrf_sim_ahead_beats_next": (ctypes.c_int, [p, _dp, u8p]),
        "utrf_mjplant_truth_sites": (
            ctypes.c_int,
            [p, ctypes.POINTER(ctypes.c_int32), ctypes.c_int],
        ),
    }
    for name, (restype, argtypes) in sigs.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    _lib = lib
    return lib
