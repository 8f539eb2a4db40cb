"""Generate the protocol bindings from protocol/spec.toml (the single source of truth).

    python -m protocol.generate            # write every output (from the repository's root)
    python -m protocol.generate --check    # exit 1 and name the outputs that are stale

Outputs (all committed):
  firmware/src/generated/protocol_messages.h   C++11 structs, constants, decode/encode (AVR + host)
  host/utrf/protocol/messages.py               Python dataclasses in SI units
  protocol/README.md                           the message tables between the GENERATED markers

Standard library only (with tools.generated), so it runs before the Python package is
installed.
"""

from __future__ import annotations

import argparse
import binascii
import json
import math
import re
import struct
import sys
import textwrap
import tomllib
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tools.generated import write_or_check

COMMAND = "python -m protocol.generate"
REPO_ROOT = Path(__file__).resolve().parents[1]
SPEC_PATH = REPO_ROOT / "protocol" / "spec.toml"
HEADER_PATH = REPO_ROOT / "firmware" / "src" / "generated" / "protocol_messages.h"
CONFIG_PATH = REPO_ROOT / "firmware" / "src" / "generated" / "config_layout.h"
MESSAGES_PATH = REPO_ROOT / "host" / "utrf" / "protocol" / "messages.py"
README_PATH = REPO_ROOT / "protocol" / "README.md"
README_BEGIN = "<!-- BEGIN GENERATED: message tables (python protocol/generate.py) -->"
README_END = "<!-- END GENERATED: message tables -->"


# Object-like macros of <avr/io.h> (ATmega2560) and <Arduino.h> that an UPPER_CASE name could
# meet; a macro would replace the name wherever both are included. (A test checks this list
# against the real headers.)
AVR_ARDUINO_MACROS = frozenset(
    {f"{reg}{port}" for reg in ("PIN", "PORT", "DDR") for port in "ABCDEFGHJKL"}
    | {"HIGH", "LOW", "INPUT", "OUTPUT", "INPUT_PULLUP", "LSBFIRST", "MSBFIRST"}
    | {"CHANGE", "FALLING", "RISING", "DEFAULT", "EXTERNAL", "INTERNAL", "INTERNAL1V1"}
    | {"INTERNAL2V56", "PI", "HALF_PI", "TWO_PI", "DEG_TO_RAD", "RAD_TO_DEG", "EULER"}
    | {"SERIAL", "DISPLAY", "DEC", "HEX", "OCT", "BIN", "NOT_A_PIN", "NOT_A_PORT"}
    | {"NOT_AN_INTERRUPT", "NOT_ON_TIMER", "TIMER0A", "TIMER1A", "SPCR", "SREG", "RAMEND"}
)


class SpecError(ValueError):
    """The spec is inconsistent; the message names the offending entry."""


@dataclass(frozen=True)
class WireType:
    name: str
    size: int
    ctype: str
    lo: int | float
    hi: int | float

    @property
    def is_float(self) -> bool:
        return self.name == "f32"

    @property
    def signed(self) -> bool:
        return self.name.startswith("i")


TYPES: dict[str, WireType] = {
    "u8": WireType("u8", 1, "uint8_t", 0, 0xFF),
    "i8": WireType("i8", 1, "int8_t", -0x80, 0x7F),
    "u16": WireType("u16", 2, "uint16_t", 0, 0xFFFF),
    "i16": WireType("i16", 2, "int16_t", -0x8000, 0x7FFF),
    "u32": WireType("u32", 4, "uint32_t", 0, 0xFFFFFFFF),
    "i32": WireType("i32", 4, "int32_t", -0x80000000, 0x7FFFFFFF),
    "f32": WireType("f32", 4, "float", -math.inf, math.inf),
}


@dataclass
class EnumValue:
    name: str
    value: int
    doc: str


@dataclass
class EnumDef:
    name: str
    doc: str
    values: list[EnumValue]
    is_flags: bool
    type: WireType

    @property
    def all_bits(self) -> int:
        return sum(1 << v.value for v in self.values)


@dataclass
class FieldDef:
    name: str
    type: WireType
    index: int
    offset: int
    count: int | None
    scale: float | None
    min: float | None
    max: float | None
    enum: EnumDef | None
    flags: EnumDef | None
    unit: str
    doc: str
    # Raw bounds actually checked (integers for integer types, floats for f32); None = the
    # type's own limit, so no check is generated.
    raw_min: int | float | None = None
    raw_max: int | float | None = None
    default: float | None = None  # a configuration value's default (SI)

    @property
    def n(self) -> int:
        return 1 if self.count is None else self.count

    @property
    def size(self) -> int:
        return self.type.size * self.n


@dataclass
class MessageDef:
    id: int
    name: str
    direction: str
    doc: str
    idempotent: bool
    reply: str | None
    reply_timeout_s: float | None
    same_fields_as: str | None
    fields: list[FieldDef] = field(default_factory=list)
    # The u8 field whose bits select fingers: the per-finger arrays are checked (and used)
    # only for the fingers it selects.
    masked_by: str | None = None

    def masked(self, f: FieldDef) -> bool:
        return self.masked_by is not None and f.count is not None and f.name != self.masked_by

    @property
    def size(self) -> int:
        return sum(f.size for f in self.fields)

    @property
    def class_name(self) -> str:
        return camel(self.name)

    @property
    def upper(self) -> str:
        return self.name.upper()

    @property
    def is_request(self) -> bool:
        return self.direction == "host_to_board"


@dataclass
class ConfigDef:
    """One part of the board's configuration: the values of a set_ request (less `finger`)."""

    name: str  # member of config::Finger (per finger) or config::Config
    struct: str  # its C++ struct
    per_finger: bool
    set: MessageDef
    get: MessageDef
    reply: MessageDef

    @property
    def fields(self) -> list[FieldDef]:
        return [f for f in self.set.fields if not (self.per_finger and f.name == "finger")]


@dataclass
class Spec:
    protocol: dict[str, Any]
    enums: list[EnumDef]
    messages: list[MessageDef]
    schema_hash: int
    configs: list[ConfigDef] = field(default_factory=list)

    def field_default(self, message: str, name: str) -> float:
        for f in self.message(message).fields:
            if f.name == name and f.default is not None:
                return f.default
        raise SpecError(f"the protocol needs a default for {message}.{name}")

    def message(self, name: str) -> MessageDef:
        for m in self.messages:
            if m.name == name:
                return m
        raise KeyError(name)

    def reply_of(self, m: MessageDef) -> MessageDef | None:
        if not m.is_request:
            return None
        return self.message(m.reply or "ack")

    def timeout_of(self, m: MessageDef) -> float:
        if m.reply_timeout_s is not None:
            return m.reply_timeout_s
        return float(self.protocol["reply_timeout_s"])


def camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


# --------------------------------------------------------------------------------------------
# Loading and checking the spec
# --------------------------------------------------------------------------------------------


def strip_docs(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: strip_docs(v) for k, v in obj.items() if k != "doc"}
    if isinstance(obj, list):
        return [strip_docs(v) for v in obj]
    return obj


def canonical_json(spec: dict[str, Any]) -> str:
    """The canonical spec: parsed TOML without `doc` keys, as compact sorted JSON."""
    return json.dumps(strip_docs(spec), sort_keys=True, separators=(",", ":"))


def schema_hash(spec: dict[str, Any]) -> int:
    return zlib.crc32(canonical_json(spec).encode("utf-8")) & 0xFFFFFFFF


