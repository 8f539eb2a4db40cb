"""Protocol benchmarks: codec speed (Python, and the firmware's C++ on the host and on the
ATmega2560 in simavr), the AVR footprint of framing and the generated codec, and Link's round
trip over TCP loopback.

    make protocol-bench          # or: .venv/bin/python -m tools.bench_protocol

Prints a Markdown section and writes it into docs/benchmarks.md between the protocol markers
(the rest of that file is left alone).
"""

from __future__ import annotations

import platform
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from tests.protocol.proto_helpers import LIB_PATH as LIB
from tests.protocol.proto_helpers import CppCodec, RxRecord
from tools.doc_sections import cpu_name, write_section
from utrf.protocol import Link
from utrf.protocol import messages as M
from utrf.protocol.framing import Frame, FrameDecoder, encode_frame

REPO_ROOT = Path(__file__).resolve().parents[1]
BENCH_DOC = REPO_ROOT / "docs" / "benchmarks.md"
BEGIN = "<!-- BEGIN protocol (make protocol-bench) -->"
END = "<!-- END protocol -->"
COMMAND = "make protocol-bench"


def per_call_us(fn: Callable[[], object], min_time_s: float = 0.3) -> float:
    """Best of 5 runs of the mean time per call, in µs."""
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        if time.perf_counter() - t0 > min_time_s / 5:
            break
        n *= 2
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        runs.append((time.perf_counter() - t0) / n)
    return min(runs) * 1e6


def sample_state() -> M.State:
    return M.State(
        board_time=12.345,
        status_seq=3,
        theta2=(0.1, 0.5, 0.9, 1.1, -0.05),
        target=(0.1, 0.5, 1.0, 1.2, 0.0),
        duty_a=(0.1, 0.3, -0.2, 0.9, 0.0),
        duty_b=(0.05, 0.0, 0.3, 0.0, -0.1),
    )


def python_codec() -> list[tuple[str, str]]:
    state = sample_state()
    body = state.encode()
    frame = encode_frame(0x80, M.State.ID, body)
    targets = M.SetTargets(M.TargetKind.JOINT2_ANGLE, 31, (0.1, 0.2, 0.3, 0.4, 0.5))
    stream = frame * 1000
    decoder = FrameDecoder()
    t_stream = per_call_us(lambda: decoder.feed(stream)) / 1000
    return [
        (
            f"`State.decode` ({M.State.SIZE}-byte body)",
            f"{per_call_us(lambda: M.State.decode(body)):.1f} µs",
        ),
        ("`State.encode`", f"{per_call_us(state.encode):.1f} µs"),
        ("`SetTargets.encode`", f"{per_call_us(targets.encode):.1f} µs"),
        ("`encode_frame` (state)", f"{per_call_us(lambda: encode_frame(0x80, 0x90, body)):.1f} µs"),
        ("`FrameDecoder.feed`, per state frame in a 1000-frame chunk", f"{t_stream:.1f} µs"),
        (
            "state stream the Python receiver keeps up with (frames + decode)",
            f"{1e6 / (t_stream + per_call_us(lambda: M.State.decode(body))):,.0f} frames/s",
        ),
    ]


def cpp_host() -> list[tuple[str, str]]:
    if not LIB.exists():
        return [("C++ on the host", f"skipped: {LIB.relative_to(REPO_ROOT)} not built")]
    lib = CppCodec(LIB).lib  # the C ABI of tests/protocol/cpp/shim.cpp, declared there
    frame = encode_frame(0x80, M.State.ID, sample_state().encode())
    stream = frame * 2000
    records = (RxRecord * 2001)()
    decoder = lib.utrf_decoder_new()
    t = per_call_us(lambda: lib.utrf_decoder_feed(decoder, stream, len(stream), records, 2001))
    lib.utrf_decoder_free(decoder)
    return [
        (
            "C++ `FrameDecoder::feed` on the host (g++ -O2), per byte",
            f"{t * 1000 / len(stream):.1f} ns",
        ),
    ]


