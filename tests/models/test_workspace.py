"""Workspace (Sec. II-C): swept areas, checked against closed forms and the postures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from utrf.models import kinematics, workspace
from utrf.models.geometry import FingerGeometry


@pytest.fixture(scope="module")
def ws() -> workspace.Workspace:
    return workspace.swept(FingerGeometry.default(), 5e-4)


def test_link1_sweeps_a_half_disc(ws: workspace.Workspace) -> None:
    g = FingerGeometry.default()
    exact = math.pi * g.link_lengths_m[0] ** 2 / 2  # θ1 over ±90°, s over [0, L1]
    perimeter = math.pi * g.link_lengths_m[0] + 2 * g.link_lengths_m[0]
    raster = ws.link_areas_m2[0]
    assert exact <= raster <= exact + perimeter * ws.resolution_m  # the stated bound
    extrapolated = workspace.areas(g, fine=ws).link_areas_m2[0]
    assert abs(extrapolated - exact) < 0.2 * abs(raster - exact)


def test_a_quarter_range_sweeps_a_quarter_disc() -> None:
    g = FingerGeometry.default()
    a = workspace.areas(g, 5e-4, q_range=(0.0, g.q_range_m[1]))
    assert a.link_areas_m2[0] == pytest.approx(math.pi * 0.07**2 / 4, rel=0.005)


def test_every_posture_lies_in_its_link_area(ws: workspace.Workspace) -> None:
    g = FingerGeometry.default()
    rng = np.random.default_rng(1)
    q = rng.uniform(*g.q_range_m, 200)
    s = rng.uniform(0, 1, 200)
    pts = kinematics.joint_positions(g, q)
    for k in range(3):
        p = pts[:, k] + s[:, None] * (pts[:, k + 1] - pts[:, k])
        assert ws.contains(p, k + 1).all()


def test_nothing_beyond_the_finger_reach(ws: workspace.Workspace) -> None:
    g = FingerGeometry.default()
    ang = np.linspace(0, 2 * math.pi, 400)
    far = 1.02 * g.total_length_m * np.column_stack([np.cos(ang), np.sin(ang)])
    for k in (1, 2, 3):
        assert not ws.contains(far, k).any()
    # Link 1 never reaches behind Joint 1 (x < 0) with θ1 within ±90°.
    behind = np.column_stack([np.full(50, -0.01), np.linspace(-0.06, 0.06, 50)])
    assert not ws.contains(behind, 1).any()


def test_bad_resolution_is_refused() -> None:
    g = FingerGeometry.default()
    with pytest.raises(ValueError, match="resolution_m"):
        workspace.swept(g, 0.0)
    with pytest.raises(ValueError, match="q_range"):
        workspace.swept(g, 1e-3, q_range=(0.01, -0.01))


def test_figure_is_written(ws: workspace.Workspace, tmp_path: Path) -> None:
    out = workspace.plot(ws, FingerGeometry.default(), tmp_path / "w.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
