"""One page of the dashboard (NiceGUI): the hand in 3D, each finger's plot, slider, mode and
faults, the pose library as buttons, the settings, recording. Angles are shown in degrees and
duties in percent (the page says so); everything sent is SI through :class:`DashboardHub`.

One update loop per page at up to ``ui_hz``: the live view (3D hand, numbers, modes, faults,
the newest sample's board time) and one finger's chart, each chart every ``1 / plot_hz``
(the last ``window_s`` decimated to ``points_per_s``, only the points sent); then it waits
until the browser has drawn them, so a slow browser gets fewer updates, never a backlog.
Each pushes only what changed. Elements carry ``utrf-*`` classes for the tests.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from nicegui import Client, ui
from nicegui import json as nicegui_json
from nicegui.elements.mixins.disableable_element import DisableableElement

from utrf.dashboard import settings as settings_
from utrf.dashboard.hand3d import DRAW_HZ, Hand3D
from utrf.dashboard.hub import DashboardHub, NotInControl
from utrf.hand.state import fault_names
from utrf.models.geometry import HandGeometry

CHART_STYLE = "height: 150px; width: 560px"
#: one update in the browser (one message): each live label's text written into its text
#: node (the one Vue made: NiceGUI's element update would re-render every element of the
#: page, sliders and buttons too, 30 times a second), drawn in the next frame, which does
#: nothing else; the 3D hand (``draw``) or a chart's new points (``setOption``, as JSON text:
#: parsed faster than the same as code) in the frame after, never the numbers' frame (the
#: 3D hand's read-back and ECharts' redraw took milliseconds there); the promise resolves
#: in a task after that frame (its paint and commit done), which paces the page's updates,
#: so the next update's message and numbers find the page idle
LIVE_JS = """<style>
.utrf-live { contain: strict; overflow: hidden; white-space: pre; }
.utrf-live { font-variant-numeric: tabular-nums; }
</style>
<script>
window.utrfLive = (texts, draw, chart, points) => {
  for (const [id, text] of texts) {
    const node = document.getElementById("c" + id)?.firstChild;
    if (node) node.nodeValue = text;
  }
  return new Promise((resolve) => requestAnimationFrame(() => {
    const drawn = () => setTimeout(resolve, 0, 0);  // a task: after the frame is painted
    if (!draw && chart === undefined) return drawn();
    requestAnimationFrame(() => {
      if (draw) draw();
      if (chart !== undefined) getElement(chart)?.chart?.setOption(JSON.parse(points));
      drawn();
    });
  }));
};
</script>"""
DRAWN_TIMEOUT_S = 1.0
#: the live labels' boxes, fixed (with ``utrf-live``'s containment): a new text is laid out
#: and painted inside its label alone, not in the rows and columns around it
LIVE_VALUE_STYLE = "width: 14rem; height: 1.25rem"
LIVE_BOARD_TIME_STYLE = "width: 11rem; height: 1.5rem; text-align: right"


def _chart(lo_deg: float, hi_deg: float) -> dict[str, Any]:
    line = {"type": "line", "showSymbol": False, "animation": False, "data": []}
    return {
        "animation": False,
        # no title or legend drawn in the chart (each costs every redraw): the page says
        # which finger and which line in text beside it
        "grid": {"left": 40, "right": 40, "top": 8, "bottom": 20},
        "xAxis": {"type": "value", "min": -5, "max": 0},
        "yAxis": [
            {"type": "value", "min": lo_deg, "max": hi_deg},
            {"type": "value", "min": -100, "max": 100, "splitLine": {"show": False}},
        ],
        "series": [
            {**line, "name": "angle (deg)"},
            {**line, "name": "setpoint (deg)", "lineStyle": {"type": "dashed"}},
            {**line, "name": "duty A−B (%)", "yAxisIndex": 1, "lineStyle": {"width": 1}},
        ],
    }


def hand_turn(hand_due: bool, chart_due: bool, drew_hand_last: bool) -> bool:
    """Whether an update draws the 3D hand (else a chart, if one is due): one of them an
    update (each takes milliseconds in the frame after the numbers'); when both are due, the
    one that waited last time, so neither starves the other."""
    return hand_due and not (chart_due and drew_hand_last)


class DashboardPage:
    """The elements of one page and their updates (one per browser tab)."""

    def __init__(
        self,
        hub: DashboardHub,
        client: Client,
        *,
        ui_hz: float,
        plot_hz: float,
        window_s: float,
        points_per_s: float,
    ) -> None:
        self.hub = hub
        self.id = client.id
        self.window_s = window_s
        self.points_per_s = points_per_s
        self._shown: dict[str, Any] = {}
        self._controls: list[DisableableElement] = []
        self.in_control = hub.join(self.id)
        # A page whose connection drops holds the fingers unless it is back within the hub's
        # grace; it gives up control only when NiceGUI drops it (its reconnect timeout).
        client.on_disconnect(lambda: hub.lost(self.id))
        client.on_connect(lambda: hub.join(self.id))
        client.on_delete(lambda: hub.leave(self.id))
        self._build(hub.hand.geometry)
        self.client = client
        self.plot_period = 1.0 / plot_hz
        self._next_plot = [0.0] * len(hub.fingers)  # when each finger's chart is next due
        self._hand_moved = False  # the 3D hand moved since it was last drawn
        self._next_hand_draw = 0.0  # when it may be drawn next
        self._drew_hand_last = False  # the last update that drew something drew the 3D hand
        self.period_s = 1.0 / ui_hz
        ui.timer(self.period_s, self._update)
        self._show_control()

    # --- layout ---------------------------------------------------------------------------------

    def _build(self, hand: HandGeometry) -> None:
        hub = self.hub
        ui.add_head_html(LIVE_JS)
        with ui.row().classes("items-center w-full"):
            ui.label("UTRF-RoboHand").classes("text-h6")
            self.control_label = ui.label().classes("utrf-control text-bold")
            self.take_button = ui.button("Take control", on_click=self._take).classes("utrf-take")
            ui.space()
            self.board_time = ui.label("board time –").classes("utrf-board-time utrf-live")
            self.board_time.style(LIVE_BOARD_TIME_STYLE)
            # the newest sample's board time on the host's wall clock, and when the server
            # sent it (ms): the latency probe's
            self.sample_wall = ui.label("–").classes("utrf-sample-wall hidden")
        ui.label(
            f"If this server stops, the board latches HOST_TIMEOUT after "
            f"{hub.safety.heartbeat_timeout:g} s without the host and applies its safe action "
            f"({self._safe_action()}); closing the page in control holds every finger where it "
            "is. Angles in degrees, duties in percent."
        ).classes("text-caption")
        self.message = ui.label("").classes("utrf-message text-negative")
        with ui.row().classes("w-full no-wrap"):
            with ui.column():
                self.hand3d = Hand3D(hand)
                self._pose_buttons()
                self._recording()
            with ui.column().classes("grow"):
                self._fingers()
        self._settings()

    def _safe_action(self) -> str:
        return str(self.hub.status()["safe_action"])

    def _pose_buttons(self) -> None:
        ui.label("Poses (one move on the board each)").classes("text-subtitle2")
        with ui.row().classes("utrf-poses"):
            for name in self.hub.pose_names:
                b = ui.button(name, on_click=lambda _e, n=name: self._do(self.hub.pose, n))
                self._controls.append(b.classes(f"utrf-pose-{name}").props("dense no-caps"))

    def _recording(self) -> None:
        with ui.row().classes("items-center"):
            self._controls.append(
                ui.button("Record", on_click=self._record).classes("utrf-record").props("dense")
            )
            self._controls.append(
                ui.button("Stop", on_click=self._stop_record).classes("utrf-stop").props("dense")
            )
            self.record_label = ui.label("").classes("utrf-record-label text-caption")

    def _fingers(self) -> None:
        self.charts: list[ui.echart] = []
        self.values: list[ui.label] = []
        self.modes: list[ui.label] = []
        self.faults: list[ui.label] = []
        ui.label(
            "Each finger over the last 5 s: the angle (solid) and setpoint (dashed) in degrees "
            "on the left axis, the net duty A−B (thin) in percent on the right."
        ).classes("text-caption")
        for i, name in enumerate(self.hub.fingers):
            lim = self.hub.limits[i]
            with ui.row().classes(f"utrf-finger-{name} items-center no-wrap w-full"):
                with ui.column().classes("w-56"):
                    with ui.row().classes("items-center"):
                        ui.label(name).classes("text-bold")
                        self.modes.append(ui.label("").classes(f"utrf-mode-{name} text-caption"))
                    # written by the live update (LIVE_JS), not by NiceGUI
                    value = ui.label("–").classes(f"utrf-value-{name} text-caption utrf-live")
                    self.values.append(value.style(LIVE_VALUE_STYLE))
                    with ui.row().classes("items-center"):
                        self.faults.append(ui.label("").classes(f"utrf-faults-{name}"))
                        b = ui.button(
                            "Clear", on_click=lambda _e, i=i: self._do(self.hub.clear_faults, i)
                        )
                        self._controls.append(b.classes(f"utrf-clear-{name}").props("dense flat"))
                    slider = ui.slider(
                        min=round(math.degrees(lim.theta2_min), 1),
                        max=round(math.degrees(lim.theta2_max), 1),
                        step=0.5,
                        value=0.0,
                    ).classes(f"utrf-slider-{name}")
                    slider.props("label")
                    # every change while sliding, at most 4 a second, the last one always
                    slider.on(
                        "update:model-value",
                        lambda e, i=i: self._do(
                            self.hub.move_finger, i, math.radians(float(e.args))
                        ),
                        throttle=0.25,
                    )
                    self._controls.append(slider)
                lo, hi = math.degrees(lim.theta2_min), math.degrees(lim.theta2_max)
                chart = ui.echart(_chart(10 * math.floor(lo / 10), 10 * math.ceil(hi / 10)))
                self.charts.append(chart.classes(f"utrf-chart-{name}").style(CHART_STYLE))

    def _settings(self) -> None:
        with ui.expansion("Settings (the protocol's ranges are checked before sending)").classes(
            "w-full utrf-settings"
        ):
            with ui.row().classes("items-center"):
                self.set_finger = ui.select(
                    {i: n for i, n in enumerate(self.hub.fingers)}, value=1, label="finger"
                ).classes("utrf-set-finger w-32")
                self.set_group = ui.toggle(list(settings_.GROUPS), value="gains").classes(
                    "utrf-set-group"
                )
                ui.button("Read", on_click=self._read_settings).classes("utrf-read").props("dense")
            self.inputs_row = ui.row()
            with ui.row():
                b = ui.button("Apply", on_click=self._apply_settings).classes("utrf-apply")
                self._controls.append(b)
                b = ui.button("Save to EEPROM", on_click=self._save).classes("utrf-save")
                self._controls.append(b)
            self.set_group.on_value_change(self._read_settings)
            self.set_finger.on_value_change(self._read_settings)
        self.inputs: dict[str, ui.number] = {}
        self._read_settings()

    def _read_settings(self) -> None:
        group, finger = str(self.set_group.value), int(self.set_finger.value)
        current = self.hub.read_settings(group, finger)
        self.inputs_row.clear()
        self.inputs = {}
        with self.inputs_row:
            for s in settings_.settings(group):
                unit = "" if s.unit in ("", "1") else f" [{s.unit}]"
                self.inputs[s.name] = ui.number(
                    f"{s.name}{unit} {s.lo:g}..{s.hi:g}", value=current[s.name], format="%.4g"
                ).classes(f"utrf-input-{s.name} w-40")

    # --- commands -------------------------------------------------------------------------------

    def _say(self, text: str, *, error: bool = True) -> None:
        self.message.text = text
        self.message.classes(replace="utrf-message " + ("text-negative" if error else ""))
        ui.notify(text, type="negative" if error else "positive", multi_line=True)

    async def _do(self, command: Callable[..., concurrent.futures.Future], *args: Any) -> Any:
        try:
            result = await asyncio.wrap_future(command(self.id, *args))
        except (NotInControl, settings_.SettingsError) as exc:
            self._say(str(exc))
            return None
        except Exception as exc:  # the Hand's errors name what went wrong: show them
            self._say(f"{type(exc).__name__}: {exc}")
            return None
        self.message.text = ""
        return result

    async def _apply_settings(self) -> None:
        group, finger = str(self.set_group.value), int(self.set_finger.value)
        values = {n: inp.value for n, inp in self.inputs.items()}
        try:
            future = self.hub.apply_settings(self.id, group, finger, values)
        except (NotInControl, settings_.SettingsError) as exc:
            self._say(str(exc))
            return
        if await self._do(lambda _page: future) is not None:
            self._say(f"{group} of {self.hub.fingers[finger]} set", error=False)

    async def _save(self) -> None:
        await self._do(self.hub.save_eeprom)
        if not self.message.text:
            self._say("configuration saved to the board's EEPROM", error=False)

    def _record(self) -> None:
        try:
            path = self.hub.start_recording(self.id)
        except (NotInControl, OSError, ValueError) as exc:
            self._say(str(exc))
            return
        self.record_label.text = f"recording to {path}"

    def _stop_record(self) -> None:
        try:
            s = self.hub.stop_recording(self.id)
        except NotInControl as exc:
            self._say(str(exc))
            return
        if s is not None:
            self.record_label.text = f"{s.samples} samples in {s.path}, lost {s.lost}"

    def _take(self) -> None:
        self.in_control = self.hub.take_control(self.id)
        self._show_control()

    def _show_control(self) -> None:
        self.in_control = self.hub.controller == self.id
        text = (
            "you control the hand"
            if self.in_control
            else "watching: another page controls the hand"
        )
        self.control_label.text = text
        self.take_button.set_visibility(not self.in_control and self.hub.controller is None)
        for c in self._controls:
            c.set_enabled(self.in_control)

    # --- live updates ---------------------------------------------------------------------------

    def _set(self, key: str, element: ui.label, text: str) -> None:
        if self._shown.get(key) != text:
            self._shown[key] = text
            element.text = text

    async def _update(self) -> None:
        """One update of the page, one message: the newest sample's numbers, drawn in a frame
        of their own, then either the 3D hand (if it moved) or one chart's new points (when
        due) in the frame after; it waits until the browser has done all of it, so a browser
        that draws slower than ``ui_hz`` gets fewer updates, never a queue of stale ones (each
        drawn update is the newest sample), and each update's numbers find the page idle.
        It starts when the next sample arrives (at most one period later), not at a timer's
        phase: the sample is as fresh as the Hand's reader gives."""
        await self.hub.next_sample(self.period_s)
        now = time.monotonic()
        live = self._update_live()
        texts: list[tuple[int, str]] = []
        if live is not None:
            texts, moved = live
            self._hand_moved = self._hand_moved or moved
        # (at most DRAW_HZ a second: a move not drawn yet is drawn at a later update)
        hand_due = self._hand_moved and now >= self._next_hand_draw
        i = int(np.argmin(self._next_plot))  # the chart most overdue
        chart_due = now >= self._next_plot[i]
        draw = hand_turn(hand_due, chart_due, self._drew_hand_last)
        chart = ""
        if chart_due and not draw:
            self._next_plot[i] = max(self._next_plot[i] + self.plot_period, now)
            points = self._plot_points(i)
            if points is not None:
                chart = f", {self.charts[i].id}, {json.dumps(points)}"
            elif hand_due:  # the chart had nothing new: the hand's turn after all
                draw = True
        if draw:
            self._hand_moved = False
            self._next_hand_draw = now + 1.0 / DRAW_HZ
            self.hub.pushed["hand3d"] += 1
        if draw or chart:
            self._drew_hand_last = draw
        if live is not None or chart or draw:
            body = f"() => {{ {self.hand3d.draw_js()}; }}" if draw else "null"
            await self._drawn(f"utrfLive({json.dumps(texts)}, {body}{chart})")

    async def _drawn(self, script: str) -> None:
        with contextlib.suppress(TimeoutError):  # a hidden tab draws nothing: go on
            await self.client.run_javascript(script, timeout=DRAWN_TIMEOUT_S)

    def _live_text(
        self, texts: list[tuple[int, str]], key: str, element: ui.label, text: str
    ) -> None:
        """A live label's text, for :data:`LIVE_JS`, when it changed."""
        if self._shown.get(key) != text:
            self._shown[key] = text
            texts.append((element.id, text))

    def _update_live(self) -> tuple[list[tuple[int, str]], bool] | None:
        """The newest sample's numbers (returned as (element id, text) for :data:`LIVE_JS`),
        modes, faults and 3D hand; None when there is no new sample, else also whether the 3D
        hand moved."""
        if (self.hub.controller == self.id) != self.in_control or (
            not self.in_control and self.hub.controller is None
        ):
            self._show_control()
        st = self.hub.latest
        if st is None or self._shown.get("t") == st.board_time:
            return None
        self._shown["t"] = st.board_time
        texts: list[tuple[int, str]] = []
        for i, f in enumerate(st.fingers):
            self._set(f"m{i}", self.modes[i], f.mode.name)  # rare changes: NiceGUI's updates
            self._live_text(
                texts,
                f"v{i}",
                self.values[i],
                f"{math.degrees(f.theta2):6.1f}° → {math.degrees(f.target):6.1f}°, "
                f"duty {100 * f.duty_a:+4.0f}/{100 * f.duty_b:+4.0f} %",
            )
            if self._shown.get(f"f{i}") != (faults := int(f.faults)):  # named when changed
                self._shown[f"f{i}"] = faults
                self.faults[i].text = f"faults: {fault_names(faults)}"
        moved = self.hand3d.show(
            [f.theta2 for f in st.fingers], [bool(f.faults) for f in st.fingers]
        )
        texts.append((self.board_time.id, f"board time {st.board_time:.3f} s"))
        sampled = 1000 * self.hub.wall_time_of(st.board_time)
        texts.append((self.sample_wall.id, f"{sampled:.1f} {1000 * time.time():.1f}"))
        self.hub.pushed["live"] += 1
        return texts, moved

    def _plot_points(self, i: int) -> str | None:
        """Finger ``i``'s chart's new points as ``setOption``'s JSON (only its series' data:
        the chart's options, observed dicts and lists on the server, are left alone; ECharts
        merges the data in), None when it has nothing new."""
        s = self.hub.ring.series(self.window_s, self.points_per_s)
        if len(s.board_time) < 2 or self._shown.get(f"plot{i}") == s.board_time[-1]:
            return None
        self._shown[f"plot{i}"] = s.board_time[-1]
        x = (s.board_time - s.board_time[-1]).round(3)
        duty = 100 * (s.duty_a[:, i] - s.duty_b[:, i])
        ys = (np.degrees(s.theta2[:, i]), np.degrees(s.target[:, i]), duty)
        series = [{"data": np.column_stack((x, y.round(2)))} for y in ys]
        self.hub.pushed["plots"] += 1
        return nicegui_json.dumps({"series": series})  # orjson: numpy arrays as they are
