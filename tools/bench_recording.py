"""A long recording at 1 kHz loses no sample (``make bench-recording``; 10 minutes by default,
not part of ``make test``; results in docs/benchmarks.md).

``utrf emulate`` serves the board in its own process; ``utrf record --port`` records its
1 kHz stream for ``--seconds`` while moving to a pose. The file is then read back with the
``mcap`` reader: every ``/hand/state`` sample one board tick after the last (no gap), as many
``/joint_states`` as states, and the counts against the board's ``tx_dropped`` and the link's
seq gaps that ``utrf record`` wrote into the file.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from tools.doc_sections import cpu_name, write_section
from utrf.recording import schemas

BEGIN = "<!-- BEGIN recording (make bench-recording) -->"
END = "<!-- END recording -->"


def run(elf: Path | None, seconds: float, tmp: Path) -> dict:
    url_file = tmp / "emulator.url"
    cmd = [sys.executable, "-m", "utrf", "emulate", "--no-pty", "--url-file", str(url_file),
           "--status-interval", "0", "--no-commands"]  # fmt: skip
    if elf:
        cmd += ["--elf", str(elf)]
    emu = subprocess.Popen(cmd, stdout=(tmp / "emulate.log").open("w"), stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while not (url_file.exists() and "socket://" in url_file.read_text()):
            if emu.poll() is not None or time.monotonic() > deadline:
                raise SystemExit("bench-recording: utrf emulate did not start")
            time.sleep(0.2)
        url = next(w for w in url_file.read_text().split() if w.startswith("socket://"))
        out = tmp / "long.mcap"
        t0 = time.monotonic()
        rec = subprocess.run(
            [
                sys.executable,
                "-m",
                "utrf",
                "record",
                str(out),
                "--port",
                url,
                "--boot-wait",
                "0.5",
                "--duration",
                str(seconds),
                "--pose",
                "fist",
                "--json",
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.monotonic() - t0
    finally:
        emu.send_signal(signal.SIGINT)
        emu.wait(30)
    if rec.returncode not in (0, 1):
        raise SystemExit(f"bench-recording: utrf record failed:\n{rec.stdout}\n{rec.stderr}")
    summary = json.loads(rec.stdout.strip().splitlines()[-1])
    with out.open("rb") as f:
        reader = make_reader(f)
        board = np.array(
            [
                json.loads(msg.data)["board_time_s"]
                for _, _, msg in reader.iter_messages(topics=[schemas.STATE_TOPIC])
            ]
        )
    with out.open("rb") as f:
        joints = sum(1 for _ in make_reader(f).iter_messages(topics=[schemas.JOINT_STATES_TOPIC]))
    steps = np.round(np.diff(board) * 1000).astype(int)
    return {
        "seconds": seconds,
        "wall_s": wall,
        "samples": len(board),
        "joint_states": joints,
        "board_span_s": float(board[-1] - board[0]),
        "gaps_in_file": int((steps - 1).clip(min=0).sum()),
        "summary": summary,
        "file_mb": out.stat().st_size / 1e6,
        "load_average": os.getloadavg()[0],
    }


def section(r: dict) -> str:
    s = r["summary"]
    lost = int(s["lost"]) + r["gaps_in_file"]
    return "\n".join(
        [
            BEGIN,
            "## Recording",
            "",
            f"`make bench-recording` ({date.today().isoformat()}, {cpu_name()}, 2 cores shared "
            f"with other work: load average {r['load_average']:.1f} at the end): `utrf record "
            f"--port` on `utrf emulate` (its own process) at 1 kHz for {r['seconds']:.0f} s of "
            f"the host's clock, moving to a pose: {r['samples']} samples over "
            f"{r['board_span_s']:.1f} s of board time (the emulated board runs slower than real "
            f"time on a loaded machine), {r['file_mb']:.1f} MB.",
            "",
            "| count | value |",
            "|---|---|",
            f"| `/hand/state` samples in the file | {r['samples']} |",
            f"| `/joint_states` messages | {r['joint_states']} |",
            f"| board-clock gaps in the file (a step longer than 1 ms) | {r['gaps_in_file']} |",
            f"| the board's `tx_dropped` over the recording | {s['board_tx_dropped']} |",
            f"| the link's stream seq gaps over the recording | {s['link_stream_lost']} |",
            f"| **samples lost** (goal 0) | **{lost}** |",
            END,
        ]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--elf", type=Path)
    p.add_argument("--seconds", type=float, default=600.0)
    p.add_argument("--update", type=Path)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="utrf-bench-rec-") as tmp:
        r = run(args.elf, args.seconds, Path(tmp))
    print(json.dumps(r, indent=1))
    text = section(r)
    print(text)
    if args.update:
        write_section(args.update, text, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
