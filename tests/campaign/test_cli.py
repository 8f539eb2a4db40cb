"""``utrf campaign``: bad input refused before anything runs (exit 2, the line named, no
directory made); a design exported ready to flash and to simulate."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from utrf.campaign import engine, kinds, sampling, spec
from utrf.campaign.store import Store
from utrf.cli import main


def test_a_bad_file_runs_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('[campaign]\nkind = "design"\n[parameters]\nlink1_m = [0.05]\nwidth_m = 1\n')
    code = main(["campaign", "run", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and f"{path}:5:" in err and "unknown design parameter 'width_m'" in err
    assert not (tmp_path / "out").exists()


def test_bad_command_line_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["campaign", "run", "design-sweep", "--firmware", "nolabel"]) == 2
    assert "LABEL=ELF" in capsys.readouterr().err
    assert main(["campaign", "run", str(tmp_path / "none.toml")]) == 2
    assert "no such campaign file" in capsys.readouterr().err
    assert main(["campaign", "report", str(tmp_path)]) == 2


def test_the_examples_are_listed(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["campaign", "examples"]) == 0
    out = capsys.readouterr().out
    assert "design-sweep" in out and "grasp-monte-carlo" in out and "firmware-ab" in out


def test_a_design_exported_is_ready_to_flash_and_simulate(tmp_path: Path) -> None:
    import mujoco

    from tools import kinematics_table as ft
    from utrf.models.geometry import FingerGeometry

    text = (
        '[campaign]\nkind = "design"\n[sampler]\nmethod = "grid"\n[parameters]\n'
        "link1_m = [0.070, 0.080]\n"
    )
    c = spec.parse(text, "c.toml")
    store = Store(tmp_path / "c")
    store.claim(c)
    cols = sampling.columns(c)
    keys = sampling.run_keys(cols, engine.salt(c))
    store.append(kinds.table("design", {}, cols, keys))
    default = keys[np.flatnonzero(cols["link1_m"] == 0.070)[0]]
    assert main(["campaign", "export", str(tmp_path / "c"), str(default), "--out",
                 str(tmp_path / "x")]) == 0  # fmt: skip
    finger = tomllib.loads((tmp_path / "x" / "finger.toml").read_text())["finger"]
    got, ref = FingerGeometry.from_dict(finger), FingerGeometry.default()
    # a sweep's links weigh link_mass_per_m times their length (the default's mean density)
    assert replace(got, link_masses_kg=ref.link_masses_kg) == ref
    assert sum(got.link_masses_kg) == pytest.approx(sum(ref.link_masses_kg))
    # the table is the one `make generate` writes for the package's own hand
    header = (tmp_path / "x" / "kinematics_table.h").read_text()
    tables, _ = ft.build_tables(ft.HandGeometry.default())
    for t in tables:
        rows = "\n".join("    {" + ", ".join(str(int(v)) for v in r) + "}," for r in t.raw)
        assert rows in header
    mujoco.MjModel.from_xml_string((tmp_path / "x" / "hand.xml").read_text())
    assert main(["campaign", "export", str(tmp_path / "c"), "0" * 16, "--out",
                 str(tmp_path / "y")]) == 2  # fmt: skip
