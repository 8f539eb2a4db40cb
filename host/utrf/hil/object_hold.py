"""The grasp hold with a real object, on the MuJoCo hand (``utrf hil grasp-hold --emulated
--object NAME``; paper Sec. IV-C, Fig. 11).

The real firmware on the emulated board drives the MuJoCo hand (``EmulatedBoard(plant=
MujocoPlant(obj=NAME))``) over a ``Hand``. The object (``utrf.models.objects``) rests on the
palm, the hand palm-up; the grasp pose's closing fingers close on it in GRASP mode with the
pose's effort (or ``effort``) until they stop against it. Then the hand is turned over (gravity
along +z of the world: palm down), so only the grasp holds the object, and seeded hammer hits
(force pulses on the object) come during the hold. Samples at ``sample_hz``: the object's
pose, each finger's contact force on it and Joint-2 angle.

Reported (``results.json``): the object's slip (mm, from its pose at the start of the hold to
the end, as a tracker's sensor on it would see), each hit's peak displacement and recovery
time (back to rest within ``rest_mm`` for ``rest_s``), the largest contact force per finger,
for a fragile object whether (and when) a contact force passed its breaking force, and a
grasp that lets the object fall is reported as dropped (it moved more than ``drop_mm``), not
as settled. The figure (``utrf.hil.object_hold_report``) puts the object's displacement, slip
and contact forces over the hold beside a render of the hand holding it (MuJoCo, off-screen,
when the machine can render). A killed run's logs analyse as they are (``utrf hil analyse``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from utrf.datalog import CsvLog, read_rows
from utrf.hil.runs import RunError, write_json
from utrf.models import objects

G = 9.81


@dataclass(frozen=True)
class ObjectHoldConfig:
    object: str = "bottle"
    pose: str | None = None  # default: the object's grasp_pose (objects.toml)
    effort: float | None = None  # GRASP duty limit; default: the object's, else the pose's
    duration_s: float = 120.0
    hits: int = 10
    hit_impulse_n_s: float | None = None  # each hit's impulse on the object (N s)
    hit_dv_m_s: float = 0.025  # default impulse: this speed change of the object (a tap)
    hit_duration_s: float = 5e-3
    sample_hz: float = 100.0
    baseline_s: float = 1.0
    close_s: float = 1.5  # the fingers' way to the object
    close_timeout_s: float = 4.0  # after close_s, the longest wait for the fingers to stop
    squeeze_s: float = 1.0  # once the fingers have stopped on it, before letting go
    release_s: float = 0.3  # let go, palm up, before the turn-over
    settle_s: float = 1.0  # after the turn-over, before the hold's baseline
    drop_mm: float = 20.0
    rest_mm: float = 0.5
    rest_s: float = 0.2
    seed: int = 0
    picture: bool = True
    library: str | None = None  # an objects TOML of one's own (default: the package's)

    def __post_init__(self) -> None:
        library = objects.load_objects(self.library)
        if self.object not in library:
            raise RunError(f"unknown object {self.object!r}; the library has {sorted(library)}")
        if not (math.isfinite(self.duration_s) and self.duration_s >= 2 * self.baseline_s):
            raise RunError(
                f"duration_s must be at least {2 * self.baseline_s:g} s, got {self.duration_s}"
            )
        if self.effort is not None and not 0.0 < self.effort <= 1.0:
            raise RunError(f"effort must lie in (0, 1], got {self.effort}")
        if not 0 <= self.hits <= 10_000:
            raise RunError(f"hits must be 0..10000, got {self.hits}")
        imp = self.hit_impulse_n_s
        if imp is not None and not (math.isfinite(imp) and 0 <= imp <= 5):
            raise RunError(f"hit_impulse_n_s must lie in [0, 5] N s, got {imp}")
        if not (math.isfinite(self.hit_dv_m_s) and 0 <= self.hit_dv_m_s <= 5):
            raise RunError(f"hit_dv_m_s must lie in [0, 5] m/s, got {self.hit_dv_m_s}")
        if not 5 <= self.sample_hz <= 1000:
            raise RunError(f"sample_hz must lie in [5, 1000], got {self.sample_hz}")

    @property
    def pose_name(self) -> str:
        return self.pose or self.grasp_object.grasp_pose or "grasp-bottle"

    @property
    def grasp_object(self) -> objects.GraspObject:
        return objects.get_object(self.object, self.library)

    @property
    def impulse_n_s(self) -> float:
        """Each hit's impulse: given, or the object's mass times ``hit_dv_m_s``."""
        if self.hit_impulse_n_s is not None:
            return self.hit_impulse_n_s
        return self.grasp_object.mass_kg * self.hit_dv_m_s

    def hit_plan(self) -> list[tuple[float, tuple[float, float, float]]]:
        """Seeded hits: (time into the hold, world-frame impulse), spread over the hold after
        its baseline, each in a random direction."""
        if not self.hits:
            return []
        rng = np.random.default_rng(self.seed + 7919)
        lo, hi = self.baseline_s + 0.1, self.duration_s - 0.5
        edges = np.linspace(lo, hi, self.hits + 1)
        slots = edges[:-1] + np.diff(edges) * rng.uniform(0.1, 0.6, self.hits)
        out = []
        for t in slots:
            u = rng.normal(size=3)
            u /= np.linalg.norm(u)
            j = self.impulse_n_s * u
            out.append((float(t), (float(j[0]), float(j[1]), float(j[2]))))
        return out


RENDER = "object_render.png"  # the hand holding the object, once closed (MuJoCo)
HIT_COLUMNS = ("time_s", "jx_ns", "jy_ns", "jz_ns", "duration_s")
SAMPLE_COLUMNS = (
    ["time_s", "phase", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"]
    + [f"force_{n}_n" for n in ("thumb", "index", "middle", "ring", "little")]
    + [f"theta2_{n}_rad" for n in ("thumb", "index", "middle", "ring", "little")]
)


def run(
    config: ObjectHoldConfig,
    out: Path,
    *,
    elf: Path | None = None,
    progress: Any = print,
    on_hand: Any = None,
) -> dict[str, Any]:
    """Close on the object, let go, turn the hand over, hold under hits, record, analyse.
    Every phase is sampled (``object_samples.csv``, time from the hold's start: the close,
    release and turn-over come before 0). ``on_hand(hand)``, when given, is called once the
    hand is connected, before the close (a campaign sets gains and listens to telemetry)."""
    from utrf.emulator import EmulatedBoard
    from utrf.emulator.mujoco_plant import MujocoPlant
    from utrf.hand import Hand
    from utrf.hand.simlink import SimLink

    if (out / "object_samples.csv").exists():
        raise RunError(f"{out} already holds an object hold; give a new --out")
    obj = config.grasp_object
    plant = MujocoPlant(obj=obj, seed=config.seed, timestep=1e-3)
    # palm up (the model's gravity, −z) while the hand closes: the object rests on the palm
    out.mkdir(parents=True, exist_ok=True)
    meta: dict[str, Any] = {"config": asdict(config), "object": asdict(obj)}
    write_json(out / "meta.json", meta)
    board = EmulatedBoard(elf, realtime=False, seed=config.seed, plant=plant, exchange_period=1e-3)
    with (
        board,
        Hand.emulated(board) as hand,
        CsvLog(out / "object_samples.csv", SAMPLE_COLUMNS) as log,
        CsvLog(out / "object_hits.csv", HIT_COLUMNS) as hit_log,
    ):
        # the board's output is read once a sample, not every millisecond (the samples' rate
        # is all this run needs; the telemetry still arrives whole)
        if isinstance(hand.link, SimLink):
            hand.link.pump_interval_s = 1.0 / config.sample_hz
        if on_hand is not None:
            on_hand(hand)
        s = _Sampler(hand, board, plant, config, log)
        closed_forces, effort = _close(hand, s, config, progress)
        # what the close found, for the analysis of a run killed later
        meta["close"] = {"effort": effort, "contact_forces_n": [float(x) for x in closed_forces]}
        write_json(out / "meta.json", meta)
        if config.picture:
            _picture(plant, out / RENDER)
        plant.hold_object(False)
        s.run_until(s.t0 + config.release_s, "release")
        progress("turning the hand over: palm down, the grasp alone holds the object")
        plant.model.opt.gravity[:] = (0.0, 0.0, G)
        s.run_until(s.t0 + config.release_s + config.settle_s - 1e-9, "turn")
        if not s.fell:
            _hold(s, config, hit_log, progress)
    from utrf.hil import object_hold_report

    return object_hold_report.write(out, figure=config.picture)


class _Sampler:
    """Samples the object and the fingers at ``sample_hz`` on the board's clock, every phase
    alike. A row's time is from the hold's start, known once the close has ended: the close's
    rows wait in memory until then. ``fell``: the object is far out of the hand (no need to
    go on)."""

    def __init__(self, hand: Any, board: Any, plant: Any, config: ObjectHoldConfig, log: Any):
        self.hand, self.board, self.plant, self.log = hand, board, plant, log
        self.period = 1.0 / config.sample_hz
        self.fall_m = 5 * config.drop_mm * 1e-3
        self.t0 = hand.clock.now()  # the phase's start: sample k is due at t0 + k period
        self.k = 0
        self.hold_start: float | None = None
        self.pending: list[tuple[float, list[object]]] = []
        self.ref: np.ndarray | None = None  # the object's position when it was let go
        self.fell = False
        self.forces = np.zeros(5)

    def restart(self, hold_start: float) -> None:
        """A new phase from now; the hold starts at ``hold_start`` (board clock)."""
        self.t0, self.k, self.hold_start = self.hand.clock.now(), 0, hold_start
        for now, row in self.pending:
            self.log.write([f"{now - hold_start:.6f}", *row])
        self.pending.clear()

    def sample(self, phase: str) -> float:
        """Wait for the next sample time, then log one row; returns the time (board clock)."""
        self.k += 1
        clock = self.hand.clock
        clock.sleep(self.t0 + self.k * self.period - clock.now())
        now = clock.now()
        pos, quat = self.plant.object_pose()
        self.forces = self.plant.contact_forces()
        row: list[object] = [phase]
        row += [f"{v:.7f}" for v in (*pos, *quat)]
        row += [f"{v:.4f}" for v in self.forces]
        row += [f"{v:.5f}" for v in self.board.theta2]
        if self.hold_start is None:
            self.pending.append((now, row))
        else:
            self.log.write([f"{now - self.hold_start:.6f}", *row])
        if phase != "close":
            if self.ref is None:
                self.ref = pos.copy()
            self.fell = bool(np.linalg.norm(pos - self.ref) > self.fall_m)
        return now

    def run_until(self, until: float, phase: str) -> None:
        while self.t0 + (self.k + 1) * self.period <= until + 1e-9 and not self.fell:
            self.sample(phase)


def _close(
    hand: Any, s: _Sampler, config: ObjectHoldConfig, progress: Any
) -> tuple[np.ndarray, float]:
    """The grasp pose's closing fingers close on the object in GRASP with the effort, each
    heading for (almost) full flexion: it stops on the object. The thumb closes with them when
    the object says so (``grasp_thumb``); otherwise, as for every object of the package's
    library, the four fingers cage the object against the palm and the thumb stays open
    (closing it too held the ball and the egg worse over 120 s: measured, docs/mujoco.md).
    Waits until the fingers have stopped (they reach the object after the path's time:
    measured). Returns the contact forces once closed and the effort."""
    from utrf.protocol import messages as m

    plant = s.plant
    pose = hand.poses.get(config.pose_name)
    if pose is None or pose.grasp is None:
        raise RunError(f"pose {config.pose_name!r} is not a grasp pose")
    effort = config.effort
    if effort is None:
        effort = plant.object.grasp_effort or pose.grasp.effort
    goal = pose.theta2(hand.geometry)
    thumb = plant.object.grasp_thumb
    closing = [i for i in range(5) if goal[i] > 0.2 and (i > 0 or thumb)]
    hand.clear_faults()
    plant.hold_object(True)  # an operator keeps it in place while the fingers close
    progress(
        f"closing on the {plant.object.name} "
        f"({', '.join(hand.fingers[i] for i in closing)}; GRASP, effort {effort:g})"
    )
    targets = [0.95 if i in closing else 0.0 for i in range(5)]
    s.t0, s.k = hand.clock.now(), 0
    hand.move(
        targets, config.close_s, kind="flexion", mode=m.ControlMode.GRASP, effort=effort,
        wait=False,
    )  # fmt: skip
    s.run_until(s.t0 + config.close_s, "close")
    window = max(1, round(0.2 / s.period))
    last: list[np.ndarray] = []
    while hand.clock.now() < s.t0 + config.close_s + config.close_timeout_s:
        s.sample("close")
        last = [*last, np.array(s.board.theta2)][-window - 1 :]
        if len(last) > window and np.abs(last[-1] - last[0]).max() < 0.005:
            break  # still for 0.2 s: on the object, or as far as it goes
    s.run_until(hand.clock.now() + config.squeeze_s, "close")
    progress("closed: contact forces " + " ".join(f"{f:.1f}" for f in s.forces) + " N")
    s.restart(hand.clock.now() + config.release_s + config.settle_s)
    return np.asarray(s.forces), float(effort)


def _hold(s: _Sampler, config: ObjectHoldConfig, hit_log: Any, progress: Any) -> None:
    """Sample the object and the fingers at sample_hz, hitting the object as planned; stop
    early once the object has fallen well clear of the hand."""
    assert s.hold_start is not None  # set by the close
    hits = config.hit_plan()
    start = s.hold_start
    report = max(1, round(config.sample_hz * max(config.duration_s / 10, 1.0)))
    s.t0, s.k = start, 0
    while not s.fell:
        t_next = (s.k + 1) * s.period
        if t_next > config.duration_s + 1e-9:
            break
        t = s.sample("baseline" if t_next < config.baseline_s else "hold") - start
        while hits and hits[0][0] <= t:
            _, imp = hits.pop(0)
            s.plant.hit_object(imp, config.hit_duration_s)
            hit_log.write([f"{t:.6f}", *imp, config.hit_duration_s])
        if s.k % report == 0:
            moved = np.linalg.norm(s.plant.object_pose()[0] - s.ref) * 1e3
            progress(f"hold {t:7.1f} / {config.duration_s:g} s  object moved {moved:.2f} mm")
    if s.fell:
        progress(f"the {s.plant.object.name} fell out of the hand")


def _picture(plant: Any, path: Path) -> Path | None:
    """The hand holding the object, rendered off-screen; None when this machine cannot."""
    try:
        from utrf.models.render import RenderError, framed_camera, hand_camera, render_png
    except ImportError:
        return None
    try:  # framed: the hand and the object fill the picture
        camera = framed_camera(plant.model, plant.data, hand_camera())
        return render_png(plant.model, plant.data, path, camera=camera)
    except RenderError:
        return None


def analyse(out: Path) -> dict[str, Any]:
    """The object hold's figures, from its logs alone: a killed run's too (its cut last row
    is skipped; killed during the close, whose rows wait in memory, it has no samples)."""
    meta = json.loads((out / "meta.json").read_text())
    config = ObjectHoldConfig(**meta["config"])
    obj = config.grasp_object
    close = meta.get("close", {})
    rows = _read(out / "object_samples.csv", SAMPLE_COLUMNS)
    result: dict[str, Any] = {
        "object": obj.name,
        "pose": config.pose_name,
        "effort": close.get("effort", config.effort),
        "closed_contact_forces_n": close.get("contact_forces_n"),
        "planned_duration_s": config.duration_s,
        "samples": len(rows.get("time_s", ())),
        "breaking_force_n": obj.breaking_force_n,
    }
    if not result["samples"]:
        return {**result, "complete": False, "duration_s": 0.0, "dropped": False,
                "dropped_at_s": None, "slip_mm": None, "largest_displacement_mm": None,
                "hits": [], "largest_contact_force_n": dict.fromkeys(FINGERS, 0.0),
                "broke": None, "broke_at_s": None}  # fmt: skip
    t = rows["time_s"]
    pos = np.column_stack((rows["x_m"], rows["y_m"], rows["z_m"]))
    forces = np.column_stack([rows[f"force_{n}_n"] for n in FINGERS])
    # let go (after the close, whose object is held in place): a drop is measured from where
    # the grasp had it then, slip from the hold's baseline
    free = np.asarray(rows["phase"]) != "close"
    ref = pos[free][0] if free.any() else pos[0]
    fall = np.linalg.norm(pos - ref, axis=1) * 1e3
    dropped_at = next((float(t[i]) for i in np.nonzero(free)[0] if fall[i] > config.drop_mm), None)
    base = baseline_position(t, pos, config.baseline_s, ref)
    held = t >= 0
    disp = np.linalg.norm(pos[held] - base, axis=1) * 1e3  # mm
    hits_t = _read(out / "object_hits.csv", HIT_COLUMNS).get("time_s", np.zeros(0))
    hit_rows = []
    for j, th in enumerate(hits_t):
        end = hits_t[j + 1] if j + 1 < len(hits_t) else t[-1] + 1e-9
        seg = (t >= th) & (t < end)
        if not seg.any():
            continue
        before = pos[t < th][-1] if (t < th).any() else base
        d = np.linalg.norm(pos[seg] - before, axis=1) * 1e3
        ts = t[seg]
        rest = _rest_time(ts, pos[seg], config.rest_mm, config.rest_s)
        hit_rows.append(
            {
                "time_s": float(th),
                "peak_displacement_mm": float(d.max()),
                "recovery_s": None if rest is None else float(rest - th),
                "offset_after_mm": float(d[-1]),
            }
        )
    fmax = forces.max(axis=0)
    broke_at = None
    if obj.breaking_force_n is not None:
        over = np.nonzero(forces.max(axis=1) > obj.breaking_force_n)[0]
        broke_at = float(t[over[0]]) if len(over) else None
    duration = max(float(t[-1]), 0.0)
    ended = dropped_at is not None or duration >= config.duration_s - 1.5 / config.sample_hz
    return {
        **result,
        "duration_s": duration,
        "complete": ended,
        "dropped": dropped_at is not None,
        "dropped_at_s": dropped_at,
        # never held: how far it fell
        "slip_mm": float(disp[-1]) if len(disp) else float(fall[free].max(initial=0.0)),
        "largest_displacement_mm": float(max(disp.max(initial=0.0), fall[free].max(initial=0.0))),
        "hits": hit_rows,
        "largest_contact_force_n": {n: float(f) for n, f in zip(FINGERS, fmax, strict=True)},
        "broke": broke_at is not None if obj.fragile else None,
        "broke_at_s": broke_at,
    }


def baseline_position(t: np.ndarray, pos: np.ndarray, baseline_s: float, ref: np.ndarray) -> Any:
    """Where the object sat over the hold's baseline (its first ``baseline_s``): what slip and
    displacement are measured from; ``ref`` (where it was let go) when the run has none."""
    in_base = (t >= 0) & (t < baseline_s)
    return pos[in_base].mean(axis=0) if in_base.any() else ref


FINGERS = ("thumb", "index", "middle", "ring", "little")


def _rest_time(t: np.ndarray, pos: np.ndarray, rest_mm: float, rest_s: float) -> float | None:
    """The first time after which the object stays within ``rest_mm`` of where it ends up
    (its position at the end of the segment) for ``rest_s``."""
    final = pos[-1]
    d = np.linalg.norm(pos - final, axis=1) * 1e3
    for i in range(len(t)):
        j = np.searchsorted(t, t[i] + rest_s)
        if j >= len(t):
            return None
        if (d[i : j + 1] <= rest_mm).all():
            return float(t[i])
    return None


def _read(path: Path, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """A log's complete rows as columns (numbers as float); {} when it has none."""
    rows = read_rows(path, columns)
    if not rows:
        return {}
    return {c: np.array([r[c] for r in rows]) for c in columns}