_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_UPPER_RE = re.compile(r"^[A-Z][A-Z0-9_]*$")
_CAMEL_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
_PROTOCOL_KEYS = {
    "name": str,
    "version": int,
    "byte_order": str,
    "max_payload": int,
    "finger_count": int,
    "default_baud": int,
    "crc": str,
    "framing": str,
    "reply_timeout_s": float,
    "retries": int,
    "heartbeat_period_s": float,
    "max_telemetry_hz": int,
    "board_seq_flag": int,
}
_MESSAGE_KEYS = {
    "id",
    "name",
    "direction",
    "doc",
    "idempotent",
    "reply",
    "reply_timeout_s",
    "same_fields_as",
    "masked_by",
    "fields",
}
_FIELD_KEYS = {
    "name",
    "type",
    "count",
    "scale",
    "min",
    "max",
    "enum",
    "flags",
    "unit",
    "doc",
    "default",
}
_CONFIG_KEYS = {"name", "struct", "per_finger", "set", "get", "doc"}


def _raw_bound(value: float, scale: float, up: bool) -> int:
    """The raw integer bound for an SI bound: inside [min, max], forgiving float noise."""
    x = value / scale
    r = round(x)
    if abs(x - r) < 1e-6 * max(1.0, abs(x)):
        return int(r)
    return math.ceil(x) if up else math.floor(x)


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def _check_keys(where: str, table: dict[str, Any], allowed: set[str]) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SpecError(f"{where}: unknown key(s) {', '.join(unknown)}")


def _load_enum(entry: dict[str, Any], is_flags: bool) -> EnumDef:
    kind = "flags" if is_flags else "enum"
    name = entry.get("name")
    if not isinstance(name, str) or not _CAMEL_RE.match(name):
        raise SpecError(f"[[{kind}]] name {name!r} must be CamelCase")
    items = entry.get("bits" if is_flags else "values")
    if not isinstance(items, list) or not items:
        raise SpecError(f"{kind} {name}: needs a non-empty {'bits' if is_flags else 'values'} list")
    wire = TYPES.get(entry.get("type", "u8"))
    if wire is None or wire.is_float or wire.signed:
        raise SpecError(f"{kind} {name}: type must be an unsigned integer type")
    values: list[EnumValue] = []
    for item in items:
        vname = item.get("name")
        value = item.get("bit" if is_flags else "value")
        if not isinstance(vname, str) or not _UPPER_RE.match(vname):
            raise SpecError(f"{kind} {name}: member name {vname!r} must be UPPER_CASE")
        if vname in AVR_ARDUINO_MACROS:
            raise SpecError(
                f"{kind} {name}.{vname}: a macro of <avr/io.h> or <Arduino.h> has this name"
            )
        if not isinstance(value, int) or isinstance(value, bool):
            key = "bit" if is_flags else "value"
            raise SpecError(f"{kind} {name}.{vname}: needs an integer {key}")
        limit = wire.size * 8 - 1 if is_flags else wire.hi
        if not 0 <= value <= limit:
            raise SpecError(f"{kind} {name}.{vname}: {value} does not fit in {wire.name}")
        values.append(EnumValue(vname, value, str(item.get("doc", ""))))
    if len({v.name for v in values}) != len(values):
        raise SpecError(f"{kind} {name}: duplicate member names")
    if len({v.value for v in values}) != len(values):
        raise SpecError(f"{kind} {name}: duplicate member values")
    return EnumDef(name, str(entry.get("doc", "")), values, is_flags, wire)


def _load_field(
    msg: str, entry: dict[str, Any], index: int, offset: int, enums: dict[str, EnumDef]
) -> FieldDef:
    name = entry.get("name")
    where = f"message {msg}, field {name}"
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise SpecError(f"message {msg}: field name {name!r} must be snake_case")
    _check_keys(where, entry, _FIELD_KEYS)
    wire = TYPES.get(entry.get("type", ""))
    if wire is None:
        raise SpecError(f"{where}: type {entry.get('type')!r} is not one of {', '.join(TYPES)}")
    count = entry.get("count")
    if count is not None and (not isinstance(count, int) or count < 1):
        raise SpecError(f"{where}: count must be a positive integer")
    scale = entry.get("scale")
    if scale is not None:
        if wire.is_float:
            raise SpecError(f"{where}: an f32 field takes no scale")
        if not isinstance(scale, int | float) or scale <= 0:
            raise SpecError(f"{where}: scale must be a positive number")
        scale = float(scale)
    enum = flags = None
    if "enum" in entry:
        enum = enums.get(entry["enum"])
        if enum is None or enum.is_flags:
            raise SpecError(f"{where}: enum {entry['enum']!r} is not defined")
    if "flags" in entry:
        flags = enums.get(entry["flags"])
        if flags is None or not flags.is_flags:
            raise SpecError(f"{where}: flags {entry['flags']!r} is not defined")
    for ref in (enum, flags):
        if ref is not None:
            if scale is not None or "min" in entry or "max" in entry:
                raise SpecError(f"{where}: an enum or flags field takes no scale, min or max")
            if ref.type is not wire:
                raise SpecError(
                    f"{where}: type {wire.name} differs from {ref.name}'s {ref.type.name}"
                )
    lo, hi = entry.get("min"), entry.get("max")
    for key, bound in (("min", lo), ("max", hi)):
        if bound is not None and (not isinstance(bound, int | float) or isinstance(bound, bool)):
            raise SpecError(f"{where}: {key} must be a number")
    if lo is not None and hi is not None and lo > hi:
        raise SpecError(f"{where}: min {lo} is above max {hi}")
    default = entry.get("default")
    if default is not None:
        if not isinstance(default, int | float) or isinstance(default, bool) or count:
            raise SpecError(f"{where}: default must be a number, on a field that is no array")
        if (lo is not None and default < lo) or (hi is not None and default > hi):
            raise SpecError(f"{where}: default {default} is outside [{lo}, {hi}]")
        if enum is not None and default not in {v.value for v in enum.values}:
            raise SpecError(f"{where}: default {default} is not a {enum.name}")
    f = FieldDef(
        name=name,
        type=wire,
        index=index,
        offset=offset,
        count=count,
        scale=scale,
        min=None if lo is None else float(lo),
        max=None if hi is None else float(hi),
        enum=enum,
        flags=flags,
        unit=str(entry.get("unit", "")),
        doc=str(entry.get("doc", "")),
        default=None if default is None else float(default),
    )
    if wire.is_float:
        f.raw_min = None if lo is None else _f32(float(lo))
        f.raw_max = None if hi is None else _f32(float(hi))
        return f
    for key, bound in (("min", lo), ("max", hi)):
        if bound is None:
            continue
        if scale is None and bound != int(bound):
            raise SpecError(f"{where}: {key} {bound} must be an integer for an unscaled field")
        raw = _raw_bound(float(bound), scale or 1.0, up=(key == "min"))
        if not wire.lo <= raw <= wire.hi:
            raise SpecError(f"{where}: {key} {bound} is raw {raw}, outside {wire.name}")
        if key == "min" and raw > wire.lo:
            f.raw_min = raw
        if key == "max" and raw < wire.hi:
            f.raw_max = raw
    return f


