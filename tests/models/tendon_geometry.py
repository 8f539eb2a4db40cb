"""Explicit planar geometry of the tendons, written for the tests independently of the models.

A crossed coupling strand runs between guide A (centred at the spanning link's proximal joint,
fixed to the body before it) and guide B (centred at the distal joint, fixed to the body after
it), with axes ``d`` apart. Its tangent points are found by a root search, its wraps from the
anchors' angles with atan2, so nothing here reuses the closed forms under test.

Frames: the spanning link's, x from A's centre to B's. ``rot_a`` is the proximal body's angle
relative to the spanning link (−θ of the proximal joint), ``rot_b`` the distal body's (θ of the
distal joint). Anchors sit at the far ends of the line of centres when straight: angle π on A,
0 on B. The flexion strand leaves A on its −y side and reaches B on its +y side; the extension
strand is the mirror image.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq


def tangent_points(r_a: float, r_b: float, d: float, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Points where the crossed strand leaves A and meets B (spanning link's frame)."""

    # A line tangent to A at angle a has unit normal n(a); B's centre must sit r_b beyond it.
    def gap(a: float) -> float:
        return d * math.cos(a) - r_a - r_b

    a = brentq(gap, 0.0, math.pi / 2, xtol=1e-15)
    sign = -1.0 if side == "flexion" else 1.0
    n = np.array([math.cos(a), sign * math.sin(a)])
    p_a = r_a * n
    p_b = np.array([d, 0.0]) - r_b * n
    return p_a, p_b


def _angle(p: np.ndarray) -> float:
    return math.atan2(p[1], p[0])


def crossed_path_length(
    r_a: float, r_b: float, d: float, rot_a: float, rot_b: float, side: str
) -> tuple[float, float, float]:
    """(total length, wrap on A, wrap on B) of the taut strand; wraps in rad."""
    p_a, p_b = tangent_points(r_a, r_b, d, side)
    anchor_a = math.pi + rot_a
    anchor_b = rot_b
    # The flexion strand travels counter-clockwise on A from its anchor to p_a, then clockwise
    # on B from p_b to its anchor; the extension strand the other way round.
    if side == "flexion":
        wrap_a = (_angle(p_a) - anchor_a) % (2 * math.pi)
        wrap_b = (_angle(p_b - np.array([d, 0.0])) - anchor_b) % (2 * math.pi)
    else:
        wrap_a = (anchor_a - _angle(p_a)) % (2 * math.pi)
        wrap_b = (anchor_b - _angle(p_b - np.array([d, 0.0]))) % (2 * math.pi)
    span = float(np.hypot(*(p_b - p_a)))
    return r_a * wrap_a + span + r_b * wrap_b, wrap_a, wrap_b


def rotate(v: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
