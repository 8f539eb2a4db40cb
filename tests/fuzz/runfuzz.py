"""Run the fuzzers: each harness for a time or a number of executions, and report.

    python tests/fuzz/runfuzz.py --seconds 600            # make fuzz
    python tests/fuzz/runfuzz.py --runs 1000000           # each to a million executions
    python tests/fuzz/runfuzz.py --replay                 # the committed corpus and crashes
    python tests/fuzz/runfuzz.py --merge                  # minimise the finds into the corpus

Harnesses: ``raw`` and ``struct`` (build/fuzz/fuzz_*, libFuzzer, ASan + UBSan over the host
build of firmware/src/core) and ``python`` (fuzz_python.py, atheris). Each runs on a working
corpus in build/fuzz/corpus/<name>, seeded from the committed tests/fuzz/corpus/<name>;
what it finds goes to build/fuzz/artifacts/<name>/. A finding, once fixed, is kept in
tests/fuzz/crashes/<name>/ and replayed for ever after. The figures go to
build/fuzz/results.json (docs/reliability.md is written from it: tools/reliability_doc.py).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
BUILD = REPO / "build" / "fuzz"
HARNESSES = ("raw", "struct", "python")
FINDING_PREFIXES = ("crash-", "leak-", "timeout-", "oom-", "slow-unit-")


def command(name: str) -> list[str]:
    if name == "python":
        return [sys.executable, str(HERE / "fuzz_python.py")]
    return [str(BUILD / f"fuzz_{name}")]


def findings(name: str) -> list[Path]:
    d = BUILD / "artifacts" / name
    if not d.is_dir():
        return []
    return sorted(p for p in d.glob("*") if p.name.startswith(FINDING_PREFIXES))


def parse(output: str) -> dict:
    out: dict = {}
    for key in (
        "number_of_executed_units",
        "average_exec_per_sec",
        "new_units_added",
        "peak_rss_mb",
    ):
        mt = re.findall(rf"stat::{key}:\s+(\d+)", output)
        if mt:
            out[key] = int(mt[-1])
    cov = re.findall(r"cov: (\d+) ft: (\d+) corp: (\d+)/", output)
    if cov:
        out["coverage_edges"], out["features"], out["corpus_units"] = map(int, cov[-1])
    return out


def run(name: str, seconds: float | None, runs: int | None, log_dir: Path) -> dict:
    work = BUILD / "corpus" / name
    art = BUILD / "artifacts" / name
    work.mkdir(parents=True, exist_ok=True)
    art.mkdir(parents=True, exist_ok=True)
    before = set(findings(name))
    args = [
        *command(name),
        "-print_final_stats=1",
        "-timeout=20",
        "-rss_limit_mb=2048",
        f"-artifact_prefix={art.relative_to(REPO)}/",
    ]
    if runs:
        args.append(f"-runs={runs}")
    if seconds:
        args.append(f"-max_total_time={int(seconds)}")
    args += [str(work), str(HERE / "corpus" / name)]
    log = log_dir / f"{name}.log"
    t0 = time.monotonic()
    with log.open("w") as fh:
        proc = subprocess.run(args, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT, check=False)
    wall = time.monotonic() - t0
    text = log.read_text(errors="replace")
    new = [p for p in findings(name) if p not in before]
    res = {
        "harness": name,
        "command": " ".join(_short(a) for a in args),
        "wall_s": round(wall, 1),
        "exit_code": proc.returncode,
        "findings": [str(p.relative_to(REPO)) for p in new],
        **parse(text),
    }
    if "libFuzzer: run interrupted" in text:
        res["interrupted"] = True  # stopped by hand (SIGINT): the figures so far, no finding
    elif proc.returncode != 0 and not new:
        res["findings"].append(f"exit {proc.returncode}: see {log.relative_to(REPO)}")
    oracle = re.findall(r"(ORACLE .*|runtime error: .*|AssertionError: .*)", text)
    if oracle:
        res["finding_text"] = oracle[:3]
    return res


def _short(a: str) -> str:
    try:
        return str(Path(a).relative_to(REPO))
    except ValueError:
        return a


def replay(name: str) -> tuple[int, str]:
    """The committed corpus and every past crash, once each (the firmware harnesses with
    clang's libFuzzer build and with the g++ build, each under its sanitizers): (exit code,
    output)."""
    dirs = [HERE / "corpus" / name, HERE / "crashes" / name]
    dirs = [str(d) for d in dirs if d.is_dir() and any(d.iterdir())]
    if name == "python":
        runs = [[*command(name), "--replay", *dirs]]
    else:
        # a crash goes where a campaign's go, not into the working directory
        art = f"-artifact_prefix={(BUILD / 'artifacts' / name).relative_to(REPO)}/"
        (BUILD / "artifacts" / name).mkdir(parents=True, exist_ok=True)
        runs = [
            [*command(name), "-runs=0", art, *dirs],
            [str(BUILD / f"replay_{name}"), *dirs],
        ]
    out = ""
    for args in runs:
        proc = subprocess.run(args, cwd=REPO, capture_output=True, text=True, check=False)
        out += proc.stdout + proc.stderr
        if proc.returncode:
            return proc.returncode, out
    return 0, out


def merge(name: str) -> None:
    """Minimise: the committed corpus becomes the smallest set with the coverage of it and of
    the working corpus (libFuzzer's -merge=1 into a fresh directory)."""
    committed = HERE / "corpus" / name
    fresh = BUILD / "merge" / name
    shutil.rmtree(fresh, ignore_errors=True)
    fresh.mkdir(parents=True)
    args = [*command(name), "-merge=1", str(fresh), str(committed), str(BUILD / "corpus" / name)]
    subprocess.run(args, cwd=REPO, check=True, capture_output=True)
    for old in committed.iterdir():
        if not old.name.startswith("seed-"):
            old.unlink()
    seeds = {p.read_bytes() for p in committed.iterdir()}
    for p in fresh.iterdir():
        if p.read_bytes() not in seeds:
            shutil.copy(p, committed / p.name)
    print(f"{name}: {len(list(committed.iterdir()))} inputs in {committed.relative_to(REPO)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--runs", type=int, default=None)
    ap.add_argument("--harness", action="append", choices=HARNESSES)
    ap.add_argument("--replay", action="store_true")
    ap.add_argument("--merge", action="store_true")
    ap.add_argument("--results", type=Path, default=BUILD / "results.json")
    a = ap.parse_args(argv)
    names = a.harness or list(HARNESSES)
    if a.replay:
        bad = 0
        for n in names:
            code, out = replay(n)
            print(f"{n}: replay exit {code}")
            if code:
                print(out[-3000:])
                bad += 1
        return 1 if bad else 0
    if a.merge:
        for n in names:
            merge(n)
        return 0
    if a.seconds is None and a.runs is None:
        a.seconds = 600
    log_dir = BUILD / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    results = json.loads(a.results.read_text()) if a.results.exists() else {}
    failed = False
    for n in names:
        print(f"fuzz {n}: " + (f"{a.runs} runs" if a.runs else f"{a.seconds:.0f} s"), flush=True)
        res = run(n, a.seconds, a.runs, log_dir)
        res["cpu_load"] = os.getloadavg()[0]
        res["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        git = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=False,
        )
        res["commit"] = git.stdout.strip() or None
        print(
            f"  {res.get('number_of_executed_units', '?')} executions in {res['wall_s']} s "
            f"({res.get('average_exec_per_sec', '?')}/s), coverage {res.get('coverage_edges')} "
            f"edges / {res.get('features')} features, corpus {res.get('corpus_units')}, "
            f"findings: {res['findings'] or 'none'}"
        )
        for t in res.get("finding_text", []):
            print(f"    {t}")
        failed |= bool(res["findings"])
        results[n] = res
    a.results.parent.mkdir(parents=True, exist_ok=True)
    a.results.write_text(json.dumps(results, indent=1) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
