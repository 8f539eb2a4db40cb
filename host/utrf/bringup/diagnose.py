"""The first steps on a finger: is its encoder read, which way do its motors turn it and on
which channel, and where are this build's stops (and so the encoder's zero and the limits).
Every move is a bounded pulse (``pulses.pulse``); the finger's configuration is changed only
while it is braked."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from utrf.bringup.findings import Finding
from utrf.bringup.pulses import Bounds, Recorder, Trace, brake, pulse, settle
from utrf.hand import Hand
from utrf.protocol import messages as m

#: a channel whose reading moves this much more under a pulse than at rest has moved
MOVED_RAD = 0.05
#: pulses (duty, s) tried in turn to see a finger move: a stiff, weak or slow finger needs
#: more (the last: the duty bound less the pretension, for the diagnostic pulse's longest)
TRY_PULSES = ((0.2, 0.25), (0.35, 0.25), (0.4, 0.4))
#: both motors pull this hard, balanced, this long (as built; then the other way, after a
#: round that may have pushed the carriages to their ends) to take up the tendons
TAKE_UP = (0.1, 0.35)
TAKE_UP_S = (1.2, 3.0)
#: a pulse that moves the finger's own reading no more than this (one count) did not move it
STILL_RAD = 0.01
#: a rest (both motors at the pretension) that moves the reading more: the finger is not held
HELD_RAD = 0.1
#: the longest pulse, when it moved the finger's own reading more than ``STILL_RAD`` but less
#: than ``MOVED_RAD`` (a stiff finger creeping: 14 N of friction moved it 0.046 rad), is
#: repeated this many times more, each one bounded and braked after, and the moves summed
CREEP_REPEATS = 2
#: a take-up that runs a finger otherwise wired right this far open (its frame): motor A may
#: push (fault-free fingers -0.015 to +0.41 rad; seed 15's index, lead A swapped, -0.73), so
#: the other way is tried too (margins in docs/bringup.md)
PUSHED_RAD = 0.15
#: a stop is searched for at this duty, for at most this long per leg
STOP_DUTY = 0.35
STOP_LEG_S = 6.0
#: legs a search may take while the finger still moves (a slow motor crosses the travel late)
STOP_LEGS = 5
#: a leg that, driven again after a stall, moves this much: the stall was a pause (slack went
#: on 1.4-1.9 rad; 14 N of friction sticks and slips on by 0.05-0.3: a jam)
PAUSE_RAD = 0.3


@dataclass
class Wiring:
    """Per motor-invert setting (0, 1) and direction (+1 A pulls, -1 B pulls): the channel that
    moved and its sign, or None."""

    moved: dict[tuple[int, int], tuple[int, int] | None] = field(default_factory=dict)
    held: dict[int, bool] = field(default_factory=dict)  # the pretension held it at rest
    drift: dict[int, float] = field(default_factory=dict)  # how far the take-up ran it
    #: per setting and direction, the most a pulse moved the finger's own reading beyond its rest
    pulsed: dict[tuple[int, int], float] = field(default_factory=dict)
    motor_invert: int = 0
    encoder_invert: int = 0
    findings: list[Finding] = field(default_factory=list)
    traces: list[Trace] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(f.fixable for f in self.findings)


def encoder_check(hand: Hand, rec: Recorder, f: int, name: str) -> Finding | None:
    """The reading in band with the motors off (ENCODER_RANGE otherwise)."""
    hand.clear_faults([f])
    settle(hand, 0.02)
    st = hand.state().fingers[f]
    if st.faults & m.FaultBits.ENCODER_RANGE:
        return Finding(
            name,
            "encoder-signal",
            "the encoder's reading is outside the AS5600's 10-90 % band with the motors off: "
            "its cable is unplugged or broken, it has no 5 V, or the magnet is missing or too "
            "far from the chip",
            "check the encoder's three wires (5 V, GND, OUT to A0-A4) and the magnet's gap",
            False,
        )
    return None


def _moved(rest: Trace, drive: Trace) -> tuple[int, int] | None:
    """The channel the pulse moved (beyond what it drifts at rest, e.g. under gravity): the
    finger's own when its reading moved (another finger sagging or swinging while braked is
    not this pulse's doing), else the one that moved most."""
    extra = drive.delta() - rest.delta()
    f = drive.finger
    ch = f if abs(extra[f]) >= MOVED_RAD else int(np.argmax(np.abs(extra)))
    if abs(extra[ch]) < MOVED_RAD:
        return None
    return ch, int(np.sign(extra[ch]))


