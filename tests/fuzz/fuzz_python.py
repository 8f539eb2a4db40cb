"""Fuzzing the host's protocol code (atheris, coverage-guided): the frame decoder, every
message's decoder and the client engine, with the oracles as assertions.

The input: its first byte seeds the chunk sizes, the rest is what arrives from the board.

- the streaming decoder reports the same events however the bytes are split into chunks;
- a frame it reports re-encodes to bytes that decode to the same frame;
- a message body decodes to its message or raises DecodeError, nothing else, and a decoded
  message encodes back to the same body;
- the engine with a request in flight takes any bytes without an error escaping, never
  finishes the request with a frame that does not carry its seq and reply, and counts.

    python tests/fuzz/fuzz_python.py -max_total_time=60 tests/fuzz/corpus/python
    python tests/fuzz/fuzz_python.py --replay FILE...   # without atheris (the suite's replay)
"""

from __future__ import annotations

import logging
import random
import sys
from pathlib import Path


class _Raise(logging.Handler):
    """The engine logs (and swallows) an exception in its receiver: a finding here."""

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info:
            raise AssertionError(f"the engine raised inside its receiver: {record.getMessage()}")


def _imports():  # type: ignore[no-untyped-def]
    from utrf.protocol import messages as m
    from utrf.protocol.engine import Done, Engine, Transmit
    from utrf.protocol.errors import DecodeError
    from utrf.protocol.framing import Frame, FrameDecoder, decode_stream, encode_frame

    names = (m, Done, Engine, Transmit, DecodeError, Frame, FrameDecoder)
    return (*names, decode_stream, encode_frame)


def one_input(data: bytes) -> None:
    (m, Done, Engine, Transmit, DecodeError, Frame, FrameDecoder, decode_stream, encode_frame) = (
        _IMPORTS
    )
    if not data:
        return
    rng = random.Random(data[0])
    stream = data[1:]

    # the decoder: chunking does not matter
    whole = decode_stream(stream)
    dec = FrameDecoder()
    events = []
    i = 0
    while i < len(stream):
        n = rng.randint(1, 80)
        events += dec.feed(stream[i : i + n])
        i += n
    assert events == whole, "the decoder's events depend on how the bytes were split"

    # frames re-encode; bodies decode to their message or refuse with DecodeError
    for ev in whole:
        if not isinstance(ev, Frame):
            continue
        again = decode_stream(encode_frame(ev.seq, ev.msg_id, ev.body))
        assert again == [ev], f"{ev} re-encoded decodes as {again}"
        cls = m.BY_ID.get(ev.msg_id)
        if cls is None:
            continue
        try:
            msg = cls.decode(ev.body)
        except DecodeError:
            continue
        assert msg.encode() == ev.body, f"{cls.NAME} does not encode back to its body"

    # the engine with a ping in flight
    engine = Engine(heartbeat_period_s=None)
    token = rng.getrandbits(32)
    engine.start_request(m.Ping(token))
    now = 0.0
    action = engine.poll(now)
    assert isinstance(action, Transmit)
    seq = decode_stream(action.data)[0].seq
    engine.sent(action, now)
    i = 0
    done = None
    while i < len(stream) and done is None:
        n = rng.randint(1, 80)
        engine.receive(stream[i : i + n], now)
        i += n
        now += 0.001
        action = engine.poll(now)
        if isinstance(action, Transmit):
            engine.sent(action, now)
        elif isinstance(action, Done):
            done = action
    if done is not None and done.error is None:
        frame = done.value
        assert frame.seq == seq and frame.msg_id == m.Pong.ID, f"ping {seq} finished by {frame}"
        assert frame in whole, "the engine finished with a frame that was never sent"
    # its counters agree with the decoder over the bytes it took
    stats = engine.stats()
    seen = decode_stream(stream[:i])
    kinds = [e.kind.name if not isinstance(e, Frame) else "FRAME" for e in seen]
    assert stats.rx_frames == kinds.count("FRAME"), (stats, kinds)
    assert stats.crc_errors == kinds.count("CRC_ERROR"), (stats, kinds)
    assert stats.framing_errors == kinds.count("FRAMING_ERROR"), (stats, kinds)
    assert stats.oversize == kinds.count("OVERSIZE"), (stats, kinds)


_IMPORTS = None


def main(argv: list[str]) -> int:
    global _IMPORTS
    logging.getLogger("utrf.protocol.engine").addHandler(_Raise())
    logging.getLogger("utrf.protocol.engine").propagate = False
    if argv[1:2] == ["--replay"]:
        _IMPORTS = _imports()
        files = [
            p for a in map(Path, argv[2:]) for p in (sorted(a.iterdir()) if a.is_dir() else [a])
        ]
        for p in files:
            one_input(p.read_bytes())
        print(f"replayed {len(files)} inputs")
        return 0
    import atheris

    with atheris.instrument_imports(include=["utrf.protocol"]):
        _IMPORTS = _imports()
    atheris.Setup(argv, one_input)
    atheris.Fuzz()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
