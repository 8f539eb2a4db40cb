"""What a recording's channels hold: the topics, the hand sample's JSON schema (Foxglove plots
any of its fields), the ROS 2 ``sensor_msgs/msg/JointState`` definition (so ``ros2 bag`` and
ROS-free readers decode it without ROS installed), and the columns' SI units.

The column names are the telemetry CSV's (:func:`utrf.hand.log_columns`), so a recording and
a CSV log export to the same Parquet columns."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from utrf.hand.state import FingerState
from utrf.hand.telemetry_log import FINGER_FIELDS, log_columns
from utrf.protocol import messages as m

STATE_TOPIC = "/hand/state"  # every sample, JSON (schema utrf.HandState)
JOINT_STATES_TOPIC = "/joint_states"  # every sample, ROS 2 sensor_msgs/msg/JointState (CDR)
SCENE_TOPIC = "/hand/scene"  # the hand in 3D, decimated, foxglove.SceneUpdate (protobuf)
FAULT_TOPIC = "/hand/faults"  # every fault message, JSON (schema utrf.FaultEvent)
SUMMARY_METADATA = "utrf.recording"  # the recording's counts, an MCAP metadata record

#: each column's unit ("1": a fraction or a count; "" for a name)
FIELD_UNITS = {
    "theta2_rad": "rad",
    "target_rad": "rad",
    "duty_a": "1",
    "duty_b": "1",
    "mode": "",
    "faults": "1",
    "tip_x_m": "m",
    "tip_y_m": "m",
}
TIME_UNITS = {"host_time_s": "s", "board_time_s": "s", "seq": "1"}
assert tuple(FIELD_UNITS) == FINGER_FIELDS  # one list of fields: the CSV log's

FIELD_DOCS = {
    "theta2_rad": "measured Joint-2 angle",
    "target_rad": "Joint-2 setpoint in use on the board",
    "duty_a": "motor A duty (flexor), signed fraction",
    "duty_b": "motor B duty (extensor), signed fraction",
    "mode": "control mode (ControlMode name)",
    "faults": "latched FaultBits",
    "tip_x_m": "fingertip x in the finger frame, from the kinematics",
    "tip_y_m": "fingertip y in the finger frame, from the kinematics",
}


def finger_fields(f: FingerState) -> dict[str, float | int | str]:
    """One finger of a sample under the field names of ``FIELD_UNITS``: what a recording's
    ``/hand/state`` holds per finger, and the dashboard's ``/api/status``."""
    return {
        "theta2_rad": f.theta2,
        "target_rad": f.target,
        "duty_a": f.duty_a,
        "duty_b": f.duty_b,
        "mode": f.mode.name,
        "faults": int(f.faults),
        "tip_x_m": f.tip_x,
        "tip_y_m": f.tip_y,
    }


def column_units(finger_names: Sequence[str]) -> dict[str, str]:
    """Every column of a sample table (the CSV log's) and its unit."""
    units = dict(TIME_UNITS)
    for name in finger_names:
        for field, unit in FIELD_UNITS.items():
            units[f"{name}_{field}"] = unit
    assert list(units) == log_columns(finger_names)
    return units


def _number(doc: str) -> dict[str, Any]:
    return {"type": "number", "description": doc}


def hand_state_schema(finger_names: Sequence[str]) -> dict[str, Any]:
    """The JSON schema of ``/hand/state``: one sample, its fingers by name, SI units."""
    modes = [c.name for c in m.ControlMode]
    finger = {
        "type": "object",
        "properties": {
            **{
                f: _number(f"{FIELD_DOCS[f]} ({u})")
                for f, u in FIELD_UNITS.items()
                if f not in ("mode", "faults")
            },
            "mode": {"type": "string", "enum": modes, "description": FIELD_DOCS["mode"]},
            "faults": {"type": "integer", "minimum": 0, "maximum": 255},
        },
        "required": list(FINGER_FIELDS),
        "additionalProperties": False,
    }
    return {
        "title": "utrf.HandState",
        "type": "object",
        "properties": {
            "board_time_s": _number("the board's clock at the sample, unwrapped (s)"),
            "host_time_s": _number("when the host received it (s, Unix time)"),
            "seq": {"type": "integer", "description": "the board's stream seq (7 bits)"},
            "fingers": {
                "type": "object",
                "properties": {n: finger for n in finger_names},
                "required": list(finger_names),
                "additionalProperties": False,
            },
        },
        "required": ["board_time_s", "host_time_s", "seq", "fingers"],
        "additionalProperties": False,
    }


def fault_event_schema(finger_names: Sequence[str]) -> dict[str, Any]:
    """The JSON schema of ``/hand/faults``: one ``fault`` message."""
    byte = {"type": "integer", "minimum": 0, "maximum": 255}
    return {
        "title": "utrf.FaultEvent",
        "type": "object",
        "properties": {
            "finger": {"type": "string", "enum": list(finger_names)},
            "new_faults": {**byte, "description": "the bits that just latched"},
            "new_fault_names": {"type": "string"},
            "faults": {
                "type": "object",
                "properties": {n: byte for n in finger_names},
                "required": list(finger_names),
            },
            "board_time_s": _number("the board's clock at the fault (s)"),
        },
        "required": ["finger", "new_faults", "faults", "board_time_s"],
    }


def schema_bytes(schema: dict[str, Any]) -> bytes:
    return json.dumps(schema, separators=(",", ":")).encode()


#: sensor_msgs/msg/JointState with its dependencies, as ROS 2 writes a ``ros2msg`` schema
JOINT_STATE_MSGDEF = """\
# measured Joint-2 angles (rad) of the fingers, named <finger>_joint2
std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"


def joint_names(finger_names: Sequence[str]) -> list[str]:
    return [f"{n}_joint2" for n in finger_names]
