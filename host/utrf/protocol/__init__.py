"""The host side of the host-board protocol (wire format: ``protocol/README.md``).

- :mod:`utrf.protocol.messages`: generated message classes in SI units, and the constants;
- :mod:`utrf.protocol.framing`: COBS + CRC-16 frames and the streaming decoder;
- :mod:`utrf.protocol.transport`: a byte pipe over any pyserial URL;
- :mod:`utrf.protocol.engine`: the client's rules (seq, retries, hints, resets, stream loss,
  heartbeats) without I/O, driven by :class:`Link` and by the Hand's ``SimLink``;
- :mod:`utrf.protocol.link`: :class:`Link`, requests and replies, retries, telemetry;
- :mod:`utrf.protocol.errors`: the exceptions.
"""

from utrf.protocol.errors import (
    BoardResetError,
    DecodeError,
    DisconnectedError,
    NackError,
    Outcome,
    ProtocolError,
    ReplyTimeout,
    SchemaMismatchError,
)
from utrf.protocol.link import Link, LinkStats, Telemetry

__all__ = [
    "BoardResetError",
    "DecodeError",
    "DisconnectedError",
    "Link",
    "LinkStats",
    "NackError",
    "Outcome",
    "ProtocolError",
    "ReplyTimeout",
    "SchemaMismatchError",
    "Telemetry",
]
