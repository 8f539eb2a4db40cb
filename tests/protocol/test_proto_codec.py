"""Properties of the message codecs: round trips, refusals, and C++/Python agreement."""

from __future__ import annotations

import math
import struct
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from proto_helpers import CppCodec

from utrf.protocol import messages as M
from utrf.protocol.codec import WIRE_TYPES, Field, Message, to_f32
from utrf.protocol.errors import DecodeError

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
messages = st.sampled_from(M.MESSAGES)


def raw_strategy(f: Field) -> st.SearchStrategy[Any]:
    if f.enum is not None:
        return st.sampled_from([int(m) for m in f.enum])
    if f.flags is not None:
        bits = [int(m) for m in f.flags]
        return st.lists(st.sampled_from(bits), unique=True).map(sum)
    if f.type == "f32":
        lo = -3.4e38 if f.min is None else f.min
        hi = 3.4e38 if f.max is None else f.max
        return st.floats(lo, hi, width=32, allow_nan=False, allow_infinity=False)
    return st.integers(int(f._lo), int(f._hi))


@st.composite
def raw_messages(draw: st.DrawFn, cls: type[Message] | None = None) -> tuple[type[Message], dict]:
    cls = cls or draw(messages)
    raw: dict[str, Any] = {}
    for f in cls.FIELDS:
        values = st.tuples(*[raw_strategy(f)] * f.count) if f.count else raw_strategy(f)
        raw[f.name] = draw(values)
    return cls, raw


def pack(cls: type[Message], raw: dict[str, Any]) -> bytes:
    flat: list[Any] = []
    for f in cls.FIELDS:
        flat.extend(raw[f.name] if f.count else [raw[f.name]])
    return struct.pack("<" + "".join(f.struct_codes for f in cls.FIELDS), *flat)


@SETTINGS
@given(raw_messages())
def test_raw_to_message_to_raw_is_identity(case: tuple[type[Message], dict]) -> None:
    cls, raw = case
    body = pack(cls, raw)
    msg = cls.decode(body)
    assert msg.encode() == body
    assert msg.to_raw() == {k: v for k, v in raw.items()}
    assert cls.from_raw(raw) == msg


@st.composite
def si_messages(draw: st.DrawFn) -> tuple[type[Message], dict[str, Any]]:
    """Field values in SI units, anywhere within each field's range (not just on LSBs)."""
    cls = draw(messages)
    values: dict[str, Any] = {}
    for f in cls.FIELDS:
        if f.scale is not None:
            lo, hi = f.si_bounds()
            # stay half an LSB inside, where rounding cannot leave the range
            strat: st.SearchStrategy[Any] = st.floats(lo + f.scale / 2, hi - f.scale / 2)
        elif f.type == "f32":
            lo = -1e30 if f.min is None else f.min
            hi = 1e30 if f.max is None else f.max
            strat = st.floats(lo, hi)
        else:
            strat = raw_strategy(f).map(lambda v, f=f: f.from_raw(v))
        values[f.name] = draw(st.tuples(*[strat] * f.count) if f.count else strat)
    return cls, values


def _close(f: Field, got: Any, want: Any) -> bool:
    if f.scale is not None:
        # half an LSB, plus the float noise of the conversion itself
        return abs(got - want) <= f.scale / 2 + 1e-12 * max(1.0, abs(want))
    if f.type == "f32":
        return abs(got - want) <= abs(want) * 2**-24 + 1e-45  # half a binary32 ulp
    return got == want


@SETTINGS
@given(si_messages())
def test_si_values_round_trip_within_one_lsb(case: tuple[type[Message], dict[str, Any]]) -> None:
    cls, values = case
    decoded = cls.decode(cls(**values).encode())
    for f in cls.FIELDS:
        got, want = getattr(decoded, f.name), values[f.name]
        pairs = zip(got, want, strict=True) if f.count else [(got, want)]
        for g, w in pairs:
            assert _close(f, g, w), f"{cls.NAME}.{f.name}: {w} came back as {g}"


@SETTINGS
@given(st.data())
def test_cpp_and_python_agree_on_any_body(cpp: CppCodec, data: st.DataObject) -> None:
    cls = data.draw(messages)
    # Mostly bodies of the right length (random bytes hit every range check); some not.
    size = data.draw(st.one_of(st.just(cls.SIZE), st.integers(0, M.MAX_PAYLOAD)))
    body = data.draw(st.binary(min_size=size, max_size=size))
    result = cpp.decode_message(cls.ID, body)
    try:
        msg = cls.decode(body)
    except DecodeError as exc:
        if exc.field is None:
            assert (result.status, result.bad_field) == (1, 0xFF)
        else:
            index = next(f.index for f in cls.FIELDS if f.name == exc.field.split("[")[0])
            assert (result.status, result.bad_field) == (2, index), str(exc)
        return
    assert (result.status, result.bad_field) == (0, 0xFF)
    assert result.reencoded == body
    flat = [
        v
        for value in msg.to_raw().values()
        for v in (value if isinstance(value, tuple) else [value])
    ]
    assert result.values == flat


def test_every_message_size_fits_the_payload(cpp: CppCodec) -> None:
    for cls in M.MESSAGES:
        assert cls.SIZE <= M.MAX_PAYLOAD
        assert cpp.message_size(cls.ID) == cls.SIZE
    unused = next(i for i in range(256) if i not in M.BY_ID)
    assert cpp.message_size(unused) == -1
    assert cpp.decode_message(unused, b"").status == -1


