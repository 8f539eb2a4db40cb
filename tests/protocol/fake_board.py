"""A scripted stand-in for the board on 127.0.0.1, for the Link tests.

It speaks the real framing and messages over TCP (the host connects with ``socket://``) and
answers like the firmware: replies echo the request's seq, its own frames carry seqs with
BOARD_SEQ_FLAG from a running counter. Tests replace the answer to any message id.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable

from utrf.protocol import messages as M
from utrf.protocol.codec import Message
from utrf.protocol.framing import Frame, FrameDecoder, encode_frame

# What a handler returns: frames to send back (seq, message or (msg_id, body)), or None for
# no answer at all (a lost request).
Reply = list[tuple[int, Message | tuple[int, bytes]]] | None
Handler = Callable[[Frame], Reply]


def state_sample(t: float = 1.0) -> M.State:
    # angles the wire carries exactly (2 pi / 32768 rad a count), so the sample round-trips
    res = M.State.FIELDS[2].scale or 1.0
    angles = tuple(round(x / res) * res for x in (0.1, 0.2, 0.3, 0.4, 0.5))
    return M.State(
        board_time=t,
        theta2=angles,
        target=angles,
        duty_a=(0.0,) * 5,
        duty_b=(0.0,) * 5,
        status_seq=0,
    )


def identity(version: int = M.PROTOCOL_VERSION, schema: int = M.SCHEMA_HASH) -> M.Identity:
    return M.Identity(
        protocol_version=version,
        schema_hash=schema,
        fw_major=0,
        fw_minor=1,
        fw_patch=0,
        build_id=0x1234ABCD,
        finger_count=5,
        actuation=(M.Actuation.ANTAGONISTIC,) * 4 + (M.Actuation.ROTARY,),
        loop_rate_hz=1000,
        reset_cause=M.ResetCause.RESET_PIN,
        config_status=M.ConfigStatus.LOADED,
        max_telemetry_hz=M.MAX_TELEMETRY_HZ,
    )


class FakeBoard:
    def __init__(self) -> None:
        self._server = socket.create_server(("127.0.0.1", 0))
        self.url = f"socket://127.0.0.1:{self._server.getsockname()[1]}"
        self.received: list[Frame] = []
        self.handlers: dict[int, Handler] = {}
        self._stream_seq = M.BOARD_SEQ_FLAG
        self._conn: socket.socket | None = None
        self._lock = threading.Lock()
        self._connected = threading.Event()
        self._got_frame = threading.Condition()
        self._thread = threading.Thread(target=self._serve, name="fake-board", daemon=True)
        self._thread.start()

    # --- scripting ----------------------------------------------------------------------

    def on(self, msg_id: int, handler: Handler) -> None:
        self.handlers[msg_id] = handler

    def count(self, msg_id: int) -> int:
        """How many valid frames with this id the board has received."""
        with self._got_frame:
            return self._count(msg_id)

    def wait_for(self, msg_id: int, n: int = 1, timeout: float = 2.0) -> bool:
        with self._got_frame:
            return self._got_frame.wait_for(lambda: self._count(msg_id) >= n, timeout)

    def _count(self, msg_id: int) -> int:
        return sum(1 for f in self.received if f.msg_id == msg_id)

    def send(self, data: bytes) -> None:
        assert self._connected.wait(2.0), "the host never connected"
        with self._lock:
            assert self._conn is not None
            self._conn.sendall(data)

    def reply(self, seq: int, msg: Message | tuple[int, bytes]) -> None:
        msg_id, body = (msg.ID, msg.encode()) if isinstance(msg, Message) else msg
        self.send(encode_frame(seq, msg_id, body))

    def emit(self, msg: Message, skip: int = 0) -> int:
        """Send a board-initiated frame with the next stream seq (after skipping `skip`)."""
        with self._lock:
            for _ in range(skip + 1):
                seq = self._stream_seq
                self._stream_seq = M.BOARD_SEQ_FLAG | ((seq + 1) & 0x7F)
        self.reply(seq, msg)
        return seq

    def boot(self, cause: M.ResetCause = M.ResetCause.WATCHDOG) -> None:
        with self._lock:
            self._stream_seq = M.BOARD_SEQ_FLAG
        self.emit(M.Boot(M.PROTOCOL_VERSION, M.SCHEMA_HASH, cause, M.ConfigStatus.LOADED))

    def disconnect(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def close(self) -> None:
        self.disconnect()
        self._server.close()

    # --- the board ----------------------------------------------------------------------

    def default(self, frame: Frame) -> Reply:
        cls = M.BY_ID.get(frame.msg_id)
        if cls is None or not hasattr(cls, "REPLY"):
            return [(frame.seq, M.Nack(frame.msg_id, M.ErrorCode.UNKNOWN_ID, 0))]
        try:
            request = cls.decode(frame.body)
        except Exception:
            return [(frame.seq, M.Nack(frame.msg_id, M.ErrorCode.BAD_LENGTH, 0))]
        if isinstance(request, M.Identify):
            return [(frame.seq, identity())]
        if isinstance(request, M.Ping):
            return [(frame.seq, M.Pong(request.token, 12.5))]
        if isinstance(request, M.GetGains):
            gains = M.Gains(request.finger, 2.0, 0.5, 0.01, 50.0, 0.05, 100.0, 0.8, 0.1)
            return [(frame.seq, gains)]
        if isinstance(request, M.GetState):
            return [(frame.seq, state_sample())]
        if cls.REPLY is M.Ack:
            return [(frame.seq, M.Ack(frame.msg_id))]
        return [(frame.seq, M.Nack(frame.msg_id, M.ErrorCode.UNKNOWN_ID, 0))]

    def _serve(self) -> None:
        try:
            conn, _ = self._server.accept()
        except OSError:
            return
        with self._lock:
            self._conn = conn
        self._connected.set()
        decoder = FrameDecoder()
        while True:
            try:
                data = conn.recv(4096)
            except OSError:
                return
            if not data:
                return
            for event in decoder.feed(data):
                if not isinstance(event, Frame):
                    continue
                with self._got_frame:
                    self.received.append(event)
                    self._got_frame.notify_all()
                handler = self.handlers.get(event.msg_id, self.default)
                answers = handler(event)
                try:
                    for seq, msg in answers or []:
                        self.reply(seq, msg)
                except (OSError, AssertionError):
                    return
