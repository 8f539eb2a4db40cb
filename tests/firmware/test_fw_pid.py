"""The firmware's PID, alone (through the C ABI) and closing the loop on a simulated finger.

Figures (rise time, overshoot, settling) are measured on FingerPlant, the reference plant in
fwsim.py, with the firmware's default gains; firmware/README.md quotes them.
"""

from __future__ import annotations

import ctypes
import itertools
import math

import pytest
from fwsim import (
    BU,
    Q15,
    ClosedLoop,
    FingerPlant,
    Sim,
    m,
    pid_config,
    step_figures,
    step_response,
)
from hypothesis import given, settings
from hypothesis import strategies as st

LIMIT = round(0.7 * Q15)  # default max_duty 0.8 less the pretension 0.1


def pid_state(lib: ctypes.CDLL) -> tuple[int, int, bool]:
    i31, v8, sat = ctypes.c_int32(), ctypes.c_int32(), ctypes.c_int32()
    lib.fw_pid_state(ctypes.byref(i31), ctypes.byref(v8), ctypes.byref(sat))
    return i31.value, v8.value, bool(sat.value)


def bu(rad: float) -> int:
    return round(rad / BU)


@pytest.mark.parametrize("step", [0.5, -0.4, 1.2])
def test_step_response_figures(sim: Sim, step: float) -> None:
    """Default gains on the reference plant: a clean, well-damped step in closed loop."""
    fig = step_figures(
        [(t, x * math.copysign(1, step), u) for t, x, u in step_response(sim, step)], abs(step)
    )
    # The motor saturates at 0.7 duty (4 rad/s on this plant): the rise is speed-limited.
    assert fig["rise_s"] < 0.12 + abs(step) / (0.67 * 6.0)
    assert fig["overshoot"] < 0.05
    assert fig["settle_s"] < 0.6
    # Within two encoder counts (AS5600 analog: 2 pi / 819 rad a count) at rest.
    assert abs(fig["final_error_rad"]) < 2 * (2 * math.pi / 819)
    assert sim.finger(0).faults == 0


def test_derivative_on_measurement_gives_no_kick(fwlib: ctypes.CDLL) -> None:
    """A target step moves only P (and later I); D sees the measurement, which did not move."""
    pid_config(
        fwlib, LIMIT, kp=0.0, ki=0.0, kd=0.5, d_cutoff_hz=30.0, deadband_duty=0.0, slew_per_s=1000.0
    )
    fwlib.fw_pid_reset(0, 0)
    assert fwlib.fw_pid_step(bu(1.0), 0) == 0
    # A measurement step does move D, against the motion, then the filter lets it decay.
    first = fwlib.fw_pid_step(bu(1.0), bu(0.01))
    assert first < 0
    later = [fwlib.fw_pid_step(bu(1.0), bu(0.01)) for _ in range(200)]
    assert abs(later[-1]) < abs(first) / 50


@pytest.mark.parametrize("cutoff_hz", [5.0, 50.0])
def test_derivative_filter_follows_its_cutoff(fwlib: ctypes.CDLL, cutoff_hz: float) -> None:
    """A ramp in the measurement: D rises toward kd * speed with the filter's time constant."""
    kd, speed = 0.01, 2.0  # s/rad, rad/s
    pid_config(
        fwlib,
        LIMIT,
        kp=0.0,
        ki=0.0,
        kd=kd,
        d_cutoff_hz=cutoff_hz,
        deadband_duty=0.0,
        slew_per_s=1000.0,
    )
    fwlib.fw_pid_reset(0, 0)
    tau_ticks = 1000.0 / (2 * math.pi * cutoff_hz)
    outs = [
        -fwlib.fw_pid_step(0, bu(speed * (k + 1) * 1e-3)) / Q15 for k in range(int(8 * tau_ticks))
    ]
    final = kd * speed
    k63 = next(k for k, u in enumerate(outs) if u >= 0.632 * final)
    assert abs(outs[-1] - final) < 0.02 * final + 2 / Q15
    assert abs((k63 + 1) - tau_ticks) <= 0.15 * tau_ticks + 1


