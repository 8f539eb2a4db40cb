"""``utrf flash --port PORT``: write the firmware to an Arduino MEGA 2560 with avrdude.

Runs ``avrdude -p atmega2560 -c wiring -P PORT -b 115200 -D -U flash:w:HEX:i``, as
``make flash`` does: ``wiring`` is avrdude's STK500v2 programmer with the DTR pulse that
resets the MEGA into its bootloader (``--programmer stk500v2`` for the plain protocol), at the
bootloader's 115200 baud; ``-D`` leaves the erase to the bootloader. The HEX defaults to
``build/firmware/utrf.hex`` (``make firmware``). ``--dry-run`` prints the command and checks
everything but the board. Exit codes: 0 flashed (or would be); 2 bad input (no HEX, not an
Intel HEX file, no avrdude); 1 avrdude failed (its output says why).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
DEFAULT_HEX = Path(__file__).resolve().parents[3] / "build" / "firmware" / "utrf.hex"
MCU = "atmega2560"
FLASH_BAUD = 115200
MEGA_FLASH_BYTES = 256 * 1024 - 8 * 1024  # less the bootloader


class FlashError(ValueError):
    """Something to fix before avrdude can run; the message says what."""


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
        print(f"utrf flash: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    cmd = avrdude_command(avrdude, args.port, args.hex, args.programmer, args.baud)
    print(f"{shlex.join(cmd)}    # {size} bytes", flush=True)
    if args.dry_run:
        return EXIT_OK
    proc = subprocess.run(cmd, check=False)
    if proc.returncode:
        print(f"utrf flash: error: avrdude failed (exit {proc.returncode})", file=sys.stderr)
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
        "--hex", type=Path, default=DEFAULT_HEX, metavar="FILE", help="Intel HEX to write"
    )
    p.add_argument("--avrdude", default="avrdude", metavar="PATH", help="the avrdude to run")
    p.add_argument(
        "--programmer", default="wiring", help="avrdude programmer (wiring: STK500v2 + DTR reset)"
    )
    p.add_argument("--baud", type=int, default=FLASH_BAUD, help="bootloader baud (115200)")
    p.add_argument(
        "--dry-run", action="store_true", help="check and print the command, do not run it"
    )
    p.set_defaults(handler=run)