def wiring(
    hand: Hand, rec: Recorder, f: int, name: str, names: list[str], bounds: Bounds
) -> Wiring:
    """Pulse each motor on top of the pretension (A pulls harder at duty > 0, B at duty < 0)
    with the configuration's motor direction as built, and, unless that moved the finger both
    ways while the pretension held it at rest, swapped; see which channel moves which way
    against a rest of the same length just before."""
    w = Wiring()
    pretension = hand.gains(f).pretension_duty
    for invert in (0, 1):
        hand.set_finger_config(f, motor_invert=invert, encoder_invert=0)
        # both motors pull at TAKE_UP duty, balanced, until the tendons are taut (a finger
        # that sagged while braked, or carriages a first round pushed away): a finger wired
        # right comes to rest; one motor pushing runs it to the other one's side
        hand.set_gains(f, pretension_duty=TAKE_UP[invert])
        take_up = pulse(hand, rec, f, 0.0, bounds, seconds=TAKE_UP_S[invert], travel=1.0)
        w.traces.append(take_up)
        w.drift[invert] = float(take_up.delta()[f])
        hand.set_gains(f, pretension_duty=pretension)
        held = True
        for sign in (1, -1):
            w.moved[(invert, sign)] = None
            for i, (duty, seconds) in enumerate(TRY_PULSES):
                if i == len(TRY_PULSES) - 1 and not held:
                    break  # a motor pushes: the longest pulse would only run it to the stroke's end
                duty = min(duty, bounds.duty - pretension)
                seconds = min(seconds, bounds.pulse_s)
                rest = pulse(hand, rec, f, 0.0, bounds, seconds=seconds)
                settle(hand, 0.05)
                drive = pulse(hand, rec, f, sign * duty, bounds, seconds=seconds)
                w.traces += [rest, drive]
                settle(hand, 0.05)
                hand.clear_faults([f])
                if abs(rest.delta()[f]) > HELD_RAD:
                    held = False  # the pretension does not hold it: a motor pushes, or none pulls
                got = _moved(rest, drive)
                extra = float(abs(drive.delta()[f] - rest.delta()[f]))
                if got is None and held and i == len(TRY_PULSES) - 1 and extra > STILL_RAD:
                    got, extra = _creep(hand, rec, f, sign * duty, seconds, bounds, rest, drive, w)
                w.pulsed[(invert, sign)] = max(w.pulsed.get((invert, sign), 0.0), extra)
                if got is not None and got[0] != f:
                    w.moved[(invert, sign)] = got
                    if extra <= STILL_RAD:
                        break  # its own reading did not move at all: another channel's doing
                    continue  # a larger pulse may move its own (the other moved on its own)
                if got is not None and held:
                    w.moved[(invert, sign)] = got
                    break
        w.held[invert] = held
        both = all((w.moved[(0, d)] or (-1, 0))[0] == f for d in (1, -1))
        if invert == 0 and held and both and not _pushed_open(w):
            break  # both ways: known; one way: a lead swapped
        if (
            invert == 0
            and all(w.moved[(0, d)] for d in (1, -1))
            and max(w.pulsed.values()) <= STILL_RAD
        ):
            break  # another channel moves both ways, its own never: a cable swap
    _interpret(w, f, name, names)
    return w


