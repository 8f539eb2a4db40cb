"""The protocol's exceptions. All derive from :class:`ProtocolError`."""

from __future__ import annotations

from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from utrf.protocol.codec import Message


class ProtocolError(Exception):
    """Base class of every error raised by ``utrf.protocol``."""


class DecodeError(ProtocolError, ValueError):
    """A body does not decode as the message it claims to be (length or a field's value).

    ``message`` is the message name, ``field`` the field (``mode[2]`` for an array element)
    or ``None`` when the length is wrong.
    """

    def __init__(self, message: str, field: str | None, reason: str) -> None:
        self.message = message
        self.field = field
        self.reason = reason
        where = message if field is None else f"{message}.{field}"
        super().__init__(f"{where}: {reason}")


class Outcome(Enum):
    """What a request that timed out did on the board."""

    #: the board did not apply it: every attempt that went out came back as a BAD_CRC nack
    #: naming it (it arrived damaged), or none went out
    NOT_APPLIED = "not applied"
    #: an attempt may have arrived whole and been applied, its reply lost
    UNKNOWN = "unknown"


class ReplyTimeout(ProtocolError, TimeoutError):
    """No reply came within the request's timeout, after every allowed retry.

    ``outcome`` says whether the request is known not to have been applied, or unknown.
    """

    def __init__(
        self,
        request: Message,
        timeout_s: float,
        attempts: int,
        outcome: Outcome = Outcome.UNKNOWN,
    ) -> None:
        self.request = request
        self.timeout_s = timeout_s
        self.attempts = attempts
        self.outcome = outcome
        super().__init__(
            f"no reply to {request.NAME} after {attempts} attempt(s) of {timeout_s:g} s each "
            f"({outcome.value})"
        )


class NackError(ProtocolError):
    """The board refused a request (and changed nothing).

    ``code`` is the :class:`~utrf.protocol.messages.ErrorCode` (an ``int`` if unknown),
    ``detail`` its detail byte (a field index, or a finger), ``request`` the refused message.
    """

    def __init__(self, code: int, detail: int, request: Message) -> None:
        self.code = code
        self.detail = detail
        self.request = request
        name = getattr(code, "name", f"code {int(code)}")
        why = _explain(request, code, detail)
        super().__init__(f"{request.NAME} refused: {name} (detail {detail}){why}")


def _explain(request: Message, code: int, detail: int) -> str:
    """Names the field or finger a nack's detail points at."""
    name = getattr(code, "name", "")
    if name == "OUT_OF_RANGE":
        if detail & 0x80:
            return f": finger {detail & 0x7F} is outside its limits"
        if detail < len(request.FIELDS):
            return f": field {request.FIELDS[detail].name}"
    if name in ("FAULTED", "BUSY") and detail != 0xFF:
        return f": finger {detail}"
    return ""


class SchemaMismatchError(ProtocolError):
    """The board's firmware was built from another protocol spec than this host."""

    def __init__(
        self, host_version: int, host_hash: int, board_version: int, board_hash: int
    ) -> None:
        self.host_version = host_version
        self.host_hash = host_hash
        self.board_version = board_version
        self.board_hash = board_hash
        super().__init__(
            f"protocol mismatch: host speaks version {host_version} (schema 0x{host_hash:08X}), "
            f"board speaks version {board_version} (schema 0x{board_hash:08X}); "
            "rebuild the firmware or the host package from the same protocol/spec.toml"
        )


class DisconnectedError(ProtocolError, ConnectionError):
    """The link is closed, or the line went away (cable, port, socket)."""


class PortBusyError(DisconnectedError):
    """The line is in use by another host: the emulated board already has one attached (it
    said so in a ``utrf busy:`` line), or the OS says another program holds the port."""


class NotABoardError(ProtocolError):
    """Something answered on the line, but not as a UTRF board: no identity came back."""


class NoAnswerError(ReplyTimeout):
    """Nothing at all came back on the line during the handshake (a :class:`ReplyTimeout`
    of ``identify`` that says so)."""

    def __init__(self, text: str, timeout: ReplyTimeout) -> None:
        self.request = timeout.request
        self.timeout_s = timeout.timeout_s
        self.attempts = timeout.attempts
        self.outcome = timeout.outcome
        Exception.__init__(self, text)


class BoardResetError(ProtocolError):
    """The board restarted (it sent ``boot``): its state is gone.

    Raised by the request that was waiting, and by every request after it, until the host
    calls :meth:`utrf.protocol.link.Link.handshake` again. ``boot`` is the board's message
    (``None`` if it could not be decoded, e.g. firmware of another protocol version).
    """

    def __init__(self, boot: Message | None) -> None:
        self.boot = boot
        cause = getattr(getattr(boot, "reset_cause", None), "name", "unknown cause")
        super().__init__(f"the board reset ({cause}); call handshake() and configure it again")