# --- refusals with clear errors ---------------------------------------------------------------


def _set_mode(**changes: Any) -> M.SetMode:
    base: dict[str, Any] = dict(
        mask=0b11111,
        mode=(M.ControlMode.DUTY,) * 5,
        duty=(0.0, 0.5, -0.5, 1.0, -1.0),
        effort=(0.0, 0.25, 0.5, 0.75, 1.0),
    )
    base.update(changes)
    return M.SetMode(**base)


@pytest.mark.parametrize(
    ("msg", "where", "words"),
    [
        (_set_mode(duty=(0.0, 0.0, 1.2, 0.0, 0.0)), "set_mode.duty[2]", "outside [-1, 1]"),
        (_set_mode(effort=(-0.1, 0, 0, 0, 0)), "set_mode.effort[0]", "outside [0, 1]"),
        (_set_mode(mask=32), "set_mode.mask", "outside [0, 31]"),
        (_set_mode(mode=(0, 1, 9, 0, 0)), "set_mode.mode[2]", "not a ControlMode"),
        (_set_mode(duty=(0.0, 0.0)), "set_mode.duty", "needs 5 values"),
        (_set_mode(duty=0.5), "set_mode.duty", "sequence of 5"),
        (_set_mode(duty=(0, 0, math.nan, 0, 0)), "set_mode.duty[2]", "finite"),
        (_set_mode(duty=(0, 0, "a", 0, 0)), "set_mode.duty[2]", "not a number"),
        (_set_mode(mask=3.0), "set_mode.mask", "not an integer"),
        (M.SetTelemetry(rate_hz=1001), "set_telemetry.rate_hz", "outside [0, 1000] Hz"),
        (
            M.SetGains(0, math.nan, 0, 0, 10, 0, 1, 1, 0),
            "set_gains.kp",
            "not a finite number",
        ),
        (M.SetGains(0, 1e39, 0, 0, 10, 0, 1, 1, 0), "set_gains.kp", "outside [0, 1000] 1/rad"),
        (M.SetGains(0, 1, 0, 0, 0.5, 0, 1, 1, 0), "set_gains.d_cutoff_hz", "outside [1, 500] Hz"),
        (
            M.SetTargets(M.TargetKind.FLEXION, 1, (3000.0, 0, 0, 0, 0)),
            "set_targets.value[0]",
            "outside",
        ),
        (M.Fault(0.0, 7, M.FaultBits(0), (0,) * 5), "fault.finger", "outside [0, 4]"),
        (M.Fault(0.0, 1, 0x40, (0,) * 5), "fault.new_faults", "FaultBits"),
        (M.Ping(token=-1), "ping.token", "outside"),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_encode_refuses_with_a_clear_error(msg: Message, where: str, words: str) -> None:
    with pytest.raises(ValueError) as info:
        msg.encode()
    text = str(info.value)
    assert text.startswith(where + ":"), text
    assert words in text, text


def test_encode_accepts_the_exact_bounds_and_rounds_to_the_nearest_lsb() -> None:
    body = _set_mode(duty=(1.0, -1.0, 0.0004, 0.0006, -0.0006)).encode()
    duty = struct.unpack_from("<5h", body, 6)
    assert duty == (1000, -1000, 0, 1, -1)
    assert M.SetTelemetry(rate_hz=500).encode() == (500).to_bytes(2, "little")
    # f32 bounds compare in binary32, as the firmware does
    gains = M.SetGains(0, 1000.0, 10000.0, 100.0, 500.0, 0.5, 1000.0, 1.0, 0.5)
    assert M.SetGains.decode(gains.encode()) == gains


def test_decode_refuses_and_names_message_and_field() -> None:
    body = bytearray(_set_mode().encode())
    body[3] = 7  # mode[2]
    with pytest.raises(DecodeError, match=r"^set_mode\.mode\[2\]: 7 is not a ControlMode") as info:
        M.SetMode.decode(bytes(body))
    assert (info.value.message, info.value.field) == ("set_mode", "mode[2]")
    with pytest.raises(DecodeError, match=r"^set_mode: body is 25 bytes, expected 26"):
        M.SetMode.decode(bytes(body[:-1]))
    gains = bytearray(M.SetGains(0, 1, 0, 0, 10, 0, 1, 1, 0).encode())
    gains[1:5] = struct.pack("<f", math.inf)
    with pytest.raises(DecodeError, match=r"^set_gains\.kp: inf is not a finite number"):
        M.SetGains.decode(bytes(gains))


def test_numpy_values_encode_like_python_ones() -> None:
    np = pytest.importorskip("numpy")
    a = M.SetTargets(M.TargetKind.JOINT2_ANGLE, np.uint8(31), np.array([0.1, 0.2, 0.3, 0.4, 0.5]))
    b = M.SetTargets(M.TargetKind.JOINT2_ANGLE, 31, (0.1, 0.2, 0.3, 0.4, 0.5))
    assert a.encode() == b.encode()


def test_wire_types_match_struct_sizes() -> None:
    for name, (code, lo, hi) in WIRE_TYPES.items():
        size = struct.calcsize("<" + code)
        assert size == int(name[1:]) // 8
        if name != "f32":
            struct.pack("<" + code, lo)
            struct.pack("<" + code, hi)
            with pytest.raises(struct.error):
                struct.pack("<" + code, hi + 1)
    assert to_f32(0.1) != 0.1 and abs(to_f32(0.1) - 0.1) < 1e-8
