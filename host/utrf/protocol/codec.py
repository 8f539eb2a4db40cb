"""The generic message codec behind the generated classes in :mod:`utrf.protocol.messages`.

A message body is its fields in order, little-endian, packed with no padding. A field with a
``scale`` carries ``round(value / scale)`` on the wire and is a float in SI units here; enum
fields are ``IntEnum`` members, flag fields ``IntFlag`` values, arrays tuples. Both ways are
checked: :meth:`Message.encode` raises ``ValueError`` naming ``message.field`` for a value it
cannot put on the wire, :meth:`Message.decode` raises :class:`DecodeError` for a body that is
not a valid message. A body that fails a check never becomes a message.
"""

from __future__ import annotations

import builtins
import dataclasses
import math
import numbers
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum, IntFlag, StrEnum
from typing import Any, ClassVar, Generic, Self, TypeVar, cast

from utrf.protocol.errors import DecodeError

# type: (struct code, lowest, highest) of the raw wire value
WIRE_TYPES: dict[str, tuple[str, float, float]] = {
    "u8": ("B", 0, 0xFF),
    "i8": ("b", -0x80, 0x7F),
    "u16": ("H", 0, 0xFFFF),
    "i16": ("h", -0x8000, 0x7FFF),
    "u32": ("I", 0, 0xFFFFFFFF),
    "i32": ("i", -0x80000000, 0x7FFFFFFF),
    "f32": ("f", -math.inf, math.inf),
}

_F32 = struct.Struct("<f")

RawValue = int | float
Value = Any  # int, float, IntEnum, IntFlag, or a tuple of them


def to_f32(x: float) -> float:
    """x rounded to the nearest binary32, as a Python float (OverflowError if too large)."""
    return float(_F32.unpack(_F32.pack(x))[0])


class Direction(StrEnum):
    HOST_TO_BOARD = "host_to_board"
    BOARD_TO_HOST = "board_to_host"


