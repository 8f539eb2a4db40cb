"""Helpers for the emulator's tests: a console for the fixture program, and a small client for
the real firmware's protocol that runs entirely in simulated time (a driven board)."""

from __future__ import annotations

from utrf.emulator import EmulatedBoard, SimSerial
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.framing import Frame, FrameDecoder, encode_frame


class Console:
    """The fixture's ASCII command line, over a driven board's SimSerial."""

    def __init__(self, board: EmulatedBoard, timeout: float = 0.05) -> None:
        self.board = board
        self.port: SimSerial = board.serial(timeout=timeout)

    def line(self, timeout: float | None = None) -> str:
        if timeout is not None:
            self.port.timeout = timeout
        data = self.port.read_until(b"\n")
        if not data.endswith(b"\n"):
            raise TimeoutError(f"no line within {self.port.timeout} s (got {data!r})")
        return data.decode().strip()

    def command(self, text: str, timeout: float = 0.05) -> str:
        self.port.write(text.encode() + b"\n")
        return self.line(timeout)


class SimClient:
    """Requests to the real firmware in simulated time: send a frame, run the board until its
    reply. Board-initiated frames (state, fault, boot) are kept in ``stream``."""

    def __init__(self, board: EmulatedBoard) -> None:
        self.board = board
        self.port = board.serial(timeout=0.0)
        self.decoder = FrameDecoder()
        self.stream: list[Message] = []
        self.errors = 0
        self._seq = 0

    def pump(self) -> list[Frame]:
        frames = []
        for item in self.decoder.feed(self.port.read(1 << 16)):
            if isinstance(item, Frame):
                if item.seq & m.BOARD_SEQ_FLAG:
                    self.stream.append(m.BY_ID[item.msg_id].decode(item.body))
                else:
                    frames.append(item)
            else:
                self.errors += 1
        return frames

    def request(self, req: Request, timeout: float = 0.1, retries: int = m.RETRIES) -> Message:
        """Send, and resend an idempotent request (same seq) after each timeout, as Link does."""
        self._seq = (self._seq + 1) & (m.BOARD_SEQ_FLAG - 1)
        frame = encode_frame(self._seq, req.ID, req.encode())
        for _attempt in range(1 + (retries if req.IDEMPOTENT else 0)):
            self.port.write(frame)
            end = self.board.sim_time + timeout
            while self.board.sim_time < end:
                self.board.run_for(self.board.exchange_period)
                for reply in self.pump():
                    if reply.seq == self._seq:
                        return m.BY_ID[reply.msg_id].decode(reply.body)
        raise TimeoutError(f"no reply to {type(req).__name__} within {timeout} s of simulated time")

    def run(self, seconds: float, heartbeat: float = 0.1) -> None:
        """Let time pass, feeding the board's host-silence watchdog."""
        end = self.board.sim_time + seconds
        while self.board.sim_time < end:
            self.request(m.Heartbeat())
            self.board.run_for(max(0.0, min(heartbeat, end - self.board.sim_time)))
            self.pump()

    def wait_boot(self, timeout: float = 0.2) -> m.Boot:
        end = self.board.sim_time + timeout
        while self.board.sim_time < end:
            self.board.run_for(1e-3)
            self.pump()
            boots = [s for s in self.stream if isinstance(s, m.Boot)]
            if boots:
                return boots[-1]
        raise TimeoutError("no boot frame")