def _creep(
    hand: Hand,
    rec: Recorder,
    f: int,
    duty: float,
    seconds: float,
    bounds: Bounds,
    rest: Trace,
    drive: Trace,
    w: Wiring,
) -> tuple[tuple[int, int] | None, float]:
    """The longest pulse moved the finger's own reading a little, not ``MOVED_RAD``: repeat it
    (each against a rest just before) up to ``CREEP_REPEATS`` times; moved if its moves, summed
    and none the other way by more than ``STILL_RAD``, reach ``MOVED_RAD``. Returns the
    channel and sign (or None) and the summed move (rad)."""
    moves = [float(drive.delta()[f] - rest.delta()[f])]
    for _ in range(CREEP_REPEATS):
        rest = pulse(hand, rec, f, 0.0, bounds, seconds=seconds)
        settle(hand, 0.05)
        drive = pulse(hand, rec, f, duty, bounds, seconds=seconds)
        w.traces += [rest, drive]
        settle(hand, 0.05)
        hand.clear_faults([f])
        moves.append(float(drive.delta()[f] - rest.delta()[f]))
        total = sum(moves)
        if abs(total) >= MOVED_RAD:
            break
    total = sum(moves)
    way = int(np.sign(total))
    if abs(total) < MOVED_RAD or any(mv * way < -STILL_RAD for mv in moves):
        return None, abs(total)
    return (f, way), abs(total)


def _pushed_open(w: Wiring) -> bool:
    """As built, the take-up ran the finger open (in the frame its pulses show) further than a
    finger wired right runs: motor A may push while B pulls (the pulses still move it both
    ways when the pretension holds it)."""
    a = w.moved.get((0, 1))
    sa = a[1] if a is not None else 1
    return sa * w.drift.get(0, 0.0) < -PUSHED_RAD


def _interpret(w: Wiring, f: int, name: str, names: list[str]) -> None:
    seen = [v for v in w.moved.values() if v is not None]
    others = sorted({ch for ch, _ in seen if ch != f})
    # another channel counts only while the finger's own reading never moved under a pulse
    if others and max(w.pulsed.values(), default=0.0) < MOVED_RAD:
        g = others[0]
        w.findings.append(
            Finding(
                name,
                "cable-swap",
                f"driving {name}'s motor channel moves the reading of input {g} ({names[g]}): "
                f"{name}'s and {names[g]}'s motor cables, or their encoder cables, are swapped "
                "between the driver channels or the analog inputs",
                f"watch which finger moves when {name} is driven: if it is {names[g]}, swap the "
                f"two fingers' motor cables; if it is {name}, swap their encoder cables "
                f"(A{f} and A{g})",
                False,
                {"channel": f, "moves": g},
            )
        )
        return
    own = {k: v for k, v in w.moved.items() if v is not None and v[0] == f}
    a0, b0 = own.get((0, 1)), own.get((0, -1))
    a1, b1 = own.get((1, 1)), own.get((1, -1))
    d0, d1 = w.drift.get(0, 0.0), w.drift.get(1, 0.0)
    # both motors' pulses moved it the same way, held or not: toward the side of the motor
    # that pulls (as built: A's side is closing, +1; driven the other way the sides swap)
    one_way = next(
        (
            (1 - 2 * inv) * p[1]
            for inv, (p, q) in enumerate(((a0, b0), (a1, b1)))
            if p and q and p[1] == q[1]
        ),
        0,
    )
    # taking up, one motor pulls and the other pushes: the finger runs to the puller's side,
    # and to the other side once both are driven the other way
    pushes = abs(d0) > HELD_RAD and abs(d1) > HELD_RAD and d0 * d1 < 0
    if w.held.get(0) and a0 and b0 and a0[1] != b0[1] and not (pushes and _pushed_open(w)):
        w.motor_invert, sa = 0, a0[1]
    elif w.held.get(1) and a1 and b1 and a1[1] != b1[1]:
        w.motor_invert, sa = 1, a1[1]
        w.findings.append(
            Finding(
                name,
                "leads-swapped",
                "the pretension does not hold the finger and the motors do not move it as they "
                "should; driven the other way, both do: both motors' leads are swapped (the "
                "driver's outputs wired the other way round)",
                "motor_invert = 1 (the firmware drives both the other way)",
                True,
            )
        )
    elif pushes or one_way:
        # or pulsing either motor harder runs it the same way (the pusher's harder push lets
        # the puller pull)
        bad = "A" if (one_way or d0) < 0 else "B"
        how = (
            f"pulsing either motor harder runs the finger {'open' if bad == 'A' else 'closed'}"
            if one_way
            else f"with both motors pulling, the finger runs {'open' if bad == 'A' else 'closed'}"
            f" and, with the motors driven the other way, {'closed' if bad == 'A' else 'open'}"
        )
        w.findings.append(
            Finding(
                name,
                "lead-a-swapped" if bad == "A" else "lead-b-swapped",
                f"{how}: motor {bad} pushes where it should pull, its two leads are swapped",
                f"swap motor {bad}'s two wires ({'AO1/AO2' if bad == 'A' else 'BO1/BO2'} on "
                f"{name}'s TB6612); the configuration turns both motors together and cannot "
                "fix one",
                False,
                {"drift_rad": [d0, d1]},
            )
        )
        return
    else:
        w.findings.append(
            Finding(
                name,
                "no-motion",
                "no encoder movement when either motor is driven, either way: the motors have "
                "no supply (VM), the driver's STBY is low, a motor or driver wire is open, or "
                "the encoder's magnet does not turn with Joint 2",
                "check the motor supply and STBY, the motor wires and the magnet's fixing",
                False,
                {"moved": {f"{k}": v for k, v in w.moved.items()}, "drift_rad": [d0, d1]},
            )
        )
        return
    if sa < 0:
        w.encoder_invert = 1
        w.findings.append(
            Finding(
                name,
                "encoder-inverted",
                "the finger flexes when driven to flex but its reading goes down: the motor and "
                "the encoder turn opposite ways (the magnet glued the other way round, or the "
                "AS5600's DIR pin on the other level)",
                "encoder_invert = 1",
                True,
            )
        )


