"""Fuzzing the host's protocol code (atheris, coverage-guided): the frame decoder, every
message's decoder and the client engine, with the oracles as assertions.

The input: its first byte seeds the chunk sizes, the rest is what arrives from the board.

- the streaming decoder reports the same events however the bytes are split into chunks;
- a frame it reports re-encodes to bytes that decode to the same frame;
- a message body decodes to its message or raises DecodeError, nothing else, and a decoded
  message encodes back to the same body;
- the engine with a request in flight takes any bytes without an error escaping (the rest
  of the stream too once the request is done), never finishes the request with a frame that
  does not carry its seq and reply, and counts what its decoder reported.

Speed (atheris runs the instrumented protocol code at about a third of its plain speed): the
stream is decoded twice per execution, once whole (the reference) and once in chunks by the
engine's own decoder, which records its events for the chunking oracle; the chunk sizes come
from a table drawn once. Only ``utrf.protocol`` is instrumented.

    python tests/fuzz/fuzz_python.py -max_total_time=60 tests/fuzz/corpus/python
    python tests/fuzz/fuzz_python.py --replay FILE...   # without atheris (the suite's replay)
"""

from __future__ import annotations

import logging
import random
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported for real inside _Harness, under atheris's instrumentation
    from utrf.protocol.framing import Frame, FrameError


class _Raise(logging.Handler):
    """The engine logs (and swallows) an exception in its receiver: a finding here."""

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info:
            raise AssertionError(f"the engine raised inside its receiver: {record.getMessage()}")


#: For each value of the input's first byte: the chunk sizes (1-80 bytes, cycled) and the
#: ping's token, drawn once rather than from a fresh ``random.Random`` every execution.
_SCHEDULES = [
    (tuple(r.randint(1, 80) for _ in range(64)), r.getrandbits(32))
    for r in map(random.Random, range(256))
]


class _Harness:
    """The protocol code, imported once (under atheris's instrumentation when fuzzing)."""

    def __init__(self) -> None:
        from utrf.protocol import messages as m
        from utrf.protocol.engine import Done, Engine, Transmit
        from utrf.protocol.errors import DecodeError
        from utrf.protocol.framing import Frame, FrameDecoder, RxEvent, decode_stream, encode_frame

        class RecordingDecoder(FrameDecoder):
            """The engine's own decoder, keeping what it reports: the chunking oracle is
            checked on the very pass that feeds the engine, not on a second decode."""

            def __init__(self) -> None:
                super().__init__()
                self.events: list[Frame | FrameError] = []

            def feed(self, data: bytes | bytearray | memoryview) -> list[Frame | FrameError]:
                out = super().feed(data)
                self.events += out
                return out

        self.m, self.Done, self.Engine, self.Transmit = m, Done, Engine, Transmit
        self.DecodeError, self.Frame, self.RxEvent = DecodeError, Frame, RxEvent
        self.RecordingDecoder = RecordingDecoder
        self.decode_stream, self.encode_frame = decode_stream, encode_frame

    def one_input(self, data: bytes) -> None:
        if not data:
            return
        m, Frame, decode_stream = self.m, self.Frame, self.decode_stream
        sizes, token = _SCHEDULES[data[0]]
        stream = data[1:]
        whole = decode_stream(stream)

        # frames re-encode; bodies decode to their message or refuse with DecodeError
        for ev in whole:
            if type(ev) is not Frame:
                continue
            again = decode_stream(self.encode_frame(ev.seq, ev.msg_id, ev.body))
            assert again == [ev], f"{ev} re-encoded decodes as {again}"
            cls = m.BY_ID.get(ev.msg_id)
            if cls is None:
                continue
            try:
                msg = cls.decode(ev.body)
            except self.DecodeError:
                continue
            assert msg.encode() == ev.body, f"{cls.NAME} does not encode back to its body"

        # the engine with a ping in flight, fed the stream in chunks; once the ping is done,
        # the rest still goes in (late and stale replies, the stream, boots)
        engine = self.Engine(heartbeat_period_s=None)
        recorder = self.RecordingDecoder()
        engine._decoder = recorder  # the engine's decoder, recording (see RecordingDecoder)
        engine.start_request(m.Ping(token))
        now = 0.0
        action = engine.poll(now)
        assert isinstance(action, self.Transmit)
        seq = decode_stream(action.data)[0].seq
        engine.sent(action, now)
        done = None
        i = k = 0
        while i < len(stream):
            n = sizes[k & 63]
            k += 1
            engine.receive(stream[i : i + n], now)
            i += n
            now += 0.001
            if done is None:
                action = engine.poll(now)
                if isinstance(action, self.Transmit):
                    engine.sent(action, now)
                elif isinstance(action, self.Done):
                    done = action
        # the decoder: chunking does not matter
        assert recorder.events == whole, "the decoder's events depend on how the bytes were split"
        if done is not None and done.error is None:
            frame = done.value
            assert frame.seq == seq and frame.msg_id == m.Pong.ID, f"ping {seq} finished by {frame}"
            assert frame in whole, "the engine finished with a frame that was never sent"
        # its counters agree with the decoder
        stats = engine.stats()
        kinds = [Frame if type(e) is Frame else e.kind for e in whole]
        RxEvent = self.RxEvent
        assert stats.rx_frames == kinds.count(Frame), (stats, kinds)
        assert stats.crc_errors == kinds.count(RxEvent.CRC_ERROR), (stats, kinds)
        assert stats.framing_errors == kinds.count(RxEvent.FRAMING_ERROR), (stats, kinds)
        assert stats.oversize == kinds.count(RxEvent.OVERSIZE), (stats, kinds)


def main(argv: list[str]) -> int:
    logging.getLogger("utrf.protocol.engine").addHandler(_Raise())
    logging.getLogger("utrf.protocol.engine").propagate = False
    if argv[1:2] == ["--replay"]:
        harness = _Harness()
        files = [
            p for a in map(Path, argv[2:]) for p in (sorted(a.iterdir()) if a.is_dir() else [a])
        ]
        for p in files:
            harness.one_input(p.read_bytes())
        print(f"replayed {len(files)} inputs")
        return 0
    import atheris

    # Only the protocol package is instrumented (its imports of the standard library, cobs
    # and pyserial are not): the per-execution cost is the protocol code itself.
    with atheris.instrument_imports(include=["utrf.protocol"]):
        harness = _Harness()
    atheris.Setup(argv, harness.one_input)
    atheris.Fuzz()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