def avr_footprint() -> list[tuple[str, str]]:
    flags = ["-mmcu=atmega2560", "-std=gnu++11", "-Os", "-Wall", "-Wextra", "-fno-exceptions"]
    out: list[tuple[str, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        probe = Path(tmp) / "probe.cpp"
        probe.write_text(
            f'#include "{REPO_ROOT}/firmware/src/core/framing.h"\n'
            "utrf::framing::FrameDecoder g_decoder;\n"
        )
        objects = {
            "framing.o (CRC, encode_frame, FrameDecoder)": REPO_ROOT
            / "firmware/src/core/framing.cpp",
            "every generated decode + encode (each used once)": REPO_ROOT
            / "tests/protocol/cpp/all_messages.cpp",
            "one FrameDecoder instance": probe,
        }
        for label, source in objects.items():
            obj = Path(tmp) / (source.stem + ".o")
            try:
                subprocess.run(["avr-g++", *flags, "-c", str(source), "-o", str(obj)], check=True)
                size = (
                    subprocess.run(
                        ["avr-size", str(obj)], check=True, capture_output=True, text=True
                    )
                    .stdout.splitlines()[1]
                    .split()
                )
            except (OSError, subprocess.CalledProcessError) as exc:
                return [("AVR footprint", f"skipped: {exc}")]
            text, data, bss = (int(x) for x in size[:3])
            if "instance" in label:
                out.append((f"AVR: {label}", f"{data + bss} B of SRAM"))
            else:
                out.append((f"AVR: {label}", f"{text} B flash, {data + bss} B SRAM"))
    return out


AVR_CYCLES_PROGRAM = r"""
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdio.h>
#include "@ROOT@/firmware/src/core/framing.h"
#include "@ROOT@/firmware/src/generated/protocol_messages.h"
using namespace utrf;
static const uint8_t kFrame[] = {@FRAME@};
static int put(char c, FILE*) { while (!(UCSR0A & (1 << UDRE0))) {} UDR0 = c; return 0; }
static FILE out;
volatile uint8_t sink;
int main() {
  UCSR0B = (1 << TXEN0);
  fdev_setup_stream(&out, put, NULL, _FDEV_SETUP_WRITE);
  TCCR1A = 0;
  TCCR1B = (1 << CS10);  // timer 1 counts CPU cycles
  framing::FrameDecoder d;
  uint8_t frames = 0;
  TCNT1 = 0;
  for (uint8_t i = 0; i + 1 < sizeof kFrame; ++i) {
    frames += d.feed(kFrame[i]) == framing::RxEvent::FRAME;
  }
  const uint16_t t_bytes = TCNT1;
  TCNT1 = 0;
  frames += d.feed(0) == framing::RxEvent::FRAME;
  const uint16_t t_end = TCNT1;
  proto::State s;
  uint8_t bad;
  TCNT1 = 0;
  const proto::DecodeStatus st = proto::decode(d.body(), d.body_len(), s, bad);
  const uint16_t t_decode = TCNT1;
  uint8_t frame[framing::kMaxFrameBytes];
  TCNT1 = 0;
  framing::FrameWriter w(frame, 0x81, proto::MsgId::STATE);
  proto::write(w, s);
  const uint8_t n = w.finish();
  const uint16_t t_encode = TCNT1;
  sink = frame[n - 1];
  fprintf(&out, "RESULT %u %u %u %u %u %u\n", frames, (unsigned)st, t_bytes, t_end,
          t_decode, t_encode);
  while (!(UCSR0A & (1 << TXC0))) {}
  cli();
  sleep_mode();
}
"""


def avr_cycles() -> list[tuple[str, str]]:
    """Cycles on the ATmega2560 (simavr, timer 1 at the CPU clock) for one state frame, built
    with -O2 as the firmware is."""
    frame = encode_frame(0x80, M.State.ID, sample_state().encode())
    source = AVR_CYCLES_PROGRAM.replace("@ROOT@", str(REPO_ROOT)).replace(
        "@FRAME@", ",".join(str(b) for b in frame)
    )
    with tempfile.TemporaryDirectory() as tmp:
        src, elf = Path(tmp) / "cycles.cpp", Path(tmp) / "cycles.elf"
        src.write_text(source)
        try:
            subprocess.run(
                [
                    "avr-g++",
                    "-mmcu=atmega2560",
                    "-DF_CPU=16000000L",
                    "-std=gnu++11",
                    "-O2",
                    "-fno-exceptions",
                    "-o",
                    str(elf),
                    str(src),
                    str(REPO_ROOT / "firmware/src/core/framing.cpp"),
                ],
                check=True,
            )
            run = subprocess.run(
                ["simavr", "-m", "atmega2560", "-f", "16000000", str(elf)],
                capture_output=True,
                text=True,
                timeout=60,
            )
        except (OSError, subprocess.SubprocessError) as exc:
            return [("AVR cycles", f"skipped: {exc}")]
    match = re.search(r"RESULT (\d+) (\d+) (\d+) (\d+) (\d+) (\d+)", run.stdout + run.stderr)
    if match is None:
        return [("AVR cycles", "skipped: simavr printed no result")]
    frames, status, t_bytes, t_end, t_decode, t_encode = (int(x) for x in match.groups())
    if (frames, status) != (1, 0):
        return [("AVR cycles", f"failed: {frames} frames, decode status {status}")]

    def cyc(n: int) -> str:
        return f"{n} cycles ({n / 16:.0f} µs at 16 MHz)"

    raw = len(frame) - 2
    return [
        (
            f"AVR: `FrameDecoder::feed`, {len(frame) - 1} bytes of a state frame (incl. the loop)",
            cyc(t_bytes),
        ),
        (f"AVR: `feed(0x00)` ending it: COBS decode + CRC of {raw} bytes", cyc(t_end)),
        ("AVR: `proto::decode(State)`", cyc(t_decode)),
        (
            f"AVR: a state frame written ({len(frame)} bytes; CRC and COBS per byte)",
            cyc(t_encode),
        ),
    ]


def link_round_trip() -> list[tuple[str, str]]:
    """Ping round trips through Link, TCP loopback, against a minimal in-process board."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def board() -> None:
        conn, _ = server.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        decoder = FrameDecoder()
        while data := conn.recv(4096):
            for ev in decoder.feed(data):
                if isinstance(ev, Frame) and ev.msg_id == M.Ping.ID:
                    token = M.Ping.decode(ev.body).token
                    conn.sendall(encode_frame(ev.seq, M.Pong.ID, M.Pong(token, 0.0).encode()))

    threading.Thread(target=board, daemon=True).start()
    times = []
    with Link.open(f"socket://127.0.0.1:{port}", heartbeat_period_s=None) as link:
        for i in range(2000):
            t0 = time.perf_counter()
            link.request(M.Ping(i))
            times.append((time.perf_counter() - t0) * 1e6)
    server.close()
    times.sort()
    return [
        (
            "`Link.request(Ping)` round trip, TCP loopback, median",
            f"{statistics.median(times):.0f} µs",
        ),
        ("... 99th percentile", f"{times[int(len(times) * 0.99)]:.0f} µs"),
    ]


def line_use() -> str:
    """What the fastest state stream takes of the line, at 10 bits a byte (8N1)."""
    n = len(encode_frame(0x80, M.State.ID, sample_state().encode()))
    frame_s = n * 10 / M.DEFAULT_BAUD
    return (
        f"a state frame is {n} bytes, {frame_s * 1e3:.1f} ms at {M.DEFAULT_BAUD / 1e6:g} Mbaud,"
        f" so {M.MAX_TELEMETRY_HZ} Hz of telemetry uses {100 * M.MAX_TELEMETRY_HZ * frame_s:.0f} %"
        " of it"
    )


def main() -> int:
    rows = python_codec() + cpp_host() + avr_footprint() + avr_cycles() + link_round_trip()
    lines = [
        BEGIN,
        "## Protocol",
        "",
        f"Measured with `{COMMAND}` on {cpu_name()}, Python {platform.python_version()}"
        f" ({time.strftime('%Y-%m-%d')}). The line itself: {line_use()}.",
        "",
        "| what | result |",
        "|---|---|",
        *[f"| {k} | {v} |" for k, v in rows],
        END,
    ]
    section = "\n".join(lines)
    print(section)
    write_section(BENCH_DOC, section, BEGIN, END)
    print(f"bench_protocol: wrote {BENCH_DOC.relative_to(REPO_ROOT)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