@dataclass
class Stop:
    raw: float  # the encoder's reading there (rad of turn, the configuration's frame undone)
    trace: Trace  # the leg that ended at the stop
    first: Trace  # the search's first leg (from rest: where the take-up shows)
    legs: list[Trace] = field(default_factory=list)  # every leg of the search, in order
    paused: float = 0.0  # the travel (rad) at which it paused and went on (0: it did not)


def take_up_s(trace: Trace, direction: int, moved: float = 0.01) -> float:
    """The time from a pulse's start until the finger's reading moved ``moved`` rad its way:
    the motor's travel before Joint 2 follows, as a time (NaN: it never moved)."""
    th = trace.theta2[:, trace.finger] if len(trace.t) else np.zeros(0)
    idx = np.nonzero(direction * (th - th[0]) > moved)[0] if len(th) else np.zeros(0, int)
    return float(trace.t[idx[0]] - trace.t[0]) if len(idx) else math.nan


def _driven(trace: Trace) -> np.ndarray:
    """The samples of a leg while the board drove it at the leg's duty: not the ramp down after
    a limit or the stop (campaign seed 19's little finger stood 0.07 s there, 0.41 s before the
    stall rule ended the leg, and was taken for slack)."""
    f = trace.finger
    drive = np.abs(trace.duty_a[:, f] - trace.duty_b[:, f])  # either way the motors turn
    return np.asarray(drive >= 0.9 * abs(trace.duty))


def _speed_by_angle(trace: Trace, direction: int, edges: np.ndarray) -> np.ndarray:
    """The reading's mean speed (rad/s, positive its driven way) across each bin of ``edges``:
    the bin's width over the time the reading took to cross it (NaN where not crossed), from
    after the take-up to before the stop that ended the leg."""
    out = np.full(len(edges) - 1, np.nan)
    if len(trace.t) < 50:
        return out
    start = take_up_s(trace, direction)
    if not math.isfinite(start):
        return out
    t, y = trace.t, direction * trace.theta2[:, trace.finger]
    # a leg that ended at its target was still running: only a stall's slowing is cut
    end_cut = 0.03 if trace.stop == "reached" else 0.3
    use = (t >= t[0] + start + 0.1) & (t <= t[-1] - end_cut) & _driven(trace)
    t, y = t[use], y[use]
    if len(t) < 50:
        return out
    run = np.maximum.accumulate(y)  # the running extreme: noise cannot send it back
    for i in range(len(edges) - 1):
        a, b = sorted((direction * edges[i], direction * edges[i + 1]))
        if run[0] > a or run[-1] < b:
            continue
        dt = np.interp(b, run, t) - np.interp(a, run, t)
        if dt > 0:
            out[i] = (b - a) / dt
    return out