def load_spec(path: Path = SPEC_PATH) -> Spec:
    with path.open("rb") as fh:
        try:
            raw = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise SpecError(f"{path}: {exc}") from exc
    _check_keys("spec", raw, {"protocol", "enum", "flags", "message", "config"})
    proto = raw.get("protocol", {})
    for key, kind in _PROTOCOL_KEYS.items():
        value = proto.get(key)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise SpecError(f"[protocol] {key} must be a {kind.__name__} (got {value!r})")
    _check_keys("[protocol]", proto, set(_PROTOCOL_KEYS) | {"doc"})
    # The codecs implement exactly these; a spec asking for anything else is refused.
    fixed = {"byte_order": "little", "crc": "CRC-16/CCITT-FALSE", "framing": "COBS"}
    for key, want in fixed.items():
        if proto[key] != want:
            raise SpecError(f"[protocol] {key} = {proto[key]!r}: the codecs implement {want!r}")
    if not 1 <= proto["max_payload"] <= 250:
        raise SpecError("[protocol] max_payload must be within 1..250")
    if proto["board_seq_flag"] not in (0x40, 0x80):
        raise SpecError("[protocol] board_seq_flag must be one bit of the seq byte (0x80)")

    enums: dict[str, EnumDef] = {}
    for entry, is_flags in [(e, False) for e in raw.get("enum", [])] + [
        (e, True) for e in raw.get("flags", [])
    ]:
        e = _load_enum(entry, is_flags)
        if e.name in enums:
            raise SpecError(f"enum/flags {e.name} is defined twice")
        enums[e.name] = e

    entries = raw.get("message", [])
    by_name = {m.get("name"): m for m in entries}
    messages: list[MessageDef] = []
    for entry in entries:
        name = entry.get("name")
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise SpecError(f"message name {name!r} must be snake_case")
        _check_keys(f"message {name}", entry, _MESSAGE_KEYS)
        mid = entry.get("id")
        if not isinstance(mid, int) or not 0 <= mid <= 0xFF:
            raise SpecError(f"message {name}: id must be an integer 0..255")
        direction = entry.get("direction")
        if direction not in ("host_to_board", "board_to_host"):
            raise SpecError(f"message {name}: direction must be host_to_board or board_to_host")
        source = entry
        same = entry.get("same_fields_as")
        if same is not None:
            if "fields" in entry:
                raise SpecError(f"message {name}: has both fields and same_fields_as")
            if same not in by_name or "same_fields_as" in by_name[same]:
                raise SpecError(
                    f"message {name}: same_fields_as {same!r} is not a message with fields"
                )
            source = by_name[same]
        fields: list[FieldDef] = []
        offset = 0
        for i, fentry in enumerate(source.get("fields", [])):
            f = _load_field(name, fentry, i, offset, enums)
            offset += f.size
            fields.append(f)
        if len({f.name for f in fields}) != len(fields):
            raise SpecError(f"message {name}: duplicate field names")
        m = MessageDef(
            id=mid,
            name=name,
            direction=direction,
            doc=str(entry.get("doc", "") or by_name.get(same, {}).get("doc", "")),
            idempotent=bool(entry.get("idempotent", False)),
            reply=entry.get("reply"),
            reply_timeout_s=entry.get("reply_timeout_s"),
            same_fields_as=same,
            fields=fields,
            masked_by=entry.get("masked_by"),
        )
        if m.masked_by is not None:
            mask = next((f for f in fields if f.name == m.masked_by), None)
            if mask is None or mask.type.name != "u8" or mask.count is not None:
                raise SpecError(f"message {name}: masked_by {m.masked_by!r} is no u8 field")
            if fields.index(mask) > min(i for i, f in enumerate(fields) if m.masked(f)):
                raise SpecError(f"message {name}: {m.masked_by} must come before the arrays")
        if m.size > proto["max_payload"]:
            limit = proto["max_payload"]
            raise SpecError(f"message {name}: {m.size} bytes, above max_payload {limit}")
        if not m.is_request and (
            "idempotent" in entry or m.reply is not None or m.reply_timeout_s is not None
        ):
            raise SpecError(
                f"message {name}: only requests take idempotent, reply, reply_timeout_s"
            )
        messages.append(m)

    if len({m.name for m in messages}) != len(messages):
        raise SpecError("two messages share a name")
    ids: dict[int, str] = {}
    for m in messages:
        if m.id in ids:
            raise SpecError(f"messages {ids[m.id]} and {m.name} share id 0x{m.id:02X}")
        ids[m.id] = m.name
    names = {m.name: m for m in messages}
    for m in messages:
        if m.reply is not None and (
            m.reply not in names or names[m.reply].direction != "board_to_host"
        ):
            raise SpecError(f"message {m.name}: reply {m.reply!r} is not a board_to_host message")
    for needed in ("identify", "identity", "ack", "nack", "heartbeat", "boot", "state", "fault"):
        if needed not in names:
            raise SpecError(f"the protocol needs a message named {needed}")
    # The handshake reads these two fields of any firmware's identity and boot, whatever
    # its version: they keep their place forever.
    for fixed_msg in ("identity", "boot"):
        head = [(f.name, f.type.name, f.count) for f in names[fixed_msg].fields[:2]]
        if head != [("protocol_version", "u16", None), ("schema_hash", "u32", None)]:
            raise SpecError(
                f"message {fixed_msg}: must start with u16 protocol_version, u32 schema_hash"
            )
    if "ErrorCode" not in enums:
        raise SpecError("the protocol needs an ErrorCode enum")
    spec = Spec(proto, list(enums.values()), messages, schema_hash(raw))
    spec.configs = [_load_config(entry, spec) for entry in raw.get("config", [])]
    if len({c.name for c in spec.configs}) != len(spec.configs):
        raise SpecError("two config blocks share a name")
    spec.field_default("set_safety", "heartbeat_timeout")
    return spec


def _load_config(entry: dict[str, Any], spec: Spec) -> ConfigDef:
    name = entry.get("name")
    where = f"config {name}"
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise SpecError(f"config name {name!r} must be snake_case")
    _check_keys(where, entry, _CONFIG_KEYS)
    struct = entry.get("struct")
    if not isinstance(struct, str) or not _CAMEL_RE.match(struct):
        raise SpecError(f"{where}: struct {struct!r} must be CamelCase")
    per_finger = entry.get("per_finger")
    if not isinstance(per_finger, bool):
        raise SpecError(f"{where}: per_finger must be true or false")
    try:
        set_msg = spec.message(str(entry.get("set")))
        get_msg = spec.message(str(entry.get("get")))
    except KeyError as exc:
        raise SpecError(f"{where}: no message {exc}") from None
    reply = spec.reply_of(get_msg)
    if not set_msg.is_request or reply is None or reply.same_fields_as != set_msg.name:
        raise SpecError(
            f"{where}: {get_msg.name}'s reply must have the same fields as {set_msg.name}"
        )
    head = [(f.name, f.type.name) for f in set_msg.fields[:1]]
    if per_finger and head != [("finger", "u8")]:
        raise SpecError(f"{where}: a per-finger {set_msg.name} starts with u8 finger")
    get_head = [(f.name, f.type.name) for f in get_msg.fields]
    if get_head != (head if per_finger else []):
        raise SpecError(f"{where}: {get_msg.name} takes {'finger' if per_finger else 'nothing'}")
    c = ConfigDef(name, struct, per_finger, set_msg, get_msg, reply)
    for f in c.fields:
        if f.count is not None:
            raise SpecError(f"{where}: {set_msg.name}.{f.name}: no arrays in the configuration")
    return c


# --------------------------------------------------------------------------------------------
# Shared formatting helpers
# --------------------------------------------------------------------------------------------


def fmt_number(x: float) -> str:
    """Shortest text that reads back as x (1e-06 -> 1e-06, 1000.0 -> 1000.0)."""
    return repr(float(x))


def one_line(text: str) -> str:
    return " ".join(text.split())


def wrap(text: str, width: int, prefix: str) -> list[str]:
    text = one_line(text)
    if not text:
        return []
    return [prefix + line for line in textwrap.wrap(text, width - len(prefix))]


def si_range(f: FieldDef) -> tuple[float | None, float | None]:
    """The SI range a value must lie in, as checked on the wire (None: the type's limit)."""
    if f.type.is_float:
        return f.min, f.max
    scale = f.scale or 1.0
    lo = f.raw_min if f.raw_min is not None else f.type.lo
    hi = f.raw_max if f.raw_max is not None else f.type.hi
    if f.scale is None:
        return lo, hi
    return lo * scale, hi * scale


# --------------------------------------------------------------------------------------------
# C++ header
# --------------------------------------------------------------------------------------------


def c_int(value: int, wire: WireType) -> str:
    """An integer literal that keeps its value and type on AVR (16-bit int) and x86."""
    if wire.size == 4 or abs(value) > 0x7FFF:
        if wire.signed or value < 0:
            if value == -0x80000000:
                return "(-2147483647L - 1)"
            return f"{value}L"
        return f"{value}UL"
    return str(value)


