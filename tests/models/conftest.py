"""Shared strategies for the finger-model tests: random valid geometries and bounded loads."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume
from hypothesis import strategies as st

from utrf.models import tendons
from utrf.models.geometry import FingerGeometry


@pytest.fixture
def geom() -> FingerGeometry:
    return FingerGeometry.default()


@st.composite
def geometries(draw: st.DrawFn) -> FingerGeometry:
    """Valid fingers over a wide range of proportions (lengths 20-90 mm, radii 2-15 mm)."""
    L = [draw(st.floats(0.02, 0.09)) for _ in range(3)]
    R = [draw(st.floats(0.002, 0.015)) for _ in range(3)]
    assume(R[0] + R[1] < 0.9 * L[0] and R[1] + R[2] < 0.9 * L[1])
    return FingerGeometry(
        link_lengths_m=tuple(L),  # type: ignore[arg-type]
        guide_radii_m=tuple(R),  # type: ignore[arg-type]
        tendon_diameter_m=draw(st.floats(0.5e-3, 1.5e-3)),
        tendon_youngs_modulus_pa=draw(st.floats(50e9, 250e9)),
        actuating_tendon_length_m=draw(st.floats(0.03, 0.3)),
        link_masses_kg=tuple(draw(st.floats(0.0, 0.05)) for _ in range(3)),  # type: ignore[arg-type]
        link_com_fraction=tuple(draw(st.floats(0.0, 1.0)) for _ in range(3)),  # type: ignore[arg-type]
        theta1_range_rad=(-math.pi / 2, math.pi / 2),
    )


def moderate_force(geom: FingerGeometry, rotation_rad: float = 0.15) -> float:
    """A tip force (N) whose tendon stretch turns the joints by about ``rotation_rad``.

    First order: a tip force F needs tensions up to ~F L / R and turns the joints by
    ~(T L_T / EA) / R, so F ~ rotation · EA R_min² / (L L_T_max).
    """
    ea = geom.tendon_youngs_modulus_pa * geom.tendon_area_m2
    r = min(geom.guide_radii_m)
    return rotation_rad * ea * r**2 / (3 * geom.total_length_m * tendons.rest_lengths(geom).max())


@st.composite
def cases(
    draw: st.DrawFn, rotation_rad: float = 0.15
) -> tuple[FingerGeometry, float, dict[str, object]]:
    """A geometry, a q within its range and a conservative load of moderate size."""
    g = draw(geometries())
    lo, hi = g.q_range_m
    q = draw(st.floats(lo, hi))
    f = moderate_force(g, rotation_rad)
    angle = draw(st.floats(-math.pi, math.pi))
    mag = draw(st.floats(0.0, f))
    moment = draw(st.floats(-1.0, 1.0)) * f * g.total_length_m / 3
    load = {
        "tip_force_n": (mag * math.cos(angle), mag * math.sin(angle)),
        "tip_moment_nm": moment,
        "gravity": draw(st.booleans()),
    }
    return g, q, load


def unit(a: float | np.ndarray) -> np.ndarray:
    return np.stack([np.cos(a), np.sin(a)], axis=-1)