def dwell_rad(trace: Trace, direction: int, counts_rad: float = 0.012) -> float:
    """The longest the reading stood (moved under ``counts_rad``, about 1.5 counts) while a
    leg drove it at one duty, as the travel it would have made at the leg's median speed, less
    those counts (rad): Joint 2 waiting while the motor takes up a slack strand stands
    still for the motor's travel across the slack; a reading scaled by an off-centre magnet
    only slows. 0 for a leg too short to judge."""
    if len(trace.t) < 50:
        return 0.0
    start = take_up_s(trace, direction)
    if not math.isfinite(start):
        return 0.0
    t, y = trace.t, direction * trace.theta2[:, trace.finger]
    end_cut = 0.03 if trace.stop == "reached" else 0.3
    use = (t >= t[0] + start + 0.05) & (t <= t[-1] - end_cut) & _driven(trace)
    t, y = t[use], np.maximum.accumulate(y[use])
    # the stand at the stop that ended the leg is not a dwell, however late the stall rule
    # ended it (seed 60's ring stood 0.4 s there, a count of noise "going on" after 0.3 s)
    last = int(np.searchsorted(y, y[-1] - counts_rad)) if len(y) else 0
    t, y = t[: last + 1], y[: last + 1]
    if len(t) < 50 or y[-1] - y[0] < 0.1:
        return 0.0
    speed = (y[-1] - y[0]) / (t[-1] - t[0])
    j = np.searchsorted(y, y + counts_rad)
    ok = j < len(t)
    if not ok.any():
        return 0.0
    longest = float(np.max(t[j[ok]] - t[ok]))
    return float(max(0.0, longest * speed - counts_rad))


def backward_rad(trace: Trace, direction: int) -> float:
    """The most the reading went back against a leg driven ``direction`` (rad), from when it
    first moved (0 for a leg too short to judge)."""
    if len(trace.t) <= 50:
        return 0.0
    y = direction * trace.theta2[:, trace.finger]
    start = take_up_s(trace, direction)
    if not math.isfinite(start):
        return 0.0
    y = y[trace.t >= trace.t[0] + start]
    return float(np.max(np.maximum.accumulate(y) - y))


def reading_curve(
    closing: Trace | list[Trace], opening: Trace, bin_rad: float = 0.2
) -> dict[str, float]:
    """The reading against the model's curve over the travel two legs at one duty crossed,
    closing and opening: at a steady duty the joint turns at a steady speed, a load (gravity,
    a weaker motor) speeding one leg as much as it slows the other, so the two legs' speeds
    summed at each angle are the same all along; a magnet off-centre scales both by its
    once-per-turn error, and a loose one sends the reading back. ``spread``: the largest of
    those sums over the smallest; ``backward_rad``: the most the reading went back against the
    drive; ``covered_rad``: the travel compared. ``closing`` may be the legs of a search, in
    one frame (a slow finger crosses its travel in several)."""
    legs = [c for c in (closing if isinstance(closing, list) else [closing]) if len(c.t) >= 50]
    out = {"spread": math.nan, "covered_rad": 0.0}
    out["backward_rad"] = max([backward_rad(c, 1) for c in legs] + [backward_rad(opening, -1)])
    out["dwell_rad"] = max([dwell_rad(c, 1) for c in legs] + [dwell_rad(opening, -1)])
    if not legs or len(opening.t) < 50:
        return out
    back = opening.theta2[:, opening.finger]
    lo = max(min(c.theta2[:, c.finger].min() for c in legs), back.min())
    hi = min(max(c.theta2[:, c.finger].max() for c in legs), back.max())
    if hi - lo < 3 * bin_rad:
        return out
    edges = np.arange(lo, hi, bin_rad)
    closing_speed = np.full(len(edges) - 1, np.nan)
    for c in legs:
        closing_speed = np.fmax(closing_speed, _speed_by_angle(c, 1, edges))
    total = closing_speed + _speed_by_angle(opening, -1, edges)
    ok = np.isfinite(total) & (total > 0)
    if ok.sum() >= 3:
        out["spread"] = float(total[ok].max() / total[ok].min())
        out["covered_rad"] = float(ok.sum() * bin_rad)
    return out