@dataclass(frozen=True)
class Field:
    """One field of a message, as the spec describes it.

    ``raw_min``/``raw_max`` bound the raw integer (already converted from the spec's SI
    bounds); ``min``/``max`` bound an f32 field. ``None`` means the type's own limit.
    """

    name: str
    type: str
    index: int
    count: int | None = None
    scale: float | None = None
    raw_min: int | None = None
    raw_max: int | None = None
    min: float | None = None
    max: float | None = None
    # `type` is also a field of Field: the builtin by its full name
    enum: builtins.type[IntEnum] | None = None
    flags: builtins.type[IntFlag] | None = None
    unit: str = ""
    _lo: float = field(init=False, repr=False, compare=False)
    _hi: float = field(init=False, repr=False, compare=False)
    _inv: float | None = field(init=False, repr=False, compare=False)
    _bits: int = field(init=False, repr=False, compare=False)  # every bit ``flags`` defines

    def __post_init__(self) -> None:
        if self.type not in WIRE_TYPES:
            raise TypeError(f"field {self.name}: unknown wire type {self.type!r}")
        _, lo, hi = WIRE_TYPES[self.type]
        if self.type == "f32":
            lo = -math.inf if self.min is None else self.min
            hi = math.inf if self.max is None else self.max
        else:
            lo = lo if self.raw_min is None else self.raw_min
            hi = hi if self.raw_max is None else self.raw_max
        object.__setattr__(self, "_lo", lo)
        object.__setattr__(self, "_hi", hi)
        # Dividing by an exact integer inverse (1e-6 -> 1e6) gives the correctly rounded SI
        # value (0.001234, not 0.0012339999999999999).
        inv = None
        if self.scale is not None:
            candidate = round(1.0 / self.scale)
            if candidate > 0 and abs(candidate * self.scale - 1.0) < 1e-12:
                inv = float(candidate)
        object.__setattr__(self, "_inv", inv)
        # The flag bits, once: decode checks them for every element of every stream frame.
        bits = 0
        if self.flags is not None:
            for member in self.flags.__members__.values():
                bits |= int(member)
        object.__setattr__(self, "_bits", bits)

    @property
    def n(self) -> int:
        """How many wire values the field holds (1 for a scalar)."""
        return 1 if self.count is None else self.count

    @property
    def struct_codes(self) -> str:
        return WIRE_TYPES[self.type][0] * self.n

    @property
    def _unit(self) -> str:
        return f" {self.unit}" if self.unit and self.unit != "1" else ""

    def si_bounds(self) -> tuple[float, float]:
        """The range of valid values in SI units (the wire's, after rounding)."""
        if self.scale is None:
            return self._lo, self._hi
        return self._scale_up(int(self._lo)), self._scale_up(int(self._hi))

    def _scale_up(self, raw: int) -> float:
        assert self.scale is not None
        return raw / self._inv if self._inv is not None else raw * self.scale

    # --- wire -> value ------------------------------------------------------------------

    def check_raw(self, raw: RawValue, message: str, label: str) -> None:
        """Raise DecodeError unless ``raw`` is a valid wire value of this field."""
        if self.type == "f32":
            if not isinstance(raw, int | float) or not math.isfinite(raw):
                raise DecodeError(message, label, f"{raw!r} is not a finite number")
        elif not isinstance(raw, int) or isinstance(raw, bool):
            raise DecodeError(message, label, f"{raw!r} is not an integer")
        if self.enum is not None:
            if raw not in self.enum._value2member_map_:
                raise DecodeError(message, label, f"{raw} is not a {self.enum.__name__}")
        elif self.flags is not None:
            unknown = int(raw) & ~self._bits
            if unknown:
                raise DecodeError(
                    message, label, f"0x{int(raw):02X} sets undefined {self.flags.__name__} bits"
                )
        elif not self._lo <= raw <= self._hi:
            lo, hi = self.si_bounds()
            what = f"{raw!r}" if self.scale is None else f"raw {raw} ({self.from_raw(raw):g})"
            raise DecodeError(message, label, f"{what} is outside [{lo:g}, {hi:g}]{self._unit}")

    def from_raw(self, raw: RawValue) -> Value:
        """The value of a checked raw wire value (SI for scaled fields)."""
        if self.enum is not None:
            return self.enum(int(raw))  # enum and flag fields are integer types
        if self.flags is not None:
            return self.flags(int(raw))
        if self.scale is not None:
            return self._scale_up(int(raw))
        return raw

    # --- value -> wire ------------------------------------------------------------------

    def to_raw(self, value: Value, where: str) -> RawValue:
        """The raw wire value of ``value``; ValueError (naming ``where``) if it has none."""
        if self.enum is not None:
            try:
                return int(self.enum(_as_int(value, where)))
            except ValueError:
                raise ValueError(f"{where}: {value!r} is not a {self.enum.__name__}") from None
        if self.flags is not None:
            bits = _as_int(value, where)
            if bits & ~self._bits or bits < 0:
                raise ValueError(f"{where}: {value!r} sets bits {self.flags.__name__} lacks")
            return bits
        if self.type == "f32":
            x = _as_real(value, where)
            try:
                f = to_f32(x)
            except OverflowError:
                f = math.inf
            if not math.isfinite(f) or not self._lo <= f <= self._hi:
                lo, hi = self._lo, self._hi
                raise ValueError(f"{where}: {value!r} is outside [{lo:g}, {hi:g}]{self._unit}")
            return f
        if self.scale is None:
            raw = _as_int(value, where)
            if not self._lo <= raw <= self._hi:
                lo, hi = self._lo, self._hi
                raise ValueError(f"{where}: {value!r} is outside [{lo:g}, {hi:g}]{self._unit}")
            return raw
        x = _as_real(value, where)
        scaled = x * self._inv if self._inv is not None else x / self.scale
        if not math.isfinite(scaled):
            raise ValueError(f"{where}: {value!r} is not a finite number")
        raw = round(scaled)
        if not self._lo <= raw <= self._hi:
            lo, hi = self.si_bounds()
            raise ValueError(f"{where}: {value!r} is outside [{lo:g}, {hi:g}]{self._unit}")
        return raw


class Unread(int):
    """A finger's wire value that its message's mask leaves unread and that is no valid value
    of the field (e.g. an enum value out of its table): kept as it came, re-encoded as is."""


def _as_int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{where}: {value!r} is not an integer")
    return int(value)


