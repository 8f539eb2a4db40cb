"""Finger and hand geometry: one schema for the models, the firmware table, the plant and HIL.

A finger file is TOML with a ``[finger]`` table (see ``utrf/data/geometry/finger.toml``).
Values are SI (m, Pa, kg) except ``theta1_range_deg``, kept in degrees as people write it;
the loaded object holds radians. Bad values raise :class:`GeometryError` naming the field.

Frame: Joint 1 at the origin; at q = 0 the finger lies straight along +x; θ is positive in
flexion, toward +y; gravity and bench loads act along −y. Joint angles are relative
(θ_i of link i to link i−1), coupled by the tendons as θ_i = q / R_i.
"""

from __future__ import annotations

import contextlib
import math
import tomllib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

ACTUATIONS = ("antagonistic", "rotary")
FINGER_KEYS = (
    "link_lengths_m",
    "guide_radii_m",
    "tendon_diameter_m",
    "tendon_youngs_modulus_pa",
    "actuating_tendon_length_m",
    "link_masses_kg",
    "link_com_fraction",
    "theta1_range_deg",
)


class GeometryError(ValueError):
    """A finger or hand description that cannot describe a real finger."""


def read_toml(path: Path, what: str, error: type[ValueError] = GeometryError) -> dict[str, Any]:
    """The TOML document at ``path``; ``error`` naming the file (a ``what`` file) when there
    is none or it is not TOML."""
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path}: no such {what} file") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None


@contextlib.contextmanager
def package_data(*parts: str) -> Iterator[Path]:
    """A file under the package's ``data/`` as a real path while in use: the one place that
    says where the built-in TOML files are, installed or from a checkout."""
    ref = resources.files("utrf") / "data"
    for part in parts:
        ref = ref / part
    with resources.as_file(ref) as path:
        yield path


def _triple(
    data: Mapping[str, Any], key: str, where: str, *, positive: bool
) -> tuple[float, float, float]:
    value = data.get(key)
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != 3:
        raise GeometryError(f"{where}: {key} must be a list of 3 numbers, got {value!r}")
    out = []
    for i, v in enumerate(value):
        if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise GeometryError(f"{where}: {key}[{i}] must be a finite number, got {v!r}")
        if positive and v <= 0:
            raise GeometryError(f"{where}: {key}[{i}] must be > 0, got {v!r}")
        if not positive and v < 0:
            raise GeometryError(f"{where}: {key}[{i}] must be >= 0, got {v!r}")
        out.append(float(v))
    return (out[0], out[1], out[2])


