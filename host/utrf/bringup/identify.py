"""The finger's plant from DUTY-mode steps read at the 1 kHz stream, the gains tuned from it,
and the closed loop checked before and after.

The plant from the duty u (the controller's output: pretension on both motors, u added to one)
to the Joint-2 angle, as the firmware's feedforward already assumes it (set_motion: kv, ka):

    τ θ'' + θ' = K (u − u_f sign θ')

K the speed gain (rad/s per unit duty), τ the mechanical time constant, u_f the duty friction
takes (a deadband). Fitted by least squares on the angle of each step (scipy), K and u_f across
two step sizes. Backlash: the extra time a reversal toward flexion takes to move the joint,
against a reversal toward extension, times the speed.

Tuning (model-based, stated; τ the model motors' scaled by the measured K, see :func:`tune`):
a PD whose zero cancels the plant's pole (kd = kp τ) leaves the
loop kp K / s, crossover ωc = kp K; ωc is chosen so the loop's delays (the 1 ms tick, the
derivative filter, the stream's hold: T ≈ 1.5 ms + 1 / (2π d_cutoff)) cost at most 30° of the
90° phase margin (ωc ≤ (π/6) / T), and at most ``MAX_CROSSOVER`` rad/s for the encoder's noise;
the integral's zero a decade below ωc (ki = kp ωc / 10, about 6° more). Feedforward kv = 1 / K,
ka = τ / K; deadband = u_f; max_speed so a move's peak needs at most 70 % of the duty left
above the pretension and friction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from utrf.bringup.pulses import Bounds, Recorder, Trace, brake, pulse, settle
from utrf.hand import Hand
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError

STEP_DUTIES = (0.15, 0.3, 0.4)  # the third only when one of the first does not move it
STEP_S = 0.3
#: the step duty whose reversals are timed for slack (``plant_check``)
REVERSAL_DUTY = 0.3
#: a check waits this long (s) for the finger to settle after each move (a slow finger on the
#: saved gains does not: 2 s was most of its check's 11.9 s)
SETTLE_WAIT_S = 0.5
MOVING_RAD_S = 0.05
MAX_CROSSOVER = 30.0  # rad/s
PHASE_BUDGET = math.pi / 6  # of the 90° margin a PD with a cancelled pole gives


@dataclass
class Plant:
    K: float  # rad/s per unit duty
    tau: float  # s
    u_f: float  # duty
    backlash_rad: float
    steps: int
    #: per step size, the median time a reversal took to move the joint 0.01 rad back
    reversal_s: dict[str, float] = field(default_factory=dict)
    #: the time constant of a step from rest each way ("flex", "extend")
    lag_s: dict[str, float] = field(default_factory=dict)
    #: every fit behind ``lag_s`` and ``reversal_s`` (more are added near a rule's threshold)
    lag_fits: dict[str, list[float]] = field(default_factory=dict)
    reversal_fits: dict[str, list[float]] = field(default_factory=dict)
    #: the smallest step duty that moved it both ways (K and u_f are fitted from it up)
    first_duty: float = math.nan

    def add_fits(self, lags: dict[str, list[float]], reversals: dict[str, list[float]]) -> None:
        """More lag and reversal readings: the medians (and τ, the faster way's lag) anew."""
        for mine, more in ((self.lag_fits, lags), (self.reversal_fits, reversals)):
            for k, v in more.items():
                mine.setdefault(k, []).extend(v)
        self.lag_s = {k: float(np.median(v)) if v else math.nan for k, v in self.lag_fits.items()}
        self.reversal_s = {k: float(np.median(v)) for k, v in self.reversal_fits.items() if v}
        fin = [v for v in self.lag_s.values() if math.isfinite(v)]
        self.tau = min(fin) if fin else math.nan  # the motor's; slack lengthens one way only

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _fit_step(t: np.ndarray, th: np.ndarray, u: float) -> tuple[float, float] | None:
    """(steady speed, τ) of one step from its start at rest-or-moving: θ(t) fitted with a
    first-order speed response."""
    if len(t) < 30:
        return None
    t = t - t[0]
    th = th - th[0]
    v0 = (th[3] - th[0]) / max(t[3], 1e-3)

    def model(p: np.ndarray) -> np.ndarray:
        v, tau = p[0], max(p[1], 1e-4)
        return v * t + (v0 - v) * tau * (1 - np.exp(-t / tau))

    r = least_squares(
        lambda p: model(p) - th, x0=[th[-1] / t[-1], 0.02], bounds=([-50, 1e-3], [50, 0.5])
    )
    return float(r.x[0]), float(r.x[1])


#: the steps from rest that time the motor's lag: their duty and length (s), and how many
#: each way (the lag is 1-3 counts of the reading: one step's fit scatters 3-10 times over,
#: measured in docs/bringup.md; the median of three)
LAG_DUTY = 0.3
LAG_S = 0.25
LAG_REPEATS = 3


def _fit_from_rest(tr: Trace, sign: int) -> tuple[float, float] | None:
    """(steady speed, τ) of a step from rest, timed from the sample whose duties show the
    board applying it: θ − θ0 = v (t − τ (1 − e^(−t/τ))). The speed's lag v τ is the intercept
    of the ramp the reading settles on, resolved by fitting the whole ramp (a few counts)."""
    f = tr.finger
    if len(tr.t) < 50:
        return None
    drive = sign * (tr.duty_a[:, f] - tr.duty_b[:, f])
    on = np.nonzero(drive > 0.5 * LAG_DUTY)[0]
    if not len(on) or len(tr.t) - on[0] < 50:
        return None
    i = max(0, on[0] - 1)
    t = tr.t[i:] - tr.t[i]
    th = sign * (tr.theta2[i:, f] - tr.theta2[i, f])

    def model(p: np.ndarray) -> np.ndarray:
        v, tau = p[0], max(p[1], 1e-4)
        return v * (t - tau * (1 - np.exp(-t / tau)))

    r = least_squares(
        lambda p: model(p) - th, x0=[max(th[-1] / t[-1], 0.1), 0.02], bounds=([0, 1e-3], [50, 0.3])
    )
    return float(r.x[0]), float(r.x[1])


def lag(
    hand: Hand, rec: Recorder, f: int, bounds: Bounds, repeats: int = LAG_REPEATS
) -> tuple[dict[str, list[float]], list[Trace]]:
    """The finger's time constant from steps from rest (held by the pretension), ``repeats``
    each way, in turn: {"flex": [τ, ...], "extend": [...]}, the steps that fitted."""
    fits: dict[str, list[float]] = {"flex": [], "extend": []}
    traces: list[Trace] = []
    for sign in (1, -1) * repeats:
        rest = pulse(hand, rec, f, 0.0, bounds, seconds=0.3)
        tr = pulse(hand, rec, f, sign * LAG_DUTY, bounds, seconds=LAG_S, travel=0.5)
        traces += [rest, tr]
        hand.clear_faults([f])
        got = _fit_from_rest(tr, sign)
        # a time constant at the fit's lower bound is unresolved (the fit failed), not a
        # prompt start (at the upper one it did not come up to speed: late, kept)
        if got is not None and got[0] > MOVING_RAD_S and got[1] > 1.01e-3:
            fits["flex" if sign > 0 else "extend"].append(got[1])
    return fits, traces


def _reversal_s(tr: Trace, sign: int) -> float:
    """The time a step took to move the joint 0.01 rad its way (NaN: it never did)."""
    th = tr.theta2[:, tr.finger]
    if len(th) <= 40:
        return math.nan
    moved = np.nonzero(sign * (th - th[0]) > 0.01)[0]
    return float(tr.t[moved[0]] - tr.t[0]) if len(moved) else math.nan


def _to_mid(hand: Hand, rec: Recorder, f: int, bounds: Bounds, mid: float, within: float) -> bool:
    """Back toward ``mid`` at 0.35 duty if the finger is further than ``within``; True if moved."""
    here = hand.state().fingers[f].theta2
    if abs(here - mid) <= within:
        return False
    pulse(hand, rec, f, math.copysign(0.35, mid - here), bounds, seconds=1.0, until=mid)
    return True


def refine(
    hand: Hand,
    rec: Recorder,
    f: int,
    bounds: Bounds,
    plant: Plant,
    mid: float,
    lags: int = 0,
    reversals: int = 0,
) -> list[Trace]:
    """More readings for a rule near its threshold (``plant_check.near``): ``reversals`` more
    reversals at ``REVERSAL_DUTY`` (a square wave about ``mid``) and ``lags`` more steps from
    rest each way; ``plant``'s medians taken anew over all of them."""
    traces: list[Trace] = []
    got: list[float] = []
    sign, from_rest = 1, True
    _to_mid(hand, rec, f, bounds, mid, 0.2)
    for _ in range(2 * reversals + 2 if reversals else 0):
        if len(got) >= reversals:
            break
        tr = pulse(hand, rec, f, sign * REVERSAL_DUTY, bounds, seconds=STEP_S, travel=0.5)
        traces.append(tr)
        hand.clear_faults([f])
        settle(hand, 0.0)
        if not from_rest:  # the step before ran the other way: a reversal
            got.append(_reversal_s(tr, sign))
        from_rest = tr.stop != "time"
        sign = -sign
        if _to_mid(hand, rec, f, bounds, mid, 0.35):
            from_rest = True
    brake(hand, [f])
    _to_mid(hand, rec, f, bounds, mid, 0.2)
    fits, more = lag(hand, rec, f, bounds, lags) if lags else ({}, [])
    plant.add_fits(fits, {f"{REVERSAL_DUTY:g}": [g for g in got if math.isfinite(g)]})
    return traces + more


def _mean_speed(speeds: dict[tuple[float, int], list[float]], u: float) -> float:
    up, down = speeds[(u, 1)], speeds[(u, -1)]
    if not up or not down or min(np.median(up), np.median(down)) < MOVING_RAD_S:
        return math.nan  # it did not move both ways at this duty
    return 0.5 * (float(np.median(up)) + float(np.median(down)))


def identify(
    hand: Hand,
    rec: Recorder,
    f: int,
    bounds: Bounds,
    mid: float,
    with_lags: Callable[[Plant], bool] = lambda p: True,
) -> tuple[Plant, list[Trace]]:
    """Square-wave duty steps about ``mid`` (rad), two sizes, each way; then, when
    ``with_lags`` says a rule will read them (from the speed gain and friction found), the
    steps from rest (``lag``)."""
    traces: list[Trace] = []
    speeds: dict[tuple[float, int], list[float]] = {
        (u, d): [] for u in STEP_DUTIES for d in (1, -1)
    }
    taus: list[float] = []
    dead: dict[int, list[float]] = {1: [], -1: []}
    rev: dict[float, list[float]] = {u: [] for u in STEP_DUTIES}
    pretension = hand.gains(f).pretension_duty
    good: list[float] = []
    for u in STEP_DUTIES:
        if len(good) == 2 or u + pretension > bounds.duty + 1e-9:
            break
        from_rest = True
        for sign in (1, -1, 1, -1):
            room = 0.5
            tr = pulse(
                hand, rec, f, sign * u, bounds, seconds=STEP_S, travel=room, stop_on_stall=True
            )
            traces.append(tr)
            hand.clear_faults([f])  # a step too small to move it may have stalled it
            th = tr.theta2[:, f]
            if len(th) > 40:
                # the reversal: time until it has moved 0.01 rad back from where it started
                moved = np.nonzero(sign * (th - th[0]) > 0.01)[0]
                if len(moved):
                    dead[sign].append(float(tr.t[moved[0]] - tr.t[0]))
                    if not from_rest:  # a reversal: the step before ran the other way
                        rev[u].append(dead[sign][-1])
                    got = _fit_step(tr.t[moved[0] :], th[moved[0] :], u)
                    if got is not None:
                        speeds[(u, sign)].append(abs(got[0]))
                        taus.append(got[1])
            settle(hand, 0.0)
            from_rest = tr.stop != "time"
            # toward the middle again if the steps walked away from it
            here = hand.state().fingers[f].theta2
            if abs(here - mid) > 0.35:
                from_rest = True
                pulse(
                    hand,
                    rec,
                    f,
                    math.copysign(0.35, mid - here),
                    bounds,
                    seconds=1.0,
                    travel=1.0,
                    until=mid,
                )
        if math.isfinite(_mean_speed(speeds, u)):
            good.append(u)
    brake(hand, [f])
    # each duty's speed: its flexing and extending steps averaged (gravity helps one and
    # hinders the other); a line K (u - u_f) through the two duties
    good = [u for u in STEP_DUTIES if math.isfinite(_mean_speed(speeds, u))][:2]
    K, u_f, v2 = math.nan, math.nan, 0.0
    if len(good) == 2:
        v1, v2 = (_mean_speed(speeds, u) for u in good)
        K = (v2 - v1) / (good[1] - good[0])
        u_f = max(0.0, good[0] - v1 / K) if K > 0 else math.nan
    flex, ext = dead[1][1:], dead[-1]  # the first flexion step starts from rest
    extra = (np.median(flex) - np.median(ext)) if flex and ext else 0.0
    backlash = max(0.0, float(extra)) * v2
    plant = Plant(float(K), math.nan, float(u_f), backlash, sum(map(len, speeds.values())))
    plant.first_duty = good[0] if good else math.nan
    lags: dict[str, list[float]] = {}
    if with_lags(plant):
        _to_mid(hand, rec, f, bounds, mid, 0.2)
        lags, more = lag(hand, rec, f, bounds)
        traces += more
    plant.add_fits(lags, {f"{u:g}": v for u, v in rev.items()})
    return plant, traces


@dataclass
class Tuned:
    gains: dict[str, float]
    motion: dict[str, float]
    crossover_rad_s: float
    phase_margin_deg: float
    tau_s: float  # the time constant the gains were tuned for
    method: str = "PD zero on the plant's pole, crossover within the delay budget, PI zero ωc/10"


def tune(
    plant: Plant,
    model: Plant,
    d_cutoff_hz: float,
    pretension: float,
    max_duty: float,
    measured_tau: bool = False,
) -> Tuned:
    """Gains for ``plant``. Its time constant is taken from the ``model`` motors' scaled by the
    speed gain measured (τ = m v_no_load / F_stall: a slower motor's is shorter in proportion),
    or, with ``measured_tau`` (a weak motor found: its force is not the model's), the one the
    steps from rest measured (``lag``: resolved by fitting the whole ramp, where a single
    reading's lag v τ is under one count)."""
    tau = plant.tau if measured_tau else model.tau * plant.K / model.K
    delay = 1.5e-3 + 1.0 / (2 * math.pi * d_cutoff_hz)
    wc = min(MAX_CROSSOVER, PHASE_BUDGET / delay)
    kp = wc / plant.K
    kd = kp * tau
    ki = kp * wc / 10.0
    pm = 90.0 - math.degrees(wc * delay) - math.degrees(math.atan(1 / 10.0))
    room = max(0.1, max_duty - pretension - plant.u_f)
    gains = {
        "kp": round(kp, 3),
        "ki": round(ki, 3),
        "kd": round(kd, 4),
        "deadband_duty": round(min(0.5, plant.u_f), 3),
    }
    motion = {
        "kv": round(min(10.0, 1.0 / plant.K), 4),
        "ka": round(min(1.0, tau / plant.K), 5),
        "max_speed": round(max(0.2, min(3.0, 0.7 * room * plant.K)), 3),
    }
    return Tuned(gains, motion, wc, pm, tau)


@dataclass
class Check:
    """A closed-loop check: a move out and back, then a hold."""

    label: str
    rms_rad: float
    worst_rad: float
    overshoot_rad: float
    settle_s: float
    t: list[float] = field(default_factory=list)
    theta2: list[float] = field(default_factory=list)
    target: list[float] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def check(
    hand: Hand, rec: Recorder, f: int, a: float, b: float, label: str, brake_after: bool = True
) -> Check:
    """POSITION: hold ``a``, move to ``b`` in 0.8 s, settle, back to ``a``; the tracking error
    against the board's own setpoint, the overshoot past ``b`` and the time to settle there.
    Then the motors off, or (``brake_after`` False, a check to follow) both at the
    pretension, open loop: the tendons stay taut and the next move needs no take-up."""
    name = hand.fingers[f]
    mark = rec.mark()
    settle_s = math.nan
    start = math.nan
    try:
        if abs(hand.state().fingers[f].theta2 - a) > 0.02:  # not already there (a check before)
            hand.move({name: a}, duration=0.8, wait=False)
            hand.clock.sleep(0.8)
            hand.wait_settled(timeout=SETTLE_WAIT_S, fingers=[f])
        start = hand.state().board_time
        hand.move({name: b}, duration=0.8, wait=False)
        hand.clock.sleep(0.8)
        end = hand.state().board_time
        try:
            hand.wait_settled(timeout=SETTLE_WAIT_S, fingers=[f])
            settle_s = max(0.0, hand.state().board_time - end)
        except NotSettledError:
            settle_s = math.inf
        hand.clock.sleep(0.2)
        hand.move({name: a}, duration=0.8, wait=False)
        hand.clock.sleep(0.8)
        hand.wait_settled(timeout=SETTLE_WAIT_S, fingers=[f])
    except (FingerFaultError, NotSettledError, NotControlledError):
        pass
    finally:
        if brake_after or hand.state().fingers[f].faults:
            brake(hand, [f])
        else:
            hand.set_mode("duty", [f], duty=0.0)
    got = [s for s in rec.since(mark) if s.fingers[f].closed_loop]
    t = np.array([s.board_time for s in got])
    th = np.array([s.fingers[f].theta2 for s in got])
    tg = np.array([s.fingers[f].target for s in got])
    if len(t) == 0:
        return Check(label, math.inf, math.inf, math.inf, math.inf)
    e = th - tg
    after = (t >= start + 0.8) & (t <= start + 1.3) if len(t) else np.zeros(0, bool)
    over = float(np.max(np.sign(b - a) * (th[after] - b))) if after.any() else 0.0
    return Check(
        label,
        float(np.sqrt(np.mean(e * e))),
        float(np.max(np.abs(e))),
        max(0.0, over),
        settle_s,
        t.tolist(),
        th.tolist(),
        tg.tolist(),
    )
