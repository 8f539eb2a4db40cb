"""Tip tracking for the rig runs: an electromagnetic tracker's sensor on the fingertip.

A :class:`Tracker` gives :class:`TrackerSample` s: the sensor's position in the tracker's own
frame (3D, m), a timestamp and whether the sensor was seen (``visible``) with the tracker's
quality figure. A :class:`Registration` maps tracker coordinates to the finger frame (x along
the straight finger, y toward flexion, origin at Joint 1; ``docs/architecture.md``); it is
fitted by :func:`register` from the sensor's positions at known finger poses.

- :class:`NDIAuroraTracker`: an NDI Aurora (or Polaris) through ``scikit-surgerynditracker``,
  an optional dependency (``pip install 'utrf[rig]'``; in a checkout
  ``pip install -e '.[rig]'``) imported only when one is opened.
- :class:`SimulatedTracker`: for the emulated board. It reads the plant's true fingertip,
  places it in a tracker frame of its own (a rotation and an offset the run does not know),
  and adds seeded Gaussian noise, so registration and calibration have something to find.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

NDI_PACKAGE = "scikit-surgerynditracker"
NDI_INSTALL = (
    "pip install 'utrf[rig]' (an installed utrf), or pip install -e '.[rig]' "
    "(in a checkout of the repository)"
)


class TrackerError(RuntimeError):
    """A tracker that cannot be opened or read, or a registration that cannot be fitted."""


@dataclass(frozen=True)
class TrackerSample:
    """One reading: position in the tracker's frame (m), its time (s), visibility, quality,
    and the tracker's frame number.

    ``position_m`` is NaN when the sensor was not seen. ``quality`` is the tracker's own
    figure (NDI: the RMS error of the sensor's fit, smaller is better; NaN if none).
    ``frame``: the tracker's own frame number (NDI counts its measurements); a read faster
    than the tracker measures returns the same frame again, which is not a new sample.
    """

    time_s: float
    position_m: np.ndarray  # (3,)
    visible: bool
    quality: float = math.nan
    frame: int = -1


class NewFrames:
    """Passes each tracker frame once: ``new(sample)`` is False for a frame seen before."""

    def __init__(self) -> None:
        self.last: int | None = None
        self.repeated = 0

    def new(self, sample: TrackerSample) -> bool:
        if sample.frame >= 0 and sample.frame == self.last:
            self.repeated += 1
            return False
        self.last = sample.frame
        return True


class Tracker(Protocol):
    """What a rig run needs of a tracker. ``rate_hz``: how many frames a second it
    measures (None: a new one at every read)."""

    rate_hz: float | None

    def read(self) -> TrackerSample: ...

    def read_later(self) -> Callable[[], TrackerSample]:
        """What :meth:`read` gives, measured now and finished when called (call each before
        the next ``read``/``read_later``): a run that reads with its rig stopped keeps the
        stop short (the grasp hold's samples, the board waiting)."""
        ...

    def close(self) -> None: ...


# -- registration ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Registration:
    """Rigid map between the finger frame and the tracker frame: ``p_tracker = R p_finger +
    t`` with the finger's points in its plane (z = 0). ``to_finger`` maps back and drops the
    out-of-plane part (reported by :meth:`out_of_plane`)."""

    rotation: np.ndarray  # (3, 3)
    translation_m: np.ndarray  # (3,)
    rms_residual_m: float = math.nan  # of the fit's points
    points: int = 0

    def to_tracker(self, finger_xy: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(finger_xy, dtype=float))
        p3 = np.column_stack((p, np.zeros(len(p))))
        return p3 @ self.rotation.T + self.translation_m

    def _local(self, tracker_xyz: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(tracker_xyz, dtype=float))
        return (p - self.translation_m) @ self.rotation

    def to_finger(self, tracker_xyz: np.ndarray) -> np.ndarray:
        """Finger-frame (x, y) of tracker positions, shape (n, 2)."""
        return self._local(tracker_xyz)[:, :2]

    def out_of_plane(self, tracker_xyz: np.ndarray) -> np.ndarray:
        """Distance of tracker positions from the finger's plane (m), shape (n,)."""
        return self._local(tracker_xyz)[:, 2]

    def to_json(self) -> dict[str, Any]:
        return {
            "rotation": self.rotation.tolist(),
            "translation_m": self.translation_m.tolist(),
            "rms_residual_m": self.rms_residual_m,
            "points": self.points,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Registration:
        try:
            rot = np.asarray(data["rotation"], dtype=float)
            trans = np.asarray(data["translation_m"], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise TrackerError(f"registration: missing or bad field ({exc})") from None
        if rot.shape != (3, 3) or trans.shape != (3,):
            raise TrackerError("registration: rotation must be 3x3 and translation_m 3 numbers")
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
            raise TrackerError("registration: rotation is not a proper rotation matrix")
        return cls(
            rot,
            trans,
            float(data.get("rms_residual_m", math.nan)),
            int(data.get("points", 0)),
        )

    @classmethod
    def identity(cls) -> Registration:
        return cls(np.eye(3), np.zeros(3))


def register(finger_xy: np.ndarray, tracker_xyz: np.ndarray) -> Registration:
    """Fit the rigid map from finger-frame points (n, 2) to the tracker's readings of them
    (n, 3): least squares over rotations (the SVD solution of the orthogonal Procrustes
    problem, with the reflection excluded) and translations.

    Needs at least three points not on one line (a finger swept through several poses
    gives a curve). Errors name what is wrong with the points."""
    a = np.asarray(finger_xy, dtype=float)
    b = np.asarray(tracker_xyz, dtype=float)
    if a.ndim != 2 or a.shape[1] != 2:
        raise TrackerError(f"finger points must be (n, 2) in m, got shape {a.shape}")
    if b.ndim != 2 or b.shape[1] != 3:
        raise TrackerError(f"tracker points must be (n, 3) in m, got shape {b.shape}")
    if len(a) != len(b):
        raise TrackerError(f"{len(a)} finger points but {len(b)} tracker points")
    if len(a) < 3:
        raise TrackerError(f"registration needs at least 3 poses, got {len(a)}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise TrackerError("registration points must be finite (a sensor not seen at a pose?)")
    a3 = np.column_stack((a, np.zeros(len(a))))
    ca, cb = a3.mean(axis=0), b.mean(axis=0)
    da, db = a3 - ca, b - cb
    sv_a = np.linalg.svd(da[:, :2], compute_uv=False)
    if sv_a[1] < 1e-3 * max(sv_a[0], 1e-12) or sv_a[0] < 1e-6:
        raise TrackerError(
            "registration poses lie on one line (or coincide): sweep the finger through "
            "poses whose tips form a curve"
        )
    # Planar source: the third axis follows from the first two (right-handed).
    h = da.T @ db
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    trans = cb - rot @ ca
    resid = b - (a3 @ rot.T + trans)
    rms = float(np.sqrt((resid**2).sum(axis=1).mean()))
    return Registration(rot, trans, rms, len(a))


def rotation_from_euler(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll), angles in rad."""
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return rz @ ry @ rx


# -- simulated -------------------------------------------------------------------------------
class SimulatedTracker:
    """A tracker for the emulated board: ``tip()`` gives the true fingertip in the finger
    frame (m, e.g. ``lambda: board.tip[1]``); readings are that point in this tracker's
    frame (``frame``, unknown to the run) plus seeded Gaussian noise of ``noise_m`` per axis.
    ``clock`` gives the timestamps (the board's simulated time). ``rate_hz``: measure at this
    rate, as a real tracker does (a read within the same frame returns it again, frame
    number and all); None: every read is a new frame."""

    def __init__(
        self,
        tip: Callable[[], np.ndarray],
        clock: Callable[[], float],
        *,
        frame: Registration,
        noise_m: float = 1e-4,
        seed: int = 0,
        dropout: float = 0.0,
        rate_hz: float | None = None,
    ) -> None:
        if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
            raise TrackerError(f"rate_hz must be > 0 or None, got {rate_hz!r}")
        if not (math.isfinite(noise_m) and noise_m >= 0):
            raise TrackerError(f"noise_m must be >= 0, got {noise_m!r}")
        if not 0.0 <= dropout < 1.0:
            raise TrackerError(f"dropout must lie in [0, 1), got {dropout!r}")
        self._tip = tip
        self._clock = clock
        self.frame = frame
        self.noise_m = float(noise_m)
        self.dropout = float(dropout)
        self._rng = np.random.default_rng(seed)
        self.rate_hz = rate_hz
        self._frames = 0
        self._last: TrackerSample | None = None
        self.closed = False

    def read(self) -> TrackerSample:
        return self.read_later()()

    def read_later(self) -> Callable[[], TrackerSample]:
        """The time and the true tip taken now; the noise, the tracker's frame and the sample
        made when called (the same sample :meth:`read` makes, the noise drawn in call order)."""
        if self.closed:
            raise TrackerError("the simulated tracker is closed")
        return self.read_later_at(self._clock(), self._tip())

    def read_later_at(self, t: float, tip: np.ndarray) -> Callable[[], TrackerSample]:
        """:meth:`read_later` with the time and the true tip given (a stop's truth, taken by
        the harness as the board ran on)."""
        if self.closed:
            raise TrackerError("the simulated tracker is closed")
        t = float(t)
        if self.rate_hz is not None:
            frame = math.floor(t * self.rate_hz + 1e-9)
            if self._last is not None and self._last.frame == frame:
                last = self._last
                return lambda: last
        else:
            frame = self._frames
            self._frames += 1
        tip = np.array(tip, dtype=float)  # a copy: the plant moves on

        def finish() -> TrackerSample:
            noise = self._rng.normal(0.0, self.noise_m, 3)
            if self.dropout and self._rng.random() < self.dropout:
                sample = TrackerSample(t, np.full(3, np.nan), False, frame=frame)
            else:
                p = self.frame.to_tracker(tip)[0] + noise
                sample = TrackerSample(t, p, True, float(np.linalg.norm(noise)), frame)
            self._last = sample
            return sample

        return finish

    def close(self) -> None:
        self.closed = True


# -- NDI -------------------------------------------------------------------------------------
def _import_ndi() -> Any:
    try:
        from sksurgerynditracker.nditracker import NDITracker
    except ImportError as exc:
        raise TrackerError(
            f"the NDI tracker needs the optional package {NDI_PACKAGE}, which is not "
            f"installed ({exc.msg}); install it with: {NDI_INSTALL}"
        ) from None
    return NDITracker


class NDIAuroraTracker:
    """An NDI Aurora (electromagnetic) through scikit-surgerynditracker.

    ``serial_port``: the System Control Unit's port (None: the package probes for it);
    ``ports_to_probe``: how many to try. ``sensor``: which of the tracked tools is the
    fingertip's sensor (0: the first). Positions come in mm from the package; they are
    returned in m. A tool the tracker does not see comes as NaN, ``visible`` False. Each
    sample keeps the Aurora's frame number; it measures at ``rate_hz`` (40 Hz).
    """

    rate_hz: float | None = 40.0  # the Aurora's measurement rate

    def __init__(
        self,
        serial_port: str | None = None,
        *,
        ports_to_probe: int = 20,
        sensor: int = 0,
        verbose: bool = False,
        clock: Callable[[], float] = time.time,
    ) -> None:
        ndi = _import_ndi()
        settings: dict[str, Any] = {
            "tracker type": "aurora",
            "ports to probe": ports_to_probe,
            "verbose": verbose,
        }
        if serial_port is not None:
            settings["serial port"] = serial_port
        try:
            self._tracker = ndi(settings)
            self._tracker.start_tracking()
        except Exception as exc:  # the package raises plain exceptions for every failure
            raise TrackerError(f"could not start the NDI Aurora ({exc})") from exc
        self.sensor = int(sensor)
        self._clock = clock
        self.closed = False

    def read(self) -> TrackerSample:
        if self.closed:
            raise TrackerError("the NDI tracker is closed")
        try:
            _ports, _stamps, frame_numbers, matrices, quality = self._tracker.get_frame()
        except Exception as exc:
            raise TrackerError(f"NDI Aurora read failed ({exc})") from exc
        t = float(self._clock())
        if self.sensor >= len(matrices):
            raise TrackerError(
                f"NDI Aurora reports {len(matrices)} tool(s); sensor {self.sensor} is not one"
            )
        mat = np.asarray(matrices[self.sensor], dtype=float)
        pos = mat[:3, 3] * 1e-3 if mat.shape == (4, 4) else np.full(3, np.nan)
        q = float(quality[self.sensor]) if self.sensor < len(quality) else math.nan
        visible = bool(np.all(np.isfinite(pos)))
        try:
            frame = int(frame_numbers[self.sensor])
        except (IndexError, TypeError, ValueError):
            frame = -1
        return TrackerSample(t, pos if visible else np.full(3, np.nan), visible, q, frame)

    def read_later(self) -> Callable[[], TrackerSample]:
        sample = self.read()  # a real tracker's frame is read at once
        return lambda: sample

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self._tracker.stop_tracking()
            finally:
                self._tracker.close()


def mean_position(samples: Sequence[TrackerSample]) -> tuple[np.ndarray, int]:
    """Mean of the visible samples' positions and how many were visible."""
    pts = np.array([s.position_m for s in samples if s.visible])
    if len(pts) == 0:
        return np.full(3, np.nan), 0
    return pts.mean(axis=0), len(pts)
