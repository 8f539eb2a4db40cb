"""Targets and control modes: naming and checking targets, steps (``set_targets``), modes
(``set_mode``, ``coast``, ``brake``, ``hold``)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from utrf.hand.errors import TargetError
from utrf.hand.session import FingerKey, Kind, finger_mask
from utrf.hand.state import CLOSED_LOOP
from utrf.hand.telemetry import HandTelemetry
from utrf.models import kinematics
from utrf.protocol import messages as m
from utrf.protocol.errors import NackError

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


class HandControl(HandTelemetry):
    """Targets and modes (a part of :class:`~utrf.hand.Hand`)."""

    # --- targets --------------------------------------------------------------------------------

    def _targets(self, targets: TargetsArg, kind: str, during: str) -> dict[int, float]:
        if kind not in KINDS:
            raise TargetError(f"{during}: kind must be one of {list(KINDS)}, got {kind!r}")
        if isinstance(targets, Mapping):
            items = [(self.finger_index(k), v) for k, v in targets.items()]
        elif isinstance(targets, str) or not isinstance(targets, Sequence | np.ndarray):
            raise TargetError(
                f"{during}: targets must be a mapping finger -> value or a sequence of "
                f"{len(self.fingers)} values, got {targets!r}"
            )
        else:
            values = list(targets)
            if len(values) != len(self.fingers):
                raise TargetError(
                    f"{during}: {len(values)} targets for {len(self.fingers)} fingers"
                )
            items = list(enumerate(values))
        out: dict[int, float] = {}
        for i, v in items:
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise TargetError(f"{during}: target of {self.fingers[i]} is not a number: {v!r}")
            if not math.isfinite(float(v)):
                raise TargetError(f"{during}: target of {self.fingers[i]} is {v}")
            out[i] = float(v)
        if not out:
            raise TargetError(f"{during}: no targets given")
        return out

    def to_theta2(self, finger: FingerKey, value: float, kind: Kind = "theta2") -> float:
        """A target of any kind as the Joint-2 angle (rad), with the host's finger model."""
        g = self.geometry.fingers[self.finger_index(finger)].geometry
        if kind == "theta2":
            return float(value)
        if kind == "q":
            return float(kinematics.theta2_from_q(g, value))
        if kind == "flexion":
            return float(kinematics.theta2_from_q(g, kinematics.q_from_flexion(g, value)))
        raise TargetError(f"kind must be one of {list(KINDS)}, got {kind!r}")

    def _describe_limits(self, i: int) -> str:
        lo, hi = self._limits[i]
        return f"[{lo:.3f}, {hi:.3f}] rad ([{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg)"

    def _check_limits(self, theta2: Mapping[int, float], during: str) -> None:
        for i, t in theta2.items():
            lo, hi = self._limits[i]
            if not lo - 1e-4 <= t <= hi + 1e-4:
                raise TargetError(
                    f"{during}: finger {self.fingers[i]!r} target {t:.3f} rad "
                    f"({math.degrees(t):.1f} deg) is outside its Joint-2 limits "
                    f"{self._describe_limits(i)}"
                )

    def set_targets(
        self, targets: TargetsArg, *, kind: Kind = "theta2", enable: bool = True
    ) -> None:
        """Set targets at once (a step), in ``kind``'s unit, sent as that kind (the board
        converts q and flexion with its kinematics table and refuses what lies beyond a
        finger's limits: TargetError naming it). ``enable``: fingers not under closed-loop
        control are switched to POSITION."""
        values = self._targets(targets, kind, "set_targets")
        mask = finger_mask(values)
        wire = [values.get(i, 0.0) for i in range(len(self.fingers))]
        try:
            self._request(m.SetTargets(kind=KINDS[kind], mask=mask, value=tuple(wire)))
        except NackError as exc:
            if exc.code == m.ErrorCode.OUT_OF_RANGE and exc.detail & 0x80:
                i = exc.detail & 0x7F
                unit = KIND_UNITS[kind]
                raise TargetError(
                    f"set_targets: the board refused finger {self.fingers[i]!r}'s target "
                    f"{kind} = {values.get(i, math.nan):g}{(' ' + unit) if unit else ''}: "
                    f"beyond its Joint-2 limits {self._describe_limits(i)}"
                    + (" (flexion targets lie in 0..1)" if kind == "flexion" else "")
                ) from exc
            raise
        for i, v in values.items():
            self._goal[i] = self.to_theta2(i, v, kind)
        if enable:
            self._ensure_position(sorted(values), keep_closed=True)

    def _send_joint2(self, idx: Sequence[int], values: np.ndarray) -> None:
        wire = [0.0] * len(self.fingers)
        for i, v in zip(idx, values, strict=True):
            wire[i] = float(v)
        self._request(
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
        idx = self._finger_set(fingers)
        n = len(self.fingers)

        def per_finger(value: float | Mapping[FingerKey, float], name: str) -> list[float]:
            if isinstance(value, Mapping):
                out = [0.0] * n
                for k, v in value.items():
                    out[self.finger_index(k)] = float(v)
            else:
                out = [float(value)] * n
            lo = -1.0 if name == "duty" else 0.0
            for i in idx:
                if not lo <= out[i] <= 1.0:
                    raise ValueError(
                        f"{name} of {self.fingers[i]} must lie in [{lo:g}, 1], got {out[i]}"
                    )
            return out

        duties = per_finger(duty, "duty")
        efforts = per_finger(effort, "effort")
        modes = [m.ControlMode.COAST] * n
        for i in idx:
            modes[i] = mode_
        try:
            self._set_mode_raw(finger_mask(idx), modes, duties, efforts)
        except NackError as exc:
            if exc.code == m.ErrorCode.FAULTED:
                raise self._fault_error(exc, f"set_mode {mode_.name}") from exc
            raise
        if mode_ not in CLOSED_LOOP:
            self._goal[idx] = np.nan

    def coast(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor outputs off: the fingers are free."""
        self.set_mode(m.ControlMode.COAST, fingers)

    def brake(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Motor terminals shorted: unpowered, motion is damped."""
        self.set_mode(m.ControlMode.BRAKE, fingers)

    def hold(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Hold where the fingers are now, in closed loop."""
        idx = self._finger_set(fingers)
        st = self.state()
        self.set_targets({i: st.fingers[i].theta2 for i in idx}, enable=False)
        self._ensure_position(idx, keep_closed=False)

    def _ensure_position(self, idx: Sequence[int], keep_closed: bool) -> None:
        """Put fingers in POSITION; with ``keep_closed``, those in GRASP stay in GRASP."""
        st = self.state()
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
