"""The unchecked fast decode (codec.plain_decoder) against the general, checked one."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from proto_helpers import load_vectors

from utrf.protocol import messages as M
from utrf.protocol.codec import Message, plain_decoder
from utrf.protocol.errors import DecodeError

PLAIN = [cls for cls in M.BY_ID.values() if cls._PLAIN is not None]
GOLDEN = [
    (M.BY_NAME[v["name"]], bytes.fromhex(v["body"]))
    for v in load_vectors("messages.json")["messages"]
    if "body" in v and M.BY_NAME[v["name"]]._PLAIN is not None
]


def _exact(message: Message) -> list[tuple[str, Any]]:
    """Each field's value with its type and repr, so 0.1 vs 0.10000000000000002 or 1 vs 1.0
    differ."""
    out = []
    for f in dataclasses.fields(message):
        value = getattr(message, f.name)
        items = value if isinstance(value, tuple) else (value,)
        out.append((f.name, type(value).__name__, [(type(x).__name__, repr(x)) for x in items]))
    return out


def test_the_state_stream_takes_the_fast_path() -> None:
    assert M.State in PLAIN
    assert M.State._PLAIN is not None
    # a class with a check to do has none (enum/flag fields, masks, bounds)
    assert M.Fault._PLAIN is None
    assert plain_decoder(M.Fault) is None


def test_golden_bodies_decode_alike() -> None:
    assert any(cls is M.State for cls, _ in GOLDEN)
    for cls, body in GOLDEN:
        fast, general = cls.decode(body), cls.decode_checked(body)
        assert fast == general and type(fast) is cls
        assert _exact(fast) == _exact(general)


@pytest.mark.parametrize("cls", PLAIN, ids=lambda c: c.NAME)
@given(data=st.data())
def test_random_bodies_decode_alike(cls: type[Message], data: st.DataObject) -> None:
    body = data.draw(st.binary(min_size=cls.SIZE, max_size=cls.SIZE))
    fast = cls.decode(memoryview(body))
    assert _exact(fast) == _exact(cls.decode_checked(body))
    assert fast.encode() == body  # and it round-trips


@pytest.mark.parametrize("cls", PLAIN, ids=lambda c: c.NAME)
@given(data=st.data())
def test_wrong_sizes_are_refused_alike(cls: type[Message], data: st.DataObject) -> None:
    size = data.draw(st.integers(0, 2 * cls.SIZE + 2).filter(lambda n: n != cls.SIZE))
    body = bytes(size)
    with pytest.raises(DecodeError) as fast:
        cls.decode(body)
    with pytest.raises(DecodeError) as general:
        cls.decode_checked(body)
    assert str(fast.value) == str(general.value)