def c_float(value: float) -> str:
    text = repr(float(value))
    if "e" not in text and "." not in text:
        text += ".0"
    return text + "f"


def c_comment(f: FieldDef) -> str:
    parts: list[str] = []
    if f.enum is not None:
        parts.append(f.enum.name)
    if f.flags is not None:
        parts.append(f.flags.name)
    if f.scale is not None:
        parts.append(f"x {fmt_number(f.scale)}")
    if f.unit:
        parts.append(f.unit)
    lo, hi = si_range(f)
    if f.raw_min is not None or f.raw_max is not None:
        parts.append(
            f"[{fmt_number(lo) if f.scale or f.type.is_float else lo}, "
            f"{fmt_number(hi) if f.scale or f.type.is_float else hi}]"
        )
    if f.doc:
        parts.append(one_line(f.doc))
    return "; ".join(parts)


def _c_checks(f: FieldDef, ref: str) -> list[str]:
    """Conditions that make the raw value `ref` invalid (no tautologies: -Wtype-limits)."""
    conds: list[str] = []
    if f.type.is_float:
        conds.append(f"!detail::is_finite({ref})")
        if f.raw_min is not None:
            conds.append(f"{ref} < {c_float(f.raw_min)}")
        if f.raw_max is not None:
            conds.append(f"{ref} > {c_float(f.raw_max)}")
        return conds
    if f.enum is not None:
        values = sorted(v.value for v in f.enum.values)
        lo, hi = values[0], values[-1]
        if values == list(range(lo, hi + 1)):
            if lo > 0:
                conds.append(f"{ref} < {lo}")
            if hi < f.type.hi:
                conds.append(f"{ref} > {hi}")
        else:
            conds.append(f"!{f.enum.name}_valid({ref})")
        return conds
    if f.flags is not None:
        all_bits = f.flags.all_bits
        if all_bits != f.type.hi:
            conds.append(f"({ref} & ~{f.flags.name}::kAll) != 0")
        return conds
    if f.raw_min is not None:
        conds.append(f"{ref} < {c_int(int(f.raw_min), f.type)}")
    if f.raw_max is not None:
        conds.append(f"{ref} > {c_int(int(f.raw_max), f.type)}")
    return conds


