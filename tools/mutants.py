"""The mutation check (issue 13 §4): each safety rule of the firmware disabled in turn, and the
safety tests run against it; a test must fail for every mutant.

    python tools/mutants.py                  # make mutants: every mutant
    python tools/mutants.py --only stall     # some of them
    python tools/mutants.py --list

Each mutant is a copy of the checkout (its sources, tests and build products, timestamps
kept, so make rebuilds only what the mutation touched) under build/mutants/<name>/, with one
exact edit to firmware/src: a rule's condition made false, its action removed (each rule has
one home; a rule with a fast path beside its general one has a mutant for each). The tests
run there, on the mutated firmware, both as the host build (tests/firmware/test_fw_safety.py,
test_fw_moves.py and test_fw_limits_rule.py) and as the ELF on the emulated board
(tests/reliability/test_safety_matrix.py), and stop at the first failure: the mutant is
caught. An edit whose text is no longer in the source is an error (the list must follow the
code). The score goes to
build/reliability/mutants.json for docs/reliability.md.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
WORK = REPO / "build" / "mutants"
TESTS = [
    "tests/firmware/test_fw_safety.py",
    "tests/firmware/test_fw_moves.py",
    "tests/firmware/test_fw_limits_rule.py",
    "tests/reliability/test_safety_matrix.py",
]
COPY = ["Makefile", "pyproject.toml", "firmware", "protocol", "tests", "tools", "host"]
COPY_BUILD = ["firmware", "emulator"]


@dataclass(frozen=True)
class Edit:
    path: str
    old: str
    new: str


@dataclass(frozen=True)
class Mutant:
    name: str
    rule: str  # the safety table's row (firmware/README.md)
    path: str
    old: str
    new: str
    # further edits of the same mutant: a rule whose condition the code states in more than
    # one place is off only with every copy of it off
    more: tuple[Edit, ...] = ()

    @property
    def edits(self) -> tuple[Edit, ...]:
        return (Edit(self.path, self.old, self.new), *self.more)


MUTANTS = [
    Mutant(
        "host-silence-off",
        "host silence",
        "firmware/src/core/hand.h",
        "} else if (UTRF_UNLIKELY(silence_left_ != 0 && --silence_left_ == 0)) {",
        "} else if (false) {",
    ),
    Mutant(
        "host-silence-always-hold",
        "host silence (safe action COAST)",
        "firmware/src/core/hand.cpp",
        "const bool hold = safe_action_ == 0;",
        "const bool hold = true;",
    ),
    # The encoder's rules each have one home: the band (the driver's valid band, as5600_reading)
    # and the limits in encoder::judge(), which the sampler runs on each sample and the tick
    # again on a reading judged with an earlier setup (Finger::judge_reading(), the only place
    # ENCODER_RANGE and JOINT_LIMIT are latched); the jump in Finger::take_angle(), which both
    # of the tick's paths call. So a rule has two mutants: its judgment off, and its latch off.
    Mutant(
        "encoder-band-off",
        "encoder band (and a stale ADC round): the latch",
        "firmware/src/core/finger.cpp",
        "        encoder_ok_ = false;\n        return ENCODER_RANGE;",
        "        encoder_ok_ = false;\n        return 0;",
    ),
    Mutant(
        "encoder-band-sampler-off",
        "encoder band (the driver's judgment)",
        "firmware/src/core/encoder.h",
        "    r.status = (sample < kAdcBandLow || sample > kAdcBandHigh) ? "
        "hal::EncoderStatus::OUT_OF_BAND\n"
        "                                                               : "
        "hal::EncoderStatus::OK;",
        "    r.status = hal::EncoderStatus::OK;",
    ),
    Mutant(
        "encoder-jump-off",
        "encoder jump (Finger::take_angle, both tick paths)",
        "firmware/src/core/finger.h",
        "        found = ENCODER_JUMP;",
        "        ;",
    ),
    Mutant(
        "joint-limit-off",
        "joint limit: the latch",
        "firmware/src/core/finger.cpp",
        "return (r.flags & hal::kReadingLimit) ? (uint8_t)(found | JOINT_LIMIT) : found;",
        "return found;",
    ),
    Mutant(
        "joint-limit-sampler-off",
        "joint limit (encoder::judge)",
        "firmware/src/core/encoder.h",
        "r.flags = (r.angle < s.low || r.angle > s.high) ? hal::kReadingLimit : 0;",
        "r.flags = 0;",
    ),
    Mutant(
        "stall-off",
        "stall",
        "firmware/src/core/finger.cpp",
        "latch(STALL);  // COAST; the motors go off with the caller's motor_off()\n"
        "                duty_a_ = duty_b_ = 0;\n                return true;",
        "contact_ = true;",
    ),
    Mutant(
        "overrun-off",
        "overrun",
        "firmware/src/core/hand.h",
        "        overrun_pending_ = true;",
        "",
    ),
    Mutant(
        "loop-alive-off",
        "loop alive",
        "firmware/src/core/hand.h",
        "    } else if (!halted_) {\n        halt();",
        "    } else if (false) {\n        halt();",
    ),
    Mutant(
        "tick-alive-off",
        "tick alive",
        "firmware/src/core/app.cpp",
        "if (ms - tick_ms > kTickDeadMs) {",
        "if (false) {",
    ),
    Mutant(
        "watchdog-fed-while-halted",
        "loop alive (the watchdog resets the board)",
        "firmware/src/core/app.cpp",
        "if (!b.hand.halted()) hal::watchdog_feed();",
        "hal::watchdog_feed();",
    ),
    Mutant(
        "stop-fault-keeps-mode",
        "every stop fault: motors off",
        "firmware/src/core/finger.cpp",
        "if ((bits & kStopFaults) && mode_ != COAST) {",
        "if (false) {",
    ),
    Mutant(
        "faulted-not-refused",
        "a latched fault refuses POSITION, DUTY and GRASP",
        "firmware/src/core/dispatch.cpp",
        "if (drives && (fg.faults() != 0 || !fg.has_theta())) refused = f;",
        "if (drives && !fg.has_theta()) refused = f;",
    ),
    Mutant(
        "brake-stby-with-stop-fault",
        "STBY low with a stop fault (BRAKE)",
        "firmware/src/core/finger.cpp",
        "mode == BRAKE && (faults_ & (kStopFaults & ~JOINT_LIMIT)) == 0);",
        "mode == BRAKE);",
    ),
    # The target range rule's one home (finger::Params::accepts(): move, and set_targets'
    # kinds other than JOINT2_ANGLE) and its fast path (set_targets' micro-radian window)
    Mutant(
        "target-range-off",
        "joint limit (targets and a move's end outside the limits refused)",
        "firmware/src/core/finger.h",
        "return bu >= (int32_t)theta_min - 1 && bu <= (int32_t)theta_max + 1;",
        "return true;",
    ),
    Mutant(
        "target-window-off",
        "joint limit (set_targets' JOINT2_ANGLE window, the fast path)",
        "firmware/src/core/dispatch.cpp",
        "if ((m.mask & bit) && (m.value[f] < b.urad_lo[f] || m.value[f] > b.urad_hi[f])) {",
        "if ((m.mask & bit) && false) {",
    ),
    Mutant(
        "limits-keep-path",
        "joint limit (new limits end a path that would leave them)",
        "firmware/src/core/finger.cpp",
        "    if (end_path) path_.stop();\n",
        "",
    ),
    Mutant(
        "duty-past-limit",
        "joint limit (DUTY never drives further past a limit)",
        "firmware/src/core/finger.cpp",
        "if ((th >= params_.theta_max && d > 0) || (th <= params_.theta_min && d < 0)) d = 0;",
        ";",
    ),
    Mutant(
        "eeprom-crc-off",
        "EEPROM image checks at boot (CRC)",
        "firmware/src/core/config.cpp",
        "if (crc != stored || !valid(out)) st = LoadStatus::DEFAULTS_CORRUPT;",
        "if (!valid(out)) st = LoadStatus::DEFAULTS_CORRUPT;",
    ),
    Mutant(
        "eeprom-range-off",
        "EEPROM image checks at boot (ranges)",
        "firmware/src/core/config.cpp",
        "if (crc != stored || !valid(out)) st = LoadStatus::DEFAULTS_CORRUPT;",
        "if (crc != stored) st = LoadStatus::DEFAULTS_CORRUPT;",
    ),
]


def prepare(m: Mutant | None) -> Path:
    """A copy of the checkout under build/mutants/ with ``m``'s edit (None: the baseline)."""
    root = WORK / (m.name if m else "baseline")
    shutil.rmtree(root, ignore_errors=True)
    root.mkdir(parents=True)
    for name in COPY:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, root / name, symlinks=True)
        else:
            shutil.copy2(src, root / name)
    for name in COPY_BUILD:
        src = REPO / "build" / name
        if src.is_dir():
            shutil.copytree(src, root / "build" / name, symlinks=True)
    # This checkout's environment, not a set-up of the copy's own: a new .venv and its pip
    # install took minutes a mutant (the tests' `make` runs the set-up too).
    (root / ".venv").symlink_to(REPO / ".venv")
    if m is None:
        return root
    for e in m.edits:
        path = root / e.path
        text = path.read_text()
        if text.count(e.old) != 1:
            raise SystemExit(
                f"mutant {m.name}: {e.path} has {text.count(e.old)} copies of the text to "
                "change (the mutant list must follow the code)"
            )
        path.write_text(text.replace(e.old, e.new))
    return root


