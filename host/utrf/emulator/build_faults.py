"""A twin that can be built wrong: the mistakes a person makes building the hand from the paper,
put into the emulated plant where the physical fault is (the driver-to-motor wiring, the motor's
constants, the tendons, the joint stops, the encoder's magnet and cable), never into the
firmware. A bring-up on such a board sees only the wire, as on a real hand.

    build = BuildFaults.parse(["swap-leads:index", "slack:2=0.003", "swap-cables:1,2"])
    with EmulatedBoard(realtime=False, build=build) as board: ...

:meth:`BuildFaults.random` draws a seeded build (several faults, the motors' constants drawn
±30 % around the model's) for a campaign. ``docs/mujoco.md`` lists the kinds.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from utrf.emulator.plant_params import FINGERS, PlantError, _finger_index

if TYPE_CHECKING:
    from utrf.emulator.mujoco_plant import MujocoPlant

FINGER_NAMES = ("thumb", "index", "middle", "ring", "little")

#: kind -> (what it is, the value's meaning and unit, or "" for none)
KINDS: dict[str, tuple[str, str]] = {
    "swap-leads": ("both motors' leads swapped (the driver's outputs wired the other way)", ""),
    "swap-lead-a": ("motor A's leads swapped (it pushes when driven to pull)", ""),
    "invert-magnet": ("the encoder's magnet glued the other way round", ""),
    "magnet-offset": ("the magnet glued turned by VALUE rad", "rad"),
    "off-centre": ("the magnet off-centre: a once-per-turn error of VALUE rad", "rad"),
    "slack": ("Tendon 2 longer by VALUE m: Joint 1 (the motor) moves that far before Joint 2", "m"),
    "weak-motor": ("both motors give VALUE times the model's stall force", "factor"),
    "slow-motor": ("both motors run at VALUE times the model's no-load speed", "factor"),
    "narrow-range": ("the closed stop at Joint-2 angle VALUE rad (flexion stops early)", "rad"),
    "friction": ("VALUE N more Coulomb friction at each motor carriage", "N"),
    "unpowered": ("the finger's driver has no motor supply (or STBY wired low)", ""),
    "unplugged": ("the encoder's cable is off (the ADC input reads 0 V)", ""),
    "swap-cables": ("two fingers' motor cables swapped between driver channels", "pair"),
    "swap-encoders": ("two fingers' encoder cables swapped between ADC inputs", "pair"),
}
PAIR_KINDS = ("swap-cables", "swap-encoders")
#: the kinds a finger's configuration (and its tuning) can fix
FIXABLE_KINDS = (
    "swap-leads",
    "invert-magnet",
    "magnet-offset",
    "weak-motor",
    "slow-motor",
    "narrow-range",
    "friction",
)
#: a motor constant below this times the model's is a fault (a wrong part), not the spread
WRONG_PART = 0.5


@dataclass(frozen=True)
class FingerBuild:
    """How one finger was built (the defaults: as the model says)."""

    leads: str = "ok"  # "ok", "swapped" (both motors), "a" (motor A alone)
    magnet_inverted: bool = False
    magnet_offset_rad: float = 0.0
    magnet_eccentric_rad: float = 0.0
    slack_m: float = 0.0  # Tendon 2 (the Joint-1-to-Joint-2 flexion coupling)
    force_scale: float = 1.0  # stall force, times the model's
    speed_scale: float = 1.0  # no-load speed, times the model's
    closed_stop_rad: float | None = None  # Joint-2 angle of the closed stop; None: the model's
    friction_n: float = 0.0  # extra Coulomb friction at each carriage
    unpowered: bool = False
    unplugged: bool = False

    def faults(self) -> list[str]:
        """The kinds of fault in this finger (constants drawn near the model's are not)."""
        out = []
        if self.leads == "swapped":
            out.append("swap-leads")
        if self.leads == "a":
            out.append("swap-lead-a")
        for kind, on in (
            ("invert-magnet", self.magnet_inverted),
            ("magnet-offset", abs(self.magnet_offset_rad) > 0.0),
            ("off-centre", abs(self.magnet_eccentric_rad) > 0.0),
            ("slack", self.slack_m > 0.0),
            # a motor far outside the spread any build's motors have (a wrong part)
            ("weak-motor", self.force_scale < WRONG_PART),
            ("slow-motor", self.speed_scale < WRONG_PART),
            ("narrow-range", self.closed_stop_rad is not None),
            ("friction", self.friction_n > 0.0),
            ("unpowered", self.unpowered),
            ("unplugged", self.unplugged),
        ):
            if on:
                out.append(kind)
        return out


@dataclass(frozen=True)
class BuildFaults:
    """A whole hand's build: per finger (0 thumb .. 4 little), and the cable swaps."""

    fingers: tuple[FingerBuild, ...] = field(default_factory=lambda: (FingerBuild(),) * FINGERS)
    motor_swap: tuple[int, int] | None = None
    encoder_swap: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if len(self.fingers) != FINGERS:
            raise PlantError(f"a build has {FINGERS} fingers, got {len(self.fingers)}")
        for pair in (self.motor_swap, self.encoder_swap):
            if pair is not None and (len(pair) != 2 or pair[0] == pair[1]):
                raise PlantError(f"a swap names two different fingers, got {pair!r}")
        for f, b in enumerate(self.fingers):
            if b.leads not in ("ok", "swapped", "a"):
                raise PlantError(f"finger {f}: leads must be ok, swapped or a, got {b.leads!r}")
            for name in ("force_scale", "speed_scale"):
                v = getattr(b, name)
                if not (math.isfinite(v) and 0.05 <= v <= 5.0):
                    raise PlantError(f"finger {f}: {name} must lie in [0.05, 5], got {v!r}")
            if not (math.isfinite(b.slack_m) and 0.0 <= b.slack_m <= 0.02):
                raise PlantError(f"finger {f}: slack must lie in [0, 0.02] m, got {b.slack_m!r}")
            if not (math.isfinite(b.friction_n) and 0.0 <= b.friction_n <= 100.0):
                raise PlantError(f"finger {f}: friction must lie in [0, 100] N, got {b.friction_n}")

    @property
    def is_model(self) -> bool:
        return self == BuildFaults()

    def faults(self) -> list[tuple[str, tuple[int, ...]]]:
        """Every fault as (kind, fingers)."""
        out: list[tuple[str, tuple[int, ...]]] = [
            (k, (f,)) for f, b in enumerate(self.fingers) for k in b.faults()
        ]
        if self.motor_swap is not None:
            out.append(("swap-cables", tuple(sorted(self.motor_swap))))
        if self.encoder_swap is not None:
            out.append(("swap-encoders", tuple(sorted(self.encoder_swap))))
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "fingers": [asdict(b) for b in self.fingers],
            "motor_swap": self.motor_swap,
            "encoder_swap": self.encoder_swap,
            "faults": [{"kind": k, "fingers": list(f)} for k, f in self.faults()],
        }

    def with_finger(self, finger: int, **changes: Any) -> BuildFaults:
        f = _finger_index(finger)
        fingers = list(self.fingers)
        fingers[f] = replace(fingers[f], **changes)
        return replace(self, fingers=tuple(fingers))

    # -- from words ------------------------------------------------------------------------------
    @classmethod
    def parse(
        cls, specs: list[str] | tuple[str, ...], base: BuildFaults | None = None
    ) -> BuildFaults:
        """From ``KIND:FINGER[=VALUE]`` or ``KIND:F1,F2`` words (fingers by name or 0..4), e.g.
        ``swap-leads:index``, ``slack:2=0.003``, ``swap-cables:1,2``. A bad word raises
        PlantError naming it and the kinds. ``base``: the build they add to."""
        build = base if base is not None else cls()
        for spec in specs:
            build = build._add(spec)
        return build

    def _add(self, spec: str) -> BuildFaults:
        kind, _, rest = spec.partition(":")
        where, _, value = rest.partition("=")
        if kind not in KINDS or not where:
            raise PlantError(
                f"build fault {spec!r}: write KIND:FINGER[=VALUE]; kinds: {', '.join(KINDS)}"
            )
        fingers = [_finger(w, spec) for w in where.split(",")]
        if kind in PAIR_KINDS:
            if len(fingers) != 2 or value:
                raise PlantError(f"build fault {spec!r}: {kind} names two fingers, no value")
            pair = (fingers[0], fingers[1])
            if kind == "swap-cables":
                return replace(self, motor_swap=pair)
            return replace(self, encoder_swap=pair)
        if len(fingers) != 1:
            raise PlantError(f"build fault {spec!r}: {kind} names one finger")
        unit = KINDS[kind][1]
        if bool(unit) != bool(value):
            need = f"a value in {unit}" if unit else "no value"
            raise PlantError(f"build fault {spec!r}: {kind} takes {need}")
        try:
            v = float(value) if value else 0.0
        except ValueError:
            raise PlantError(f"build fault {spec!r}: {value!r} is not a number") from None
        every: dict[str, dict[str, Any]] = {
            "swap-leads": {"leads": "swapped"},
            "swap-lead-a": {"leads": "a"},
            "invert-magnet": {"magnet_inverted": True},
            "magnet-offset": {"magnet_offset_rad": v},
            "off-centre": {"magnet_eccentric_rad": v},
            "slack": {"slack_m": v},
            "weak-motor": {"force_scale": v},
            "slow-motor": {"speed_scale": v},
            "narrow-range": {"closed_stop_rad": v},
            "friction": {"friction_n": v},
            "unpowered": {"unpowered": True},
            "unplugged": {"unplugged": True},
        }
        return self.with_finger(fingers[0], **every[kind])

    # -- seeded builds ---------------------------------------------------------------------------
    @classmethod
    def random(
        cls,
        seed: int,
        faults: int = 3,
        spread: float = 0.3,
        kinds: tuple[str, ...] | None = None,
    ) -> BuildFaults:
        """A seeded build: every motor's stall force and speed drawn within ±``spread`` of the
        model's (not faults: what any build has), and ``faults`` faults on distinct fingers
        drawn from ``kinds`` (default: every kind), with values in the ranges a bring-up must
        handle."""
        rng = np.random.default_rng([0xB01D, int(seed)])
        build = cls()
        for f in range(FINGERS):
            build = build.with_finger(
                f,
                force_scale=float(1 + rng.uniform(-spread, spread)),
                speed_scale=float(1 + rng.uniform(-spread, spread)),
            )
        pool = list(KINDS) if kinds is None else [k for k in KINDS if k in kinds]
        if kinds is not None and len(pool) != len(set(kinds)):
            raise PlantError(f"unknown build fault kinds in {kinds!r}; kinds: {', '.join(KINDS)}")
        free = list(rng.permutation(FINGERS))
        for kind in rng.permutation(pool)[: max(0, int(faults))]:
            need = 2 if kind in PAIR_KINDS else 1
            if len(free) < need:
                break
            fs = [int(free.pop()) for _ in range(need)]
            value = {
                "magnet-offset": rng.uniform(0.15, 0.6) * rng.choice([-1, 1]),
                "slack": rng.uniform(0.001, 0.002),
                "narrow-range": rng.uniform(1.45, 1.55),
                "friction": rng.uniform(5.0, 12.0),
                # well outside the ±spread every motor has, as a wrong part would be
                "weak-motor": rng.uniform(0.25, 0.35),
                "slow-motor": rng.uniform(0.3, 0.42),
                "off-centre": rng.uniform(0.3, 0.5) * rng.choice([-1, 1]),
            }.get(str(kind))
            word = f"{kind}:{','.join(map(str, fs))}" + (f"={value:.4f}" if value else "")
            build = build._add(word)
        return build

    # -- into the plant --------------------------------------------------------------------------
    def apply(self, plant: MujocoPlant) -> None:
        """Build the plant this way (once, before the board runs)."""
        st = plant.native.state
        m = plant.model
        for f, b in enumerate(self.fingers):
            lead = {"ok": (1, 1), "swapped": (-1, -1), "a": (-1, 1)}[b.leads]
            st["build_lead"][f] = lead
            st["build_powered"][f] = 0.0 if b.unpowered else 1.0
            # stall force K V / R and no-load speed V / K: slower scales K and R by 1 / speed,
            # weaker R by 1 / force
            st["build_k_scale"][f] = 1.0 / b.speed_scale
            st["build_r_scale"][f] = 1.0 / (b.speed_scale * b.force_scale)
            st["build_encoder_invert"][f] = float(b.magnet_inverted)
            st["build_encoder_offset"][f] = b.magnet_offset_rad
            st["build_encoder_eccentric"][f] = b.magnet_eccentric_rad
            name = plant.names[f]
            if b.slack_m:
                # Tendon 2 longer by the slack: Joint 2 hangs free between its strands. A
                # strand's spring and damping act only while it is taut, so both coupling
                # strands become one-sided limits (MuJoCo's tendon limit: a constraint, stiff
                # and critically damped at the timestep, solved implicitly), Tendon 2 taut
                # past the slack and Tendon 5 past zero. Their two-sided damping (the model's,
                # on the stretch's speed) would couple Joint 2 to Joint 1 through the slack,
                # and undamped springs made the thumb's stiff strands blow up (MuJoCo's "Nan,
                # Inf or huge value in QACC").
                for k, taut in (("t2", b.slack_m), ("t5", 0.0)):
                    t = m.tendon(f"{name}_{k}").id
                    m.tendon_stiffness[t] = 0.0
                    m.tendon_damping[t] = 0.0
                    m.tendon_limited[t] = 1
                    m.tendon_range[t] = (-10.0, taut)
                    m.tendon_solref_lim[t] = (2.0 * m.opt.timestep, 1.0)
            if b.friction_n:
                for side in ("xa", "xb"):
                    m.dof_frictionloss[m.jnt_dofadr[m.joint(f"{name}_{side}").id]] += b.friction_n
            if b.closed_stop_rad is not None:
                plant.set_closed_stop(f, b.closed_stop_rad)
            if b.unplugged:
                plant.unplug_encoder(f)
        for key, pair in (
            ("build_motor_from", self.motor_swap),
            ("build_encoder_from", self.encoder_swap),
        ):
            if pair is not None:
                st[key][pair[0]], st[key][pair[1]] = pair[1], pair[0]


def _finger(word: str, spec: str) -> int:
    w = word.strip().lower()
    if w in FINGER_NAMES:
        return FINGER_NAMES.index(w)
    if w.isdigit() and int(w) < FINGERS:
        return int(w)
    raise PlantError(f"build fault {spec!r}: {word!r} is not a finger (0..4 or {FINGER_NAMES})")
