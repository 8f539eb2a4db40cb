"""``bringup(hand)``: a new hand's first power-on, finger by finger: its encoder, its wiring,
its stops (the encoder's zero and the limits), its plant and gains, checked closed loop; the
configuration saved only after the person confirms it, and a report.

Safe at every step: the only open-loop drive is a bounded pulse (``pulses.py``), the motors are
braked between steps, and any exception (Ctrl-C included) brakes every finger and puts the
running configuration back to the saved one (``load_config``): the EEPROM is written only by
the one ``save_config`` after the confirmation. Resumable: each finger's result goes into
``progress.json`` of the report folder as it is done, and ``resume=True`` skips those fingers.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from utrf.bringup.diagnose import Wiring
from utrf.bringup.findings import Finding, FingerConfig, changes
from utrf.bringup.finger import FingerResult, Steps, finish_finger, wire_finger
from utrf.bringup.overlap import apart_fingers, run_overlapped
from utrf.bringup.pulses import Bounds, Recorder, brake
from utrf.hand import Hand

#: the steps of a finger's bring-up, in order
UPTO = ("wiring", "stops", "plant", "check")
#: fingers whose steps after the wiring run at once (each finger's own channel; the hand's
#: board time for five fingers, measured in docs/bringup.md)
OVERLAP = 2


@dataclass
class BringupResult:
    fingers: list[FingerResult]
    saved: bool = False
    unchanged: bool = False
    message: str = ""
    board_time_s: float = 0.0
    bounds: Bounds = field(default_factory=Bounds)
    out_dir: Path | None = None
    changes: list[str] = field(default_factory=list)  # what the proposal changes, if anything

    @property
    def findings(self) -> list[Finding]:
        return [f for r in self.fingers for f in r.findings]

    @property
    def ok(self) -> bool:
        return all(r.fixable for r in self.fingers)

    def to_dict(self) -> dict[str, Any]:
        return {
            "saved": self.saved,
            "unchanged": self.unchanged,
            "message": self.message,
            "changes": self.changes,
            "board_time_s": self.board_time_s,
            "bounds": asdict(self.bounds),
            "fingers": [r.to_dict() for r in self.fingers],
        }


Confirm = Callable[[str], bool]


def _saved_config(hand: Hand, f: int) -> dict[str, dict[str, Any]]:
    def fields(msg: Any) -> dict[str, Any]:
        return {k: v for k, v in asdict(msg).items() if k != "finger"}

    return {
        "finger_config": fields(hand.finger_config(f)),
        "limits": fields(hand.limits(f)),
        "gains": fields(hand.gains(f)),
        "motion": fields(hand.motion(f)),
    }


def _apply(hand: Hand, f: int, c: FingerConfig) -> None:
    if c.finger_config:
        hand.set_finger_config(f, **c.finger_config)
    if c.limits:
        hand.set_limits(f, **c.limits)
    if c.gains:
        hand.set_gains(f, **c.gains)
    if c.motion:
        hand.set_motion(f, **c.motion)


def summary(results: list[FingerResult]) -> str:
    lines = []
    for r in results:
        lines.append(f"{r.name}:")
        for fd in r.findings:
            lines.append(f"  - {fd.message}\n    fix: {fd.fix}")
        if not r.findings:
            lines.append("  - built as the model says")
        for group, values in asdict(r.config).items():
            if values:
                pretty = ", ".join(f"{k}={v:.4g}" for k, v in values.items())
                lines.append(f"    {group}: {pretty}")
    return "\n".join(lines)


def bringup(
    hand: Hand,
    out_dir: str | Path | None = None,
    *,
    fingers: Iterable[int | str] | None = None,
    confirm: Confirm = lambda text: False,
    bounds: Bounds | None = None,
    on_step: Callable[[str], None] | None = None,
    resume: bool = False,
    upto: str = "check",
    overlap: int = OVERLAP,
) -> BringupResult:
    """Bring up ``fingers`` (default all) of a connected hand; see the module's text.
    ``confirm(summary)`` is asked before anything is saved (the CLI asks the person;
    ``--yes`` answers yes). ``on_step(text)`` is told each step as it starts. ``upto``: the
    last step to take on each finger (``"wiring"``, ``"stops"``, ``"plant"`` or ``"check"``,
    the default: all of them). ``overlap``: how many fingers' steps after the wiring run at
    once (``utrf.bringup.overlap``; 1: one finger after another)."""
    if upto not in UPTO:
        raise ValueError(f"upto must be one of {UPTO}, got {upto!r}")
    bounds = bounds or Bounds()
    out = Path(out_dir) if out_dir is not None else None
    progress_path = out / "progress.json" if out is not None else None
    done: dict[int, FingerResult] = {}
    if resume and progress_path is not None and progress_path.exists():
        for d in json.loads(progress_path.read_text())["fingers"]:
            done[d["index"]] = FingerResult.from_dict(d)
    idx = (
        sorted({hand.finger_index(k) for k in fingers})
        if fingers is not None
        else list(range(len(hand.fingers)))
    )
    step = on_step or (lambda text: None)
    rec = Recorder(hand)
    t_start = hand.state().board_time
    result = BringupResult([], bounds=bounds, out_dir=out)
    try:
        hand.set_telemetry(1000)
        brake(hand)
        # a host that dies mid-pulse leaves the motors off, not holding (the board's
        # host-silence rule); load_config puts the saved safe action back
        hand.set_safety(safe_action="coast")
        saved = {f: _saved_config(hand, f) for f in range(len(hand.fingers))}
        by_finger: dict[int, FingerResult] = {}

        def finished(r: FingerResult, steps: Steps) -> FingerResult:
            brake(hand, [r.index])
            steps.end()
            r.steps_s = dict(steps.spans)
            r.board_time_s = round(sum(r.steps_s.values()), 3)
            by_finger[r.index] = r
            if progress_path is not None:
                progress = replace(result, fingers=[by_finger[i] for i in idx if i in by_finger])
                progress_path.parent.mkdir(parents=True, exist_ok=True)
                progress_path.write_text(json.dumps(progress.to_dict(), indent=1))
            return r

        # the fingers in turns of up to ``overlap`` that can never touch: each one's wiring, one
        # at a time (the cable check reads every channel), then the rest of theirs at once
        # (each its own channel). Soon after its wiring: a finger braked long sags and a weak
        # or stiff one then stuck in its open search (campaign seeds 30 and 47, all wired first)
        apart = apart_fingers(hand) if overlap > 1 else (lambda i, j: False)
        batch: list[tuple[int, Callable[[], FingerResult]]] = []
        for f in idx:
            if batch and (len(batch) >= overlap or not all(apart(f, g) for g, _ in batch)):
                run_overlapped(hand, [job for _, job in batch], overlap)
                batch = []
            if f in done:
                step(f"{hand.fingers[f]}: done before (resumed)")
                by_finger[f] = done[f]
                continue
            steps = Steps(hand, hand.fingers[f], step)
            r, w = wire_finger(hand, rec, f, saved[f], bounds, steps)
            brake(hand, [f])
            if w is None or upto == "wiring":
                finished(r, steps)
                continue
            steps.end()

            def rest(r: FingerResult = r, w: Wiring = w, steps: Steps = steps) -> FingerResult:
                return finished(
                    finish_finger(hand, rec, r, w, saved[r.index], bounds, steps, upto), steps
                )

            batch.append((f, rest))
        run_overlapped(hand, [job for _, job in batch], overlap)
        result.fingers = [by_finger[i] for i in idx]
        # every finger's temporary settings back to the saved ones, then the proposal on top
        hand.load_config("eeprom")
        bad = [fd for fd in result.findings if not fd.fixable]
        if bad:
            result.message = (
                "NOT saved: configuration cannot fix "
                + "; ".join(f"{fd.finger}: {fd.kind}" for fd in bad)
                + ". Fix those and run the bring-up again (the motors are off)."
            )
        elif not any(changes(r.config, saved[r.index]) for r in result.fingers):
            result.unchanged = True
            result.message = "this hand is already brought up: nothing to change, nothing saved"
        else:
            result.changes = [
                f"{r.name} {c}" for r in result.fingers for c in changes(r.config, saved[r.index])
            ]
            for r in result.fingers:
                _apply(hand, r.index, r.config)
            text = summary(result.fingers) + "\nchanges:\n  " + "\n  ".join(result.changes)
            if confirm(text):
                step("saving the configuration to the board's EEPROM")
                hand.save_config()
                result.saved = True
                result.message = "saved to the board's EEPROM"
            else:
                hand.load_config("eeprom")
                result.message = (
                    "not confirmed: nothing saved (the board runs its saved configuration)"
                )
        result.board_time_s = hand.state().board_time - t_start
    except BaseException:
        _safe_stop(hand)
        raise
    finally:
        rec.close()
    brake(hand)
    if out is not None:
        from utrf.bringup.report import write_report  # matplotlib: only when a report is asked

        write_report(result, out, rec.samples)
    return result


def _safe_stop(hand: Hand) -> None:
    """Motors off and the running configuration the saved one, as far as the link allows (a
    lost link leaves it to the board's host-silence rule)."""
    for action in (lambda: brake(hand), lambda: hand.load_config("eeprom")):
        with contextlib.suppress(Exception):  # best effort while stopping
            action()
