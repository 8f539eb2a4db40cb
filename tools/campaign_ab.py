"""A real firmware A/B on the twin (``make campaign-ab``): the project's firmware (A) and the
same sources built with other defaults (B: ``make firmware-b``, ``FW_B_DEFS``) over the same
Latin-hypercube grasp scenarios, paired; the verdict (B's success rate minus A's with its 95 %
interval, McNemar's exact test) and the contact forces, into docs/campaigns.md.

    python -m tools.campaign_ab --a build/firmware/utrf.elf --b build/firmware/b/utrf.elf \\
        --b-defs "-DUTRF_DEFAULT_MAX_DUTY=300" --scenarios 40 --update docs/campaigns.md
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from tools.doc_sections import cpu_name, write_section
from utrf.campaign import engine, report, spec

COMMAND = "make campaign-ab"
BEGIN = "<!-- BEGIN campaign-ab (make campaign-ab) -->"
END = "<!-- END campaign-ab -->"


def campaign_text(a: Path, b: Path, scenarios: int) -> str:
    return (
        '[campaign]\nname = "firmware-ab"\nkind = "grasp"\nseed = 1\n\n'
        f'[sampler]\nmethod = "lhs"\nsamples = {scenarios}\ncross = ["firmware"]\n\n'
        '[parameters]\nfirmware = ["a", "b"]\nobject = ["ball", "box"]\n'
        "mass_kg = { min = 0.2, max = 0.9 }\nfriction = { min = 0.4, max = 1.0 }\n"
        "seed = { min = 0, max = 1000, integer = true }\nduration_s = 3.0\nhits = 1\n"
        "hit_impulse_n_s = 0.02\n\n"
        f'[firmware]\na = "{a.resolve()}"\nb = "{b.resolve()}"\n'
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--a", type=Path, required=True)
    parser.add_argument("--b", type=Path, required=True)
    parser.add_argument("--b-defs", default="", help="what B was built with (for the text)")
    parser.add_argument("--scenarios", type=int, default=40)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--update", type=Path)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="utrf-campaign-ab-") as tmp:
        path = Path(tmp) / "ab.toml"
        path.write_text(campaign_text(args.a, args.b, args.scenarios))
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        s = engine.run(spec.load(path), Path(tmp) / "out", workers=args.workers, progress=print)
        wall = time.perf_counter() - t0
        out = report.report(Path(tmp) / "out", plots=False)
        table = pq.read_table(Path(tmp) / "out" / "results.parquet").to_pylist()
    ab = out["grasp"]["ab"]
    ok = [r for r in table if r["status"] == "ok"]
    force = {
        fw: float(np.median([r["largest_contact_force_n"] for r in ok if r["firmware"] == fw]))
        for fw in ("a", "b")
    }
    lines = [
        BEGIN,
        f"`{COMMAND}` (FW_B_DEFS=`{args.b_defs}`, {args.scenarios} scenarios; "
        f"{cpu_name()}, {os.cpu_count()} cores, load average {load:.1f} at the start): "
        f"{s.ok + s.failed} runs in {wall:.0f} s, {s.failed} failed.",
        "",
        f"- A (`build/firmware/utrf.elf`, duty cap 80 %): {ab['rate_a'] * 100:.0f} % held; "
        f"B (`build/firmware/b/utrf.elf`): {ab['rate_b'] * 100:.0f} % held, over the same "
        f"{ab['scenarios']} scenarios (ball or box, 0.2-0.9 kg, friction 0.4-1.0, a 3 s hold "
        "palm down with one 0.02 N s hit).",
        f"- **Verdict: B minus A = {ab['difference'] * 100:+.1f} % held (95 % CI "
        f"{ab['ci_low'] * 100:+.1f} % to {ab['ci_high'] * 100:+.1f} %; McNemar p = "
        f"{ab['mcnemar_p']:.3g}; held by A only {ab['only_a_held']}, by B only "
        f"{ab['only_b_held']}).**",
        f"- Median largest contact force: A {force['a']:.2f} N, B {force['b']:.2f} N.",
        END,
    ]
    text = "\n".join(lines)
    print(text)
    if args.update:
        write_section(args.update, text, BEGIN, END)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