def render_header(spec: Spec) -> str:
    p = spec.protocol
    out: list[str] = []
    w = out.append
    w("// Generated by protocol/generate.py from protocol/spec.toml: do not edit.")
    w("// Regenerate with `make generate`; a test fails when this file is stale.")
    w("//")
    w("// The host-board protocol's messages for the firmware: constants, enums, flag bits, one")
    w("// struct per message holding the raw wire integers (f32 fields are float), and")
    w("// decode/encode functions. Bodies are little-endian and read byte by byte, so this works")
    w("// on AVR and x86 alike. C++11, no heap, no STL. The frame around a body (seq, id, CRC,")
    w("// COBS) is core/framing.h; the wire format for people is protocol/README.md.")
    w("#ifndef UTRF_PROTOCOL_MESSAGES_H")
    w("#define UTRF_PROTOCOL_MESSAGES_H")
    w("")
    w("#include <stdint.h>")
    w("#include <string.h>")
    w("")
    clashes = [m.upper for m in spec.messages if m.upper in AVR_ARDUINO_MACROS]
    if clashes:
        w(f"// Macros of <avr/io.h> or <Arduino.h> with the name of a MsgId: {', '.join(clashes)}.")
        w("// They are suspended within this file so that it compiles everywhere; in a file that")
        kids = ", ".join(camel(c.lower()) + "::kId" for c in clashes)
        w(f"// includes those headers, write {kids} rather than MsgId::{clashes[0]}.")
        for c in clashes:
            w(f'#pragma push_macro("{c}")')
            w(f"#undef {c}")
    w("")
    w("namespace utrf {")
    w("namespace proto {")
    w("")
    w(f"static const uint16_t kProtocolVersion = {p['version']};")
    w("// CRC-32 of the canonical spec (doc texts excluded); compared at the handshake.")
    w(f"static const uint32_t kSchemaHash = 0x{spec.schema_hash:08X}UL;")
    w(f"static const uint8_t kMaxPayload = {p['max_payload']};  // body bytes")
    w(f"static const uint8_t kFingerCount = {p['finger_count']};")
    w(f"static const uint32_t kDefaultBaud = {p['default_baud']}UL;")
    w(f"static const uint16_t kMaxTelemetryHz = {p['max_telemetry_hz']};")
    hb_ms = round(spec.field_default("set_safety", "heartbeat_timeout") * 1000)
    w(f"static const uint16_t kDefaultHeartbeatTimeoutMs = {hb_ms};")
    w("// Seq of board-initiated frames (state stream, fault, boot): this bit set, the low bits a")
    w("// running counter. Requests use seqs without it and replies echo them, so a reply and a")
    w("// stream frame can never be confused.")
    w(f"static const uint8_t kBoardSeqFlag = 0x{p['board_seq_flag']:02X};")
    w("")
    w("// Next seq for a board-initiated frame (the first after reset is kBoardSeqFlag).")
    w("inline uint8_t next_board_seq(uint8_t seq) {")
    w("  return static_cast<uint8_t>(kBoardSeqFlag | ((seq + 1u) & (kBoardSeqFlag - 1u)));")
    w("}")
    w("")
    for e in spec.enums:
        for line in wrap(e.doc, 98, "// "):
            w(line)
        if e.is_flags:
            w(f"namespace {e.name} {{")
            for v in e.values:
                w(f"static const {e.type.ctype} {v.name} = 1u << {v.value};  // {one_line(v.doc)}")
            w(f"static const {e.type.ctype} kAll = 0x{e.all_bits:02X};")
            w(f"}}  // namespace {e.name}")
        else:
            w(f"enum class {e.name} : {e.type.ctype} {{")
            for v in e.values:
                w(f"  {v.name} = {v.value},  // {one_line(v.doc)}")
            w("};")
            values = sorted(v.value for v in e.values)
            if values != list(range(values[0], values[-1] + 1)):
                cases = " || ".join(f"v == {x}" for x in values)
                w(f"inline bool {e.name}_valid({e.type.ctype} v) {{ return {cases}; }}")
        w("")
    w("namespace MsgId {")
    for m in spec.messages:
        w(f"static const uint8_t {m.upper} = 0x{m.id:02X};")
    w("}  // namespace MsgId")
    w("")
    w("enum class DecodeStatus : uint8_t { OK = 0, BAD_LENGTH, OUT_OF_RANGE };")
    w("")
    w("namespace detail {")
    w("inline uint16_t rd_u16(const uint8_t* p) {")
    w("  return static_cast<uint16_t>(p[0] | (static_cast<uint16_t>(p[1]) << 8));")
    w("}")
    w("inline uint32_t rd_u32(const uint8_t* p) {")
    w("  return static_cast<uint32_t>(p[0]) | (static_cast<uint32_t>(p[1]) << 8) |")
    w("         (static_cast<uint32_t>(p[2]) << 16) | (static_cast<uint32_t>(p[3]) << 24);")
    w("}")
    w("inline uint8_t rd_u8(const uint8_t* p) { return p[0]; }")
    w("inline int8_t rd_i8(const uint8_t* p) { return static_cast<int8_t>(p[0]); }")
    w("inline int16_t rd_i16(const uint8_t* p) { return static_cast<int16_t>(rd_u16(p)); }")
    w("inline int32_t rd_i32(const uint8_t* p) { return static_cast<int32_t>(rd_u32(p)); }")
    w("inline float rd_f32(const uint8_t* p) {")
    w("  uint32_t u = rd_u32(p);")
    w("  float f;")
    w("  memcpy(&f, &u, sizeof f);  // IEEE-754 binary32 on AVR and x86")
    w("  return f;")
    w("}")
    w("inline void wr_u8(uint8_t* p, uint8_t v) { p[0] = v; }")
    w("inline void wr_u16(uint8_t* p, uint16_t v) {")
    w("  p[0] = static_cast<uint8_t>(v);")
    w("  p[1] = static_cast<uint8_t>(v >> 8);")
    w("}")
    w("inline void wr_u32(uint8_t* p, uint32_t v) {")
    w("  p[0] = static_cast<uint8_t>(v);")
    w("  p[1] = static_cast<uint8_t>(v >> 8);")
    w("  p[2] = static_cast<uint8_t>(v >> 16);")
    w("  p[3] = static_cast<uint8_t>(v >> 24);")
    w("}")
    w("inline void wr_i8(uint8_t* p, int8_t v) { p[0] = static_cast<uint8_t>(v); }")
    w("inline void wr_i16(uint8_t* p, int16_t v) { wr_u16(p, static_cast<uint16_t>(v)); }")
    w("inline void wr_i32(uint8_t* p, int32_t v) { wr_u32(p, static_cast<uint32_t>(v)); }")
    w("inline void wr_f32(uint8_t* p, float f) {")
    w("  uint32_t u;")
    w("  memcpy(&u, &f, sizeof u);")
    w("  wr_u32(p, u);")
    w("}")
    w("// False for NaN and the infinities (inf - inf is NaN, and NaN != NaN).")
    w("inline bool is_finite(float v) { return (v - v) == (v - v); }")
    w("}  // namespace detail")
    w("")

    for m in spec.messages:
        w(
            f"// {m.name} (0x{m.id:02X}, {m.direction.replace('_', ' ')}"
            + (f", reply {spec.reply_of(m).name}" if m.is_request else "")  # type: ignore[union-attr]
            + (", idempotent" if m.is_request and m.idempotent else "")
            + ")"
        )
        for line in wrap(m.doc, 98, "// "):
            w(line)
        w(f"struct {m.class_name} {{")
        w(f"  static const uint8_t kId = 0x{m.id:02X};")
        w(f"  static const uint8_t kSize = {m.size};")
        reply = spec.reply_of(m) if m.is_request else None
        if reply is not None:
            w(f"  static const uint8_t kReplyId = 0x{reply.id:02X};  // {reply.name}")
        for f in m.fields:
            if f.scale is not None:
                w(f"  static constexpr float k{camel(f.name)}Scale = {c_float(f.scale)};")
        for f in m.fields:
            decl = f"{f.type.ctype} {f.name}" + (f"[{f.count}]" if f.count else "") + ";"
            comment = c_comment(f)
            w(f"  {decl}" + (f"  // {comment}" if comment else ""))
        w("};")
        w("")

    w("// decode: checks the exact length, then every field (enum membership, flag bits, range,")
    w("// NaN and infinity for f32). On OUT_OF_RANGE, bad_field is the field's index in the")
    w("// message (the nack detail); otherwise 0xFF. `out` is meaningful only on OK.")
    w("// encode: writes kSize bytes (no checks: the firmware's own values) and returns kSize.")
    for m in spec.messages:
        cn = m.class_name
        w("")
        if not m.fields:
            w(f"inline DecodeStatus decode(const uint8_t* body, uint8_t len, {cn}& out,")
            w("                           uint8_t& bad_field) {")
            w("  (void)body;")
            w("  (void)out;")
            w("  bad_field = 0xFF;")
            w(f"  return len == {cn}::kSize ? DecodeStatus::OK : DecodeStatus::BAD_LENGTH;")
            w("}")
            w(f"inline uint8_t encode(const {cn}& msg, uint8_t* body) {{")
            w("  (void)msg;")
            w("  (void)body;")
            w(f"  return {cn}::kSize;")
            w("}")
            continue
        w(f"inline DecodeStatus decode(const uint8_t* body, uint8_t len, {cn}& out,")
        w("                           uint8_t& bad_field) {")
        w("  bad_field = 0xFF;")
        w(f"  if (len != {cn}::kSize) return DecodeStatus::BAD_LENGTH;")
        for f in m.fields:
            t = f.type.name
            if f.count is None:
                w(f"  out.{f.name} = detail::rd_{t}(body + {f.offset});")
                conds = _c_checks(f, f"out.{f.name}")
                if conds:
                    w(f"  if ({' || '.join(conds)}) {{")
                    w(f"    bad_field = {f.index};")
                    w("    return DecodeStatus::OUT_OF_RANGE;")
                    w("  }")
            else:
                w(f"  for (uint8_t i = 0; i < {f.count}; ++i) {{")
                w(
                    f"    out.{f.name}[i] = detail::rd_{t}(body + {f.offset} + {f.type.size} * i);"
                    if f.type.size > 1
                    else f"    out.{f.name}[i] = detail::rd_{t}(body + {f.offset} + i);"
                )
                conds = _c_checks(f, f"out.{f.name}[i]")
                if conds and m.masked(f):
                    conds = [f"((out.{m.masked_by} >> i) & 1u) && ({' || '.join(conds)})"]
                if conds:
                    w(f"    if ({' || '.join(conds)}) {{")
                    w(f"      bad_field = {f.index};")
                    w("      return DecodeStatus::OUT_OF_RANGE;")
                    w("    }")
                w("  }")
        w("  return DecodeStatus::OK;")
        w("}")
        w(f"inline uint8_t encode(const {cn}& msg, uint8_t* body) {{")
        for f in m.fields:
            t = f.type.name
            if f.count is None:
                w(f"  detail::wr_{t}(body + {f.offset}, msg.{f.name});")
            else:
                step = f" + {f.type.size} * i" if f.type.size > 1 else " + i"
                w(
                    f"  for (uint8_t i = 0; i < {f.count}; ++i) "
                    f"detail::wr_{t}(body + {f.offset}{step}, msg.{f.name}[i]);"
                )
        w(f"  return {cn}::kSize;")
        w("}")
    w("")
    w("// write: the body's bytes, one at a time, into a byte sink W (put(uint8_t)): the board's")
    w("// frame writer computes the CRC and the COBS codes as the bytes come, with no body copy.")
    w("template <typename W>")
    w("inline void put_u8(W& w, uint8_t v) { w.put(v); }")
    w("template <typename W>")
    w("inline void put_i8(W& w, int8_t v) { w.put(static_cast<uint8_t>(v)); }")
    w("template <typename W>")
    w("inline void put_u16(W& w, uint16_t v) {")
    w("  w.put(static_cast<uint8_t>(v));")
    w("  w.put(static_cast<uint8_t>(v >> 8));")
    w("}")
    w("template <typename W>")
    w("inline void put_i16(W& w, int16_t v) { put_u16(w, static_cast<uint16_t>(v)); }")
    w("template <typename W>")
    w("inline void put_u32(W& w, uint32_t v) {")
    w("  put_u16(w, static_cast<uint16_t>(v));")
    w("  put_u16(w, static_cast<uint16_t>(v >> 16));")
    w("}")
    w("template <typename W>")
    w("inline void put_i32(W& w, int32_t v) { put_u32(w, static_cast<uint32_t>(v)); }")
    w("template <typename W>")
    w("inline void put_f32(W& w, float f) {")
    w("  uint32_t u;")
    w("  memcpy(&u, &f, sizeof u);")
    w("  put_u32(w, u);")
    w("}")
    for m in spec.messages:
        if m.is_request:
            continue
        cn = m.class_name
        w("template <typename W>")
        w(f"inline void write(W& w, const {cn}& msg) {{")
        if not m.fields:
            w("  (void)w;")
            w("  (void)msg;")
        for f in m.fields:
            t = f.type.name
            if f.count is None:
                w(f"  put_{t}(w, msg.{f.name});")
            else:
                w(f"  for (uint8_t i = 0; i < {f.count}; ++i) put_{t}(w, msg.{f.name}[i]);")
        w("}")
    w("")
    w("// Body size of a message id, or -1 for an id no message has.")
    w("inline int16_t message_size(uint8_t msg_id) {")
    w("  switch (msg_id) {")
    for m in spec.messages:
        w(f"    case MsgId::{m.upper}: return {m.class_name}::kSize;")
    w("    default: return -1;")
    w("  }")
    w("}")
    w("")
    w("// X-macros over the messages, X(StructName, MSG_ID_NAME): for dispatch tables.")
    for macro, subset in (
        ("UTRF_PROTO_MESSAGES", spec.messages),
        ("UTRF_PROTO_REQUESTS", [m for m in spec.messages if m.is_request]),
        ("UTRF_PROTO_BOARD_MESSAGES", [m for m in spec.messages if not m.is_request]),
    ):
        w(f"#define {macro}(X) \\")
        for i, m in enumerate(subset):
            tail = " \\" if i < len(subset) - 1 else ""
            w(f"  X({m.class_name}, {m.upper}){tail}")
        w("")
    w("#ifdef UTRF_PROTO_FLATTEN")
    w("// Test support (host only): every scalar of a message, arrays expanded, in wire order.")
    for m in spec.messages:
        cn = m.class_name
        n = sum(f.n for f in m.fields)
        w(f"inline uint8_t flatten(const {cn}& m, double* out) {{")
        if not m.fields:
            w("  (void)m;")
            w("  (void)out;")
        k = 0
        for f in m.fields:
            for i in range(f.n):
                ref = f"m.{f.name}" + (f"[{i}]" if f.count else "")
                w(f"  out[{k}] = static_cast<double>({ref});")
                k += 1
        w(f"  return {n};")
        w("}")
        w(f"inline void unflatten(const double* in, {cn}& m) {{")
        if not m.fields:
            w("  (void)in;")
            w("  (void)m;")
        k = 0
        for f in m.fields:
            for i in range(f.n):
                ref = f"m.{f.name}" + (f"[{i}]" if f.count else "")
                w(f"  {ref} = static_cast<{f.type.ctype}>(in[{k}]);")
                k += 1
        w("}")
    w("#endif  // UTRF_PROTO_FLATTEN")
    w("")
    w("}  // namespace proto")
    w("}  // namespace utrf")
    w("")
    for c in clashes:
        w(f'#pragma pop_macro("{c}")')
    if clashes:
        w("")
    w("#endif  // UTRF_PROTOCOL_MESSAGES_H")
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# C++ configuration: structs, EEPROM layout, defaults, message <-> struct, handler table
# --------------------------------------------------------------------------------------------


