"""The finger's identified plant against the model's motors: what it says about the build
(a slow or weak motor, slack, friction), each named in plain words with its likely cause."""

from __future__ import annotations

import math

from utrf.bringup.diagnose import STOP_DUTY
from utrf.bringup.findings import Finding
from utrf.bringup.identify import LAG_DUTY, REVERSAL_DUTY, STEP_DUTIES, Plant
from utrf.hand import Hand

#: more friction (duty) than the model's makes a finding
FRICTION_DUTY = 0.03
SLOW = 0.5  # of the model motors' speed gain
#: slack is a travel: the motor runs this far (Joint-2 rad, its own lag taken off) before
#: Joint 2 leaves the open stop (``slack_rad``); fault-free fingers read up to 0.057 (one
#: reading of one leg), the twin's slack that reached the plant at most 0.047: above both
#: (docs/bringup.md)
SLACK_RAD = 0.07
#: a weak motor is late both ways: the two steps' lag over the model motors' (at the speed
#: measured), their geometric mean above this (margins in docs/bringup.md)
WEAK_LAG = 3.5
#: ... and each way at least this (a weak motor is late both ways; heavy friction late one way:
#: campaign seed 47's middle finger, friction 10 N, 8.8 and 2.1 times the model's lag)
WEAK_BOTH = 2.3
#: a finger whose reversals at ``REVERSAL_DUTY`` take this long (s) beyond its lag to move it
#: back (0.01 rad) waits for a slack strand: campaign seed 47's slack thumb 0.065-0.108 over
#: five runs; weak motors at most 0.052 over fifteen (seeds 15, 23, 29, 30, 43; up to 0.066
#: with one step's lag), fault-free fingers at most 0.050 over 118; but seed 29's weak thumb
#: 0.072 once (docs/bringup.md: the margin does not hold)
REVERSAL_SLACK_S = 0.058
#: slack seen from the steps from rest: one way this many times the model motors' lag while the
#: other way's is under ``PROMPT_LAG`` (Joint 2 loose: it starts at once one way and waits for
#: the strand the other); margins in docs/bringup.md
ONE_WAY_LAG = 6.0
PROMPT_LAG = 0.5
#: ... or, when the reading's speed was uneven over the travel too, the late way this many
#: times the other's: Joint 2 leaning on one strand (under gravity) follows that way with the
#: strand's lag and waits for the other strand the other way, and switches strands as the load
#: turns over the travel (``slack:1=0.0015``: 6.9 times apart, the speed 1.44 times uneven).
#: A weak motor can be late one way too (seed 43's ring: 1.1 and 11.9, from one step each way)
#: but runs evenly (1.03). Evenly, the late way this many times the other's (the medians of
#: three steps each way; seed 47's slack thumb: 33 and 2.6, weak thumbs within 3 of even)
ONE_WAY_SPREAD = 4.0
ONE_WAY_EVEN = 6.0


def lag_ratios(p: Plant, ref: Plant) -> dict[str, float]:
    """Each way's time constant over the one the model's motors would have at the speed gain
    measured (τ ∝ m v_no_load / F_stall, K ∝ v_no_load: τ / K measures the force alone)."""
    expected = ref.tau * p.K / ref.K
    return {k: v / expected for k, v in p.lag_s.items()} if expected > 0 else {}


#: a friction duty this much over the model's is friction, not slack, whatever the lags say
#: (slack fingers read at most 0.037 over it, heavy friction at least 0.093: docs/bringup.md)
FRICTION_NOT_SLACK = 0.065
#: a friction duty over this fraction of the lag steps' duty leaves too little of it to time
#: the motor's force by: no weak-motor then (weak motors read u_f at most 0.111, heavy
#: friction up to 0.26: docs/bringup.md)
CRAWL = 0.5
#: a reading within this factor of a lag rule's threshold (or this far, s, under the
#: reversal's) is read again (``near``) and the rule decided on the median of all readings
NEAR_FACTOR = 1.6
NEAR_REVERSAL_S = 0.02
#: how many more steps from rest each way, and reversals, a reading near a threshold takes
MORE_LAGS = 4
MORE_REVERSALS = 6