def _pytest(root: Path, timeout: float, args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args, *TESTS],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


BUILT = ("firmware", "firmware-host", "emulator")


def _build(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["make", "-s", "--no-print-directory", "SETUP_DONE=1", *BUILT],
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
    )


def _failed(out: str) -> list[str]:
    return [ln.split(" ")[1] for ln in out.splitlines() if ln.startswith("FAILED ")]


def baseline(timeout: float) -> list[str]:
    """The tests that fail without any mutation (none, when the tree is sound): a mutant is
    only counted caught by a test that passes on the unmutated firmware."""
    root = prepare(None)
    build = _build(root)
    if build.returncode:
        raise SystemExit(f"the unmutated copy does not build:\n{build.stdout}{build.stderr}")
    proc = _pytest(root, timeout, [])
    shutil.rmtree(root, ignore_errors=True)
    return _failed(proc.stdout + proc.stderr)


def run(m: Mutant, timeout: float, broken: list[str]) -> dict:
    root = prepare(m)
    t0 = time.monotonic()
    build = _build(root)
    if build.returncode:
        return {
            "name": m.name,
            "rule": m.rule,
            "caught": False,
            "by": "build failed",
            "detail": (build.stdout + build.stderr)[-2000:],
        }
    deselect = [a for t in broken for a in ("--deselect", t)]
    try:
        proc = _pytest(root, timeout, ["-x", *deselect])
        out = proc.stdout + proc.stderr
        caught = proc.returncode == 1
        failed = _failed(out)
        by = failed[0] if failed else ("no test failed" if proc.returncode == 0 else out[-500:])
    except subprocess.TimeoutExpired:
        caught, by = True, f"the tests hung (> {timeout:.0f} s)"
    res = {
        "name": m.name,
        "rule": m.rule,
        "file": ", ".join(dict.fromkeys(e.path for e in m.edits)),
        "caught": caught,
        "by": by,
        "seconds": round(time.monotonic() - t0, 1),
    }
    shutil.rmtree(root, ignore_errors=True)
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", help="a mutant's name (repeatable)")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--json", type=Path, default=REPO / "build" / "reliability" / "mutants.json")
    a = ap.parse_args(argv)
    chosen = [m for m in MUTANTS if not a.only or m.name in a.only]
    if a.list:
        for m in chosen:
            print(f"{m.name:28} {m.rule}  ({', '.join(e.path for e in m.edits)})")
        return 0
    broken = baseline(a.timeout)
    if broken:
        print(f"failing without any mutation (not counted): {broken}", flush=True)
    results = []
    for m in chosen:
        res = run(m, a.timeout, broken)
        results.append(res)
        mark = "caught" if res["caught"] else "SURVIVED"
        print(f"{m.name:28} {mark:8} by {res['by']}  ({res.get('seconds', '?')} s)", flush=True)
    if a.only and a.json.exists():
        # a partial run updates those mutants' rows of the last full one
        done = {r["name"] for r in results}
        earlier = json.loads(a.json.read_text())["mutants"]
        results = [r for r in earlier if r["name"] not in done] + results
        order = [m.name for m in MUTANTS]
        results.sort(key=lambda r: order.index(r["name"]) if r["name"] in order else len(order))
    caught = sum(r["caught"] for r in results)
    print(f"mutation score: {caught} of {len(results)} rule mutants caught")
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(
        json.dumps(
            {
                "caught": caught,
                "total": len(results),
                "tests": TESTS,
                "mutants": results,
                "failing_without_mutation": broken,
                "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            },
            indent=1,
        )
        + "\n"
    )
    return 0 if caught == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
