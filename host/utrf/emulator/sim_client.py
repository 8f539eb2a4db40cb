"""A protocol client that lives in simulated time, for a driven board (``realtime=False``).

:class:`utrf.protocol.link.Link` waits on the wall clock from its own threads; this one has
no threads and no wall clock: a request runs the board until its reply arrives, so a test or
a benchmark over it is as fast as the machine allows and the same on every run for a seed.
It resends idempotent requests after ``timeout`` simulated seconds, as Link does; frames the
board sends on its own (state stream, faults, boot) collect in :attr:`SimClient.stream`.

    with EmulatedBoard(realtime=False) as board:
        client = SimClient(board)
        client.wait_boot()
        identity = client.request(m.Identify())
        client.run(1.0)                       # one simulated second, heartbeats included
"""

from __future__ import annotations

from utrf.emulator.board import EmulatedBoard
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.framing import Frame, FrameDecoder, encode_frame


class SimClient:
    """Requests and replies over a driven board's UART0, in simulated time."""

    def __init__(self, board: EmulatedBoard) -> None:
        self.board = board
        self.port = board.serial(timeout=0.0)
        self.decoder = FrameDecoder()
        self.stream: list[Message] = []
        self.errors = 0  # damaged frames from the board
        self._seq = 0

    def pump(self) -> list[Frame]:
        """Decode what has arrived: replies are returned, stream frames kept in ``stream``."""
        replies = []
        for item in self.decoder.feed(self.port.read(1 << 16)):
            if not isinstance(item, Frame):
                self.errors += 1
            elif item.seq & m.BOARD_SEQ_FLAG:
                self.stream.append(m.BY_ID[item.msg_id].decode(item.body))
            else:
                replies.append(item)
        return replies

    def request(
        self, req: Request, timeout: float | None = None, retries: int = m.RETRIES
    ) -> Message:
        """Send ``req`` and run the board until its reply (Ack, Nack or the named reply).
        Idempotent requests are resent (same seq) after each ``timeout`` (default: the
        request's own reply timeout), up to ``retries`` times; then TimeoutError."""
        timeout = req.REPLY_TIMEOUT_S if timeout is None else timeout
        self._seq = (self._seq + 1) & (m.BOARD_SEQ_FLAG - 1)
        frame = encode_frame(self._seq, req.ID, req.encode())
        for _ in range(1 + (retries if req.IDEMPOTENT else 0)):
            self.port.write(frame)
            end = self.board.sim_time + timeout
            while self.board.sim_time < end:
                self.board.run_for(self.board.exchange_period)
                for reply in self.pump():
                    if reply.seq == self._seq:
                        return m.BY_ID[reply.msg_id].decode(reply.body)
        raise TimeoutError(f"no reply to {type(req).__name__} within {timeout} s (simulated)")

    def run(self, seconds: float, heartbeat: float = m.HEARTBEAT_PERIOD_S) -> None:
        """Let ``seconds`` of simulated time pass, sending a heartbeat every ``heartbeat``."""
        end = self.board.sim_time + seconds
        while self.board.sim_time < end:
            self.request(m.Heartbeat())
            self.board.run_for(max(0.0, min(heartbeat, end - self.board.sim_time)))
            self.pump()

    def wait_boot(self, timeout: float = 0.2) -> m.Boot:
        """The next boot frame (TimeoutError if none within ``timeout`` simulated seconds)."""
        seen = len(self.stream)
        end = self.board.sim_time + timeout
        while self.board.sim_time < end:
            self.board.run_for(self.board.exchange_period)
            self.pump()
            boots = [s for s in self.stream[seen:] if isinstance(s, m.Boot)]
            if boots:
                return boots[-1]
        raise TimeoutError(f"no boot frame within {timeout} s (simulated)")
