"""``utrf hil analyse`` on every run the ``hil`` commands write, killed ones included: one short
run of each kind (static loading, grasp hold, grasp hold with an object), then its files as a
kill at random points would leave them (every log cut at the same point of its length, a row
cut mid-way, the files written last not yet there), each analysed through the real CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from utrf.cli import main
from utrf.hil.grasp_hold import config as gh
from utrf.hil.grasp_hold import report as grasp_report
from utrf.hil.grasp_hold import run as grasp_run
from utrf.hil.rig import EmulatedTruth, open_emulated
from utrf.hil.static_loading import config as sl
from utrf.hil.static_loading import report as static_report
from utrf.hil.static_loading import run as static_run
from utrf.models.geometry import HandGeometry

GEOM = HandGeometry.default().fingers[1].geometry

KILLS = 6  # random kill points per run kind
WRITTEN_LAST = {"results.json", "static_loading.png", "grasp_hold.png", "object_hold.png",
                "object_render.png"}  # fmt: skip
SAMPLES = {"grasp-hold": "samples.csv", "object-hold": "object_samples.csv"}


def _static(out: Path) -> None:
    config = sl.StaticLoadingConfig(
        finger=1, loads_kg=(1.0,), repeats=1, settle_s=0.5, record_s=0.3, force=True, seed=2,
        registration_theta2_rad=(-0.3, 0.2, 0.7),
    )  # fmt: skip
    truth = EmulatedTruth()
    static_run.prepare_output(out, config, resume=False, extra_meta={})
    rig = open_emulated(seed=2, tracked_finger=1, truth=truth)
    try:
        static_run.run(rig, config, out, geometry=GEOM, progress=lambda _s: None)
    finally:
        rig.close()
    static_report.write(out, GEOM)


def _grasp(out: Path) -> None:
    config = gh.GraspHoldConfig(duration_s=3.0, hits=1, seed=4, sample_hz=50.0)
    rig = open_emulated(seed=4, tracked_finger=1, truth=EmulatedTruth(actuator=None))
    try:
        grasp_run.run(rig, config, out, progress=lambda _s: None)
    finally:
        rig.close()
    grasp_report.write(out)


def _object(out: Path) -> None:  # through the command, as a user runs it
    cli = ["hil", "grasp-hold", "--emulated", "--object", "ball", "--duration-s", "3"]
    assert main([*cli, "--out", str(out), "--quiet"]) == 0


RUNS = {"static-loading": _static, "grasp-hold": _grasp, "object-hold": _object}


@pytest.fixture(scope="module", params=sorted(RUNS))
def finished(request: pytest.FixtureRequest, firmware_elf: Path, tmp_path_factory) -> tuple:
    out = tmp_path_factory.mktemp(request.param) / "run"
    RUNS[request.param](out)
    return request.param, out


def _kill_at(src: Path, dst: Path, fraction: float, rng: np.random.Generator) -> None:
    """``src`` as a kill at ``fraction`` of the run would have left it: each log cut at that
    fraction of its length (mid-row as a rule), the files written at the end absent."""
    shutil.copytree(src, dst)
    for f in dst.iterdir():
        if f.name in WRITTEN_LAST:
            f.unlink()
        elif f.suffix == ".csv":
            data = f.read_bytes()
            cut = int(len(data) * fraction) + int(rng.integers(0, 40))
            f.write_bytes(data[: min(cut, len(data))])


def _whole_rows(path: Path) -> int:
    if not path.exists():
        return 0
    return max(path.read_bytes().count(b"\n") - 1, 0)


@pytest.mark.slow
def test_analyse_works_on_a_run_killed_anywhere(finished, tmp_path: Path, capsys) -> None:
    kind, out = finished
    rng = np.random.default_rng(sorted(RUNS).index(kind))
    fractions = [0.0, 0.02, 1.0, *rng.uniform(0.0, 1.0, KILLS - 3)]
    for k, fraction in enumerate(fractions):
        run = tmp_path / f"killed{k}"
        _kill_at(out, run, fraction, rng)
        assert main(["hil", "analyse", str(run)]) == 0, (kind, fraction, capsys.readouterr())
        said = capsys.readouterr().out
        result = json.loads((run / "results.json").read_text())
        assert f"results: {run / 'results.json'}" in said
        if kind == "static-loading":
            assert result["steps_completed"] <= _whole_rows(run / "steps.csv")
            assert result["complete"] is (result["steps_completed"] == 2)
            assert ("INCOMPLETE" in said) is (not result["complete"])
        else:  # every whole row analysed, the cut one left out
            assert result["samples"] == _whole_rows(run / SAMPLES[kind]), (kind, fraction)
            if fraction < 0.9 and result["samples"]:
                assert not result["complete"]
            if kind == "object-hold":  # displacement, slip, forces: drawn when there are samples
                assert (result["figure"] is not None) is (result["samples"] > 0)
                assert result["figure"] is None or Path(result["figure"]).stat().st_size > 0
        if fraction == 1.0:  # nothing cut: the run's own results
            before = json.loads((out / "results.json").read_text().replace(str(out), str(run)))
            before.pop("render", None), result.pop("render", None)  # written mid-run: removed
            assert result == before


def test_analyse_names_what_it_cannot_read(tmp_path: Path, capsys) -> None:
    assert main(["hil", "analyse", str(tmp_path)]) == 2
    assert "holds no run (no meta.json)" in capsys.readouterr().err
    (tmp_path / "meta.json").write_text('{"config": {"speed": 1}}')
    assert main(["hil", "analyse", str(tmp_path)]) == 2
    assert "of no known run (fields ['speed'])" in capsys.readouterr().err
    (tmp_path / "meta.json").write_text('{"config": ')  # cut by a kill: not a run's meta
    assert main(["hil", "analyse", str(tmp_path)]) == 2
    assert "meta.json" in capsys.readouterr().err
