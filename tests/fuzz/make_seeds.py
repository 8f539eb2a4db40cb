"""Seed corpora for the firmware fuzzers, from protocol/vectors/messages.json.

``raw/``: the request frames of the vectors, one seed each, and all of them back to back.
``struct/``: scripts for fuzz_struct.cpp (its header lists the operations): each request of
the vectors alone, and a few scenarios (drive, then faults, a save, power cycles).

    python tests/fuzz/make_seeds.py        # rewrites tests/fuzz/corpus/{raw,struct}/
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

from utrf.protocol import messages as M
from utrf.protocol.framing import encode_frame

HERE = Path(__file__).resolve().parent
VECTORS = HERE.parents[1] / "protocol" / "vectors" / "messages.json"

RUN, ADC, EEPROM, POWER, LOOP_HANG, TICK_HANG, OVERRUN, FLIP, RAW, FREEZE = range(0x80, 0x8A)


def requests() -> list[dict]:
    msgs = json.loads(VECTORS.read_text())["messages"]
    return [v for v in msgs if v["id"] < 0x80]


def req(v: dict) -> bytes:
    body = bytes.fromhex(v["body"])
    return bytes([v["id"], len(body)]) + body


def scenarios(by_name: dict[str, dict]) -> dict[str, bytes]:
    def r(name: str) -> bytes:
        return req(by_name[name])

    def msg(x: M.Message) -> bytes:
        body = x.encode()
        return bytes([x.ID, len(body)]) + body

    n = M.FINGER_COUNT
    drive = (
        msg(M.SetTelemetry(rate_hz=M.MAX_TELEMETRY_HZ))
        + msg(M.SetTargets(kind=M.TargetKind.JOINT2_ANGLE, mask=31, value=(0.3,) * n))
        + msg(
            M.SetMode(
                mask=31, mode=(M.ControlMode.POSITION,) * n, duty=(0.0,) * n, effort=(1.0,) * n
            )
        )
        + bytes([RUN, 100])
    )
    return {
        "drive": drive,
        "drive-unplug": drive + bytes([ADC, 1]) + struct.pack("<H", 20) + bytes([RUN, 20]),
        # the angle falls while in closed loop (the derivative of a decreasing measurement)
        "drive-sag": drive
        + bytes([ADC, 0])
        + struct.pack("<H", 505)
        + bytes([RUN, 5, ADC, 0])
        + struct.pack("<H", 498)
        + bytes([RUN, 5]),
        "drive-jump": drive + bytes([ADC, 2]) + struct.pack("<H", 700) + bytes([RUN, 20]),
        "drive-overrun": drive + bytes([OVERRUN]) + r("clear_faults") + bytes([RUN, 10]),
        "drive-loop-hang": drive + bytes([LOOP_HANG, 80, RUN, 10]),
        "drive-tick-hang": drive + bytes([TICK_HANG, 30, RUN, 10]),
        "drive-silence": drive + bytes([RUN, 255, RUN, 255, RUN, 100]),
        "drive-freeze": drive + bytes([FREEZE, 1, RUN, 5, FREEZE, 0]) + r("clear_faults"),
        "save-busy": bytes([EEPROM, 2, 0xFF, 0xFF]) + r("set_gains") + r("save_config"),
        "save-stuck": bytes([EEPROM, 1, 40, 0]) + r("save_config"),
        "save-power": r("save_config") + bytes([POWER, 0, 0]) + r("load_config"),
        "flip": bytes([FLIP]) + req(by_name["set_mode"])[0:] + struct.pack("<H", 37),
        "noise": bytes([RAW, 8, 1, 2, 3, 0, 5, 6, 7, 8]) + r("identify"),
    }


def python_seeds() -> dict[str, bytes]:
    """For fuzz_python.py: a chunking seed byte, then what the board sends (every message of
    the vectors, and the vectors' streams)."""
    root = VECTORS.parent
    msgs = json.loads(VECTORS.read_text())["messages"]
    seeds = {
        f"seed-{v['name']}-{v['case']}": bytes([i % 256]) + bytes.fromhex(v["frame"])
        for i, v in enumerate(msgs)
        if v["case"] == "typical"
    }
    # the pong the engine's first ping (seq 0) waits for, after a stream frame
    pong = next(v for v in msgs if v["name"] == "pong")
    state = next(v for v in msgs if v["name"] == "state")
    seeds["seed-pong-seq0"] = (
        b"\x07"
        + bytes.fromhex(state["frame"])
        + encode_frame(0, pong["id"], bytes.fromhex(pong["body"]))
    )
    for k, st in enumerate(json.loads((root / "streams.json").read_text())["streams"]):
        seeds[f"seed-stream-{st['name']}"] = bytes([k]) + bytes.fromhex(st["bytes"])
    return seeds


def main() -> None:
    reqs = requests()
    typical = {v["name"]: v for v in reqs if v["case"] == "typical"}
    raw = HERE / "corpus" / "raw"
    st = HERE / "corpus" / "struct"
    for d in (raw, st):
        d.mkdir(parents=True, exist_ok=True)
        for old in d.glob("seed-*"):
            old.unlink()
    for v in reqs:
        tag = f"seed-{v['name']}-{v['case']}"
        (raw / tag).write_bytes(bytes.fromhex(v["frame"]))
        (st / tag).write_bytes(req(v))
    (raw / "seed-all").write_bytes(b"".join(bytes.fromhex(v["frame"]) for v in reqs))
    for name, script in scenarios(typical).items():
        (st / f"seed-{name}").write_bytes(script)
    py = HERE / "corpus" / "python"
    py.mkdir(parents=True, exist_ok=True)
    for old in py.glob("seed-*"):
        old.unlink()
    for name, data in python_seeds().items():
        (py / name).write_bytes(data)


if __name__ == "__main__":
    main()
