"""The grasp hold with a real object on the MuJoCo hand (``utrf hil grasp-hold --emulated
--object``): a grasp that holds, one that drops (too little effort), and the analysis of the
logs (slip, hits, contact forces, breakage)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from utrf.datalog import CsvLog
from utrf.hil import object_hold as oh
from utrf.models import objects


@pytest.mark.parametrize("name", ["ball", "egg"])
def test_the_object_grasp_holds_it_through_a_tap(
    name: str, firmware_elf: Path, tmp_path: Path
) -> None:
    """The object's own grasp (objects.toml: pose, effort, rest position) closes on it by
    contact and holds it palm down through a hammer tap; the egg stays intact."""
    config = oh.ObjectHoldConfig(object=name, duration_s=3.0, hits=1, picture=False)
    result = oh.run(config, tmp_path / "run", elf=firmware_elf, progress=lambda s: None)
    assert not result["dropped"], oh.describe(result)
    assert result["slip_mm"] < 5.0
    # the fingers on it: the egg's own grasp (grasp-egg) holds it with index, middle and ring
    forces = result["closed_contact_forces_n"]
    on_it = [n for n, f in zip(oh.FINGERS, forces, strict=True) if f > 1.0]
    assert len(on_it) >= 2 if name == "ball" else on_it == ["index", "middle", "ring"]
    assert result["pose"] == objects.get_object(name).grasp_pose
    assert result["largest_contact_force_n"]["thumb"] == 0.0  # the thumb stays open
    assert len(result["hits"]) == 1
    assert result["broke"] is (False if name == "egg" else None)
    saved = json.loads((tmp_path / "run" / "results.json").read_text())
    assert saved["slip_mm"] == pytest.approx(result["slip_mm"])
    rows = oh._read(tmp_path / "run" / "object_samples.csv", oh.SAMPLE_COLUMNS)
    assert {"close", "release", "turn", "baseline", "hold"} <= set(rows["phase"])


def test_too_little_effort_drops_the_ball(firmware_elf: Path, tmp_path: Path) -> None:
    """At 5 % duty the fingers never reach the ball: turned over, it falls, reported so."""
    config = oh.ObjectHoldConfig(object="ball", effort=0.05, duration_s=3.0, hits=0, picture=False)
    result = oh.run(config, tmp_path / "run", elf=firmware_elf, progress=lambda s: None)
    assert result["dropped"]
    assert result["dropped_at_s"] < 0.0  # during the turn-over, before the hold began
    assert result["largest_displacement_mm"] > config.drop_mm
    assert max(result["closed_contact_forces_n"]) == 0.0
    assert "DROPPED" in oh.describe(result)


def _library(tmp_path: Path, base: str, name: str, **changes: object) -> Path:
    """An object library of one's own: the package's ``base`` object as ``name``, changed."""
    fields = {k: v for k, v in oh.asdict(objects.get_object(base)).items() if k != "name"}
    fields.update(changes)
    library = tmp_path / "objects.toml"
    library.write_text(
        f"[object.{name}]\n"
        + "".join(f"{k} = {json.dumps(list(v) if isinstance(v, tuple) else v)}\n"
                  for k, v in fields.items() if v is not None)
    )  # fmt: skip
    return library


def test_a_shell_weaker_than_the_grasp_breaks(firmware_elf: Path, tmp_path: Path) -> None:
    """An egg whose shell gives at 1 N (an object library of one's own) breaks under the grasp
    that leaves the package's egg (25 N) intact."""
    library = _library(tmp_path, "egg", "blown-egg", breaking_force_n=1.0)
    config = oh.ObjectHoldConfig(
        object="blown-egg", library=str(library), duration_s=2.0, hits=0, picture=False
    )
    result = oh.run(config, tmp_path / "run", elf=firmware_elf, progress=lambda s: None)
    assert result["broke"] is True, oh.describe(result)
    assert max(result["largest_contact_force_n"].values()) > 1.0
    assert "BROKE" in oh.describe(result)


def test_grasp_thumb_closes_the_thumb_on_the_object(firmware_elf: Path, tmp_path: Path) -> None:
    """An object that asks for the thumb (``grasp_thumb``; the ball 10 mm nearer the heel of
    the palm, where the thumb meets it) is closed on by the thumb too: it presses on it."""
    library = _library(
        tmp_path, "ball", "ball", grasp_thumb=True, rest_position_m=(-0.050, -0.005, 0.0326)
    )
    config = oh.ObjectHoldConfig(
        object="ball", library=str(library), duration_s=2.0, hits=0, picture=False
    )
    result = oh.run(config, tmp_path / "run", elf=firmware_elf, progress=lambda s: None)
    assert not result["dropped"], oh.describe(result)
    assert result["closed_contact_forces_n"][0] > 1.0  # the thumb on the ball


def _log(out: Path, config: oh.ObjectHoldConfig, rows: list[list[float]], hits: list[float]):
    out.mkdir()
    (out / "meta.json").write_text(json.dumps({"config": oh.asdict(config)}))
    with CsvLog(out / "object_samples.csv", oh.SAMPLE_COLUMNS) as log:
        for r in rows:
            t, z, f = r
            log.write([t, "hold", 0.0, 0.0, z, 1, 0, 0, 0, 0, f, f, 0, 0, 0, 0, 0, 0, 0])
    with CsvLog(out / "object_hits.csv", ["time_s", "jx_ns", "jy_ns", "jz_ns", "duration_s"]) as h:
        for t in hits:
            h.write([t, 0, 0, 0.02, 0.005])


def test_analysis_finds_breakage_hits_and_their_recovery(tmp_path: Path) -> None:
    config = oh.ObjectHoldConfig(object="egg", duration_s=3.0, baseline_s=1.0, rest_mm=0.5)
    rows = []
    for k in range(300):
        t = k * 0.01
        z = 0.0
        if 2.0 <= t < 2.1:
            z = 0.002 * (1 - (t - 2.0) / 0.1)  # a 2 mm kick, back within 0.1 s
        force = 30.0 if 2.5 <= t < 2.6 else 10.0  # past the egg's 25 N once
        rows.append([t, z, force])
    _log(tmp_path / "a", config, rows, [2.0])
    r = oh.analyse(tmp_path / "a")
    assert not r["dropped"]
    assert r["broke"] is True and r["broke_at_s"] == pytest.approx(2.5)
    assert r["largest_contact_force_n"]["index"] == pytest.approx(30.0)
    assert r["largest_contact_force_n"]["ring"] == 0.0
    (hit,) = r["hits"]
    assert hit["peak_displacement_mm"] == pytest.approx(2.0, abs=1e-6)
    assert hit["recovery_s"] == pytest.approx(0.08, abs=0.011)  # within 0.5 mm from 2.075 s
    assert r["slip_mm"] == pytest.approx(0.0)
    # the same log below the breaking force: intact
    rows2 = [[t, z, min(f, 20.0)] for t, z, f in rows]
    _log(tmp_path / "b", config, rows2, [2.0])
    assert oh.analyse(tmp_path / "b")["broke"] is False


def test_unknown_object_and_bad_effort_are_refused_by_name() -> None:
    with pytest.raises(oh.RunError, match="unknown object 'vase'"):
        oh.ObjectHoldConfig(object="vase")
    with pytest.raises(oh.RunError, match="effort"):
        oh.ObjectHoldConfig(object="ball", effort=1.5)