def frictional(p: Plant, ref: Plant) -> bool:
    """It takes the duty to move that heavy friction takes and slack does not (a slack
    finger's lags, reversals and pauses are also heavy friction's breakaway)."""
    return p.u_f > ref.u_f + FRICTION_NOT_SLACK


def resolved(p: Plant, ref: Plant) -> bool:
    """Not a slow motor: its lag is resolved (a slow motor's is far under one count, v τ)."""
    return p.K >= SLOW * ref.K


def crawling(p: Plant) -> bool:
    """The lag steps' duty less this much friction is too little to time a motor's force by
    (campaign seed 10's 10 N thumb: u_f 0.26, its lags at 0.3 duty at the fit's bound)."""
    return p.u_f > CRAWL * LAG_DUTY


def lags_read(p: Plant, ref: Plant) -> bool:
    """Whether a rule reads the steps from rest (``lag``): not on a slow motor (its lag is
    unresolved) nor a crawl (not timed); those fingers skip the steps (board time)."""
    return resolved(p, ref) and not crawling(p)


def stiff(p: Plant) -> bool:
    """The smallest plant step did not move it both ways: friction (or a weak motor's lack of
    force) holds it there; a slow motor with the model's force moves at it, only slowly
    (75 of 75 slow-motor readings moved at 0.15; heavy friction 63 of 64 did not:
    docs/bringup.md)."""
    return p.first_duty > STEP_DUTIES[0]


def near(p: Plant, ref: Plant) -> tuple[int, int]:
    """(more steps from rest each way, more reversals) to read: where a rule's reading is
    within ``NEAR_FACTOR`` of its threshold, so that one noisy reading does not decide it."""
    if not lags_read(p, ref):
        return 0, 0  # a slow motor's lag is unresolved, a crawl's not timed: no rule uses them
    r = lag_ratios(p, ref)
    flex, ext = r.get("flex", math.nan), r.get("extend", math.nan)
    slow_way, fast_way = max(flex, ext), min(flex, ext)
    late = math.sqrt(flex * ext)
    weakish = not math.isfinite(late) or (
        late > WEAK_LAG / NEAR_FACTOR
        and (late < WEAK_LAG * NEAR_FACTOR or fast_way < WEAK_BOTH * NEAR_FACTOR)
    )
    one_way = slow_way > ONE_WAY_LAG / NEAR_FACTOR and (
        fast_way < PROMPT_LAG * NEAR_FACTOR
        or slow_way > min(ONE_WAY_SPREAD, ONE_WAY_EVEN) / NEAR_FACTOR * fast_way
    )
    reversal = p.reversal_s.get(f"{REVERSAL_DUTY:g}", math.nan) - p.tau
    slack = not frictional(p, ref)  # else neither slack rule is judged
    return (
        MORE_LAGS if weakish or (slack and one_way) else 0,
        MORE_REVERSALS if slack and reversal > REVERSAL_SLACK_S - NEAR_REVERSAL_S else 0,
    )