def _as_real(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{where}: {value!r} is not a finite number")
    return x


class Message:
    """Base of the generated message dataclasses. Class attributes describe the message."""

    __slots__ = ()
    NAME: ClassVar[str] = ""
    ID: ClassVar[int] = -1
    SIZE: ClassVar[int] = 0
    DIRECTION: ClassVar[Direction] = Direction.BOARD_TO_HOST
    FIELDS: ClassVar[tuple[Field, ...]] = ()
    #: The u8 field selecting fingers, if any: the board reads and checks the per-finger
    #: arrays only for the fingers it selects, and so does :meth:`decode`.
    MASKED_BY: ClassVar[str | None] = None
    _STRUCT: ClassVar[struct.Struct] = struct.Struct("<")
    #: The unchecked decoder when no wire value can be invalid (see plain_decoder), else None.
    _PLAIN: ClassVar[Callable[[bytes | bytearray | memoryview], Any] | None] = None
    # Every message class is a dataclass (the generator decorates each): declared here so
    # that dataclasses.replace() takes any Message.
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        fmt = "<" + "".join(f.struct_codes for f in cls.FIELDS)
        cls._STRUCT = struct.Struct(fmt)
        if cls.NAME and cls._STRUCT.size != cls.SIZE:
            size = cls._STRUCT.size
            raise TypeError(f"{cls.__name__}: fields pack to {size} bytes, not {cls.SIZE}")
        cls._PLAIN = plain_decoder(cls) if cls.NAME else None

    # --- raw wire values ----------------------------------------------------------------

    def to_raw(self) -> dict[str, RawValue | tuple[RawValue, ...]]:
        """The raw wire values of the fields (ValueError naming ``message.field`` if invalid)."""
        raw: dict[str, RawValue | tuple[RawValue, ...]] = {}
        for f in self.FIELDS:
            value = getattr(self, f.name)
            where = f"{self.NAME}.{f.name}"
            if f.count is None:
                raw[f.name] = f.to_raw(value, where)
                continue
            if not _is_array(value):
                raise ValueError(f"{where}: needs a sequence of {f.count} values, got {value!r}")
            items = list(value)
            if len(items) != f.count:
                raise ValueError(f"{where}: needs {f.count} values, got {len(items)}")
            raw[f.name] = tuple(
                int(v) if isinstance(v, Unread) else f.to_raw(v, f"{where}[{i}]")
                for i, v in enumerate(items)
            )
        return raw

    @classmethod
    def from_raw(cls, raw: Mapping[str, Any]) -> Self:
        """The message with these raw wire values; DecodeError if one is invalid."""
        kwargs: dict[str, Value] = {}
        for f in cls.FIELDS:
            if f.name not in raw:
                raise DecodeError(cls.NAME, f.name, "missing")
            value = raw[f.name]
            if f.count is None:
                f.check_raw(value, cls.NAME, f.name)
                kwargs[f.name] = f.from_raw(value)
                continue
            if not isinstance(value, Sequence) or len(value) != f.count:
                raise DecodeError(cls.NAME, f.name, f"needs {f.count} values")
            kwargs[f.name] = cls._array(f, value, raw.get(cls.MASKED_BY or "", 0xFF))
        extra = sorted(set(raw) - {f.name for f in cls.FIELDS})
        if extra:
            raise DecodeError(cls.NAME, extra[0], "is not a field of this message")
        return cls(**kwargs)

    # --- bytes --------------------------------------------------------------------------

    def encode(self) -> bytes:
        """The message body (without seq, id and CRC)."""
        flat: list[RawValue] = []
        for value in self.to_raw().values():
            if isinstance(value, tuple):  # an array field
                flat.extend(value)
            else:
                flat.append(value)
        return self._STRUCT.pack(*flat)

    @classmethod
    def decode(cls, body: bytes | bytearray | memoryview) -> Self:
        """The message in ``body``; DecodeError naming the message and field if invalid."""
        # the one place the fast path is chosen: tests compare it to decode_checked
        plain = cls._PLAIN
        if plain is not None:
            return cast(Self, plain(body))
        return cls.decode_checked(body)

    @classmethod
    def decode_checked(cls, body: bytes | bytearray | memoryview) -> Self:
        """:meth:`decode` by the general path: every wire value checked against its field."""
        _check_size(cls.NAME, cls.SIZE, body)
        values = cls._STRUCT.unpack(body)
        kwargs: dict[str, Value] = {}
        pos = 0
        for f in cls.FIELDS:
            if f.count is None:
                v = values[pos]
                f.check_raw(v, cls.NAME, f.name)
                kwargs[f.name] = f.from_raw(v)
                pos += 1
            else:
                mask = kwargs.get(cls.MASKED_BY or "", 0xFF)
                kwargs[f.name] = cls._array(f, values[pos : pos + f.count], mask)
                pos += f.count
        return cls(**kwargs)

    @classmethod
    def _array(cls, f: Field, items: Sequence[RawValue], mask: Any) -> tuple[Value, ...]:
        """An array's values; with MASKED_BY, an unselected finger's value is not checked (it
        stays raw when it is no valid value)."""
        out: list[Value] = []
        for i, v in enumerate(items):
            if cls.MASKED_BY is not None and f.name != cls.MASKED_BY and not int(mask) >> i & 1:
                try:
                    f.check_raw(v, cls.NAME, f"{f.name}[{i}]")
                except DecodeError:
                    out.append(Unread(v) if isinstance(v, int) else v)
                    continue
            else:
                f.check_raw(v, cls.NAME, f"{f.name}[{i}]")
            out.append(f.from_raw(v))
        return tuple(out)


def _check_size(name: str, size: int, body: bytes | bytearray | memoryview) -> None:
    if len(body) != size:
        raise DecodeError(name, None, f"body is {len(body)} bytes, expected {size}")


def _needs_check(f: Field) -> bool:
    """Whether some wire value of ``f`` is invalid (so decoding it must check)."""
    return (
        f.type == "f32"
        or f.enum is not None
        or f.flags is not None
        or f.raw_min is not None
        or f.raw_max is not None
    )


def plain_decoder(
    cls: type[Message],
) -> Callable[[bytes | bytearray | memoryview], Any] | None:
    """A decoder of ``cls`` that skips the per-value checks, or None when it cannot.

    It exists only when every wire value of every field is valid (integer fields over their
    type's full range, no enum, flags, f32 or finger mask): the checks of
    :meth:`Message.decode_checked` then never fail, and the same scaling (``Field.from_raw``:
    divide by an exact inverse, else multiply) builds the same values. Derived from FIELDS, so
    the generated spec decides, and the stream's 1 kHz state skips ~20 method calls a sample.
    """
    if cls.MASKED_BY is not None or any(_needs_check(f) for f in cls.FIELDS):
        return None
    unpack = cls._STRUCT.unpack
    size, name = cls.SIZE, cls.NAME
    converters: list[Callable[[tuple[int, ...]], Any]] = []
    pos = 0
    for f in cls.FIELDS:
        converters.append(_converter(f, pos))
        pos += f.n

    def decode(body: bytes | bytearray | memoryview) -> Any:
        _check_size(name, size, body)
        values = unpack(body)
        return cls(*[convert(values) for convert in converters])

    return decode


def _converter(f: Field, pos: int) -> Callable[[tuple[int, ...]], Any]:
    """The field's value from the unpacked wire values (as ``Field.from_raw`` scales it)."""
    end = pos + f.n
    inv, scale = f._inv, f.scale
    if f.count is None:
        if inv is not None:
            return lambda v: v[pos] / inv
        if scale is not None:
            return lambda v: v[pos] * scale
        return lambda v: v[pos]
    if inv is not None:
        return lambda v: tuple([x / inv for x in v[pos:end]])
    if scale is not None:
        return lambda v: tuple([x * scale for x in v[pos:end]])
    return lambda v: v[pos:end]


def _is_array(value: Any) -> bool:
    """Tuples, lists, numpy arrays: anything sized and iterable but text or a mapping."""
    if isinstance(value, str | bytes | bytearray | Mapping):
        return False
    return hasattr(value, "__len__") and hasattr(value, "__iter__")


R = TypeVar("R", bound=Message)


class Request(Message, Generic[R]):
    """A host-to-board message; ``R`` is the type of its reply (``Ack`` when none is named).

    ``IDEMPOTENT`` requests may be resent after a timeout; ``REPLY_TIMEOUT_S`` is how long the
    host waits for the reply of one attempt.
    """

    __slots__ = ()
    DIRECTION: ClassVar[Direction] = Direction.HOST_TO_BOARD
    IDEMPOTENT: ClassVar[bool] = False
    REPLY_TIMEOUT_S: ClassVar[float] = 0.1
    REPLY: ClassVar[type[Message]]

    def decode_reply(self, body: bytes) -> R:
        """The reply's body decoded as this request's ``REPLY`` (an ``R``)."""
        # a ClassVar cannot name R; the generator writes REPLY and R from the same spec entry
        return cast(R, type(self).REPLY.decode(body))
