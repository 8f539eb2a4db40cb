"""Where the firmware's awake cycles go under the twin's traffic: a PC histogram per function.

    python -m tools.fw_profile [--elf ELF] [--seconds S] [--rate HZ] [--top N] [--function F]
    python -m tools.fw_profile [--elf ELF] --plant [--seconds S] [--top N]
    python -m tools.fw_profile [--elf ELF] --versus REF_ELF [--cpu-seconds S] [--repeats N]

Runs the ELF on the emulated board with no plant (as ``tools.bench_twin --engine elf``: the
grasp hold's host traffic, telemetry at ``--rate`` Hz (100: the hold's; 1000: the stream),
heartbeats, five fingers in POSITION at the angles their still encoders read), counts every
simulated cycle at the address of the instruction that spent it (the harness's PC histogram,
sleep included) and maps the addresses to the ELF's functions (``avr-nm``). Prints the share
of the cycles the CPU was awake, and the functions by awake cycles per simulated second; with
``--function``, that function's hottest instructions too (``avr-objdump`` lines). With
``--plant``: the grasp hold with the MuJoCo hand instead (the encoders moving, with the
emulated sensor's noise: what the twin's hold pays; the run's closing included). With
``--versus``: what simavr costs the host for each ELF alone instead, side by side (the process
CPU time of ``--cpu-seconds`` simulated under the same traffic, the two ELFs alternating,
``--repeats`` each; the ratio of the medians): the twin's floor, as ``tools.bench_twin``'s
"ELF alone" row measures it for a tree's own build.
"""

from __future__ import annotations

import argparse
import bisect
import re
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

CPU_HZ = 16_000_000
# The ATmega2560's vectors the firmware uses (avr-gcc names them __vector_<n>).
VECTORS = {13: "TIMER2_COMPA", 23: "TIMER0_OVF", 25: "USART0_RX", 26: "USART0_UDRE", 29: "ADC"}


def label(name: str) -> str:
    """A symbol's name, an interrupt's with its vector's name."""
    if name.startswith("__vector_") and name[9:].isdigit():
        return f"{name} ({VECTORS.get(int(name[9:]), '?')} interrupt)"
    return name


