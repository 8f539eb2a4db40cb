"""The board's settings, finger by finger: controller gains, move limits, supervision limits,
the host-silence rule, hardware configuration; saving and loading them; zeroing; faults."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from typing import Any, TypeVar

from utrf.hand.fingers import FingerKey, Fingers, finger_mask
from utrf.hand.goals import Goals
from utrf.hand.limits import JointLimits
from utrf.hand.session import HandSession
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request

M = TypeVar("M", bound=Message)


class HandConfiguration:
    """Getters and setters of the board's configuration (a part of :class:`~utrf.hand.Hand`).
    A setter changes the fields named and keeps the others, and returns what is now in use."""

    def __init__(
        self, session: HandSession, fingers: Fingers, limits: JointLimits, goals: Goals
    ) -> None:
        self._session = session
        self._fingers = fingers
        self._limits = limits
        self._goals = goals

    # --- controller and limits ------------------------------------------------------------------

    def gains(self, finger: FingerKey) -> m.Gains:
        return self._session.request(m.GetGains(finger=self._fingers.index(finger)))

    def set_gains(self, /, finger: FingerKey, **changes: float) -> m.Gains:
        """Change some of a finger's controller gains (``kp``, ``ki``, ``kd``,
        ``d_cutoff_hz``, ``deadband_duty``, ``slew_per_s``, ``max_duty``, ``pretension_duty``);
        the others keep their values. Returns the gains now in use."""
        return self._update(self.gains, m.SetGains, finger, changes, "set_gains")

    def motion(self, finger: FingerKey) -> m.Motion:
        """A finger's move limits (``max_speed`` rad/s, ``max_accel`` rad/s^2) and feedforward
        gains (``kv`` duty per rad/s, ``ka`` duty per rad/s^2)."""
        return self._session.request(m.GetMotion(finger=self._fingers.index(finger)))

    def set_motion(self, /, finger: FingerKey, **changes: float) -> m.Motion:
        """Change some of a finger's move limits and feedforward gains (``max_speed``,
        ``max_accel``, ``kv``, ``ka``; SI); they apply from the next move. Returns them."""
        return self._update(self.motion, m.SetMotion, finger, changes, "set_motion")

    def limits(self, finger: FingerKey) -> m.Limits:
        return self._session.request(m.GetLimits(finger=self._fingers.index(finger)))

    def read_limits(self) -> None:
        """Every finger's Joint-2 limits from the board, for the host's checks of targets."""
        self._limits.read(self.limits)

    def set_limits(self, /, finger: FingerKey, **changes: float) -> m.Limits:
        """Change some of a finger's supervision limits (``theta2_min``, ``theta2_max``,
        ``limit_margin``, ``stall_error``, ``stall_motion``, ``stall_time``,
        ``encoder_jump``; SI). Returns the limits now in use."""
        lim = self._update(self.limits, m.SetLimits, finger, changes, "set_limits")
        self._limits.take(lim)
        return lim

    def safety(self) -> m.Safety:
        return self._session.request(m.GetSafety())

    def set_safety(
        self,
        *,
        heartbeat_timeout: float | None = None,
        safe_action: m.SafeAction | str | None = None,
    ) -> m.Safety:
        """The host-silence rule: ``heartbeat_timeout`` (s) and ``safe_action`` (``"hold"`` or
        ``"coast"``)."""
        current = self.safety()
        if isinstance(safe_action, str):
            try:
                safe_action = m.SafeAction[safe_action.upper()]
            except KeyError:
                raise ValueError(
                    f"safe_action must be one of {[a.name.lower() for a in m.SafeAction]}, "
                    f"got {safe_action!r}"
                ) from None
        self._session.request(
            m.SetSafety(
                heartbeat_timeout=current.heartbeat_timeout
                if heartbeat_timeout is None
                else heartbeat_timeout,
                safe_action=current.safe_action if safe_action is None else safe_action,
            )
        )
        return self.safety()

    def finger_config(self, finger: FingerKey) -> m.FingerConfig:
        return self._session.request(m.GetFingerConfig(finger=self._fingers.index(finger)))

    def set_finger_config(self, /, finger: FingerKey, **changes: Any) -> m.FingerConfig:
        """Change a finger's hardware configuration (``actuation``, ``encoder_offset``,
        ``encoder_invert``, ``motor_invert``). The finger must be idle (COAST or BRAKE)."""
        return self._update(
            self.finger_config, m.SetFingerConfig, finger, changes, "set_finger_config"
        )

    def _update(
        self,
        get: Callable[[int], M],
        setter: type[Request[Any]],
        finger: FingerKey,
        changes: Mapping[str, Any],
        during: str,
    ) -> M:
        """Every setter's rule: the finger's settings as they are, the fields named changed
        (an unknown one refused, naming the fields), all sent, and read back."""
        i = self._fingers.index(finger)
        current = get(i)
        names = {f.name for f in type(current).FIELDS} - {"finger"}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise TypeError(f"{during}: unknown field(s) {unknown}; fields are {sorted(names)}")
        new = replace(current, **changes)
        self._session.request(setter(**{f.name: getattr(new, f.name) for f in setter.FIELDS}))
        return get(i)

    # --- saved configuration, zero, faults ------------------------------------------------------

    def save_config(self) -> None:
        """Write the running configuration to the board's EEPROM (about 1 s)."""
        self._session.request(m.SaveConfig())

    def load_config(self, source: m.ConfigSource | str = m.ConfigSource.EEPROM) -> None:
        """Replace the running configuration with the saved one (``"eeprom"``) or the
        firmware's defaults (``"defaults"``). Every finger must be idle."""
        if isinstance(source, str):
            try:
                source = m.ConfigSource[source.upper()]
            except KeyError:
                raise ValueError(f"source must be 'eeprom' or 'defaults', got {source!r}") from None
        self._session.request(m.LoadConfig(source=source))
        self.read_limits()

    def calibrate_zero(self, fingers: Iterable[FingerKey] | FingerKey) -> None:
        """Take the present readings as Joint-2 angle 0 (fingers straight and idle)."""
        idx = self._fingers.select(fingers)
        self._session.request(m.CalibrateZero(mask=finger_mask(idx)))

    def clear_faults(self, fingers: Iterable[FingerKey] | FingerKey | None = None) -> None:
        """Clear latched faults. The fingers stay in COAST: command them again."""
        idx = self._fingers.select(fingers)
        self._session.request(m.ClearFaults(mask=finger_mask(idx)))
        self._goals.forget(idx)