def _raw(theta: float, offset: float, invert: int) -> float:
    """The encoder's own reading from an angle the board reports: θ = s (raw - offset)."""
    return offset + (-theta if invert else theta)


def find_stop(
    hand: Hand,
    rec: Recorder,
    f: int,
    direction: int,
    invert: int,
    bounds: Bounds,
    confirm_within: float = 0.0,
    duty: float = STOP_DUTY,
    rest_first: float = 0.0,
) -> Stop | None:
    """Drive toward the open (-1) or closed (+1) stop at low duty until the finger stops
    (the host's stall rule). The board's limits would stop it first if its reading passed
    them: the encoder offset is moved so the reading starts mid-range, again each time a
    limit (not a stop) ended the leg. A stall within ``confirm_within`` rad of the search's
    start is driven once more: a finger that then moves on had paused (Joint 2 waiting on a
    slack strand), not stopped (``Stop.paused``). ``rest_first``: the first leg starts after
    that long at the pretension (``pulse``)."""
    lim = hand.limits(f)
    trace = first = None
    legs: list[Trace] = []
    travelled = 0.0
    paused = 0.0
    confirming = False
    for _ in range(STOP_LEGS + 1):
        st = hand.state().fingers[f]
        cfg = hand.finger_config(f)
        here = _raw(st.theta2, cfg.encoder_offset, invert)
        hand.set_finger_config(f, encoder_offset=_wrap(here))  # the reading here is 0
        hand.clear_faults([f])
        # samples streamed before the new offset took are in the old frame: not this leg's
        since = hand.state().board_time
        trace = pulse(
            hand,
            rec,
            f,
            direction * duty,
            bounds,
            seconds=STOP_LEG_S,
            travel=4.0,
            rest_first=0.0 if legs else rest_first,
        ).after(since)
        first = first or trace
        legs.append(trace)
        settle(hand, 0.05)
        end = trace.end
        moved = direction * float(trace.delta()[f]) if len(trace.t) else 0.0
        travelled += moved
        at_limit = end >= lim.theta2_max - 0.03 if direction > 0 else end <= lim.theta2_min + 0.03
        stalled = trace.stop == "stall" or (
            trace.stop == "fault" and hand.state().fingers[f].faults == m.FaultBits.STALL
        )  # the host's stall rule, or the board's own behind it
        hand.clear_faults([f])
        if confirming and moved > PAUSE_RAD:
            paused = max(paused, travelled - moved)  # it went on: where it had paused
        if stalled and not at_limit:
            if travelled < confirm_within and not (confirming and moved <= PAUSE_RAD):
                confirming = True
                continue
            at = trace if moved > PAUSE_RAD or len(legs) < 2 else legs[-2]
            return Stop(_raw(end, _wrap(here), invert), at, first, legs, paused)
        if not stalled and trace.stop not in ("time", "travel"):
            return None
    return None


def _wrap(a: float) -> float:
    """An offset within the configuration's ±6.3 rad."""
    return math.remainder(a, 2 * math.pi)


__all__ = [
    "Stop",
    "Wiring",
    "backward_rad",
    "brake",
    "encoder_check",
    "find_stop",
    "reading_curve",
    "take_up_s",
    "wiring",
]