def test_conditional_integration_holds_when_saturated(fwlib: ctypes.CDLL) -> None:
    """Pushing into the limit does not wind the integrator; the opposite error unwinds it."""
    pid_config(
        fwlib,
        LIMIT,
        kp=2.0,
        ki=20.0,
        kd=0.0,
        d_cutoff_hz=30.0,
        deadband_duty=0.0,
        slew_per_s=1000.0,
    )
    fwlib.fw_pid_reset(0, 0)
    for _ in range(50):  # e = 1 rad: P alone is 2 duty, far beyond the limit
        assert fwlib.fw_pid_step(bu(1.0), 0) == LIMIT
    i_before, _, sat = pid_state(fwlib)
    assert sat
    for _ in range(2000):  # two seconds of a stuck finger
        fwlib.fw_pid_step(bu(1.0), 0)
    i_after, _, _ = pid_state(fwlib)
    assert i_after == i_before
    # The target comes back to the finger: the output leaves the limit at once.
    u = fwlib.fw_pid_step(0, 0)
    assert u < LIMIT


def test_anti_windup_recovery_beats_a_wound_integrator(sim: Sim) -> None:
    """A finger held by a wall for 2 s, then freed: it overshoots its target by little."""
    sim.ok(m.SetSafety(heartbeat_timeout=10.0, safe_action=m.SafeAction.HOLD))
    sim.ok(
        m.SetLimits(
            finger=0,
            theta2_min=-1.5,
            theta2_max=1.5,
            limit_margin=0.1,
            stall_error=3.0,
            stall_motion=0.02,
            stall_time=10.0,
            encoder_jump=0.2,
        )
    )
    sim.ok(
        m.SetGains(
            finger=0,
            kp=3.0,
            ki=20.0,
            kd=0.05,
            d_cutoff_hz=30.0,
            deadband_duty=0.04,
            slew_per_s=20.0,
            max_duty=0.8,
            pretension_duty=0.1,
        )
    )
    plant = FingerPlant(wall=0.2)
    loop = ClosedLoop(sim, {0: plant})
    sim.ok(m.SetMode(mask=1, mode=(2, 0, 0, 0, 0), duty=(0,) * 5, effort=(0,) * 5))
    sim.ok(m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=1, value=(0.8, 0, 0, 0, 0)))
    loop.run(2000)
    assert sim.finger(0).integrator31 <= sim.finger(0).limit << 16
    plant.wall = None
    trace = loop.run(1500, record=0)
    assert max(x for _, x, _ in trace) < 0.8 * 1.08
    assert abs(trace[-1][1] - 0.8) < 0.02


def test_integrator_removes_a_load_offset(fwlib: ctypes.CDLL) -> None:
    """P alone leaves an error under a constant load; I drives it out."""
    pid_config(
        fwlib,
        LIMIT,
        kp=1.0,
        ki=10.0,
        kd=0.0,
        d_cutoff_hz=30.0,
        deadband_duty=0.0,
        slew_per_s=1000.0,
    )
    fwlib.fw_pid_reset(0, 0)
    theta, load = 0.0, -0.2  # the load needs 0.2 duty to hold
    for _ in range(5000):
        u = fwlib.fw_pid_step(bu(0.3), bu(theta)) / Q15
        theta += (u + load) * 6.0 * 1e-3
    assert abs(theta - 0.3) < 2 * BU


def test_bumpless_start_from_the_present_output(fwlib: ctypes.CDLL) -> None:
    pid_config(
        fwlib, LIMIT, kp=3.0, ki=2.0, kd=0.05, d_cutoff_hz=30.0, deadband_duty=0.04, slew_per_s=20.0
    )
    present = round(0.35 * Q15)
    fwlib.fw_pid_reset(present, bu(0.2))
    # Target = measured: the output stays where it was.
    assert abs(fwlib.fw_pid_step(bu(0.2), bu(0.2)) - present) <= 2
    # A target far away: the output moves off it no faster than the slew limit.
    fwlib.fw_pid_reset(present, bu(0.2))
    slew = round(20.0 * 1e-3 * Q15)
    prev = present
    for _ in range(20):
        u = fwlib.fw_pid_step(bu(1.0), bu(0.2))
        assert abs(u - prev) <= slew
        prev = u


