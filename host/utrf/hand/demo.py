"""The pose demo: the real firmware on the emulated board, driven by a :class:`Hand` over its
socket, through a sequence of poses; a picture of each pose and a plot of the trajectories.

The board is served in real time (``speed=1``) so that a person can watch it, and the Hand
connects to it as it would to a MEGA: over ``socket://``, riding out the auto-reset. Every
telemetry sample goes to ``telemetry.csv`` (SI); the plot is drawn from that file read back.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from utrf.datalog import read_log
from utrf.hand.client import DEFAULT_TOLERANCE, Hand
from utrf.hand.errors import FingerFaultError, NotControlledError, NotSettledError
from utrf.hand.state import HandState
from utrf.hand.telemetry_log import log_columns
from utrf.hand.tracking import Tracking, tracking_from_log
from utrf.models.geometry import HandGeometry
from utrf.poses import PoseLibrary

DEFAULT_SEQUENCE = ("open", "rock-and-roll", "shaka", "fist", "open")


@dataclass
class Step:
    index: int
    name: str
    settled: bool = False
    reason: str | None = None
    start: float = math.nan  # board time (s)
    settled_at: float = math.nan
    end: float = math.nan
    measured: np.ndarray = field(default_factory=lambda: np.full(5, np.nan))
    target: np.ndarray = field(default_factory=lambda: np.full(5, np.nan))
    picture: Path | None = None

    @property
    def worst_error(self) -> float:
        return float(np.max(np.abs(self.measured - self.target)))


@dataclass
class DemoResult:
    out_dir: Path
    steps: list[Step]
    telemetry: Path
    trajectories: Path | None = None
    url: str = ""
    realtime_factor: float = math.nan
    #: per finger, Joint 2 against the controller's setpoint over the whole run
    tracking: dict[str, Tracking] = field(default_factory=dict)
    #: per pose, the fingers whose paths the board stretched to keep their limits
    stretched: dict[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return all(s.settled for s in self.steps)

    @property
    def files(self) -> list[Path]:
        pics = [s.picture for s in self.steps if s.picture is not None]
        return [*pics, *([self.trajectories] if self.trajectories else []), self.telemetry]


class _Recorder:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.samples: list[HandState] = []

    def __call__(self, st: HandState) -> None:
        with self.lock:
            self.samples.append(st)

    def since(self, board_time: float) -> list[HandState]:
        with self.lock:
            return [s for s in self.samples if s.board_time >= board_time]


def _rendered(
    geometry: HandGeometry, theta2: np.ndarray
) -> tuple[np.ndarray, dict[str, tuple[float, float]]] | tuple[None, None]:
    """The MuJoCo hand at these angles, rendered off-screen, and where each fingertip is in
    the image; None where this machine cannot render (the picture then draws the hand) or an
    angle was never measured."""
    if not np.all(np.isfinite(theta2)):
        return None, None
    try:
        from utrf.models.render import RenderError, hand_at_labelled
    except ImportError:  # no mujoco
        return None, None
    try:
        return hand_at_labelled(list(theta2), geometry)
    except RenderError:
        return None, None


def run_demo(
    out_dir: str | Path,
    sequence: Sequence[str] = DEFAULT_SEQUENCE,
    *,
    elf: str | Path | None = None,
    speed: float | None = 1.0,
    move_s: float | None = None,
    hold_s: float = 0.5,
    seed: int = 0,
    poses: PoseLibrary | None = None,
    on_connect: Callable[[Hand, object], None] | None = None,
    on_step: Callable[[Step], None] | None = None,
) -> DemoResult:
    """Run the sequence; write ``pose-NN-NAME.png``, ``trajectories.png`` and
    ``telemetry.csv`` into ``out_dir``. Unknown poses raise KeyError before anything starts;
    a missing firmware ELF raises EmulatorError saying to run ``make firmware``, and leaves
    ``out_dir`` as it was."""
    from utrf.emulator import EmulatedBoard  # the harness library: only when a demo runs

    library = poses if poses is not None else PoseLibrary.load()
    for name in sequence:
        library[name]
    if not sequence:
        raise ValueError("the pose sequence is empty")
    if not ((move_s is None or move_s > 0) and hold_s >= 0):
        raise ValueError(f"move_s must be > 0 and hold_s >= 0, got {move_s}, {hold_s}")
    out = Path(out_dir)
    csv = out / "telemetry.csv"
    steps = [Step(i + 1, name) for i, name in enumerate(sequence)]
    recorder = _Recorder()
    stretched: dict[str, tuple[str, ...]] = {}
    with EmulatedBoard(elf, realtime=True, speed=speed, pty=False, seed=seed) as board:
        # The board is up (firmware and harness found): only now is the previous run replaced,
        # so a demo that cannot start leaves the last one's files as they were.
        out.mkdir(parents=True, exist_ok=True)
        for old in [*out.glob("pose-*.png"), out / "trajectories.png", csv]:
            old.unlink(missing_ok=True)  # a fresh run: no picture of a previous one left over
        url = board.url or ""
        with Hand.connect(url, poses=library, log_path=csv) as hand:
            if speed is None:
                # Unpaced, the board outruns the wall clock by whatever the machine gives
                # (5x and more since the plant steps in C): the host's heartbeats, sent on the
                # wall clock, would miss the default 0.5 s of board time.
                hand.set_safety(heartbeat_timeout=10.0)
            hand.on_state(recorder)
            if on_connect is not None:
                on_connect(hand, board)
            for step in steps:
                step.start = hand.state().board_time
                if on_step is not None:
                    on_step(step)
                try:
                    pose = hand.pose(step.name, move_s, timeout=3.0)
                    step.settled = True
                    if hand.last_move is not None and hand.last_move.stretched:
                        stretched[step.name] = hand.last_move.stretched
                except (NotSettledError, FingerFaultError, NotControlledError) as exc:
                    pose = library[step.name]
                    step.reason = str(exc)
                step.settled_at = hand.state().board_time
                hand.clock.sleep(hold_s)
                step.end = hand.state().board_time
                held = recorder.since(step.end - min(0.2, max(hold_s, 0.05)))
                if held:
                    step.measured = np.mean([s.theta2 for s in held], axis=0)
                step.target = pose.theta2(hand.geometry)
                if on_step is not None:
                    on_step(step)
        factor = board.realtime_factor
    from utrf.hand.figures import Segment, draw_pose, plot_trajectories  # matplotlib: when drawn

    result = DemoResult(out, steps, csv, url=url, realtime_factor=factor, stretched=stretched)
    geometry = hand.geometry
    for step in steps:
        image, tips = _rendered(geometry, step.measured)
        step.picture = draw_pose(
            geometry,
            step.measured,
            step.target,
            out / f"pose-{step.index:02d}-{step.name}.png",
            title=f"pose {step.index} of {len(steps)}: {step.name}"
            + ("" if step.settled else "  (NOT SETTLED)"),
            note=library[step.name].description,
            rendered=image,
            labels=tips,
        )
    data = read_log(csv, log_columns(hand.fingers))
    result.tracking = tracking_from_log(data, hand.fingers)
    t = np.array(data.column("board_time_s"), dtype=float)
    if len(t) > 1:
        names = list(hand.fingers)
        measured = {n: np.array(data.column(f"{n}_theta2_rad"), dtype=float) for n in names}
        target = {n: np.array(data.column(f"{n}_target_rad"), dtype=float) for n in names}
        segments = [Segment(s.name, s.start, s.end, list(s.target)) for s in steps]
        result.trajectories = plot_trajectories(
            names,
            t,
            measured,
            target,
            segments,
            out / "trajectories.png",
            title="Joint-2 angles against their targets (the real firmware on the emulated "
            f"board; settled within {math.degrees(DEFAULT_TOLERANCE):.0f}°)",
        )
    return result
