"""A real firmware A/B: the project's ELF and the same sources built with a 30 % duty cap
(``make firmware-b``, in make test's dependencies) over the same grasp scenarios on the twin;
paired by scenario, with the verdict and its interval from the rows."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest

from utrf.campaign import engine, report, spec

B_ELF = Path("build/firmware/b/utrf.elf")


@pytest.mark.slow
def test_two_firmwares_over_the_same_scenarios(tmp_path: Path) -> None:
    from utrf.artifacts import firmware_elf

    assert B_ELF.is_file(), "build the second firmware: make firmware-b"
    path = tmp_path / "ab.toml"
    path.write_text(
        '[campaign]\nkind = "grasp"\n[sampler]\nmethod = "grid"\ncross = ["firmware"]\n'
        '[parameters]\nfirmware = ["a", "b"]\nobject = ["ball", "box"]\nmass_kg = 0.3\n'
        f'duration_s = 2.0\nhits = 0\n[firmware]\na = "{firmware_elf().resolve()}"\n'
        f'b = "{B_ELF.resolve()}"\n'
    )
    s = engine.run(spec.load(path), tmp_path / "o", workers=2, progress=lambda _: None)
    assert s.ok == 4 and s.failed == 0
    rows = pq.read_table(tmp_path / "o" / "results.parquet").to_pylist()
    by = {(r["firmware"], r["object"]): r for r in rows}
    assert by[("a", "ball")]["firmware_sha256"] != by[("b", "ball")]["firmware_sha256"]
    for obj in ("ball", "box"):  # the same scenario; B's lower duty cap grips less hard
        a, b = by[("a", obj)], by[("b", obj)]
        assert b["largest_contact_force_n"] < a["largest_contact_force_n"]
    ab = report.report(tmp_path / "o", plots=False)["grasp"]["ab"]
    held = {k: bool(r["held"]) and not r["broke"] for k, r in by.items()}
    rate = {fw: (held[(fw, "ball")] + held[(fw, "box")]) / 2 for fw in ("a", "b")}
    assert ab["scenarios"] == 2 and ab["difference"] == pytest.approx(rate["b"] - rate["a"])
    assert ab["ci_low"] <= ab["difference"] <= ab["ci_high"]
