"""The hand's joints in 3D from the Joint-2 angles: what a viewer draws (the dashboard's 3D
hand, a recording's Foxglove scene). Fingers are placed on the palm as the MJCF places them
(``utrf/data/mjcf.toml``) and bent on the rigid coupling (θ_i = q / R_i), so the points are
the MuJoCo model's joints and tip at the same angles (tests/models/test_skeleton.py)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.models.mjcf_layout import Layout, load_layout


class HandSkeleton:
    """Joint 1, Joint 2, Joint 3 and the tip of every finger in the palm frame (m)."""

    def __init__(self, hand: HandGeometry | None = None, layout: Layout | None = None) -> None:
        self.hand = hand if hand is not None else HandGeometry.default()
        layout = layout if layout is not None else load_layout()
        self.names = tuple(f.name for f in self.hand.fingers)
        missing = [n for n in self.names if n not in layout.fingers]
        if missing:
            raise ValueError(f"the MJCF layout {layout.source} places no finger {missing}")
        self._origin = np.array([layout.fingers[n].position_m for n in self.names])
        # the finger's plane (its x and y axes) in the palm frame
        self._axes = np.array([layout.fingers[n].rotation()[:, :2] for n in self.names])
        self.palm_size_m = layout.palm_size_m

    def points(self, theta2: Sequence[float]) -> np.ndarray:
        """Shape (fingers, 4, 3): each finger's joints and tip at its Joint-2 angle (rad),
        clamped to the finger's range."""
        if len(theta2) != len(self.names):
            raise ValueError(f"need {len(self.names)} Joint-2 angles, got {len(theta2)}")
        out = np.empty((len(self.names), 4, 3))
        for i, f in enumerate(self.hand.fingers):
            g = f.geometry
            lo, hi = g.q_range_m
            q = min(max(float(theta2[i]) * g.guide_radii_m[1], lo), hi)
            planar = kinematics.joint_positions(g, q)  # (4, 2) in the finger's frame
            out[i] = self._origin[i] + planar @ self._axes[i].T
        return out
