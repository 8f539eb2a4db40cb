"""Samples of the hand to an MCAP file that Foxglove, ``ros2 bag`` and the ``mcap`` readers open.

Channels (``utrf.recording.schemas``): ``/hand/state`` every sample as JSON (schema
``utrf.HandState``: Foxglove's Plot panel plots ``/hand/state.fingers.index.theta2_rad``);
``/joint_states`` every sample as ROS 2 ``sensor_msgs/msg/JointState`` in CDR (encoded with
mcap-ros2-support, no ROS installation); ``/hand/scene`` the hand in 3D as
``foxglove.SceneUpdate`` (protobuf, the official schemas) decimated to ``scene_hz``;
``/hand/faults`` every fault. Message times are the board's clock, anchored to the host's
wall clock at the first sample, so plots keep the board's even 1 ms steps.

The recorder counts what the stream lost by the board's clock: at ``rate_hz`` each sample is
one period after the last, and a longer step is samples missing (``board_time_gaps``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema
from mcap_ros2._dynamic import serialize_dynamic  # what mcap_ros2.writer.Writer encodes with

from utrf.hand.state import FaultEvent, HandState, fault_names
from utrf.models.skeleton import HandSkeleton
from utrf.recording import schemas

#: the scene's frame (Foxglove's 3D panel follows it)
PALM_FRAME = "palm"


@dataclass
class RecordingSummary:
    """What a recording holds and what the stream lost (also in the file's metadata)."""

    path: str
    samples: int = 0
    faults: int = 0
    scene_frames: int = 0
    rate_hz: int = 0
    first_board_time_s: float = float("nan")
    last_board_time_s: float = float("nan")
    board_time_gaps: int = 0  # samples missing by the board's clock at rate_hz
    link_stream_lost: int = 0  # the host link's seq gaps (every stream frame) while recording
    board_tx_dropped: int = 0  # stream frames the board skipped while recording
    extra: dict[str, str] = field(default_factory=dict)

    @property
    def lost(self) -> int:
        """Samples the recording is missing, by any of the counters."""
        return max(self.board_time_gaps, self.link_stream_lost) + self.board_tx_dropped

    def metadata(self) -> dict[str, str]:
        out = {k: str(v) for k, v in asdict(self).items() if k != "extra"}
        out.update(self.extra)
        return out


class McapRecorder:
    """Writes :class:`HandState` samples and :class:`FaultEvent` s to ``path`` (not
    thread-safe: one writer thread)."""

    def __init__(
        self,
        path: str | Path,
        finger_names: Sequence[str],
        *,
        rate_hz: int,
        skeleton: HandSkeleton | None = None,
        scene_hz: float = 30.0,
        compression: CompressionType = CompressionType.ZSTD,
    ) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.names = tuple(finger_names)
        self.summary = RecordingSummary(path=str(self.path), rate_hz=int(rate_hz))
        self._period = 1.0 / rate_hz if rate_hz > 0 else 0.0
        self._skeleton = skeleton
        self._scene_period = 1.0 / scene_hz if scene_hz > 0 and skeleton is not None else 0.0
        self._next_scene = float("-inf")
        self._anchor_ns: int | None = None  # wall-clock ns of the first sample's board time
        self._board0 = 0.0
        self._last_board: float | None = None
        self._file = self.path.open("wb")
        self._writer = Writer(self._file, compression=compression)
        self._writer.start(profile="", library="utrf")
        w = self._writer
        self._state_ch = w.register_channel(
            schemas.STATE_TOPIC,
            "json",
            w.register_schema(
                "utrf.HandState",
                "jsonschema",
                schemas.schema_bytes(schemas.hand_state_schema(self.names)),
            ),
        )
        self._fault_ch = w.register_channel(
            schemas.FAULT_TOPIC,
            "json",
            w.register_schema(
                "utrf.FaultEvent",
                "jsonschema",
                schemas.schema_bytes(schemas.fault_event_schema(self.names)),
            ),
        )
        self._joint_ch = w.register_channel(
            schemas.JOINT_STATES_TOPIC,
            "cdr",
            w.register_schema(
                schemas.JOINT_STATE_TYPE, "ros2msg", schemas.JOINT_STATE_MSGDEF.encode()
            ),
        )
        self._encode_joint_state = serialize_dynamic(
            schemas.JOINT_STATE_TYPE, schemas.JOINT_STATE_MSGDEF
        )[schemas.JOINT_STATE_TYPE]
        self._joint_names = schemas.joint_names(self.names)
        self._scene_ch = w.register_channel(
            schemas.SCENE_TOPIC, "protobuf", register_schema(w, SceneUpdate)
        )
        self._closed = False

    # --- samples --------------------------------------------------------------------------------

    def _time_ns(self, board_time: float, host_time: float) -> int:
        if self._anchor_ns is None:
            self._anchor_ns = int(host_time * 1e9)
            self._board0 = board_time
        return self._anchor_ns + round((board_time - self._board0) * 1e9)

    def write_state(self, st: HandState) -> None:
        s = self.summary
        t_ns = self._time_ns(st.board_time, st.host_time)
        if self._last_board is None:
            s.first_board_time_s = st.board_time
        elif self._period:
            steps = round((st.board_time - self._last_board) / self._period)
            s.board_time_gaps += max(steps - 1, 0)
        self._last_board = s.last_board_time_s = st.board_time
        fingers = {f.name: schemas.finger_fields(f) for f in st.fingers}
        doc = {
            "board_time_s": st.board_time,
            "host_time_s": st.host_time,
            "seq": -1 if st.seq is None else st.seq,
            "fingers": fingers,
        }
        seq = s.samples
        self._writer.add_message(self._state_ch, t_ns, json.dumps(doc).encode(), t_ns, sequence=seq)
        joint = {
            "header": {
                "stamp": {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000},
                "frame_id": PALM_FRAME,
            },
            "name": self._joint_names,
            "position": [f.theta2 for f in st.fingers],
            "velocity": [],
            "effort": [],
        }
        self._writer.add_message(
            self._joint_ch, t_ns, self._encode_joint_state(joint), t_ns, sequence=seq
        )
        s.samples += 1
        if self._scene_period and st.board_time >= self._next_scene:
            self._next_scene = st.board_time + self._scene_period
            self._write_scene(st, t_ns)

    def _write_scene(self, st: HandState, t_ns: int) -> None:
        assert self._skeleton is not None
        pts = self._skeleton.points([f.theta2 for f in st.fingers])
        update = SceneUpdate()
        for f, finger_pts in zip(st.fingers, pts, strict=True):
            entity = update.entities.add()
            entity.timestamp.FromNanoseconds(t_ns)
            entity.frame_id = PALM_FRAME
            entity.id = f.name
            line = entity.lines.add()
            line.type = LinePrimitive.LINE_STRIP
            line.thickness = 0.012
            line.color.CopyFrom(
                Color(r=0.9, g=0.3, b=0.2, a=1.0) if f.faults else Color(r=0.3, g=0.6, b=0.9, a=1)
            )
            for x, y, z in finger_pts:
                p = line.points.add()
                p.x, p.y, p.z = float(x), float(y), float(z)
            entity.metadata.add(key="mode", value=f.mode.name)
        self._writer.add_message(
            self._scene_ch,
            t_ns,
            update.SerializeToString(),
            t_ns,
            sequence=self.summary.scene_frames,
        )
        self.summary.scene_frames += 1

    def write_fault(self, ev: FaultEvent) -> None:
        t_ns = (
            self._time_ns(ev.board_time, ev.host_time)
            if self._anchor_ns is not None
            else int(ev.host_time * 1e9)
        )
        doc: dict[str, Any] = {
            "finger": ev.finger,
            "new_faults": int(ev.new_faults),
            "new_fault_names": fault_names(int(ev.new_faults)),
            "faults": {n: int(v) for n, v in ev.faults.items()},
            "board_time_s": ev.board_time,
        }
        self._writer.add_message(self._fault_ch, t_ns, json.dumps(doc).encode(), t_ns)
        self.summary.faults += 1

    def close(self) -> RecordingSummary:
        """Write the summary as metadata and finish the file (idempotent)."""
        if not self._closed:
            self._closed = True
            try:
                self._writer.add_metadata(schemas.SUMMARY_METADATA, self.summary.metadata())
                self._writer.finish()
            finally:
                self._file.close()
        return self.summary
