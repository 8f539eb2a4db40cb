"""The host side of the host-board protocol (wire format: ``protocol/README.md``).

- :mod:`utrf.protocol.messages`: generated message classes in SI units, and the constants;
- :mod:`utrf.protocol.framing`: COBS + CRC-16 frames and the streaming decoder;
- :mod:`utrf.protocol.transport`: a byte pipe over any pyserial URL;
- :mod:`utrf.protocol.link`: :class:`Link`, requests and replies, retries, telemetry;
- :mod:`utrf.protocol.errors`: the exceptions.
"""