def symbols(elf: Path) -> tuple[list[int], list[str]]:
    """The code symbols' byte addresses (sorted) and demangled names."""
    out = subprocess.run(
        ["avr-nm", "-C", "-n", "--defined-only", str(elf)],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    addrs: list[int] = []
    names: list[str] = []
    for line in out.splitlines():
        parts = line.split(" ", 2)
        if len(parts) == 3 and parts[1] in "TtWw" and int(parts[0], 16) < 0x800000:
            addrs.append(int(parts[0], 16))
            names.append(parts[2])
    return addrs, names


def sleeps(elf: Path) -> set[int]:
    """The byte addresses of the ``sleep`` instructions and of the instructions after them:
    simavr charges the slept cycles to one or the other (the PC the core wakes at)."""
    out = subprocess.run(
        ["avr-objdump", "-d", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    found = set()
    for m in re.finditer(r"^\s*([0-9a-f]+):\s+88 95\s+sleep", out, re.M):
        found.add(int(m.group(1), 16))
        found.add(int(m.group(1), 16) + 2)
    return found


def run(elf: Path, seconds: float, rate_hz: int) -> tuple[np.ndarray, int, int]:
    """The histogram (cycles per program word), the cycles run and those slept."""
    from tools.bench_twin import elf_alone
    from utrf.protocol import messages as m

    with elf_alone(elf) as (board, link):
        native = board._native
        if rate_hz != 100:
            link.request(m.SetTelemetry(rate_hz=rate_hz))
        link.sleep(0.05)
        native.pc_histogram(-1)
        slept0, cycle0 = native.stats()["sleep_cycles"], native.cycle
        link.sleep(seconds)
        hist = native.pc_histogram_get().copy()
        slept, cycles = native.stats()["sleep_cycles"] - slept0, native.cycle - cycle0
        native.pc_histogram(None)
    return hist, cycles, slept


def run_hold(elf: Path, seconds: float) -> tuple[np.ndarray, int, int]:
    """As run(), over the grasp hold with the MuJoCo hand (``utrf hil grasp-hold --emulated``'s
    run, seed 0, one hit, ``seconds`` of hold after the closing): the encoders move and carry
    the emulated sensor's noise, as in the twin's hold."""
    import tempfile

    from utrf.hil.grasp_hold import config as gh
    from utrf.hil.grasp_hold import run as hold
    from utrf.hil.rig import EmulatedTruth, open_emulated

    rig = open_emulated(seed=0, tracked_finger=1, truth=EmulatedTruth(actuator=None), elf=str(elf))
    native = rig.board._native
    config = gh.GraspHoldConfig(pose="grasp-bottle", duration_s=seconds, hits=1,
                                hit_impulse_n_s=0.3, tracked_finger=1, sample_hz=10.0,
                                emulated=True, seed=0)  # fmt: skip
    try:
        native.pc_histogram(-1)
        slept0, cycle0 = native.stats()["sleep_cycles"], native.cycle
        with tempfile.TemporaryDirectory() as out:
            hold.run(rig, config, Path(out) / "run", progress=lambda _s: None)
        hist = native.pc_histogram_get().copy()
        slept, cycles = native.stats()["sleep_cycles"] - slept0, native.cycle - cycle0
        native.pc_histogram(None)
    finally:
        rig.close()
    return hist, cycles, slept


def awake(elf: Path, seconds: float, rate_hz: int, plant: bool = False) -> dict:
    """The awake cycles of ``seconds`` simulated under the twin's traffic: ``share`` (of every
    cycle), ``per_s`` (awake cycles per simulated second), ``functions`` (name: cycles per
    simulated second, largest first), ``hist`` (awake cycles per program word). ``plant``:
    the grasp hold with the MuJoCo hand instead (run_hold(); ``rate_hz`` its 100)."""
    hist, cycles, slept = run_hold(elf, seconds) if plant else run(elf, seconds, rate_hz)
    for a in sorted(sleeps(elf)):  # the slept cycles, off the sleep and the next
        take = min(int(hist[a // 2]), slept)
        hist[a // 2] -= take
        slept -= take
    if slept:
        raise RuntimeError(f"{slept} slept cycles not found at a sleep instruction")
    addrs, names = symbols(elf)
    per_fn: dict[str, int] = {}
    for word in np.nonzero(hist)[0]:
        i = bisect.bisect_right(addrs, 2 * int(word)) - 1
        name = names[i] if i >= 0 else "?"
        per_fn[name] = per_fn.get(name, 0) + int(hist[word])
    sim_s = cycles / CPU_HZ
    total = int(hist.sum())
    return {
        "share": total / cycles,
        "per_s": total / sim_s,
        "functions": {k: v / sim_s for k, v in sorted(per_fn.items(), key=lambda kv: -kv[1])},
        "hist": hist,
        "sim_s": sim_s,
    }


def cpu_alone(elf: Path, seconds: float) -> float:
    """The process CPU time (s) simavr takes for ``seconds`` simulated of the ELF alone."""
    from tools.bench_twin import elf_alone

    with elf_alone(elf) as (_board, link):
        cpu0 = time.process_time()
        link.sleep(seconds)
        return time.process_time() - cpu0


def versus(elf: Path, ref: Path, seconds: float, repeats: int) -> dict:
    """Each ELF alone ``repeats`` times, alternating: ``this`` and ``ref`` (CPU s per run)
    and ``ratio``, this build's median over the reference's."""
    runs: dict[str, list[float]] = {"this": [], "ref": []}
    for i in range(repeats):
        order = [("this", elf), ("ref", ref)]
        for tag, path in order if i % 2 == 0 else order[::-1]:
            runs[tag].append(cpu_alone(path, seconds))
    return {**runs, "ratio": statistics.median(runs["this"]) / statistics.median(runs["ref"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--elf", type=Path, default=Path("build/firmware/utrf.elf"))
    p.add_argument("--seconds", type=float, default=5.0, help="simulated seconds")
    p.add_argument("--rate", type=int, default=100, help="telemetry rate, Hz")
    p.add_argument("--top", type=int, default=25, help="functions listed")
    p.add_argument("--function", help="also list this function's hottest instructions")
    p.add_argument(
        "--lines", action="store_true",
        help="with --function: its cycles by source file and line instead",
    )  # fmt: skip
    p.add_argument(
        "--plant", action="store_true",
        help="the grasp hold with the MuJoCo hand (moving, noisy encoders), not the ELF alone",
    )  # fmt: skip
    p.add_argument("--versus", type=Path, help="CPU time of this ELF alone against another's")
    p.add_argument("--cpu-seconds", type=float, default=120.0, help="with --versus: simulated s")
    p.add_argument("--repeats", type=int, default=3, help="with --versus: runs of each ELF")
    args = p.parse_args(argv)
    if not args.elf.exists():
        p.error(f"no ELF at {args.elf} (make firmware)")
    if args.versus is not None:
        if not args.versus.exists():
            p.error(f"no ELF at {args.versus}")
        if not args.cpu_seconds > 0 or args.repeats < 1:
            p.error("--cpu-seconds must be > 0 and --repeats >= 1")
        v = versus(args.elf, args.versus, args.cpu_seconds, args.repeats)
        this, ref = statistics.median(v["this"]), statistics.median(v["ref"])
        print(f"ELF alone, {args.cpu_seconds:g} s simulated, CPU s (median of {args.repeats}): "
              f"{args.elf} {this:.2f} ({', '.join(f'{x:.2f}' for x in v['this'])}), "
              f"{args.versus} {ref:.2f} ({', '.join(f'{x:.2f}' for x in v['ref'])}): "
              f"ratio {v['ratio']:.2f}")  # fmt: skip
        return 0
    if not args.seconds > 0 or args.rate not in (100, 1000):
        p.error("--seconds must be > 0 and --rate 100 or 1000")
    a = awake(args.elf, args.seconds, args.rate, plant=args.plant)
    what = "the grasp hold with the MuJoCo hand, " if args.plant else ""
    print(f"{args.elf}: {a['sim_s']:.2f} s simulated, {what}telemetry {args.rate} Hz, awake "
          f"{100 * a['share']:.2f} % of the cycles ({a['per_s']:,.0f} cycles/s)")  # fmt: skip
    print(f"{'cycles/s':>10} {'% awake':>8}  function")
    for name, c in list(a["functions"].items())[: args.top]:
        print(f"{c:10,.0f} {100 * c / a['per_s']:8.2f}  {label(name)}")
    if args.function and args.lines:
        addrs, names = symbols(args.elf)
        lines(args.elf, a["hist"], args.function, a["sim_s"], addrs, names)
    elif args.function:
        hot(args.elf, a["hist"], args.function, a["sim_s"])
    return 0


def lines(
    elf: Path, hist: np.ndarray, function: str, sim_s: float, addrs: list[int], names: list[str]
) -> None:
    """The function's cycles by source file and by source line (the innermost line of the
    code inlined there; avr-addr2line 2.26 names no inlined function)."""
    words = [int(w) for w in np.nonzero(hist)[0]]
    mine = [w for w in words
            if function in names[max(bisect.bisect_right(addrs, 2 * w) - 1, 0)]]  # fmt: skip
    if not mine:
        print(f"no cycles in a function named like {function!r}")
        return
    out = subprocess.run(
        ["avr-addr2line", "-a", "-f", "-i", "-C", "-e", str(elf)] + [hex(2 * w) for w in mine],
        capture_output=True, text=True, check=True,
    ).stdout.splitlines()  # fmt: skip
    by_line: dict[str, int] = {}
    by_file: dict[str, int] = {}
    chain: list[tuple[str, str]] = []
    at = -1

    def flush() -> None:
        if at < 0 or not chain:
            return
        c = int(hist[at // 2])
        fn, where = chain[0]
        key = f"{where.rsplit('/', 1)[-1]}  {fn}"
        by_line[key] = by_line.get(key, 0) + c
        source = where.rsplit("/", 1)[-1].split(":")[0]
        by_file[source] = by_file.get(source, 0) + c

    i = 0
    while i < len(out):
        if out[i].startswith("0x"):
            flush()
            at, chain = int(out[i], 16), []
            i += 1
        else:
            chain.append((out[i], out[i + 1] if i + 1 < len(out) else "?"))
            i += 2
    flush()
    total = sum(by_file.values())
    print(f"\n{function}: {total / sim_s:,.0f} cycles/s, by source file")
    for k, c in sorted(by_file.items(), key=lambda kv: -kv[1]):
        print(f"{c / sim_s:10,.0f} {100 * c / total:6.1f} %  {k}")
    print("\nby source line (innermost)")
    for k, c in sorted(by_line.items(), key=lambda kv: -kv[1])[:40]:
        print(f"{c / sim_s:10,.0f} {100 * c / total:6.1f} %  {k}")


def hot(elf: Path, hist: np.ndarray, function: str, sim_s: float) -> None:
    """The function's instructions with their cycles per simulated second, in address order."""
    out = subprocess.run(
        ["avr-objdump", "-d", "-C", str(elf)], capture_output=True, text=True, check=True
    ).stdout
    inside = False
    for line in out.splitlines():
        if line.endswith(">:"):
            inside = f"<{function}" in line
            if inside:
                print(line)
            continue
        if inside:
            mt = re.match(r"^\s*([0-9a-f]+):", line)
            if mt:
                c = int(hist[int(mt.group(1), 16) // 2])
                print(f"{c / sim_s:10,.0f} {line}")


if __name__ == "__main__":
    raise SystemExit(main())
