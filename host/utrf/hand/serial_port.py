"""Opening the board's serial line with or without the MEGA's auto-reset.

The MEGA's USB-serial chip resets the board when DTR is raised, and Linux raises DTR when a
port is opened and drops it at the last close if the port's termios has HUPCL set (the
default). So whether opening resets the board depends on how the previous connection closed:

- ``reset=True``: set HUPCL and close once (DTR drops), then open (DTR rises: the reset),
  as a fresh plug-in would.
- ``reset=False``: open without touching DTR. If the previous connection left DTR raised,
  there is no edge and the board keeps running.
- Either way, once open, HUPCL is cleared: this connection's close leaves DTR raised, so the
  next one can choose not to reset. The first open after plugging the board in always resets
  it (DTR was down); so does any connection after a program that left HUPCL set.

``socket://`` (the emulated board's TCP port) carries no DTR line: every connection is an
open that resets the board. The emulated board's pty models DTR as above. The hardware way to
stop the auto-reset altogether is in firmware/README.md.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import TypeVar

try:
    import termios

    HAS_TERMIOS = True
except ImportError:  # Windows: no termios, no HUPCL; pyserial drives DTR itself
    HAS_TERMIOS = False

from utrf.protocol.errors import DisconnectedError

#: how long DTR stays down before the open that raises it again (the reset edge)
DTR_LOW_S = 0.1


T = TypeVar("T")


class ResetModeError(ValueError):
    """A connection without reset was asked of a line that cannot do it."""


def is_tty_path(url: str) -> bool:
    """A POSIX device path (``/dev/ttyACM0``, a pty), not a pyserial URL."""
    return HAS_TERMIOS and "://" not in url and os.path.exists(url)


def _set_hupcl(path: str, on: bool) -> None:
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError as exc:
        raise DisconnectedError(f"cannot open {path!r}: {exc}") from exc
    try:
        attrs = termios.tcgetattr(fd)
        attrs[2] = attrs[2] | termios.HUPCL if on else attrs[2] & ~termios.HUPCL
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass  # not a terminal: nothing to model
    finally:
        os.close(fd)


def open_line(url: str, reset: bool, opener: Callable[[], T]) -> T:
    """Open the line with ``opener()`` (which builds the transport), resetting the board or
    not as described above; returns what ``opener`` returned."""
    tty = is_tty_path(url)
    if not reset and url.startswith("socket://"):
        raise ResetModeError(
            f"{url}: socket:// carries no DTR line, so every TCP connection resets the emulated "
            "board; to connect without a reset use its pty (`utrf emulate` prints it) or a "
            "serial port"
        )
    if tty and reset:
        _set_hupcl(url, True)  # this close drops DTR...
        time.sleep(DTR_LOW_S)  # ...and the open below raises it: the reset
    line = opener()
    if tty:
        _set_hupcl(url, False)  # our close will leave DTR raised
    return line