def plant_findings(
    name: str, p: Plant, ref: Plant, slack: float = math.nan, uneven: bool = False
) -> list[Finding]:
    """The plant against the model's motors' (``ref``, ``model_plant``); ``uneven``: the
    reading's speed at one duty varied over the travel (``reading_curve``)."""
    out = []
    r = lag_ratios(p, ref)
    flex, ext = r.get("flex", math.nan), r.get("extend", math.nan)
    # a slow motor's lag is far under one count (v τ): neither is judged from it
    lag_resolved = resolved(p, ref)
    slow_way, fast_way = max(flex, ext), min(flex, ext)
    # breakaway friction delays a start too (late one way under gravity): not slack then
    one_way = (
        not frictional(p, ref)
        and slow_way > ONE_WAY_LAG
        and (
            fast_way < PROMPT_LAG
            or slow_way > (ONE_WAY_SPREAD if uneven else ONE_WAY_EVEN) * fast_way
        )
    )
    loose = lag_resolved and (slack > SLACK_RAD or one_way)
    late = math.sqrt(flex * ext)
    # a weaker motor takes more duty for the same friction as it comes up to speed later (both
    # ∝ 1 / F_stall): a friction duty beyond what its lag explains is friction, not weakness
    explained = ref.u_f * late + FRICTION_DUTY
    weak = (
        lags_read(p, ref)
        and not loose
        and late > WEAK_LAG
        and fast_way > WEAK_BOTH
        and not p.u_f > explained
    )
    # late on a reversal beyond its own lag: Joint 2 waits for its strand
    reversal = p.reversal_s.get(f"{REVERSAL_DUTY:g}", math.nan) - p.tau
    if lag_resolved and reversal > REVERSAL_SLACK_S and not frictional(p, ref):
        weak, loose = False, True
    if loose:
        out.append(
            Finding(
                name,
                "slack",
                (
                    f"from the open stop the motor runs {slack:.3f} rad of Joint 2's travel "
                    "beyond its own lag before Joint 2 moves"
                    if slack > SLACK_RAD
                    else f"from rest Joint 2 follows the motor at once one way and "
                    f"{slow_way:.0f} times the model's lag late the other"
                    if one_way
                    else f"on a reversal Joint 2 follows the motor {reversal:.3f} s later than "
                    "the motor's own lag"
                )
                + ": slack in the coupling tendon (Tendon 2, Joint 1 to Joint 2) lets Joint 2 "
                "hang free between its strands",
                "tighten Tendon 2 and run the bring-up again (Joint 2 is loose between its "
                "strands: no gain holds it)",
                False,
                {"lag_ratio": r, "slack_rad": slack, "reversal_s": reversal},
            )
        )
    if weak:
        out.append(
            Finding(
                name,
                "weak-motor",
                f"from rest the finger takes {late:.1f} times the time to come "
                "up to speed (both ways) that the model's motors take at its speed: its motors "
                "give less force (a weaker motor or gearing, a current-limited supply or driver)",
                "gains tuned for the lag measured (the derivative's zero on it); if it must "
                "lift more than the model's, fit the model's motors",
                True,
                {"lag_ratio": r, "tau_s": p.tau},
            )
        )
    # a low K fitted from duties that friction barely lets move is friction's: its speed at the
    # lower one stick-slips (campaign seed 5's 10 N little finger read K 0.39 of the model's
    # from 0.3 and 0.4 once, 0.75-0.78 in six other runs)
    if p.K < SLOW * ref.K and not stiff(p):  # not when K is NaN (no fit)
        out.append(
            Finding(
                name,
                "slow-motor",
                f"the finger moves at {p.K:.2f} rad/s per unit duty, the model's motors at "
                f"{ref.K:.2f}: a slower motor (another gear ratio or winding), or a low supply",
                "gains, feedforward and max_speed tuned for it",
                True,
                {"K": p.K, "K_model": ref.K},
            )
        )
    # Joint 2 loose misleads the steps; a weak motor's friction duty is larger by its weakness
    if p.u_f > ref.u_f + FRICTION_DUTY and not loose and not weak:
        out.append(
            Finding(
                name,
                "friction",
                f"it takes {p.u_f:.2f} duty to move (the model: {ref.u_f:.2f}), at the model's "
                "lag: friction in a guide, a tight tendon or a carriage",
                "deadband_duty set to it; free the tendon or the guide if it is much more",
                True,
                {"u_f": p.u_f, "u_f_model": ref.u_f},
            )
        )
    return out


def swing_finding(name: str, backward_rad: float) -> Finding:
    """Slack seen as the reading going back against a steady drive (the stop search's closing
    leg, or the opening leg after it): Joint 2 swings between its strands."""
    return Finding(
        name,
        "slack",
        f"driven at one duty across its travel, the finger's reading went back "
        f"{math.degrees(backward_rad):.1f}° against the drive: Joint 2 swings loose between "
        "its strands: slack in the coupling tendon (Tendon 2, Joint 1 to Joint 2)",
        "tighten Tendon 2 and run the bring-up again (Joint 2 is loose between its strands: no "
        "gain holds it)",
        False,
        {"backward_rad": backward_rad},
    )


