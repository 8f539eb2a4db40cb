"""One finger's bring-up, in two stretches: its encoder and wiring (``wire_finger``: every
other finger still, the cable check reads every channel), then its stops, plant, tuning and
closed-loop checks (``finish_finger``: its own channel only, so another finger's may run
meanwhile). ``procedure.bringup`` orders the fingers; each step's rules are in
docs/bringup.md."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from utrf.bringup.diagnose import (
    STOP_DUTY,
    Wiring,
    backward_rad,
    encoder_check,
    find_stop,
    reading_curve,
    take_up_s,
    wiring,
)
from utrf.bringup.findings import Finding, FingerConfig
from utrf.bringup.identify import Check, check, identify, refine, tune
from utrf.bringup.plant_check import (
    dwell_finding,
    frictional,
    lags_read,
    model_plant,
    near,
    pause_finding,
    plant_findings,
    slack_rad,
    swing_finding,
    uneven_finding,
)
from utrf.bringup.pulses import Bounds, Recorder, Trace, brake, pulse, settle
from utrf.hand import Hand

#: the limits go this far inside the stops found
STOP_MARGIN_RAD = 0.05
#: set_finger_config's default encoder_offset (protocol/spec.toml): the straight finger mid-turn
DEFAULT_OFFSET = 3.14159265
#: a reading that goes back this much (rad) against a steady drive: Joint 2 swings loose (slack;
#: fault-free fingers 2-3 counts of 7.7 mrad, margins in docs/bringup.md)
BACKWARD_RAD = 0.03
#: a reading that stands still this long while driven at one duty, as the leg's travel (rad):
#: Joint 2 waiting on a slack strand (an off-centre magnet's reading only slows; margins in
#: docs/bringup.md)
DWELL_RAD = 0.04
#: a reading whose speed at one duty varies this much (fastest over slowest) across the travel:
#: the magnet is off-centre
SPEED_SPREAD = 1.2
#: a reading that stood this long (rad) and ran this unevenly, both: Joint 2 waited on a slack
#: strand (fingers with neither slack nor an off-centre magnet ran at most 1.07 uneven over
#: 1185 readings; off-centre magnets stood at most 0.019 rad over 26; slack 72 of 90 readings
#: past both: docs/bringup.md)
UNEVEN_DWELL_RAD = 0.03
UNEVEN_SPREAD = 1.12
#: the opening leg after the closed stop runs to this fraction of the span from the open stop
#: (past the reading's middle, where an off-centre magnet's error turns fastest)
SWEEP_FRACTION = 0.4
#: a span between the stops longer than the model's by this: the reading's scale is wrong
SPAN_EXTRA_RAD = 0.1
#: shorter than the model's by this: a narrow range
NARROW_RAD = 0.08
#: a closing search that stops before this fraction of the model's span has stuck (no build's
#: range is that short: narrow-range stops at most 12 % early)
JAM_SPAN = 0.5
#: a closing search's stall within this fraction of the model's span is driven once more (an
#: off-centre magnet's span is at least 0.7 of it, a narrow range's 0.88): moving on, it paused
PAUSE_WITHIN = 0.6
#: before the stop search, the finger at the pretension this long (s)
TAKE_UP_S = 0.5
#: an open search's stall within this (rad) of its start is driven once more
OPEN_CONFIRM_RAD = 0.05


@dataclass
class FingerResult:
    name: str
    index: int
    findings: list[Finding] = field(default_factory=list)
    config: FingerConfig = field(default_factory=FingerConfig)
    stops: dict[str, float] = field(default_factory=dict)
    plant: dict[str, float] = field(default_factory=dict)
    tuning: dict[str, Any] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    board_time_s: float = 0.0
    #: what the wiring step measured: per setting, the take-up's run and whether it held
    wiring: dict[str, Any] = field(default_factory=dict)
    #: the board time each step took (s)
    steps_s: dict[str, float] = field(default_factory=dict)

    @property
    def fixable(self) -> bool:
        return all(f.fixable for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["findings"] = [f.to_dict() for f in self.findings]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FingerResult:
        r = cls(d["name"], d["index"])
        r.findings = [Finding(**x) for x in d["findings"]]
        r.config = FingerConfig.from_dict(d["config"])
        r.stops, r.plant, r.tuning = d["stops"], d["plant"], d["tuning"]
        r.checks = [Check(**c) for c in d["checks"]]
        r.board_time_s = d.get("board_time_s", 0.0)
        r.wiring, r.steps_s = d.get("wiring", {}), d.get("steps_s", {})
        return r


class Steps:
    """Each step's board time of one finger (the stream's time: no request), its steps begun
    and ended in two stretches (the wiring, then the rest, which may overlap another finger's)."""

    def __init__(self, hand: Hand, name: str, step: Callable[[str], None]) -> None:
        self.hand, self.name, self.step = hand, name, step
        self.spans: dict[str, float] = {}
        self._open: tuple[str, float] | None = None

    def begin(self, label: str) -> None:
        self.end()
        self._open = (label, now(self.hand))
        self.step(f"{self.name}: {label}")

    def end(self) -> None:
        if self._open is not None:
            label, t0 = self._open
            self.spans[label] = round(self.spans.get(label, 0.0) + now(self.hand) - t0, 3)
            self._open = None


def wire_finger(
    hand: Hand,
    rec: Recorder,
    f: int,
    saved: dict[str, dict[str, Any]],
    bounds: Bounds,
    steps: Steps,
) -> tuple[FingerResult, Wiring | None]:
    """The finger's encoder and wiring (every other finger braked: the cable check reads every
    channel); its wiring when it may go on to its stops."""
    names = list(hand.fingers)
    name = names[f]
    res = FingerResult(name, f)
    geo = hand.geometry.fingers[f].geometry
    lo, hi = geo.theta2_range_rad
    # a round trip first, as each finger's start always had: the stick-slip of
    # `friction:1=14` moves 0.046 rad under its wiring pulse without it, 0.05 (moved) with it
    hand.state()
    begin = steps.begin
    begin("encoder")
    brake(hand, [f])
    # the saved pretension: both motors pull, the finger is held against gravity between pulses
    hand.set_gains(f, pretension_duty=max(0.1, saved["gains"]["pretension_duty"]))
    hand.set_limits(
        f, theta2_min=lo, theta2_max=hi, limit_margin=0.5, stall_time=bounds.board_stall_s
    )
    hand.set_finger_config(f, motor_invert=0, encoder_invert=0, encoder_offset=DEFAULT_OFFSET)
    found = encoder_check(hand, rec, f, name)
    if found is not None:
        res.findings.append(found)
        return res, None
    begin("wiring")
    w = wiring(hand, rec, f, name, names, bounds)
    res.findings += w.findings
    res.wiring = {
        "drift_rad": w.drift,
        "held": w.held,
        "moved": {f"{k[0]},{k[1]}": v for k, v in w.moved.items()},
        "pulsed_rad": {f"{k[0]},{k[1]}": v for k, v in w.pulsed.items()},
    }
    if not w.ok:
        return res, None
    hand.set_finger_config(f, motor_invert=w.motor_invert, encoder_invert=w.encoder_invert)
    hand.set_gains(f, pretension_duty=saved["gains"]["pretension_duty"])
    res.config.finger_config = {"encoder_invert": w.encoder_invert, "motor_invert": w.motor_invert}
    return res, w


def finish_finger(
    hand: Hand,
    rec: Recorder,
    res: FingerResult,
    w: Wiring,
    saved: dict[str, dict[str, Any]],
    bounds: Bounds,
    steps: Steps,
    upto: str = "check",
) -> FingerResult:
    """The finger's stops, plant, tuning and closed-loop checks, after its wiring (``upto``:
    the last of them); its own channel only, so another finger's may run meanwhile."""
    f, name = res.index, res.name
    lo, hi = hand.geometry.fingers[f].geometry.theta2_range_rad
    begin = steps.begin
    begin("stops")
    # braked since its wiring while another's was done, it sagged and its tendons went slack
    # (a weak finger's open search then stalled at once, taken for the stop): taut again at
    # the pretension, and from there, not braked, into the search; a first leg that stalls
    # before OPEN_CONFIRM_RAD is driven once more (at the stop it stalls again)
    open_ = find_stop(
        hand, rec, f, -1, w.encoder_invert, bounds, OPEN_CONFIRM_RAD, rest_first=TAKE_UP_S
    )
    # one duty for every search (a slow finger at the duty bound less the pretension, tried:
    # 1.4 s less on a slow finger, but 14 N of friction then moved past its jam and was named
    # a narrow range and a turned magnet)
    duty = STOP_DUTY
    closed = (
        find_stop(hand, rec, f, 1, w.encoder_invert, bounds, PAUSE_WITHIN * (hi - lo), duty)
        if open_
        else None
    )
    if open_ is None or closed is None:
        res.findings.append(
            Finding(
                name,
                "friction",
                "the finger moved when pulsed, but the search for the joint's stops did not "
                "end at a stop (it stopped moving before one at the search's duty, or "
                "faulted): too much friction or a jammed joint (a tight guide, tendon or "
                "carriage), or a broken tendon",
                "free the joint, the guides and the carriages and check the tendons; then run "
                "the bring-up again",
                False,
            )
        )
        return res
    s = -1.0 if w.encoder_invert else 1.0
    span = math.remainder(s * (closed.raw - open_.raw) - math.pi, 2 * math.pi) + math.pi
    offset = math.remainder(open_.raw - s * lo, 2 * math.pi)
    closed_at = lo + span
    res.stops = {
        "open_rad": lo,
        "closed_rad": closed_at,
        "span_rad": span,
        "offset_rad": offset,
        # from the open stop, how long the motor ran before Joint 2 moved (the slack)
        "take_up_s": take_up_s(closed.first, 1),
        "search_duty": duty,
    }
    back = max(backward_rad(closed.first, 1), backward_rad(closed.trace, 1))
    if closed.paused > 0:
        # driven on at the same duty it went on: Joint 2 waited on its strand mid-travel, or
        # heavy friction stuck and slipped on (seed 10's thumb): the plant's duty to move tells
        res.stops["paused_rad"] = closed.paused
    if span < JAM_SPAN * (hi - lo) and back > BACKWARD_RAD:
        # it went back before it stopped: Joint 2 swinging loose paused it, not a jam
        res.findings.append(swing_finding(name, back))
        return res
    if span < JAM_SPAN * (hi - lo):
        res.findings.append(
            Finding(
                name,
                "friction",
                f"closing from its open stop, the finger stopped after {math.degrees(span):.0f}° "
                f"of the joint's {math.degrees(hi - lo):.0f}° at the search's duty: no build's "
                "range is that short, it stuck: too much friction for the bring-up's duty bound "
                "(a tight guide, tendon or carriage) or a jammed joint",
                "free the joint, the guides and the carriages and check the tendons; then run "
                "the bring-up again",
                False,
                {"span_rad": span, "model_span_rad": hi - lo},
            )
        )
        return res
    if span > (hi - lo) + SPAN_EXTRA_RAD:
        res.findings.append(
            Finding(
                name,
                "not-monotonic",
                f"between its stops the reading turns {math.degrees(span):.0f}°, further "
                f"than the joint can ({math.degrees(hi - lo):.0f}°): the reading is not the "
                "joint's angle, the encoder's magnet is off-centre on the shaft (or loose)",
                "centre the magnet on Joint 2's shaft and glue it; then run the bring-up again",
                False,
                {"span_rad": span, "model_span_rad": hi - lo},
            )
        )
        return res
    if abs(math.remainder(offset - DEFAULT_OFFSET, 2 * math.pi)) > 0.05:
        res.findings.append(
            Finding(
                name,
                "magnet-offset",
                "at the open stop the encoder reads "
                f"{math.degrees(math.remainder(offset - DEFAULT_OFFSET, 2 * math.pi)):+.1f}° "
                "off the model's zero: the magnet is glued turned on its shaft (or the AS5600 "
                "turned on its board)",
                f"encoder_offset = {offset:.4f} rad (the open stop reads the model's "
                f"{math.degrees(lo):.1f}°)",
                True,
                {"offset_rad": offset},
            )
        )
    if span < (hi - lo) - NARROW_RAD:
        res.findings.append(
            Finding(
                name,
                "narrow-range",
                f"this build's joint closes only to {math.degrees(closed_at):.1f}° (the model's "
                f"{math.degrees(hi):.1f}°): a knuckle, a guide or a short tendon stops it early",
                f"theta2_max = {math.degrees(closed_at - STOP_MARGIN_RAD):.1f}° (inside the stop)",
                True,
                {"closed_rad": closed_at},
            )
        )
    th_min, th_max = lo + STOP_MARGIN_RAD, min(hi, closed_at) - STOP_MARGIN_RAD
    hand.set_finger_config(f, encoder_offset=offset)
    hand.set_limits(f, theta2_min=th_min, theta2_max=th_max)
    res.config.finger_config = {
        "encoder_offset": offset,
        "encoder_invert": w.encoder_invert,
        "motor_invert": w.motor_invert,
    }
    res.config.limits = {"theta2_min": th_min, "theta2_max": th_max}
    if upto == "stops":
        if closed.paused > 0:  # the plant's friction duty would tell it from friction
            res.findings.append(pause_finding(name, closed.paused))
        return res
    begin("plant")
    mid = min(max(0.3, th_min + 0.6), th_max - 0.6)
    hand.clear_faults([f])
    here = hand.state().fingers[f].theta2
    # from the closed stop (where Joint 2 leans flexed), opening: the slack shows as take-up.
    # A short span may be an off-centre magnet's (the reading's span short by twice its
    # error): on past the reading's middle, where that error turns fastest, then back, so that
    # the curve compares the travel from the closed stop to past its middle
    short = span < (hi - lo) - NARROW_RAD
    sweep = min(mid, lo + SWEEP_FRACTION * span) if short else mid
    to_mid = pulse(
        hand,
        rec,
        f,
        math.copysign(duty, sweep - here),
        bounds,
        seconds=3.0 * max(1.0, (here - sweep) / max(here - mid, 0.3)),
        travel=3.5,
        until=sweep,
    )
    res.stops["take_up_closed_s"] = take_up_s(to_mid, -1)
    if sweep < mid - 0.05:
        # back past the middle, then opening onto it: the plant's steps start as before,
        # the finger arriving by opening
        for target in (mid + 0.1, mid):
            settle(hand, 0.0)
            now = hand.state().fingers[f].theta2
            pulse(
                hand,
                rec,
                f,
                math.copysign(duty, target - now),
                bounds,
                seconds=3.0,
                travel=3.5,
                until=target,
            )
    # the closing legs were read in the search's frame (each one's zero where it began): in
    # the calibrated one, the last ends at the closed stop and each other where the next began
    closing: list[Trace] = []
    end_at = closed_at
    for leg in reversed(closed.legs):
        if not len(leg.t):
            continue
        th = leg.theta2.copy()
        th[:, f] += end_at - leg.end
        closing.insert(0, replace(leg, theta2=th))
        end_at = float(th[0, f])
    curve = reading_curve(closing, to_mid)
    res.stops.update({f"curve_{k}": v for k, v in curve.items()})
    # every closing leg of the search (its first and last), not only the one read as a curve
    back = max(curve["backward_rad"], backward_rad(closed.first, 1))
    res.stops["backward_rad"] = back
    if stood(curve) and back <= BACKWARD_RAD:
        # driven at a steady duty the reading stood still for a stretch of the motor's travel:
        # Joint 2 waited on its strand (an off-centre magnet's reading only slows)
        res.findings = [
            fd for fd in res.findings if fd.kind in ("encoder-inverted", "leads-swapped")
        ]
        res.findings.append(dwell_finding(name, curve["dwell_rad"]))
        return res
    if back > BACKWARD_RAD:
        # driven at a steady duty the reading went back: Joint 2 swings loose between its
        # strands; its plant would be the swing's, and the stops' findings are doubtful
        res.findings = [
            fd for fd in res.findings if fd.kind in ("encoder-inverted", "leads-swapped")
        ]
        res.findings.append(swing_finding(name, back))
        return res
    uneven = curve["spread"] > SPEED_SPREAD
    settle(hand, 0.1)
    ref = model_plant(hand, f)
    plant, _ = identify(hand, rec, f, bounds, mid, lambda p: lags_read(p, ref))
    lags, reversals = near(plant, ref)
    if lags or reversals:  # a rule's reading near its threshold: decided on more of them
        refine(hand, rec, f, bounds, plant, mid, lags, reversals)
    res.plant = plant.to_dict()
    res.plant["slack_rad"] = slack_rad(plant, ref, res.stops["take_up_s"], duty)
    res.findings += plant_findings(name, plant, ref, res.plant["slack_rad"], uneven)
    if closed.paused > 0 and not frictional(plant, ref):
        res.findings = [
            fd for fd in res.findings if fd.kind in ("encoder-inverted", "leads-swapped")
        ]
        res.findings.append(pause_finding(name, closed.paused))
        return res
    if closed.paused > 0 and any(fd.kind == "narrow-range" for fd in res.findings):
        # heavy friction stuck and slipped on in the closing search, and stuck again short of
        # the stop (seed 10's 10 N thumb: paused at 1.35 rad, stuck at 1.83 of 3.31): that is
        # friction's stick, not this build's stop (no narrow range paused: 0 of 135
        # readings); the limits back to the model's closed stop (the stall rule guards it)
        res.findings = [fd for fd in res.findings if fd.kind != "narrow-range"]
        th_max = hi - STOP_MARGIN_RAD
        hand.set_limits(f, theta2_max=th_max)
        res.config.limits["theta2_max"] = th_max
        res.stops["stuck_rad"] = closed_at
    if uneven and not any(fd.kind == "slack" for fd in res.findings):
        # not Joint 2 hanging loose between its strands (slack, which runs the legs unevenly
        # too): the reading is not the joint's angle, and the zero and range from it are void
        res.findings = [
            fd for fd in res.findings if fd.kind in ("encoder-inverted", "leads-swapped")
        ]
        res.findings.append(uneven_finding(name, curve))
        return res
    if not plant.K > 0:  # a slow motor's lag may be unresolved both ways: tuned on the model's
        res.findings.append(
            Finding(
                name,
                "friction",
                "the finger moved when pulsed, but not both ways at two of the plant's step "
                "duties within the bring-up's duty bound: too much friction (a tight guide, "
                "tendon or carriage) or a jammed joint",
                "free the joint, the guides and the carriages; then run the bring-up again",
                False,
            )
        )
        return res
    g = saved["gains"]
    weak = any(fd.kind == "weak-motor" for fd in res.findings)
    tuned = tune(
        plant,
        model_plant(hand, f),
        g["d_cutoff_hz"],
        g["pretension_duty"],
        g["max_duty"],
        measured_tau=weak,
    )
    res.tuning = asdict(tuned)
    res.config.gains = dict(tuned.gains)
    res.config.motion = dict(tuned.motion)
    if upto == "plant":
        return res
    begin("closed loop")
    a, b = max(th_min, mid - 0.25), min(th_max, mid + 0.25)  # inside a narrow range's limits
    hand.set_gains(f, max_duty=min(g["max_duty"], bounds.duty))
    hand.set_gains(f, **{k: g[k] for k in tuned.gains})
    hand.set_motion(f, **{k: saved["motion"][k] for k in tuned.motion})
    hand.clear_faults([f])
    res.checks.append(check(hand, rec, f, a, b, "before (saved gains)", brake_after=False))
    hand.set_gains(f, **tuned.gains)
    hand.set_motion(f, **tuned.motion)
    hand.clear_faults([f])
    res.checks.append(check(hand, rec, f, a, b, "after (tuned)"))
    hand.set_gains(f, max_duty=g["max_duty"])
    brake(hand, [f])
    return res


def stood(curve: dict[str, float]) -> bool:
    """The reading stood still while driven (``reading_curve``'s dwell) long enough to be a
    slack strand's wait: beyond ``DWELL_RAD``, or beyond ``UNEVEN_DWELL_RAD`` while running
    uneven too (neither a fault-free finger, which runs evenly, nor an off-centre magnet,
    which only slows, does both)."""
    dwell, spread = curve["dwell_rad"], curve["spread"]
    return dwell > DWELL_RAD or (dwell > UNEVEN_DWELL_RAD and spread > UNEVEN_SPREAD)


def now(hand: Hand) -> float:
    """The board's time from the stream's last sample (a get_state would shift the steps)."""
    st = hand.latest
    return st.board_time if st is not None else hand.state().board_time
