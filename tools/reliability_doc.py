"""docs/reliability.md from the reliability runs' results, a section each (tools.doc_sections):

- fuzzing:      build/fuzz/results.json          (make fuzz, tests/fuzz/runfuzz.py)
- noisy line:   build/reliability/noise.json     (tests/reliability/test_noise.py)
- safety:       build/reliability/safety.json    (tests/reliability/test_safety_matrix.py)
- mutation:     build/reliability/mutants.json   (make mutants, tools/mutants.py)
- soak:         build/reliability/soak.json      (make soak, tools/soak.py)

A section whose results are missing is left as it stands.

    python -m tools.reliability_doc [--only fuzz|noise|safety|mutants|soak]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tools.doc_sections import cpu_name, write_section

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "reliability.md"
RESULTS = REPO / "build" / "reliability"
HEADER = """# Reliability

What the project proves about itself, each figure from a run that `make` repeats (issue 13):
fuzzing of the firmware core and the host's protocol code, a noisy serial line, every safety
rule end to end on the emulated board, a mutation check of those rules, and a soak. Each
section is written by its run (tools/reliability_doc.py); the command is given with it.
"""


def _load(path: Path) -> Any:
    """The results at ``path``; for the fuzzers, also each harness's own file of a run made
    per harness (``runfuzz.py --harness raw --results build/fuzz/results-raw.json``)."""
    res = json.loads(path.read_text()) if path.exists() else None
    if path.name == "results.json":
        for extra in sorted(path.parent.glob("results-*.json")):
            res = {**(res or {}), **json.loads(extra.read_text())}
    return res


def _markers(name: str, command: str) -> tuple[str, str]:
    return f"<!-- BEGIN {name} ({command}) -->", f"<!-- END {name} -->"


def _budget_note(r: dict) -> str:
    """' (its time budget, N s)' for a run that stopped at -max_total_time before its -runs."""
    budget = re.search(r"-max_total_time=(\d+)", r.get("command", ""))
    runs = re.search(r"-runs=(\d+)", r.get("command", ""))
    done = r.get("number_of_executed_units", 0)
    if budget and (not runs or done < int(runs.group(1))):
        return f" (its time budget, {int(budget.group(1)):,} s)"
    return ""


def _doc_rows(doc: Path, section: str) -> dict[str, str]:
    """The table rows, by their first cell, of ``section`` as the doc has it now."""
    if not doc.exists():
        return {}
    begin, end = _markers(section, SECTIONS[section][1])
    text = doc.read_text()
    if begin not in text or end not in text:
        return {}
    body = text[text.index(begin) : text.index(end)]
    return {ln.split("|")[1].strip(): ln for ln in body.splitlines() if ln.startswith("| ")}


def fuzz_section(res: dict, doc: Path = DOC) -> str:
    rows = []
    earlier = _doc_rows(doc, "fuzz")
    kept = []
    for name in ("raw", "struct", "python"):
        r = res.get(name)
        if r is None:
            # not run this time: its row from the last run that was (a run per harness)
            if name in earlier:
                rows.append(earlier[name])
                kept.append(name)
            continue
        rows.append(
            f"| {name} | {r.get('number_of_executed_units', 0):,}"
            f"{' (stopped by hand)' if r.get('interrupted') else _budget_note(r)} | "
            f"{r.get('average_exec_per_sec', '?')} | {r.get('coverage_edges', '?')} / "
            f"{r.get('features', '?')} | {r.get('corpus_units', '?')} | "
            f"{', '.join(r['findings']) or 'none'} | `{r['command']}` | {r.get('date', '')}"
            f"{', ' + r['commit'] if r.get('commit') else ''} | "
            f"{'?' if r.get('cpu_load') is None else format(r['cpu_load'], '.1f')} |"
        )
    return "\n".join(
        [
            "## Fuzzing",
            "",
            "`make fuzz` (each harness `FUZZ_SECONDS`, default 600; `FUZZ_RUNS=1000000` for a "
            "count) runs `tests/fuzz/runfuzz.py`; `make test` replays the committed corpus "
            "and every past crash and runs each harness for 20 s (tests/fuzz/test_fuzz.py).",
            "",
            "- **raw**: raw bytes into the board's UART receive path (decoder, dispatch, the "
            "application) with ticks and loop() passes interleaved, every finger in closed "
            "loop and the stream at its highest rate.",
            "- **struct**: scripts of requests in valid frames with ticks, ADC values, a "
            "stopped sampler, EEPROM busy and stuck cells, power cycles, hung loop() and tick, "
            "overruns, flipped frames and raw bytes.",
            "- **python**: the host's frame decoder, every message decoder and the client "
            "engine (atheris).",
            "",
            "The firmware harnesses run the host build of firmware/src/core (the host HAL of "
            "firmware/test) under ASan and UBSan (no recovery: UB is a crash) with the oracles "
            "as assertions after every tick and loop() pass: no motor driven (and STBY low) "
            "with a stop fault latched or a halted hand; PWM counts within the period and "
            "max_duty, duties within max_duty; closed-loop targets within the joint limits; "
            "the running configuration within the spec's ranges after any request; every byte "
            "the board sends decodes as a whole frame of a board message with its exact size; "
            "(struct) every request gets exactly one reply, with its seq, of its kind; a "
            "finished save_config reloads byte for byte.",
            "",
            "Clang treats a left shift of a negative value as defined in every C++ mode "
            "(P1236 taken as a defect report), so its UBSan does not report the one issue 13 "
            "found in pid.h; g++'s does (the host build the tests run, `-fsanitize=undefined`).",
            "",
            "| harness | executions | exec/s | coverage (edges / features) | corpus | findings "
            "| command | date, commit | load average |",
            "|---|---|---|---|---|---|---|---|---|",
            *rows,
            "",
            "Each row: `python tests/fuzz/runfuzz.py --runs 1000000 --harness NAME` (what "
            "`make fuzz FUZZ_RUNS=1000000` runs for all three), under `nice -n 10`, on "
            f"{cpu_name()} with 2 cores shared with the other sessions' builds and tests: "
            "exec/s is wall-clock under the load average shown (taken at the run's end). "
            "A run stopped by hand, or at a time budget (`--seconds` with `--runs`: "
            "`-max_total_time` in its command), shows the executions it reached."
            + (
                f" The row of {', '.join(kept)} was not run again this time: kept from the "
                "last write of this section, with that run's date, machine and load."
                if kept
                else ""
            ),
            "",
            "The python harness's cost per execution is the instrumented protocol code itself "
            "(measured in-process over the working corpus: libFuzzer's own share about 2 %; "
            "atheris's instrumentation of `utrf.protocol`, and only of it, makes that code "
            "about 3x slower; each input is decoded whole, and libFuzzer lets the inputs grow "
            "to 4,096 bytes within the hour: the 1e6 run began at about 1,700/s). The harness "
            "decodes each input twice (the reference, and the "
            "engine's own decoder in chunks, recording its events for the chunking oracle), "
            "not four times: 1.7x the executions a second of the first version on the same "
            "corpus (2,000/s against 1,176/s, load average 2).",
        ]
    )


def noise_section(res: dict) -> str:
    rows = []
    for key in sorted((k for k in res if k != "host_timeout"), key=float):
        r = res[key]
        rows.append(
            f"| {float(key):g} | {r['commands']} | {r['wrong_applied']} | {r['silent_losses']} "
            f"| {r['errors']} ({', '.join(f'{k} {v}' for k, v in r['error_kinds'].items()) or '-'}"
            f") | {r['errors_applied']} | {r['resends']} | {r['p50_ms']:.1f} | {r['p99_ms']:.1f} "
            f"| {r['max_ms']:.1f} | {r['host_timeouts']} ({r.get('held_targets', 0)}) | "
            f"{'yes' if r['recovered'] else 'NO'} |"
        )
    ht = res.get("host_timeout")
    ht_text = []
    if ht:
        big = res.get("0.01", {})
        seen = ht["host_timeouts"] + big.get("host_timeouts", 0)
        ht_text = [
            "",
            "**HOST_TIMEOUT on a noisy line.** The board latches it when no *valid* frame "
            "arrives for `heartbeat_timeout` (0.5 s). The Hand sends a heartbeat whenever, for "
            "100 ms, the board has answered no frame of its and no heartbeat went out (measured "
            f"longest gap between the Hand's frames {ht['longest_tx_gap_s'] * 1e3:.0f} ms); a "
            "request being resent does not put the heartbeat off. Until 2026-11-27 it counted "
            "from the last frame *sent*: a request's 20-40-byte attempts, resent at 1e-2 and "
            "each lost far more often than a 6-byte heartbeat, held the heartbeats back, and "
            "the 1,000-command run met HOST_TIMEOUT 3 times in 104 s (each time HOLD, cleared "
            "by the Hand, no command failed). At 1e-2 the board took "
            f"{ht['board_rx_frames']} of the Hand's {ht['tx_frames']} frames whole "
            f"({ht['frame_loss'] * 100:.0f} % lost), so a window of "
            f"{ht['frames_per_timeout']} frames is all lost with p ~ "
            f"{ht['p_all_lost_per_window']:.0e}. "
            f"In driven mode it happened {ht['host_timeouts']} time(s) in "
            f"{ht['commands']} commands ({ht['campaign_seconds']:.0f} s, seed {ht['seed']})"
            + (
                f" and {big['host_timeouts']} times in the 1,000-command run "
                f"({big['sim_seconds']:.0f} s of noisy line)"
                if big
                else ""
            )
            + (
                ": each time the board applied HOLD (the fingers held where they were, the "
                "targets above counted as HOLD's), the Hand saw the fault and cleared it, and no "
                "command failed."
                if seen
                else "."
            )
            + " The mechanism alone, deterministic in the same test: with every "
            "byte to the board dropped, the Hand's heartbeats keep flowing and every driving "
            "finger latches HOST_TIMEOUT after 0.5 s: the rule acts when the line does lose a "
            "whole window.",
        ]
    return "\n".join(
        [
            "## Noisy line",
            "",
            "`pytest tests/reliability/test_noise.py` (in `make test`): the Hand drives the "
            "emulated board in simulated time through the emulator's seeded line faults, "
            "both directions, the rate per byte split evenly between dropped, bit-flipped, "
            "inserted and duplicated bytes, and bursts of 8-32 random bytes starting at "
            "rate / 100 per byte. Commands in turn: "
            "set_targets (fingers 0-3), set_mode (little finger, BRAKE/COAST), set_gains "
            "(little finger, a new kp each). Wrong applied: a value the board shows that was "
            "never sent; silent loss: a command returned but the board does not show it; "
            "errors: raised to the user (of which applied after all). Latency in simulated "
            "time, exact to the 250 µs exchange.",
            "",
            "| rate/byte | commands | wrong applied | silent losses | errors | of which "
            "applied | resends | p50 ms | p99 ms | max ms | HOST_TIMEOUT (HOLD targets seen) "
            "| recovered |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
            *rows,
            *ht_text,
        ]
    )


def safety_section(res: dict) -> str:
    rows = []
    for rule, r in res.items():
        if "measured_ms" in r:
            ok = "yes" if r["measured_ms"] <= r["bound_ms"] else "NO"
            rows.append(
                f"| {rule} | {r['measured_ms']:.2f} | {r['bound_ms']:.2f} | {ok} | "
                f"{r.get('note', '')} |"
            )
        else:
            rows.append(f"| {rule} | at boot: {r['status']} | - | yes | |")
    return "\n".join(
        [
            "## Safety rules end to end",
            "",
            "`pytest tests/reliability/test_safety_matrix.py` (in `make test`): each row of "
            "firmware/README.md's safety table caused on the emulated board (real firmware, "
            "simavr, driven), the time from the cause to the safe action measured on the "
            "driver pins (host silence: from the fault report's board time) in simulated time "
            "(to the 250 µs exchange), against the bound the README documents.",
            "",
            "| rule | measured ms | bound ms | within | note |",
            "|---|---|---|---|---|",
            *rows,
        ]
    )


def mutants_section(res: dict) -> str:
    rows = [
        f"| {m['name']} | {m['rule']} | {'caught' if m['caught'] else '**survived**'} | {m['by']} |"
        for m in res["mutants"]
    ]
    return "\n".join(
        [
            "## Mutation check",
            "",
            f"`make mutants` (tools/mutants.py, {res.get('date', '')}): each safety rule "
            "disabled in turn by one edit of firmware/src at its one home (a fast path beside "
            "its general one has a mutant of its own) in a copy of the checkout, then "
            f"{', '.join(res['tests'])} on it (host build and ELF on the emulated board). "
            f"**Score: {res['caught']} of {res['total']} rule mutants caught.**",
            "",
            "| mutant | rule | result | first failing test |",
            "|---|---|---|---|",
            *rows,
        ]
    )


def soak_section(res: dict) -> str:
    rss = res["rss_mib"]
    rss_rows = [
        f"| {n} | {d.get('start', 0):.1f} | {d.get('after_warmup', 0):.1f} | "
        f"{d.get('end', 0):.1f} | {d.get('peak', 0):.1f} | {res['rss_growth_mib'].get(n, 0):+.1f} |"
        for n, d in rss.items()
    ]
    latched: dict[str, int] = {}
    for f in res["faults_latched"]:
        latched[f["faults"]] = latched.get(f["faults"], 0) + 1
    injected: dict[str, int] = {}
    for f in res["faults_injected"]:
        injected[f["kind"]] = injected.get(f["kind"], 0) + 1
    causes = res.get("lost_by_cause", {})
    nice = res.get("nice", "?")
    worst = res.get("board_tick_worst_s")
    twin = res.get("driven")
    return "\n".join(
        [
            "## Soak",
            "",
            f"`make soak SOAK_SECONDS={res['seconds']:.0f}` (tools/soak.py, {res['date']}"
            f"{', ' + res['commit'] if res.get('commit') else ''}): `utrf emulate` served at "
            "real time in its own process, a Hand over TCP in another, both at nice "
            f"{nice}; telemetry at {res['telemetry_hz']} Hz, set_targets at "
            f"{res['command_hz']} Hz, a fault injected every {res['seconds'] / 12:.0f} s in "
            f"turn. Counted after a warm-up of {res.get('counted_after_s', 0):.0f} s. "
            f"Result: **{'passed' if res['passed'] else 'FAILED'}**"
            + (f" ({'; '.join(res['problems'])})" if res["problems"] else "")
            + ".",
            "",
            "| what | figure |",
            "|---|---|",
            f"| wall-clock duration | {res['elapsed_s']:.0f} s |",
            f"| commands sent / late (> 10 ms) / failed | {res['commands_sent']:,} / "
            f"{res['commands_late']:,} / {res['commands_failed']} |",
            f"| state frames received | {res['stream_frames']:,} |",
            f"| **frames lost** (seq gaps) | **{res['stream_lost']}** |",
            f"| of which dropped by the firmware (its tx_dropped) / lost between its UART and "
            f"the Hand | {res['board_tx_dropped']} / {res.get('host_side_lost', '?')} |",
            "| frames lost, by what happened then (that second or the two before) | "
            + (", ".join(f"{k} {v}" for k, v in causes.items()) or "-")
            + " |",
            f"| host receive errors (CRC, framing, oversize) | {res.get('host_rx_errors', '?')} |",
            f"| link resends / timeouts; resends the board answered from its cache | "
            f"{res['link_retries']} / {res['link_timeouts']}; {res.get('board_rx_repeats', '?')} |",
            f"| emulated board: real-time factor / could run at / lag events (> 100 ms behind) "
            f"/ seconds below 0.95 real time | {res['realtime_factor']} / "
            f"{res.get('capacity', '?')} / {res['lag_events']} / "
            f"{res.get('seconds_lagging', '?')} of {res.get('seconds_counted', '?')} |",
            f"| board tick worst / tick overruns / receive overruns | "
            f"{'?' if worst is None else f'{worst * 1e6:.0f} µs'} / "
            f"{res['board_tick_overruns']} / {res['board_rx_overruns']} |",
            f"| faults injected | {', '.join(f'{k} {v}' for k, v in injected.items())} |",
            *(
                [
                    f"| the driven twin ({twin['sim_seconds']:.0f} s simulated, "
                    f"{len(twin['faults_injected'])} faults): frames lost / dropped by the "
                    f"firmware | {twin['stream_lost']} / {twin['board_tx_dropped']} |"
                ]
                if twin
                else []
            ),
            f"| faults latched | {', '.join(f'{k} {v}' for k, v in latched.items()) or 'none'} "
            f"(unexpected: {len(res['faults_unexpected'])}) |",
            "",
            "| process | RSS start MiB | after warm-up | end | peak | growth |",
            "|---|---|---|---|---|---|",
            *rss_rows,
            "",
            f"Load average at the end: {', '.join(f'{x:.1f}' for x in res['load_average'])} "
            f"on {cpu_name()}, 2 cores shared with the other sessions. Every frame lost counts "
            "against the soak whatever its cause; the causes row lays each beside what the "
            "timeline saw in that second or the two before (build/reliability/soak.json keeps "
            "the timeline): a fault injected and the recovery after it (clear_faults, then "
            "set_targets, which puts the fingers back in POSITION with get_state and set_mode: "
            "round trips back to back), a resend, the emulated board lagging the wall clock "
            "(the host's requests then reach it bunched in simulated time), or nothing. The "
            "driven twin runs the same wave, faults and recovery on a driven board in simulated "
            "time, deterministic and "
            "free of the machine's load: what it loses, the firmware loses under this load.",
        ]
    )


SECTIONS: dict[str, tuple[Path, str, Callable[[dict], str]]] = {
    "fuzz": (REPO / "build" / "fuzz" / "results.json", "make fuzz", fuzz_section),
    "noise": (RESULTS / "noise.json", "tests/reliability/test_noise.py", noise_section),
    "safety": (RESULTS / "safety.json", "tests/reliability/test_safety_matrix.py", safety_section),
    "mutants": (RESULTS / "mutants.json", "make mutants", mutants_section),
    "soak": (RESULTS / "soak.json", "make soak", soak_section),
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", choices=list(SECTIONS))
    ap.add_argument("--doc", type=Path, default=DOC)
    a = ap.parse_args(argv)
    if not a.doc.exists():
        a.doc.write_text(HEADER)
    for name in a.only or list(SECTIONS):
        path, command, render = SECTIONS[name]
        res = _load(path)
        if res is None:
            print(f"{name}: no results ({path.relative_to(REPO)}); section left as it is")
            continue
        begin, end = _markers(name, command)
        body = fuzz_section(res, a.doc) if name == "fuzz" else render(res)
        write_section(a.doc, f"{begin}\n{body}\n{end}", begin, end)
        print(f"{name}: written to {a.doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