def pause_finding(name: str, at_rad: float) -> Finding:
    """Slack seen as a pause mid-travel: the closing search stalled, and driven again at the
    same duty the finger went on (a jam does not): Joint 2 waited while the motor took up
    the strand's slack."""
    return Finding(
        name,
        "slack",
        f"closing at one duty, the finger stopped {math.degrees(at_rad):.0f}° from its open stop "
        "and, driven again at the same duty, went on: Joint 2 waited while the motor took up "
        "slack in the coupling tendon (Tendon 2, Joint 1 to Joint 2)",
        "tighten Tendon 2 and run the bring-up again (Joint 2 is loose between its strands: no "
        "gain holds it)",
        False,
        {"paused_rad": at_rad},
    )


def dwell_finding(name: str, dwell_rad: float) -> Finding:
    """Slack seen as the reading standing still mid-travel while driven at one duty (for the
    travel the motor made meanwhile): Joint 2 waited on its strand."""
    return Finding(
        name,
        "slack",
        "driven at one duty across its travel, the finger's reading stood still for "
        f"{math.degrees(dwell_rad):.1f}° of the motor's travel and went on: Joint 2 waited "
        "while the motor took up slack in the coupling tendon (Tendon 2, Joint 1 to Joint 2)",
        "tighten Tendon 2 and run the bring-up again (Joint 2 is loose between its strands: no "
        "gain holds it)",
        False,
        {"dwell_rad": dwell_rad},
    )


def uneven_finding(name: str, curve: dict[str, float]) -> Finding:
    """The reading's speed at one duty uneven over the travel, Joint 2 not loose: the
    magnet is off-centre (``reading_curve``)."""
    how = f"ran {curve['spread']:.2f} times faster in places than in others"
    return Finding(
        name,
        "not-monotonic",
        f"driven at one duty across its travel, the finger's reading {how} where the model's "
        "turns at a steady speed, and Joint 2 is not loose: the encoder's magnet is off-centre "
        "on the shaft or loose (the reading is not the joint's angle, so the stops and the zero "
        "from it are not trusted)",
        "centre the magnet on Joint 2's shaft and glue it; then run the bring-up again",
        False,
        dict(curve),
    )


def slack_rad(p: Plant, model: Plant, take_up: float, duty: float = STOP_DUTY) -> float:
    """The slack as Joint-2 travel: how far the motor ran (at the stop search's duty, at the
    identified speed) before Joint 2 moved from the open stop, less what the motor's own lag
    (measured: a weak or spread motor's is not the model's) and the 0.01 rad of the take-up's
    threshold account for."""
    v = p.K * max(0.0, duty - p.u_f)
    tau = p.tau if math.isfinite(p.tau) else model.tau * p.K / model.K
    return max(0.0, v * (take_up - tau) - 0.01) if math.isfinite(take_up) else math.nan


def model_plant(hand: Hand, f: int) -> Plant:
    """The plant the hand's model motors make (``MotorParams`` defaults, the finger's guide
    radius): two motors resisting (one pulls, the antagonist is back-driven at its pretension),
    so K = v_no_load / (2 R2), τ = m v_no_load / F_stall, u_f = 2 F_coulomb / F_stall."""
    from utrf.emulator.plant_params import MotorParams  # constants only: no MuJoCo

    mot = MotorParams()
    r2 = hand.geometry.fingers[f].geometry.guide_radii_m[1]
    return Plant(
        K=mot.no_load_speed_m_s / (2 * r2),
        tau=mot.moving_mass_kg * mot.no_load_speed_m_s / mot.stall_force_n,
        u_f=2 * mot.coulomb_friction_n / mot.stall_force_n,
        backlash_rad=0.0,
        steps=0,
    )
