"""From the controller's output to the driver pins: the antagonistic rule, rotary fingers,
motor inversion, duty limits and PWM counts."""

from __future__ import annotations

import pytest
from fwsim import COAST, FORWARD, REVERSE, Sim, m, motor_duty

DUTY = 3


def gains(sim: Sim, finger: int = 0, max_duty: float = 0.8, pretension: float = 0.1) -> None:
    sim.ok(
        m.SetGains(
            finger=finger,
            kp=3.0,
            ki=2.0,
            kd=0.05,
            d_cutoff_hz=30.0,
            deadband_duty=0.0,
            slew_per_s=1000.0,
            max_duty=max_duty,
            pretension_duty=pretension,
        )
    )


def hw(sim: Sim, finger: int = 0, actuation=m.Actuation.ANTAGONISTIC, motor_invert: int = 0):
    sim.ok(
        m.SetFingerConfig(
            finger=finger,
            actuation=actuation,
            encoder_offset=3.14159265,
            encoder_invert=0,
            motor_invert=motor_invert,
        )
    )


def duty(sim: Sim, d: float, finger: int = 0, ms: int = 3) -> tuple[float, float]:
    modes, duties = [0] * 5, [0.0] * 5
    modes[finger], duties[finger] = DUTY, d
    sim.ok(m.SetMode(mask=1 << finger, mode=tuple(modes), duty=tuple(duties), effort=(0,) * 5))
    sim.run(ms)
    mo = sim.motor(finger)
    return motor_duty(mo.drive_a, mo.counts_a), motor_duty(mo.drive_b, mo.counts_b)


@pytest.mark.parametrize("u", [0.0, 0.05, 0.3, -0.3, 0.7, -0.7])
def test_antagonistic_rule_keeps_the_slack_side_taut(sim: Sim, u: float) -> None:
    gains(sim, pretension=0.1)
    a, b = duty(sim, u)
    # Flexor p + max(u, 0), extensor p + max(-u, 0): both pull, the net is u.
    assert a == pytest.approx(0.1 + max(u, 0.0), abs=1 / 800)
    assert b == pytest.approx(0.1 + max(-u, 0.0), abs=1 / 800)
    assert a - b == pytest.approx(u, abs=2 / 800)
    assert sim.motor(0).stby


def test_antagonistic_duty_stays_within_max_duty(sim: Sim) -> None:
    gains(sim, max_duty=0.6, pretension=0.15)
    a, b = duty(sim, 1.0)
    assert a == pytest.approx(0.6, abs=1 / 800)  # net limited to max - pretension
    assert b == pytest.approx(0.15, abs=1 / 800)
    a, b = duty(sim, -1.0)
    assert (a, b) == (pytest.approx(0.15, abs=1 / 800), pytest.approx(0.6, abs=1 / 800))


@pytest.mark.parametrize("u", [0.4, -0.4])
def test_rotary_finger_has_one_signed_motor(sim: Sim, u: float) -> None:
    hw(sim, actuation=m.Actuation.ROTARY)
    gains(sim, pretension=0.1)  # pretension means nothing to a rotary finger
    a, _b = duty(sim, u)
    assert a == pytest.approx(u, abs=1 / 800)
    mo = sim.motor(0)
    assert mo.drive_a == (FORWARD if u > 0 else REVERSE)
    assert (mo.drive_b, mo.counts_b) == (COAST, 0)
    assert sim.ok(m.Identify()).actuation[0] == m.Actuation.ROTARY


def test_motor_invert_swaps_the_directions(sim: Sim) -> None:
    hw(sim, actuation=m.Actuation.ROTARY, motor_invert=1)
    gains(sim)
    duty(sim, 0.4)
    assert sim.motor(0).drive_a == REVERSE
    duty(sim, -0.4)
    assert sim.motor(0).drive_a == FORWARD


@pytest.mark.parametrize("d", [0.001, 0.125, 0.333, 0.7])
def test_pwm_counts_are_the_rounded_duty(sim: Sim, d: float) -> None:
    hw(sim, actuation=m.Actuation.ROTARY)
    gains(sim)
    duty(sim, d)
    mo = sim.motor(0)
    expected = round(d * 800)
    if expected == 0:
        assert (mo.drive_a, mo.counts_a) == (COAST, 0)
    else:
        assert abs(mo.counts_a - expected) <= 1


def test_state_reports_the_motor_duties(sim: Sim) -> None:
    gains(sim, pretension=0.1)
    duty(sim, 0.3)
    st = sim.ok(m.GetState())
    assert st.duty_a[0] == pytest.approx(0.4, abs=0.011)
    assert st.duty_b[0] == pytest.approx(0.1, abs=0.011)
    assert sim.ok(m.GetStatus()).mode[0] == m.ControlMode.DUTY  # modes: the status message
