"""A finger's loaded equilibrium computed from the MuJoCo hand's own forces.

The motors hold the tendon displacement q (x_a = q, x_b = −q, every tendon just taut when
unloaded); the three joint angles are found where MuJoCo's generalised forces on them balance:
its tendon springs (``qfrc_passive``), its gravity (``qfrc_bias`` at rest) and the load applied
at the fingertip with ``mj_applyFT``. Newton's method on those three residuals, with a
central-difference Jacobian. Contacts and joint limits take no part (``qfrc_constraint`` is
not in the balance): this is the tendon statics of ``utrf.models.statics``, computed by
MuJoCo, so the two can be checked against each other.

Gravity acts along the finger's own −y (its frame's, as in the models) for whichever way the
finger is placed on the palm: the model's gravity is turned for the solve and restored.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.models.mjcf import finger_frame, set_coupled_pose
from utrf.models.statics import Load


class MjStaticsError(RuntimeError):
    """MuJoCo's equilibrium was not found."""


@dataclass(frozen=True)
class MjEquilibrium:
    """One equilibrium in the finger's frame (SI)."""

    theta_rad: np.ndarray  # (3,) relative joint angles
    tip_m: np.ndarray  # (2,) fingertip in the finger frame
    net_tensions_n: np.ndarray  # (3,) tendon k minus tendon k + 3, from MuJoCo's tendons
    iterations: int


def _tension(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> float:
    t = model.tendon(name).id
    upper = model.tendon_lengthspring[t, 1]
    return float(model.tendon_stiffness[t] * max(data.ten_length[t] - upper, 0.0))


def equilibrium(
    model: mujoco.MjModel,
    finger: str,
    q: float,
    load: Load | None = None,
    hand: HandGeometry | None = None,
    *,
    tolerance_rad: float = 1e-14,
    max_iterations: int = 50,
) -> MjEquilibrium:
    """The equilibrium of ``finger`` at tendon displacement q (m) under ``load``."""
    hand = hand if hand is not None else HandGeometry.default()
    load = load if load is not None else Load()
    geom = hand.fingers[hand.index(finger)].geometry
    data = mujoco.MjData(model)
    set_coupled_pose(model, data, {finger: q}, hand)
    _, rot = finger_frame(model, data, finger)
    joints = [model.joint(f"{finger}_j{k + 1}") for k in range(3)]
    qadr = np.array([int(j.qposadr[0]) for j in joints])
    dadr = np.array([int(j.dofadr[0]) for j in joints])
    link3 = model.body(f"{finger}_link3").id
    tip_site = data.site(f"{finger}_tip")
    g = model.opt.gravity.copy()
    force_world = rot @ np.array([load.tip_force_n[0], load.tip_force_n[1], 0.0])
    force_world += rot @ np.array([0.0, -load.payload_kg * 9.80665, 0.0])
    moment_world = rot[:, 2] * load.tip_moment_nm
    qfrc = np.zeros(model.nv)

    def residual(theta: np.ndarray) -> np.ndarray:
        data.qpos[qadr] = theta
        mujoco.mj_forward(model, data)
        # The grasp force turns with Link 3: against its flexion side (its y axis).
        grasp = -load.grasp_force_n * data.xmat[link3].reshape(3, 3)[:, 1]
        qfrc[:] = 0.0
        mujoco.mj_applyFT(
            model, data, force_world + grasp, moment_world, tip_site.xpos, link3, qfrc
        )
        total = data.qfrc_passive + qfrc - data.qfrc_bias
        return total[dadr].copy()

    try:
        model.opt.gravity[:] = -np.linalg.norm(g) * rot[:, 1] if load.gravity else 0.0
        theta = np.asarray(kinematics.joint_angles(geom, q), dtype=float)
        h = 1e-7
        for it in range(1, max_iterations + 1):  # noqa: B007  (returned)
            r = residual(theta)
            jac = np.empty((3, 3))
            for k in range(3):
                d = np.zeros(3)
                d[k] = h
                jac[:, k] = (residual(theta + d) - residual(theta - d)) / (2 * h)
            step = np.linalg.solve(jac, -r)
            theta = theta + step
            if np.max(np.abs(step)) <= tolerance_rad:
                break
        else:
            raise MjStaticsError(
                f"{finger}: MuJoCo equilibrium at q = {q:g} m did not converge in "
                f"{max_iterations} Newton steps (last step {np.max(np.abs(step)):g} rad)"
            )
        residual(theta)
        origin, _ = finger_frame(model, data, finger)
        tip = rot.T @ (tip_site.xpos - origin)
        net = np.array(
            [
                _tension(model, data, f"{finger}_t{k}")
                - _tension(model, data, f"{finger}_t{k + 3}")
                for k in (1, 2, 3)
            ]
        )
    finally:
        model.opt.gravity[:] = g
    return MjEquilibrium(theta_rad=theta, tip_m=tip[:2], net_tensions_n=net, iterations=it)
