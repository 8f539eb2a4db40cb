"""``utrf flash --port PORT``: write the firmware to an Arduino MEGA 2560 with avrdude.

Runs ``avrdude -p atmega2560 -c wiring -P PORT -b 115200 -D -U flash:w:HEX:i``, as
``make flash`` does: ``wiring`` is avrdude's STK500v2 programmer with the DTR pulse that
resets the MEGA into its bootloader (``--programmer stk500v2`` for the plain protocol), at the
bootloader's 115200 baud; ``-D`` leaves the erase to the bootloader. The HEX defaults to
``build/firmware/utrf.hex`` in a checkout (``make firmware``), else one built from the
package's firmware sources into the user's cache (``utrf.artifacts``). ``--dry-run`` prints the
command and checks everything but the board.

Before avrdude runs, the port is opened (no port: exit 2 at once; avrdude 7.1 spins forever on
a port it cannot open) and the bootloader is asked to sign on, as avrdude's first step is: a
board that does not answer within ``--sync-timeout`` s (2 s; a MEGA's bootloader answers in
about 0.1 s after the reset) fails there with one line, where avrdude would retry for 30 s.
``--no-sync-check`` skips it (a board with auto-reset disabled: press RESET as avrdude starts).
avrdude itself is stopped after ``--timeout`` s (120). Exit codes: 0 flashed (or would be);
2 bad input (no HEX, not an Intel HEX file, no avrdude, no such port); 1 the board did not
answer or avrdude failed (its output says why).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import time
from pathlib import Path

import serial

from utrf import artifacts
from utrf.cli import error

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
DEFAULT_HEX = artifacts.CHECKOUT_HEX  # in a checkout; see artifacts.firmware_hex()
MCU = "atmega2560"
FLASH_BAUD = 115200
MEGA_FLASH_BYTES = 256 * 1024 - 8 * 1024  # less the bootloader


class FlashError(ValueError):
    """Something to fix before avrdude can run; the message says what."""


class NoBootloaderError(RuntimeError):
    """The port opened, but no STK500v2 bootloader answered."""


# STK500v2 (AVR068): MESSAGE_START, sequence, size (big-endian), TOKEN, body, XOR checksum.
STK_START, STK_TOKEN, CMD_SIGN_ON = 0x1B, 0x0E, 0x01


def stk500v2_message(seq: int, body: bytes) -> bytes:
    head = bytes([STK_START, seq & 0xFF, len(body) >> 8, len(body) & 0xFF, STK_TOKEN])
    check = 0
    for b in head + body:
        check ^= b
    return head + body + bytes([check])


def check_bootloader(port: str, baud: int, timeout_s: float) -> str:
    """Reset the board into its bootloader (DTR pulse, as avrdude's ``wiring`` does) and ask
    it to sign on; its signature (e.g. ``AVRISP_2``), or NoBootloaderError. FlashError if the
    port cannot be opened."""
    try:
        ser = serial.serial_for_url(port, baudrate=baud, timeout=0.05)
    except (serial.SerialException, ValueError) as exc:
        raise FlashError(f"cannot open {port}: {exc}") from None
    with ser:
        try:  # the MEGA's auto-reset: DTR low, then high again
            ser.dtr = False
            time.sleep(0.05)
            ser.dtr = True
        except (OSError, serial.SerialException):
            pass  # a port without modem lines (a pty): nothing to pulse
        ser.reset_input_buffer()
        deadline = time.monotonic() + timeout_s
        seq, got = 1, b""
        while time.monotonic() < deadline:
            ser.write(stk500v2_message(seq, bytes([CMD_SIGN_ON])))
            until = min(deadline, time.monotonic() + 0.25)
            while time.monotonic() < until:
                got += ser.read(64)
                start = got.find(bytes([STK_START, seq]))
                if start >= 0 and len(got) >= start + 8:
                    size = (got[start + 2] << 8) | got[start + 3]
                    frame = got[start : start + 6 + size]
                    if len(frame) == 6 + size and frame[5:7] == bytes([CMD_SIGN_ON, 0]):
                        return frame[8 : 8 + frame[7]].decode("ascii", "replace")
            seq += 1
    heard = f"; heard {len(got)} other bytes" if got else ", nothing at all"
    raise NoBootloaderError(
        f"no STK500v2 bootloader answered on {port} within {timeout_s:g} s{heard}: is it a "
        "MEGA 2560 with its bootloader, on this port? (auto-reset disabled: press RESET and "
        "flash with --no-sync-check)"
    )


def check_hex(path: Path) -> int:
    """The number of data bytes in an Intel HEX file; FlashError naming the problem."""
    if not path.exists():
        hint = " (run `make firmware`, or pass --hex FILE)" if path == DEFAULT_HEX else ""
        raise FlashError(f"no HEX file at {path}{hint}")
    if not path.is_file():
        raise FlashError(f"{path} is not a file")
    data = 0
    eof = False
    for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        where = f"{path}:{n}"
        if not line.startswith(":"):
            raise FlashError(f"{where}: not an Intel HEX record (a line must start with ':')")
        try:
            raw = bytes.fromhex(line[1:])
        except ValueError:
            raise FlashError(f"{where}: not hexadecimal") from None
        if len(raw) < 5 or len(raw) != raw[0] + 5:
            raise FlashError(f"{where}: record length does not match its byte count")
        if sum(raw) & 0xFF:
            raise FlashError(f"{where}: checksum error")
        if raw[3] == 0x00:
            data += raw[0]
        elif raw[3] == 0x01:
            eof = True
            break
    if not eof:
        raise FlashError(f"{path}: no end-of-file record: the file is cut short")
    if data == 0:
        raise FlashError(f"{path}: holds no data")
    if data > MEGA_FLASH_BYTES:
        raise FlashError(
            f"{path}: {data} bytes do not fit the MEGA's {MEGA_FLASH_BYTES} bytes of flash"
        )
    return data


def avrdude_command(
    avrdude: str, port: str, hex_path: Path, programmer: str, baud: int
) -> list[str]:
    return [
        avrdude,
        "-p",
        MCU,
        "-c",
        programmer,
        "-P",
        port,
        "-b",
        str(baud),
        "-D",
        "-U",
        f"flash:w:{hex_path}:i",
    ]


def run(args: argparse.Namespace) -> int:
    try:
        if args.hex is None:
            try:
                args.hex = artifacts.firmware_hex()
            except artifacts.ArtifactError as exc:
                raise FlashError(str(exc)) from None
        size = check_hex(args.hex)
        avrdude = shutil.which(args.avrdude)
        if avrdude is None:
            raise FlashError(
                f"avrdude not found ({args.avrdude!r} is not on PATH): install it "
                "(Debian/Ubuntu: sudo apt-get install avrdude) or pass --avrdude PATH"
            )
        if not args.port:
            raise FlashError("--port is empty")
        if not args.dry_run and args.port.startswith("/dev/") and not Path(args.port).exists():
            raise FlashError(f"no serial port {args.port}: is the MEGA plugged in?")
    except FlashError as exc:
        error("flash", exc)
        return EXIT_BAD_INPUT
    cmd = avrdude_command(avrdude, args.port, args.hex, args.programmer, args.baud)
    print(f"{shlex.join(cmd)}    # {size} bytes", flush=True)
    if args.dry_run:
        return EXIT_OK
    if args.sync_check:
        try:
            sign = check_bootloader(args.port, args.baud, args.sync_timeout)
        except FlashError as exc:
            error("flash", exc)
            return EXIT_BAD_INPUT
        except NoBootloaderError as exc:
            error("flash", exc)
            return EXIT_FAILED
        print(f"bootloader on {args.port}: {sign}", flush=True)
    try:
        proc = subprocess.run(cmd, check=False, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        error("flash", f"avrdude did not finish in {args.timeout:g} s")
        return EXIT_FAILED
    if proc.returncode:
        error("flash", f"avrdude failed (exit {proc.returncode})")
        return EXIT_FAILED
    print(f"flashed {args.hex} to {args.port}")
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "flash",
        help="write the firmware to the MEGA (avrdude)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", required=True, help="the MEGA's serial port, e.g. /dev/ttyACM0")
    p.add_argument(
        "--hex",
        type=Path,
        metavar="FILE",
        help="Intel HEX to write (default: build/firmware/utrf.hex in a checkout, else built "
        "from the package's firmware sources)",
    )
    p.add_argument("--avrdude", default="avrdude", metavar="PATH", help="the avrdude to run")
    p.add_argument(
        "--programmer", default="wiring", help="avrdude programmer (wiring: STK500v2 + DTR reset)"
    )
    p.add_argument("--baud", type=int, default=FLASH_BAUD, help="bootloader baud (115200)")
    p.add_argument(
        "--dry-run", action="store_true", help="check and print the command, do not run it"
    )
    p.add_argument(
        "--sync-timeout",
        type=float,
        default=2.0,
        metavar="S",
        help="how long the bootloader has to answer its sign-on (s, default 2)",
    )
    p.add_argument(
        "--no-sync-check",
        dest="sync_check",
        action="store_false",
        help="do not ask the bootloader first (auto-reset disabled: press RESET yourself)",
    )
    p.add_argument(
        "--timeout", type=float, default=120.0, metavar="S", help="stop avrdude after S s (120)"
    )
    p.set_defaults(handler=run)