def describe(result: dict[str, Any]) -> str:
    if not result["samples"]:
        return (
            f"object hold: the {result['object']} ({result['pose']}): no samples (the run "
            "ended during the close, whose samples are written once it is over)"
        )
    early = result["dropped"] and result["dropped_at_s"] < 0
    short = "" if result["complete"] else f" of {result['planned_duration_s']:g} s (cut short)"
    lines = [
        f"object hold: the {result['object']} ({result['pose']}), {result['duration_s']:.1f} s"
        + f"{short}, "
        + (f"DROPPED at {result['dropped_at_s']:.2f} s" if result["dropped"] else "held")
        + (" (before the hold: times are from its start)" if early else ""),
        f"object slip {result['slip_mm']:.2f} mm (largest displacement "
        f"{result['largest_displacement_mm']:.2f} mm)",
        "largest contact force per finger: "
        + "  ".join(f"{n} {f:.1f} N" for n, f in result["largest_contact_force_n"].items()),
    ]
    if result["broke"] is not None:
        lines.append(
            f"fragile ({result['breaking_force_n']:g} N): "
            + (f"BROKE at {result['broke_at_s']:.2f} s" if result["broke"] else "intact")
        )
    for h in result["hits"]:
        rec = (
            "not recovered" if h["recovery_s"] is None else f"at rest after {h['recovery_s']:.3f} s"
        )
        lines.append(
            f"hit at {h['time_s']:7.2f} s: peak {h['peak_displacement_mm']:.2f} mm, {rec}, "
            f"{h['offset_after_mm']:.2f} mm off"
        )
    return "\n".join(lines)