def layout_version(spec: Spec) -> int:
    """The EEPROM layout's version: a CRC-16 of every stored field's place and type, so that a
    change of the layout (a new gain) is another version and an old image loads the defaults."""
    text = ";".join(
        f"{c.name}:{c.per_finger}:" + ",".join(f"{f.name}/{f.type.name}" for f in c.fields)
        for c in spec.configs
    )
    v = binascii.crc_hqx(text.encode("utf-8"), 0xFFFF)
    return v if v not in (0x0000, 0xFFFF) else 0x0001  # never an erased or a zeroed cell


def _c_default(f: FieldDef) -> str:
    assert f.default is not None
    if f.type.is_float:
        return c_float(f.default)
    raw = round(f.default / (f.scale or 1.0))
    return c_int(raw, f.type)


def render_config(spec: Spec) -> str:
    n = spec.protocol["finger_count"]
    out: list[str] = []
    w = out.append
    w("// Generated by protocol/generate.py from protocol/spec.toml: do not edit.")
    w("// Regenerate with `make generate`; a test fails when this file is stale.")
    w("//")
    w("// The board's configuration as the spec's [[config]] blocks name it: one packed struct per")
    w("// set_ request (its fields but `finger`, as the wire carries them: f32 as float, scaled")
    w("// fields as their raw integers), the EEPROM layout and its version, the defaults, and the")
    w("// copies between the structs and the messages that the get/set handlers use. The checks")
    w("// beyond the spec's ranges and what a change does are core/config.* and core/dispatch.*.")
    w("#ifndef UTRF_CONFIG_LAYOUT_H")
    w("#define UTRF_CONFIG_LAYOUT_H")
    w("")
    w("#include <stdint.h>")
    w("")
    w('#include "protocol_messages.h"')
    w("")
    w("namespace utrf {")
    w("namespace config {")
    w("")
    w("#pragma pack(push, 1)")
    for c in spec.configs:
        w(f"// {c.set.name}'s values" + (", per finger" if c.per_finger else ", board-wide"))
        w(f"struct {c.struct} {{")
        for f in c.fields:
            comment = c_comment(f)
            w(f"  {f.type.ctype} {f.name};" + (f"  // {comment}" if comment else ""))
        w("};")
        w("")
    w("struct Finger {")
    for c in spec.configs:
        if c.per_finger:
            w(f"  {c.struct} {c.name};")
    w("};")
    w("")
    w("struct Config {")
    w(f"  Finger finger[{n}];")
    for c in spec.configs:
        if not c.per_finger:
            w(f"  {c.struct} {c.name};")
    w("};")
    w("#pragma pack(pop)")
    w("")
    w("// The layout's version in the EEPROM image: a CRC-16 of every stored field's place and")
    w("// type. Another layout (a new gain) is another version: an old image loads the defaults.")
    w(f"static const uint16_t kLayoutVersion = 0x{layout_version(spec):04X};")
    sizes = {c.name: sum(f.size for f in c.fields) for c in spec.configs}
    total = sum(sizes[c.name] * (n if c.per_finger else 1) for c in spec.configs)
    w(f"static const uint16_t kConfigBytes = {total};")
    w('static_assert(sizeof(Config) == kConfigBytes, "the configuration is packed");')
    w("")
    w("// The spec's defaults. A field without one is left as it is (the firmware sets it: e.g.")
    w("// the Joint-2 limits from the finger's geometry).")
    for c in spec.configs:
        w(f"inline void spec_defaults({c.struct}& c) {{")
        missing = [f.name for f in c.fields if f.default is None]
        for f in c.fields:
            if f.default is not None:
                w(f"  c.{f.name} = {_c_default(f)};")
        if missing:
            w(f"  // no default in the spec: {', '.join(missing)}")
        if all(f.default is None for f in c.fields):
            w("  (void)c;")
        w("}")
    w("")
    w("// Stored values into the message that carries them (the get_ reply, or the set_ request")
    w("// itself), and a set_ request's values into the struct.")
    for c in spec.configs:
        w("template <typename Msg>")
        if c.per_finger:
            w(f"inline void fill(const {c.struct}& c, uint8_t finger, Msg& m) {{")
            w("  m.finger = finger;")
        else:
            w(f"inline void fill(const {c.struct}& c, Msg& m) {{")
        for f in c.fields:
            w(f"  m.{f.name} = c.{f.name};")
        w("}")
        w(f"inline void take(const proto::{c.set.class_name}& m, {c.struct}& c) {{")
        for f in c.fields:
            w(f"  c.{f.name} = m.{f.name};")
        w("}")
    w("")
    w("// Where a request's values live in the configuration.")
    for c in spec.configs:
        for msg in (c.set, c.get):
            cn = msg.class_name
            if c.per_finger:
                w(f"inline {c.struct}& slot(Config& cfg, const proto::{cn}& m) {{")
                w(f"  return cfg.finger[m.finger].{c.name};")
            else:
                w(f"inline {c.struct}& slot(Config& cfg, const proto::{cn}&) {{")
                w(f"  return cfg.{c.name};")
            w("}")
    w("")
    w("// The get_ request's reply, filled from the configuration.")
    for c in spec.configs:
        g, r = c.get.class_name, c.reply.class_name
        w(f"inline void reply_of(Config& cfg, const proto::{g}& m, proto::{r}& r) {{")
        if c.per_finger:
            w("  fill(slot(cfg, m), m.finger, r);")
        else:
            w("  fill(slot(cfg, m), r);")
        w("}")
    w("")
    w("// Every stored value within the spec's ranges (an EEPROM image's body): each set_ request")
    w("// the configuration makes, encoded and decoded back.")
    ok = "proto::DecodeStatus::OK"
    w("inline bool within_spec_ranges(const Config& cfg) {")
    w("  uint8_t body[proto::kMaxPayload];")
    w("  uint8_t bad;")
    for c in spec.configs:
        cn = c.set.class_name
        if c.per_finger:
            w(f"  for (uint8_t f = 0; f < {n}; ++f) {{")
            w(f"    proto::{cn} m, back;")
            w(f"    fill(cfg.finger[f].{c.name}, f, m);")
            w("    const uint8_t len = proto::encode(m, body);")
            w(f"    if (proto::decode(body, len, back, bad) != {ok}) return false;")
            w("  }")
        else:
            w("  {")
            w(f"    proto::{cn} m, back;")
            w(f"    fill(cfg.{c.name}, m);")
            w("    const uint8_t len = proto::encode(m, body);")
            w(f"    if (proto::decode(body, len, back, bad) != {ok}) return false;")
            w("  }")
    w("  return true;")
    w("}")
    w("")
    w("}  // namespace config")
    w("}  // namespace utrf")
    w("")
    w("// X-macros over the configuration's requests, X(Struct, MSG_ID_NAME) and for the gets")
    w("// X(Struct, MSG_ID_NAME, ReplyStruct): the dispatch table.")
    w("#define UTRF_CONFIG_SETS(X) \\")
    for i, c in enumerate(spec.configs):
        tail = " \\" if i < len(spec.configs) - 1 else ""
        w(f"  X({c.set.class_name}, {c.set.upper}){tail}")
    w("")
    w("#define UTRF_CONFIG_GETS(X) \\")
    for i, c in enumerate(spec.configs):
        tail = " \\" if i < len(spec.configs) - 1 else ""
        w(f"  X({c.get.class_name}, {c.get.upper}, {c.reply.class_name}){tail}")
    w("")
    w("#endif  // UTRF_CONFIG_LAYOUT_H")
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# Python messages
# --------------------------------------------------------------------------------------------