def test_gain_change_is_bumpless(fwlib: ctypes.CDLL) -> None:
    pid_config(
        fwlib,
        LIMIT,
        kp=3.0,
        ki=2.0,
        kd=0.05,
        d_cutoff_hz=30.0,
        deadband_duty=0.0,
        slew_per_s=1000.0,
    )
    fwlib.fw_pid_reset(0, 0)
    for _ in range(30):
        u = fwlib.fw_pid_step(bu(0.1), bu(0.05))
    pid_config(
        fwlib,
        LIMIT,
        regain=True,
        kp=6.0,
        ki=2.0,
        kd=0.05,
        d_cutoff_hz=30.0,
        deadband_duty=0.0,
        slew_per_s=1000.0,
    )
    after = fwlib.fw_pid_step(bu(0.1), bu(0.05))
    assert abs(after - u) <= 0.01 * Q15  # P doubled, yet the output did not jump


def test_slew_limit(fwlib: ctypes.CDLL) -> None:
    pid_config(
        fwlib, LIMIT, kp=100.0, ki=0.0, kd=0.0, d_cutoff_hz=30.0, deadband_duty=0.0, slew_per_s=5.0
    )  # 5 duty/s
    fwlib.fw_pid_reset(0, 0)
    outs = [fwlib.fw_pid_step(bu(1.0), 0) for _ in range(200)]
    steps = [b - a for a, b in zip([0, *outs], outs, strict=False)]
    assert max(steps) == round(5.0 * 1e-3 * Q15)
    assert outs[-1] == LIMIT
    # Open loop goes through the same limiter.
    fwlib.fw_pid_reset(0, 0)
    assert fwlib.fw_pid_step_open(LIMIT, 0) == round(5.0 * 1e-3 * Q15)


def test_deadband_compensation(fwlib: ctypes.CDLL) -> None:
    db = round(0.05 * Q15)
    ramp = 256
    # Outside the ramp the deadband is added in the output's direction ...
    assert fwlib.fw_pid_add_deadband(5000, db) == 5000 + db
    assert fwlib.fw_pid_add_deadband(-5000, db) == -5000 - db
    # on the PID's unlimited sum: beyond a duty, unsaturated (the limit comes after)
    assert fwlib.fw_pid_add_deadband(40000, db) == 40000 + db
    # ... continuous through zero (no chatter between +db and -db) ...
    values = [fwlib.fw_pid_add_deadband(v, db) for v in range(-2 * ramp, 2 * ramp + 1)]
    assert values[2 * ramp] == 0
    assert all(b >= a for a, b in itertools.pairwise(values))
    assert max(b - a for a, b in itertools.pairwise(values)) <= 1 + db // ramp + 1
    # ... and its inverse (for bumpless starts) undoes it.
    for u in (-9000, -db - 100, -50, 0, 40, db + 300, 20000):
        back = fwlib.fw_pid_add_deadband(fwlib.fw_pid_remove_deadband(u, db), db)
        assert abs(back - u) <= 1 + db // ramp


@pytest.mark.parametrize(
    "value", [1e-3, 0.0131, 0.5, 1.0, 3.7, 838.86, 5000.0, 65535.0, 2.0e6, 1.0e9]
)
def test_gain_representation_precision(fwlib: ctypes.CDLL, value: float) -> None:
    """A 16-bit mantissa and byte exponent keep gains to 0.2 % over the protocol's range."""
    back = fwlib.fw_gain_roundtrip(value)
    tol = 0.002 if value >= 0.5 else 0.02  # below 1 the mantissa has fewer bits
    assert abs(back - value) <= tol * value


def test_gain_apply_saturates_without_overflow(fwlib: ctypes.CDLL) -> None:
    ymax = 1 << 26
    for value in (0.37, 512.0, 1.6e6):
        for x in (-32767, -1234, -1, 0, 1, 77, 32767):
            exact = max(-ymax, min(ymax, x * fwlib.fw_gain_roundtrip(value)))
            got = fwlib.fw_gain_apply(value, x, ymax)
            assert abs(got - exact) <= 1 + abs(exact) * 1e-6


