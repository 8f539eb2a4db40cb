"""Helpers for the emulator's tests: a console for the fixture program's command line."""

from __future__ import annotations

from utrf.emulator import EmulatedBoard, EncoderParams, PlantParams, SimSerial
from utrf.protocol import messages as m
from utrf.protocol.codec import Message, Request
from utrf.protocol.errors import NackError

# No gravity, no encoder noise: the emulator's tests judge exact readings and still fingers.
QUIET = PlantParams(gravity_m_s2=(0.0, 0.0), encoder=EncoderParams(noise_v=0.0))


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


class _Tap:
    """The board as SimLink sees it, keeping the last byte read (to catch the line mid-frame)."""

    def __init__(self, board: EmulatedBoard) -> None:
        self._board = board
        self.last_byte: int | None = None

    def read(self, size: int = -1) -> bytes:
        data = self._board.read(size)
        if data:
            self.last_byte = data[-1]
        return data

    def __getattr__(self, name: str) -> object:
        return getattr(self._board, name)


class LinkClient:
    """The protocol's one client rule set (the engine, through SimLink) as the emulator's
    tests use it: ``request`` returns the reply or the board's Nack, board-initiated frames
    collect in ``stream``, ``errors`` counts damaged frames from the board."""

    def __init__(self, board: EmulatedBoard) -> None:
        from utrf.hand.simlink import SimLink

        self.board = board
        self.tap = _Tap(board)
        self.stream: list[Message] = []
        self.link = SimLink(
            self.tap,  # type: ignore[arg-type]
            on_telemetry=lambda t: self.stream.append(t.message),
        )

    @property
    def errors(self) -> int:
        s = self.link.stats()
        return s.crc_errors + s.framing_errors + s.oversize

    def request(self, req: Request, timeout: float | None = None) -> Message:
        try:
            return self.link.request(req, timeout_s=timeout)
        except NackError as exc:
            return m.Nack(msg_id=req.ID, code=exc.code, detail=exc.detail)

    def run(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass, with heartbeats."""
        self.link.sleep(seconds)

    def step(self) -> None:
        """One exchange period, the board's output handed to the link."""
        self.link.sleep(self.board.exchange_period)

    def wait_boot(self, timeout: float = 0.2) -> m.Boot:
        """The next boot frame, then the handshake the link wants after a reset."""
        seen = len(self.stream)
        end = self.board.sim_time + timeout
        while self.board.sim_time < end:
            self.step()
            boots = [s for s in self.stream[seen:] if isinstance(s, m.Boot)]
            if boots:
                self.link.handshake()
                return boots[-1]
        raise TimeoutError(f"no boot frame within {timeout} s (simulated)")


ALL_FINGERS = 0b11111


def ready_client(board: EmulatedBoard) -> tuple[LinkClient, m.Boot]:
    """A client on a board that has booted, 20 ms on, every finger's faults cleared and the
    stream's frames so far dropped; with the boot frame it saw."""
    c = LinkClient(board)
    boot = c.wait_boot()
    board.run_for(0.02)
    reply = c.request(m.ClearFaults(mask=ALL_FINGERS))
    assert isinstance(reply, m.Ack), reply
    c.stream.clear()
    return c, boot