PY_WIDTH = 100


def py_str(text: str) -> str:
    return json.dumps(text, ensure_ascii=False)


def py_call(name: str, args: list[str], indent: str, tail: str = "") -> list[str]:
    """A call on one line if it fits, else one argument a line with a magic trailing comma
    (the layout ruff format keeps)."""
    line = f"{indent}{name}({', '.join(args)}){tail}"
    if len(line) <= PY_WIDTH:
        return [line]
    return [f"{indent}{name}("] + [f"{indent}    {a}," for a in args] + [f"{indent}){tail}"]


def py_docstring(text: str, indent: str) -> list[str]:
    text = one_line(text).replace("\\", "\\\\")
    if not text:
        return []
    if len(indent) + len(text) + 6 <= PY_WIDTH:
        return [f'{indent}"""{text}"""']
    lines = textwrap.wrap(text, PY_WIDTH - len(indent) - 3)
    if len(lines) == 1:  # ruff format would join a one-line body with its closing quotes
        lines = textwrap.wrap(text, len(text) * 2 // 3)
    return [f'{indent}"""{lines[0]}'] + [f"{indent}{ln}" for ln in lines[1:]] + [f'{indent}"""']


def py_annotation(f: FieldDef) -> str:
    if f.enum is not None:
        base = f.enum.name
    elif f.flags is not None:
        base = f.flags.name
    elif f.type.is_float or f.scale is not None:
        base = "float"
    else:
        base = "int"
    return base if f.count is None else f"tuple[{base}, ...]"


def py_field(f: FieldDef) -> list[str]:
    args = [py_str(f.name), py_str(f.type.name), str(f.index)]
    if f.count is not None:
        args.append(f"count={f.count}")
    if f.scale is not None:
        args.append(f"scale={fmt_number(f.scale)}")
    if f.type.is_float:
        if f.raw_min is not None:
            args.append(f"min={fmt_number(f.raw_min)}")
        if f.raw_max is not None:
            args.append(f"max={fmt_number(f.raw_max)}")
    else:
        if f.raw_min is not None:
            args.append(f"raw_min={int(f.raw_min)}")
        if f.raw_max is not None:
            args.append(f"raw_max={int(f.raw_max)}")
    if f.enum is not None:
        args.append(f"enum={f.enum.name}")
    if f.flags is not None:
        args.append(f"flags={f.flags.name}")
    if f.unit:
        args.append(f"unit={py_str(f.unit)}")
    return py_call("Field", args, " " * 8, ",")


def field_note(f: FieldDef) -> str:
    parts = []
    if f.doc:
        parts.append(one_line(f.doc))
    if f.unit and f.unit != "1":
        parts.append(f"[{f.unit}]")
    return " ".join(parts)


def render_messages(spec: Spec) -> str:
    p = spec.protocol
    out: list[str] = []
    w = out.append
    w('"""Generated by protocol/generate.py from protocol/spec.toml: do not edit.')
    w("")
    w("The host-board protocol's messages: one frozen dataclass per message, fields in SI units")
    w("(scaled fields as float, enums as IntEnum, flags as IntFlag, arrays as tuples).")
    w("``encode()`` gives the body, ``decode(body)`` the message; see :mod:`utrf.protocol.codec`.")
    w("Requests are ``Request[ReplyType]``; their reply class is ``REPLY``.")
    w('"""')
    w("")
    w("from __future__ import annotations")
    w("")
    w("from dataclasses import dataclass")
    w("from enum import IntEnum, IntFlag")
    w("from typing import ClassVar")
    w("")
    w("from utrf.protocol.codec import Direction, Field, Message, Request")
    w("")
    w(f"PROTOCOL_VERSION = {p['version']}")
    w("#: CRC-32 of the canonical spec (doc texts excluded), compared at the handshake.")
    w(f"SCHEMA_HASH = 0x{spec.schema_hash:08X}")
    w(f"MAX_PAYLOAD = {p['max_payload']}")
    w(f"FINGER_COUNT = {p['finger_count']}")
    w(f"DEFAULT_BAUD = {p['default_baud']}")
    w(f"REPLY_TIMEOUT_S = {fmt_number(p['reply_timeout_s'])}")
    w(f"RETRIES = {p['retries']}")
    w(f"HEARTBEAT_PERIOD_S = {fmt_number(p['heartbeat_period_s'])}")
    w(f"MAX_TELEMETRY_HZ = {p['max_telemetry_hz']}")
    w("#: The board's heartbeat timeout until the host sets one (set_safety).")
    hb = spec.field_default("set_safety", "heartbeat_timeout")
    w(f"DEFAULT_HEARTBEAT_TIMEOUT_S = {fmt_number(hb)}")
    w("#: Set in the seq of board-initiated frames (state stream, fault, boot), clear in requests.")
    w(f"BOARD_SEQ_FLAG = 0x{p['board_seq_flag']:02X}")
    for e in spec.enums:
        w("")
        w("")
        w(f"class {e.name}({'IntFlag' if e.is_flags else 'IntEnum'}):")
        doc = py_docstring(e.doc, "    ")
        out.extend(doc)
        if doc:
            w("")
        for v in e.values:
            out.extend(wrap(v.doc, PY_WIDTH, "    #: "))
            w(f"    {v.name} = {'1 << ' if e.is_flags else ''}{v.value}")
    for m in spec.messages:
        reply = spec.reply_of(m)
        base = f'Request["{reply.class_name}"]' if reply is not None else "Message"
        w("")
        w("")
        w("@dataclass(frozen=True, slots=True)")
        w(f"class {m.class_name}({base}):")
        doc = py_docstring(m.doc, "    ")
        out.extend(doc)
        if doc:
            w("")
        w(f"    NAME: ClassVar[str] = {py_str(m.name)}")
        w(f"    ID: ClassVar[int] = 0x{m.id:02X}")
        w(f"    SIZE: ClassVar[int] = {m.size}")
        direction = "HOST_TO_BOARD" if m.is_request else "BOARD_TO_HOST"
        w(f"    DIRECTION: ClassVar[Direction] = Direction.{direction}")
        if m.masked_by is not None:
            w(f"    MASKED_BY: ClassVar[str | None] = {py_str(m.masked_by)}")
        if m.is_request:
            w(f"    IDEMPOTENT: ClassVar[bool] = {m.idempotent}")
            w(f"    REPLY_TIMEOUT_S: ClassVar[float] = {fmt_number(spec.timeout_of(m))}")
        if m.fields:
            head = "    FIELDS: ClassVar[tuple[Field, ...]] = ("
            single = py_field(m.fields[0])
            if (
                len(m.fields) == 1
                and len(single) == 1
                and len(head) + len(single[0]) - 8 + 1 <= PY_WIDTH
            ):
                w(head + single[0].strip() + ")")
            else:
                w(head)
                for f in m.fields:
                    out.extend(py_field(f))
                w("    )")
            w("")
            for f in m.fields:
                out.extend(wrap(field_note(f), PY_WIDTH, "    #: "))
                w(f"    {f.name}: {py_annotation(f)}")
    w("")
    w("")
    for m in spec.messages:
        reply = spec.reply_of(m)
        if reply is not None:
            w(f"{m.class_name}.REPLY = {reply.class_name}")
    w("")
    w("#: Every message, in spec order.")
    out.extend(
        py_call("MESSAGES: tuple[type[Message], ...] = ", [m.class_name for m in spec.messages], "")
    )
    w("BY_ID: dict[int, type[Message]] = {m.ID: m for m in MESSAGES}")
    w("BY_NAME: dict[str, type[Message]] = {m.NAME: m for m in MESSAGES}")
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# README tables
# --------------------------------------------------------------------------------------------


def md(text: str) -> str:
    return one_line(text).replace("|", "\\|")


def md_range(f: FieldDef) -> str:
    if f.enum is not None:
        return f"`{f.enum.name}`"
    if f.flags is not None:
        return f"`{f.flags.name}` bits"
    if f.raw_min is None and f.raw_max is None:
        return "finite" if f.type.is_float else ""
    lo, hi = si_range(f)
    if f.type.is_float or f.scale is not None:
        return f"{lo:g} … {hi:g}"
    return f"{lo} … {hi}"


def render_readme_tables(spec: Spec) -> str:
    p = spec.protocol
    out: list[str] = []
    w = out.append
    w(README_BEGIN)
    w("")
    w("### Constants")
    w("")
    w("| name | value | meaning |")
    w("|---|---|---|")
    w(f"| protocol version | {p['version']} | bumped on every incompatible change |")
    w(f"| schema hash | `0x{spec.schema_hash:08X}` | CRC-32 of the canonical spec |")
    w(f"| max payload | {p['max_payload']} bytes | body bytes in one frame |")
    w(f"| finger count | {p['finger_count']} | per-finger arrays have this length |")
    w(f"| default baud | {p['default_baud']} | 8N1 |")
    timeout = p["reply_timeout_s"]
    w(f"| reply timeout | {timeout:g} s | per attempt, unless a message says otherwise |")
    w(
        f"| retries | {p['retries']} | resends of an idempotent request after a timeout "
        "(as many again at once on `BAD_CRC` hints) |"
    )
    period = p["heartbeat_period_s"]
    w(
        f"| heartbeat period | {period:g} s | host: longest time with no frame answered and "
        "no heartbeat sent |"
    )
    w(f"| max telemetry rate | {p['max_telemetry_hz']} Hz | fastest state stream |")
    hb = spec.field_default("set_safety", "heartbeat_timeout")
    w(
        f"| default heartbeat timeout | {hb:g} s | board: host silence before HOST_TIMEOUT, "
        "until set_safety sets another |"
    )
    flag = p["board_seq_flag"]
    w(f"| board seq flag | `0x{flag:02X}` | set in the seq of board-initiated frames |")
    w("")
    w("### Messages")
    w("")
    w("| id | message | direction | body bytes | reply | idempotent | reply timeout |")
    w("|---|---|---|---|---|---|---|")
    for m in spec.messages:
        reply = spec.reply_of(m)
        arrow = "host → board" if m.is_request else "board → host"
        w(
            f"| `0x{m.id:02X}` | [`{m.name}`](#{m.name}) | {arrow} | {m.size} | "
            + (
                f"`{reply.name}` | {'yes' if m.idempotent else 'no'} | {spec.timeout_of(m):g} s |"
                if reply is not None
                else "| | |"
            )
        )
    for m in spec.messages:
        reply = spec.reply_of(m)
        w("")
        w(f"#### {m.name}")
        w("")
        facts = [
            f"id `0x{m.id:02X}`",
            "host → board" if m.is_request else "board → host",
            f"{m.size} body bytes",
        ]
        if reply is not None:
            facts.append(f"reply `{reply.name}`")
            facts.append("idempotent" if m.idempotent else "**not idempotent**: never resent")
            facts.append(f"reply timeout {spec.timeout_of(m):g} s")
        if m.same_fields_as:
            facts.append(f"same fields as `{m.same_fields_as}`")
        w(" · ".join(facts))
        if m.doc:
            w("")
            w(one_line(m.doc))
        if not m.fields:
            w("")
            w("Empty body.")
            continue
        w("")
        w("| # | offset | field | type | scale | unit | range | meaning |")
        w("|---|---|---|---|---|---|---|---|")
        for f in m.fields:
            name = f"`{f.name}`" + (f"[{f.count}]" if f.count else "")
            scale = fmt_number(f.scale) if f.scale is not None else ""
            w(
                f"| {f.index} | {f.offset} | {name} | {f.type.name} | {scale} | {md(f.unit)} | "
                f"{md_range(f)} | {md(f.doc)} |"
            )
    w("")
    w("### Enums and flags")
    for e in spec.enums:
        w("")
        w(f"#### {e.name}" + (f" ({e.type.name} bit set)" if e.is_flags else f" ({e.type.name})"))
        w("")
        if e.doc:
            w(md(e.doc))
            w("")
        w("| bit | value | name | meaning |" if e.is_flags else "| value | name | meaning |")
        w("|---|---|---|---|" if e.is_flags else "|---|---|---|")
        for v in e.values:
            if e.is_flags:
                w(f"| {v.value} | `0x{1 << v.value:02X}` | `{v.name}` | {md(v.doc)} |")
            else:
                w(f"| {v.value} | `{v.name}` | {md(v.doc)} |")
    w("")
    w(README_END)
    return "\n".join(out) + "\n"


def splice_readme(current: str | None, tables: str) -> str:
    if current is None or README_BEGIN not in current or README_END not in current:
        raise SpecError(f"{README_PATH.relative_to(REPO_ROOT)} lacks the GENERATED markers")
    head, rest = current.split(README_BEGIN, 1)
    _, tail = rest.split(README_END, 1)
    return head + tables.rstrip("\n") + tail


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------


def outputs(spec: Spec) -> dict[Path, str]:
    readme = README_PATH.read_text(encoding="utf-8") if README_PATH.exists() else None
    return {
        HEADER_PATH: render_header(spec),
        CONFIG_PATH: render_config(spec),
        MESSAGES_PATH: render_messages(spec),
        README_PATH: splice_readme(readme, render_readme_tables(spec)),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if an output is stale")
    parser.add_argument("--spec", type=Path, default=SPEC_PATH, help="default: %(default)s")
    args = parser.parse_args(argv)
    try:
        spec = load_spec(args.spec)
        rendered = outputs(spec)
    except SpecError as exc:
        print(f"generate: error: {exc}", file=sys.stderr)
        return 2
    return write_or_check(
        rendered, check=args.check, tool="generate", command=COMMAND, root=REPO_ROOT
    )


if __name__ == "__main__":
    sys.exit(main())