def test_mul_q16_matches_exact(fwlib: ctypes.CDLL) -> None:
    for x in (-(2**31) + 1, -123456789, -65536, -1, 0, 1, 65535, 987654321, 2**31 - 1):
        for c in (0, 1, 411, 32768, 65535):
            assert fwlib.fw_mul_q16(x, c) == (x * c) >> 16


# ---- the gains' fast paths beside their general twins (fx::apply_plain(), apply16_hi(),
# apply16_mid(), chosen once by pid::compile()) ----

I_STEP_MAX31 = 1 << 29  # pid::kIStepMax31
TERM_MAX14 = 32767  # pid::kTermMax14
MAX_V8 = 63 * 256  # pid::kMaxV8
GAINS = st.floats(-4.0, 7.0).map(lambda x: 10.0**x)  # every exponent alike: each path's edges


@settings(max_examples=300, deadline=None)
@given(
    value=GAINS,
    xs=st.lists(st.integers(-32767, 32767) | st.integers(-300, 300), min_size=1, max_size=40),
)
def test_gain_fast_paths_equal_their_general_twins(
    fwlib: ctypes.CDLL, value: float, xs: list[int]
) -> None:
    """Where a gain takes a fast path, it gives apply()'s or apply16()'s result on its domain
    (|x| <= 32767 for the integrator's, |x| <= kMaxV8 for the derivative's)."""
    paths_i = fwlib.fw_gain_paths(value, I_STEP_MAX31)
    paths_t = fwlib.fw_gain_paths(value, TERM_MAX14)
    for x in [*xs, -32767, -MAX_V8, MAX_V8, 32767]:
        if paths_i & 1:
            assert fwlib.fw_gain_apply_plain(value, x, I_STEP_MAX31) == fwlib.fw_gain_apply(
                value, x, I_STEP_MAX31
            )
        general = fwlib.fw_gain_apply16(value, x, TERM_MAX14)
        if paths_t & 2 and abs(x) <= MAX_V8:
            assert fwlib.fw_gain_apply16_hi(value, x, TERM_MAX14) == general
        if paths_t & 4:
            assert fwlib.fw_gain_apply16_mid(value, x, TERM_MAX14) == general


def test_gain_fast_paths_cover_the_default_gains(fwlib: ctypes.CDLL) -> None:
    """The spec's default gains take both PID fast paths (what make bench-firmware measures),
    and a gain outside a path's condition does not."""
    pid_config(fwlib, LIMIT)
    assert fwlib.fw_pid_fast_paths() == 3
    pid_config(fwlib, LIMIT, kp=500.0, ki=5000.0)  # kp of shift 0, ki that may saturate
    assert fwlib.fw_pid_fast_paths() == 0
    assert fwlib.fw_gain_paths(1e6, I_STEP_MAX31) & 1 == 0


@settings(max_examples=60, deadline=None)
@given(
    kp=st.floats(0.0, 100.0),
    ki=st.floats(0.0, 50.0),
    kd=st.floats(0.0, 2.0),
    deadband=st.sampled_from([0.0, 0.04, 0.2]),
    u0=st.integers(-LIMIT, LIMIT),
    seq=st.lists(
        st.tuples(st.integers(-16384, 16383), st.integers(-16384, 16383)),
        min_size=1,
        max_size=60,
    ),
)
def test_pid_fast_paths_step_like_the_general_ones(
    fwlib: ctypes.CDLL,
    kp: float,
    ki: float,
    kd: float,
    deadband: float,
    u0: int,
    seq: list[tuple[int, int]],
) -> None:
    """The law with the fast paths compile() chose and with the general twins, on the same
    inputs: the same outputs and state every step (random gains, targets and angles)."""
    runs = []
    for general in (False, True):
        pid_config(fwlib, LIMIT, kp=kp, ki=ki, kd=kd, deadband_duty=deadband, slew_per_s=50.0)
        if general:
            fwlib.fw_pid_general_path()
            assert fwlib.fw_pid_fast_paths() == 0
        fwlib.fw_pid_reset(u0, seq[0][1])
        trace = []
        for target, measured in seq:
            trace.append((fwlib.fw_pid_step(target, measured), pid_state(fwlib)))
        runs.append(trace)
    assert runs[0] == runs[1]