def _positive(data: Mapping[str, Any], key: str, where: str) -> float:
    v = data.get(key)
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
        raise GeometryError(f"{where}: {key} must be a number > 0, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class FingerGeometry:
    """One UTRF finger. Lengths in m, angles in rad, modulus in Pa, masses in kg."""

    link_lengths_m: tuple[float, float, float] = (0.070, 0.055, 0.045)
    guide_radii_m: tuple[float, float, float] = (0.0100, 0.0095, 0.0090)
    tendon_diameter_m: float = 0.001
    tendon_youngs_modulus_pa: float = 200e9
    actuating_tendon_length_m: float = 0.100
    link_masses_kg: tuple[float, float, float] = (0.012, 0.009, 0.006)
    link_com_fraction: tuple[float, float, float] = (0.5, 0.5, 0.5)
    theta1_range_rad: tuple[float, float] = (-math.pi / 2, math.pi / 2)
    source: str = field(default="<defaults>", compare=False)

    def __post_init__(self) -> None:
        self._validate()

    # -- loading -----------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<dict>") -> FingerGeometry:
        """Build from the ``[finger]`` table's keys (degrees for ``theta1_range_deg``)."""
        where = f"{source} [finger]"
        unknown = sorted(set(data) - set(FINGER_KEYS))
        if unknown:
            raise GeometryError(f"{where}: unknown key(s) {unknown}; expected {list(FINGER_KEYS)}")
        missing = [k for k in FINGER_KEYS if k not in data]
        if missing:
            raise GeometryError(f"{where}: missing key(s) {missing}")
        rng = data["theta1_range_deg"]
        if not isinstance(rng, Sequence) or isinstance(rng, str) or len(rng) != 2:
            raise GeometryError(f"{where}: theta1_range_deg must be [min, max], got {rng!r}")
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in rng):
            raise GeometryError(f"{where}: theta1_range_deg must hold numbers, got {rng!r}")
        return cls(
            link_lengths_m=_triple(data, "link_lengths_m", where, positive=True),
            guide_radii_m=_triple(data, "guide_radii_m", where, positive=True),
            tendon_diameter_m=_positive(data, "tendon_diameter_m", where),
            tendon_youngs_modulus_pa=_positive(data, "tendon_youngs_modulus_pa", where),
            actuating_tendon_length_m=_positive(data, "actuating_tendon_length_m", where),
            link_masses_kg=_triple(data, "link_masses_kg", where, positive=False),
            link_com_fraction=_triple(data, "link_com_fraction", where, positive=False),
            theta1_range_rad=(math.radians(rng[0]), math.radians(rng[1])),
            source=source,
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> FingerGeometry:
        path = Path(path)
        doc = read_toml(path, "geometry")
        if "finger" not in doc or not isinstance(doc["finger"], dict):
            raise GeometryError(f"{path}: needs a [finger] table")
        return cls.from_dict(doc["finger"], source=str(path))

    @classmethod
    def default(cls) -> FingerGeometry:
        """The documented default finger (an assumption: the paper gives no dimensions)."""
        with package_data("geometry", "finger.toml") as path:
            return cls.from_toml(path)

    def to_dict(self) -> dict[str, Any]:
        """The ``[finger]`` table, as it would be written to TOML."""
        return {
            "link_lengths_m": list(self.link_lengths_m),
            "guide_radii_m": list(self.guide_radii_m),
            "tendon_diameter_m": self.tendon_diameter_m,
            "tendon_youngs_modulus_pa": self.tendon_youngs_modulus_pa,
            "actuating_tendon_length_m": self.actuating_tendon_length_m,
            "link_masses_kg": list(self.link_masses_kg),
            "link_com_fraction": list(self.link_com_fraction),
            "theta1_range_deg": [math.degrees(a) for a in self.theta1_range_rad],
        }

    def _validate(self) -> None:
        where = f"{self.source} [finger]"
        L, R = self.link_lengths_m, self.guide_radii_m
        if len(L) != 3 or len(R) != 3:
            raise GeometryError(f"{where}: link_lengths_m and guide_radii_m need 3 values each")
        if min(L) <= 0:
            raise GeometryError(f"{where}: link_lengths_m must be > 0, got {list(L)}")
        if min(R) <= 0:
            raise GeometryError(f"{where}: guide_radii_m must be > 0, got {list(R)}")
        # A crossed coupling tendon between guides of radii R_i and R_{i+1} whose axes are
        # L_i apart has a straight span sqrt(L_i² − (R_i + R_{i+1})²): it needs R_i + R_{i+1} < L_i.
        for i in range(2):
            if R[i] + R[i + 1] >= L[i]:
                raise GeometryError(
                    f"{where}: guide_radii_m R{i + 1} + R{i + 2} = {R[i] + R[i + 1]:g} m must be "
                    f"< link_lengths_m L{i + 1} = {L[i]:g} m, or coupling Tendon {i + 2} "
                    "cannot cross between the guides"
                )
        if not all(0.0 <= c <= 1.0 for c in self.link_com_fraction):
            raise GeometryError(
                f"{where}: link_com_fraction must be within [0, 1], "
                f"got {list(self.link_com_fraction)}"
            )
        if min(self.link_masses_kg) < 0:
            raise GeometryError(f"{where}: link_masses_kg must be >= 0")
        lo, hi = self.theta1_range_rad
        if not (-math.pi <= lo < hi <= math.pi):
            raise GeometryError(
                f"{where}: theta1_range_deg must satisfy -180 <= min < max <= 180, "
                f"got [{math.degrees(lo):g}, {math.degrees(hi):g}]"
            )
        for name in ("tendon_diameter_m", "tendon_youngs_modulus_pa", "actuating_tendon_length_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise GeometryError(f"{where}: {name} must be > 0, got {v!r}")

    # -- derived quantities -----------------------------------------------------------------
    @property
    def L(self) -> np.ndarray:
        """Link lengths (m), shape (3,)."""
        return np.asarray(self.link_lengths_m, dtype=float)

    @property
    def R(self) -> np.ndarray:
        """Guide radii (m), shape (3,)."""
        return np.asarray(self.guide_radii_m, dtype=float)

    @property
    def total_length_m(self) -> float:
        return float(sum(self.link_lengths_m))

    @property
    def tendon_area_m2(self) -> float:
        return math.pi * self.tendon_diameter_m**2 / 4.0

    @property
    def q_range_m(self) -> tuple[float, float]:
        """Tendon displacement range, from θ1 = q / R1 within theta1_range."""
        r1 = self.guide_radii_m[0]
        return (r1 * self.theta1_range_rad[0], r1 * self.theta1_range_rad[1])

    @property
    def theta2_range_rad(self) -> tuple[float, float]:
        """Joint-2 angle range implied by the θ1 range and the coupling θ2 = q / R2."""
        r2 = self.guide_radii_m[1]
        lo, hi = self.q_range_m
        return (lo / r2, hi / r2)


@dataclass(frozen=True)
class FingerSpec:
    """One finger of a hand: its name, geometry and actuation mode."""

    name: str
    geometry: FingerGeometry
    actuation: str = "antagonistic"


@dataclass(frozen=True)
class HandGeometry:
    """The five fingers in board order (index 0..4 on the wire)."""

    name: str
    fingers: tuple[FingerSpec, ...]

    @classmethod
    def from_toml(cls, path: str | Path) -> HandGeometry:
        path = Path(path)
        doc = read_toml(path, "hand")
        hand = doc.get("hand")
        if not isinstance(hand, dict):
            raise GeometryError(f"{path}: needs a [hand] table")
        entries = hand.get("finger")
        if not isinstance(entries, list) or len(entries) != 5:
            raise GeometryError(f"{path}: [[hand.finger]] must appear exactly 5 times")
        fingers = []
        for i, entry in enumerate(entries):
            where = f"{path} [[hand.finger]] #{i}"
            name = entry.get("name")
            if not isinstance(name, str) or not name:
                raise GeometryError(f"{where}: name must be a non-empty string")
            actuation = entry.get("actuation", "antagonistic")
            if actuation not in ACTUATIONS:
                raise GeometryError(
                    f"{where}: actuation must be one of {ACTUATIONS}, got {actuation!r}"
                )
            geo = entry.get("geometry")
            if isinstance(geo, str):
                geometry = FingerGeometry.from_toml(path.parent / geo)
            elif isinstance(geo, dict):
                geometry = FingerGeometry.from_dict(geo, source=where)
            else:
                raise GeometryError(f"{where}: geometry must be a file name or a table")
            fingers.append(FingerSpec(name=name, geometry=geometry, actuation=actuation))
        names = [f.name for f in fingers]
        if len(set(names)) != len(names):
            raise GeometryError(f"{path}: finger names must be unique, got {names}")
        return cls(name=str(hand.get("name", path.stem)), fingers=tuple(fingers))

    @classmethod
    def default(cls) -> HandGeometry:
        with package_data("hand.toml") as path:
            return cls.from_toml(path)

    def index(self, name: str) -> int:
        for i, f in enumerate(self.fingers):
            if f.name == name:
                return i
        raise KeyError(f"no finger named {name!r}; fingers are {[f.name for f in self.fingers]}")
