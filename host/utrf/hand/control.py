"""Targets and control modes: naming and checking targets, steps (``set_targets``), modes
(``set_mode``, ``coast``, ``brake``, ``hold``)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Literal

import numpy as np

from utrf.hand.errors import TargetError
from utrf.hand.fingers import FingerKey, Fingers, finger_mask
from utrf.hand.goals import Goals
from utrf.hand.limits import JointLimits
from utrf.hand.session import HandSession
from utrf.hand.state import CLOSED_LOOP
from utrf.hand.telemetry import HandTelemetry
from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.protocol import messages as m
from utrf.protocol.errors import NackError

Kind = Literal["theta2", "q", "flexion"]
TargetsArg = Mapping[FingerKey, float] | Sequence[float]

KINDS: dict[str, m.TargetKind] = {
    "theta2": m.TargetKind.JOINT2_ANGLE,
    "q": m.TargetKind.TENDON_Q,
    "flexion": m.TargetKind.FLEXION,
}
KIND_UNITS = {"theta2": "rad", "q": "m", "flexion": ""}


def control_mode(value: m.ControlMode | str) -> m.ControlMode:
    if isinstance(value, m.ControlMode):
        return value
    try:
        return m.ControlMode[str(value).upper()]
    except KeyError:
        names = [c.name.lower() for c in m.ControlMode]
        raise ValueError(f"unknown control mode {value!r}; modes are {names}") from None


class HandControl:
    """Targets and modes (a part of :class:`~utrf.hand.Hand`)."""

    def __init__(
        self,
        session: HandSession,
        fingers: Fingers,
        geometry: HandGeometry,
        telemetry: HandTelemetry,
        limits: JointLimits,
        goals: Goals,
    ) -> None:
        self._session = session
        self._fingers = fingers
        self._geometry = geometry
        self._telemetry = telemetry
        self._limits = limits
        self._goals = goals

    # --- targets --------------------------------------------------------------------------------

    def targets(self, targets: TargetsArg, kind: str, during: str) -> dict[int, float]:
        """Targets as given to a call, checked: finger index -> value in ``kind``'s unit."""
        names = self._fingers.names
        if kind not in KINDS:
            raise TargetError(f"{during}: kind must be one of {list(KINDS)}, got {kind!r}")
        if isinstance(targets, Mapping):
            items = [(self._fingers.index(k), v) for k, v in targets.items()]
        elif isinstance(targets, str) or not isinstance(targets, Sequence | np.ndarray):
            raise TargetError(
                f"{during}: targets must be a mapping finger -> value or a sequence of "
                f"{len(names)} values, got {targets!r}"
            )
        else:
            values = list(targets)
            if len(values) != len(names):
                raise TargetError(f"{during}: {len(values)} targets for {len(names)} fingers")
            items = list(enumerate(values))
        out: dict[int, float] = {}
        for i, v in items:
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise TargetError(f"{during}: target of {names[i]} is not a number: {v!r}")
            if not math.isfinite(float(v)):
                raise TargetError(f"{during}: target of {names[i]} is {v}")
            out[i] = float(v)
        if not out:
            raise TargetError(f"{during}: no targets given")
        return out

    def to_theta2(self, finger: FingerKey, value: float, kind: Kind = "theta2") -> float:
        """A target of any kind as the Joint-2 angle (rad), with the host's finger model."""
        g = self._geometry.fingers[self._fingers.index(finger)].geometry
        if kind == "theta2":
            return float(value)
        if kind == "q":
            return float(kinematics.theta2_from_q(g, value))
        if kind == "flexion":
            return float(kinematics.theta2_from_q(g, kinematics.q_from_flexion(g, value)))
        raise TargetError(f"kind must be one of {list(KINDS)}, got {kind!r}")

    def set_targets(
        self, targets: TargetsArg, *, kind: Kind = "theta2", enable: bool = True
    ) -> None:
        """Set targets at once (a step), in ``kind``'s unit, sent as that kind (the board
        converts q and flexion with its kinematics table and refuses what lies beyond a
        finger's limits: TargetError naming it). ``enable``: fingers not under closed-loop
        control are switched to POSITION."""
        values = self.targets(targets, kind, "set_targets")
        mask = finger_mask(values)
        wire = [values.get(i, 0.0) for i in range(len(self._fingers))]
        try:
            self._session.request(m.SetTargets(kind=KINDS[kind], mask=mask, value=tuple(wire)))
        except NackError as exc:
            if exc.code == m.ErrorCode.OUT_OF_RANGE and exc.detail & 0x80:
                i = exc.detail & 0x7F
                unit = KIND_UNITS[kind]
                raise TargetError(
                    f"set_targets: the board refused finger {self._fingers.names[i]!r}'s "
                    f"target {kind} = {values.get(i, math.nan):g}{(' ' + unit) if unit else ''}"
                    f": beyond its Joint-2 limits {self._limits.describe(i)}"
                    + (" (flexion targets lie in 0..1)" if kind == "flexion" else "")
                ) from exc
            raise
        idx = sorted(values)
        self._goals.set(idx, [self.to_theta2(i, values[i], kind) for i in idx])
        if enable:
            self.ensure_position(idx, keep_closed=True)

    def send_joint2(self, idx: Sequence[int], values: Iterable[float]) -> None:
        """Joint-2 targets (rad) for some fingers, as they are (no mode change)."""
        wire = [0.0] * len(self._fingers)
        for i, v in zip(idx, values, strict=True):
            wire[i] = float(v)
        self._session.request(
            m.SetTargets(kind=m.TargetKind.JOINT2_ANGLE, mask=finger_mask(idx), value=tuple(wire))
        )

    # --- modes ----------------------------------------------------------------------------------

    def set_mode(
        self,
        mode: m.ControlMode | str,
        fingers: Iterable[FingerKey] | FingerKey | None = None,
        *,
        duty: float | Mapping[FingerKey, float] = 0.0,
        effort: float | Mapping[FingerKey, float] = 1.0,
    ) -> None:
        """Set the control mode (``"coast" "brake" "position" "duty" "grasp"``) of some
        fingers (default all). ``duty`` (DUTY, signed, positive flexes) and ``effort`` (GRASP:
        the largest closing duty) are fractions, one for all or per finger. A finger with a
        latched fault cannot be driven: FingerFaultError."""
        mode_ = control_mode(mode)
        idx = self._fingers.select(fingers)
        n = len(self._fingers)

        def per_finger(value: float | Mapping[FingerKey, float], name: str) -> list[float]:
            if isinstance(value, Mapping):
                out = [0.0] * n
                for k, v in value.items():
                    out[self._fingers.index(k)] = float(v)
            else:
                out = [float(value)] * n
            lo = -1.0 if name == "duty" else 0.0
            for i in idx:
                if not lo <= out[i] <= 1.0:
                    raise ValueError(
                        f"{name} of {self._fingers.names[i]} must lie in [{lo:g}, 1], got {out[i]}"
                    )
            return out

        duties = per_finger(duty, "duty")
        efforts = per_finger(effort, "effort")
        modes = [m.ControlMode.COAST] * n
        for i in idx:
            modes[i] = mode_
        try:
            self.send_modes(finger_mask(idx), modes, duties, efforts)
        except NackError as exc:
            if exc.code == m.ErrorCode.FAULTED:
                raise self._telemetry.fault_error(exc, f"set_mode {mode_.name}") from exc
            raise
        if mode_ not in CLOSED_LOOP:
            self._goals.forget(idx)

    def send_modes(
        self,
        mask: int,
        modes: Sequence[m.ControlMode],
        duty: Sequence[float] | None = None,
        effort: Sequence[float] | None = None,
    ) -> None:
        """One ``set_mode`` as given, unchecked (closing uses it as it is)."""
        n = len(self._fingers)
        self._session.request(
            m.SetMode(
                mask=mask,
                mode=tuple(modes),
                duty=tuple(duty) if duty is not None else (0.0,) * n,
                effort=tuple(effort) if effort is not None else (0.0,) * n,
            )
        )

    def coast(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor outputs off: the fingers are free."""
        self.set_mode(m.ControlMode.COAST, fingers)

    def brake(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor terminals shorted: unpowered, motion is damped."""
        self.set_mode(m.ControlMode.BRAKE, fingers)

    def hold(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Hold where the fingers are now, in closed loop."""
        idx = self._fingers.select(fingers)
        st = self._telemetry.state()
        self.set_targets({i: st.fingers[i].theta2 for i in idx}, enable=False)
        self.ensure_position(idx, keep_closed=False)

    def ensure_position(self, idx: Sequence[int], keep_closed: bool) -> None:
        """Put fingers in POSITION; with ``keep_closed``, those in GRASP stay in GRASP."""
        st = self._telemetry.state()
        todo = [
            i
            for i in idx
            if not (
                st.fingers[i].mode == m.ControlMode.POSITION
                or (keep_closed and st.fingers[i].closed_loop)
            )
        ]
        if todo:
            self.set_mode(m.ControlMode.POSITION, todo)
