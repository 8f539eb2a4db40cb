"""Recordings as their users' tools read them: the ``mcap`` reader and its schemas, a ROS-free
ROS 2 decoder (rosbags), Parquet through pandas; every sample of the 1 kHz stream kept."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import jsonschema
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.typesys import Stores, get_typestore

from utrf.cli import main
from utrf.emulator import EmulatedBoard
from utrf.hand import Hand
from utrf.recording import schemas
from utrf.recording.export import ExportError, export_parquet
from utrf.recording.session import Recording

RATE = 1000
pytestmark = pytest.mark.slow  # an emulated run of a few seconds, shared by the module


@pytest.fixture(scope="module")
def recorded(firmware_elf: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """A pose recorded at 1 kHz on the driven emulated board, with the CSV log beside it."""
    out = tmp_path_factory.mktemp("rec")
    with (
        EmulatedBoard(firmware_elf, realtime=False, seed=3) as board,
        Hand.emulated(board, telemetry_hz=RATE) as hand,
    ):
        hand.start_log(out / "log.csv")
        with Recording(hand, out / "rec.mcap") as rec:
            hand.pose("fist", duration=0.4)
            summary = rec.stop()
        hand.stop_log()
        names = hand.fingers
    yield {"dir": out, "summary": summary, "names": names, "mcap": out / "rec.mcap"}


def messages(path: Path, topic: str) -> list:
    with path.open("rb") as f:
        return list(make_reader(f).iter_messages(topics=[topic]))


def test_every_sample_is_kept_against_the_board_counters(recorded: dict) -> None:
    s = recorded["summary"]
    assert s.samples > 400  # the move and its settling, at 1 kHz
    assert (s.board_time_gaps, s.link_stream_lost, s.board_tx_dropped, s.lost) == (0, 0, 0, 0)
    states = messages(recorded["mcap"], schemas.STATE_TOPIC)
    joints = messages(recorded["mcap"], schemas.JOINT_STATES_TOPIC)
    assert len(states) == len(joints) == s.samples
    board = np.array([json.loads(msg.data)["board_time_s"] for _, _, msg in states])
    np.testing.assert_allclose(np.diff(board), 1.0 / RATE, atol=1e-6)  # one per tick, none lost
    # message times follow the board's clock
    log_ns = np.array([msg.log_time for _, _, msg in states])
    np.testing.assert_allclose(np.diff(log_ns) * 1e-9, np.diff(board), atol=1e-6)
    with recorded["mcap"].open("rb") as f:
        meta = {r.name: r.metadata for r in make_reader(f).iter_metadata()}
    assert meta[schemas.SUMMARY_METADATA]["samples"] == str(s.samples)


def test_json_channels_validate_against_their_schemas(recorded: dict) -> None:
    states = messages(recorded["mcap"], schemas.STATE_TOPIC)
    schema = json.loads(states[0][0].data)
    assert states[0][0].encoding == "jsonschema" and states[0][1].message_encoding == "json"
    validator = jsonschema.Draft202012Validator(schema)
    for _, _, msg in states[::50]:
        validator.validate(json.loads(msg.data))
    bad = json.loads(states[0][2].data)
    bad["fingers"]["index"]["mode"] = "SPINNING"
    with pytest.raises(jsonschema.ValidationError):
        validator.validate(bad)
    # the fist closed every finger: the recording saw it
    last = json.loads(states[-1][2].data)["fingers"]
    assert all(f["theta2_rad"] > 0.3 for f in last.values())


def test_scene_is_a_foxglove_scene_update(recorded: dict) -> None:
    scenes = messages(recorded["mcap"], schemas.SCENE_TOPIC)
    schema, channel, _ = scenes[0]
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "foxglove.SceneUpdate",
        "protobuf",
        "protobuf",
    )
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.SceneUpdate"))
    update = cls.FromString(scenes[-1][2].data)
    assert [e.id for e in update.entities] == list(recorded["names"])
    assert all(len(e.lines[0].points) == 4 for e in update.entities)  # 3 joints and the tip
    # decimated: about 30 a second of board time, not 1000
    s = recorded["summary"]
    span = s.last_board_time_s - s.first_board_time_s
    assert 0.5 * 30 * span <= len(scenes) <= 30 * span + 2


def test_ros2_joint_states_decode_without_ros(recorded: dict) -> None:
    joints = messages(recorded["mcap"], schemas.JOINT_STATES_TOPIC)
    states = messages(recorded["mcap"], schemas.STATE_TOPIC)
    schema, channel, _ = joints[0]
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "sensor_msgs/msg/JointState",
        "ros2msg",
        "cdr",
    )
    store = get_typestore(Stores.ROS2_HUMBLE)  # rosbags' own JointState, not our text
    decode = DecoderFactory().decoder_for("cdr", schema)
    assert decode is not None
    for (_, _, jmsg), (_, _, smsg) in list(zip(joints, states, strict=True))[::97]:
        ros = store.deserialize_cdr(jmsg.data, "sensor_msgs/msg/JointState")
        other = decode(jmsg.data)
        fingers = json.loads(smsg.data)["fingers"]
        assert list(ros.name) == [f"{n}_joint2" for n in fingers] == list(other.name)
        np.testing.assert_array_equal(ros.position, [f["theta2_rad"] for f in fingers.values()])
        assert ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec == jmsg.log_time


def test_parquet_reads_back_in_pandas_with_the_same_samples(recorded: dict) -> None:
    out = recorded["dir"]
    assert main(["export", str(recorded["mcap"]), str(out / "rec.parquet")]) == 0
    df = pd.read_parquet(out / "rec.parquet")
    states = [json.loads(m.data) for _, _, m in messages(recorded["mcap"], schemas.STATE_TOPIC)]
    assert len(df) == len(states)
    np.testing.assert_array_equal(df["board_time_s"], [s["board_time_s"] for s in states])
    np.testing.assert_array_equal(
        df["ring_theta2_rad"], [s["fingers"]["ring"]["theta2_rad"] for s in states]
    )
    assert list(df["thumb_mode"].unique()) != []
    schema = pq.read_schema(out / "rec.parquet")
    assert schema.field("index_theta2_rad").metadata == {b"unit": b"rad"}
    assert json.loads(schema.metadata[b"utrf.units"])["little_tip_y_m"] == "m"
    # the CSV log of the same run exports to the same columns and samples (at its precision)
    csv_df = pd.read_parquet(export_and_path(out / "log.csv", out / "log.parquet"))
    assert list(csv_df.columns) == list(df.columns)
    tick = {"tick": lambda d: (d["board_time_s"] * RATE).round().astype(int)}
    both = df.assign(**tick).merge(csv_df.assign(**tick), on="tick", suffixes=("", "_csv"))
    assert len(both) >= len(df) - 2  # the log ran a moment longer on each side
    np.testing.assert_allclose(both["index_theta2_rad"], both["index_theta2_rad_csv"], atol=6e-5)


def export_and_path(src: Path, dest: Path) -> Path:
    export_parquet(src, dest)
    return dest


def test_export_names_what_is_wrong(tmp_path: Path) -> None:
    with pytest.raises(ExportError, match="no such file"):
        export_parquet(tmp_path / "missing.mcap", tmp_path / "x.parquet")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(ExportError, match=r"expected a \.mcap recording or a \.csv"):
        export_parquet(tmp_path / "notes.txt", tmp_path / "x.parquet")
    assert not (tmp_path / "x.parquet").exists()


def test_record_command_on_its_own_emulated_board(
    firmware_elf: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli.mcap"
    code = main(["record", str(out), "--elf", str(firmware_elf), "--duration", "1", "--json"])
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert code == 0 and summary["lost"] == 0 and int(summary["samples"]) > 100
    assert len(messages(out, schemas.STATE_TOPIC)) == int(summary["samples"])


def test_record_command_refuses_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["record", str(tmp_path / "a.mcap"), "--rate", "2000"]) == 2
    assert "--rate must lie in 1..1000 Hz, got 2000" in capsys.readouterr().err
    assert main(["record", str(tmp_path / "a.csv"), "--duration", "1"]) == 2
    assert "must end in .mcap" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
