"""The hand in 3D on the page (NiceGUI's ``ui.scene``, three.js): the palm and each finger's
three links placed as the MJCF places them (``utrf/data/mjcf.toml``), each joint a group
turned by its angle on the rigid coupling (θ_i = q / R_i from the measured Joint-2 angle).
Only joints that moved are sent, and the scene is drawn when they moved (:meth:`Hand3D.draw_js`)
or the view is dragged, not on a clock: a hand at rest costs nothing."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence

from nicegui import ui
from nicegui.elements.scene.objects import Cylinder, Group

from utrf.models import kinematics
from utrf.models.geometry import HandGeometry
from utrf.models.mjcf_layout import load_layout

#: three.js's own render loop (NiceGUI's) at this rate (once a minute), only to catch what
#: the page does not ask for: the page draws the scene when the hand moved, while the view is
#: dragged and when the window is resized, each in a frame that does not show new numbers
#: (NiceGUI's loop would draw in any frame: software WebGL without a GPU is costly)
SCENE_FPS = 1 / 60
#: at most this many draws a second while the hand moves (as NiceGUI's loop drew it before)
DRAW_HZ = 15.0
#: metres to the scene's units
SCALE = 10.0
#: a finger is turned on the page when its Joint-2 angle moved more than this from the angle
#: shown (rad, 0.6 degree): above the one-count dither of a finger at rest (docs/dashboard.md)
RESOLUTION = math.radians(0.6)
COLOR = "#5b8fd9"
FAULT_COLOR = "#d9534f"


class Hand3D:
    """The scene and its joints; :meth:`show` moves them to the measured angles."""

    def __init__(self, hand: HandGeometry, *, width: int = 420, height: int = 340) -> None:
        self.hand = hand
        layout = load_layout()
        px, py, pz = layout.palm_size_m
        with (
            ui.scene(width=width, height=height, grid=False) as self.scene,
            self.scene.group() as top,
        ):
            self.scene.props["fps"] = SCENE_FPS  # (NiceGUI's argument is an int)
            top.scale(SCALE)  # decimetres on the page: the default camera's near plane
            self.scene.box(px, py, pz).move(0.0, 0.0, -pz / 2).material("#c8c8c8")
            self._joints: list[list[Group]] = []
            self._links: list[list[Cylinder]] = []
            for f in hand.fingers:
                place = layout.fingers[f.name]
                g = f.geometry
                radius = layout.link_radius_fraction * float(g.guide_radii_m[0])
                joints: list[Group] = []
                links: list[Cylinder] = []
                with self.scene.group() as base:
                    base.move(*place.position_m)
                    base.rotate_R(place.rotation().tolist())
                    self._chain([float(x) for x in g.L], radius, joints, links)
                self._joints.append(joints)
                self._links.append(links)
        self.scene.move_camera(
            x=2.2, y=-2.6, z=2.4, look_at_x=0.3, look_at_y=0.0, look_at_z=0.3, duration=0.0
        )
        self._shown = [math.nan] * len(hand.fingers)  # each finger's Joint-2 angle shown
        self._faulted = [False] * len(hand.fingers)
        # once the browser has the scene (and again after a remount), the next update draws
        # it and installs the drawing on a drag (draw_js), even with the hand at rest
        self.scene.on("init", self._forget_shown)

    def _forget_shown(self) -> None:
        self._shown = [math.nan] * len(self.hand.fingers)

    def _chain(
        self, lengths: list[float], radius: float, joints: list[Group], links: list[Cylinder]
    ) -> None:
        """Joint k's group holds link k and, at the link's end, joint k+1's group."""
        k = len(joints)
        with self.scene.group() as joint:
            joint.move(lengths[k - 1] if k else 0.0, 0.0, 0.0)
            # a three.js cylinder stands on y: turned onto the finger's x axis
            link = self.scene.cylinder(radius, radius, lengths[k], 12)
            link.rotate(0.0, 0.0, -math.pi / 2).move(lengths[k] / 2, 0.0, 0.0).material(COLOR)
            joints.append(joint)
            links.append(link)
            if k + 1 < len(lengths):
                self._chain(lengths, radius, joints, links)

    def draw_js(self) -> str:
        """JavaScript (an expression) that draws the scene now, as NiceGUI's render loop does
        a frame, and the first time also draws it in the frame after each pointer move or
        wheel turn over it (the view is dragged or zoomed) and each resize of the window
        (NiceGUI's resize clears the canvas). Run inside a ``requestAnimationFrame`` callback."""
        return (
            f"((s) => {{ if (!s || !s.renderer) return;"
            " if (!s.utrfDraw) { s.utrfDraw = () => { s.camera_tween?.update();"
            " s.controls.update(s.clock.getDelta()); s.renderer.render(s.scene, s.camera); };"
            " let due = false; const later = () => { if (due) return; due = true;"
            " requestAnimationFrame(() => { due = false; s.utrfDraw(); }); };"
            " for (const e of ['pointermove', 'pointerup', 'wheel'])"
            " s.$el.addEventListener(e, later, {passive: true});"
            " window.addEventListener('resize', later); }"
            f" s.utrfDraw(); }})(getElement({self.scene.id}))"
        )

    def show(self, theta2: Sequence[float], faulted: Sequence[bool]) -> bool:
        """Turn the joints that moved (and colour a finger by its fault); returns whether
        anything was sent (the scene is then to be drawn: :meth:`draw_js`)."""
        sent = False
        # every joint that moved in one message to the page (NiceGUI's own batching, as it
        # uses to resend a scene), not one message and one task per joint
        with getattr(self.scene, "_batch_calls", contextlib.nullcontext)():
            for i, f in enumerate(self.hand.fingers):
                if not abs(theta2[i] - self._shown[i]) < RESOLUTION:
                    self._shown[i] = float(theta2[i])
                    g = f.geometry
                    lo, hi = g.q_range_m
                    q = min(max(float(theta2[i]) * g.guide_radii_m[1], lo), hi)
                    for k, angle in enumerate(kinematics.joint_angles(g, q)):
                        self._joints[i][k].rotate(0.0, 0.0, float(angle))
                    sent = True
                if faulted[i] != self._faulted[i]:
                    self._faulted[i] = bool(faulted[i])
                    for link in self._links[i]:
                        link.material(FAULT_COLOR if faulted[i] else COLOR)
                    sent = True
        return sent
