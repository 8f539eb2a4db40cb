"""Bad campaign files are refused before anything runs, naming the file and the line."""

from __future__ import annotations

from pathlib import Path

import pytest

from utrf.campaign import kinds, spec

DESIGN = """\
[campaign]
name = "t"
kind = "design"

[sampler]
method = "lhs"
samples = 10

[parameters]
link1_m = { min = 0.05, max = 0.08 }
radius1_m = [0.008, 0.010]
payload_kg = 1.0

[objectives]
link3_area_m2 = "max"
"""


def refused(text: str, tmp_path: Path, **kw: object) -> str:
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(spec.CampaignError) as info:
        campaign = spec.load(path, **kw)  # type: ignore[arg-type]
        kinds.get(campaign.kind).check(campaign)
    return str(info.value)


def test_a_good_file_reads(tmp_path: Path) -> None:
    (tmp_path / "c.toml").write_text(DESIGN)
    c = spec.load(tmp_path / "c.toml")
    kinds.get(c.kind).check(c)
    assert c.kind == "design" and c.samples == 10 and c.param("radius1_m").values == (0.008, 0.01)
    assert c.param("link1_m").range == spec.Range(0.05, 0.08)


@pytest.mark.parametrize(
    ("old", "new", "line", "words"),
    [
        ("radius1_m = [", "radius9_m = [", 11, "unknown design parameter 'radius9_m'"),
        ("max = 0.08", "max = 0.8", 10, "outside what the finger models describe"),
        ('link3_area_m2 = "max"', 'link3_area = "max"', 15, "unknown objective"),
        ('link3_area_m2 = "max"', 'link3_area_m2 = "up"', 15, 'must be "min" or "max"'),
        ('method = "lhs"', 'method = "sobol"', 6, "method must be one of"),
        ("samples = 10", "samples = 0", 7, "samples must be an integer >= 1"),
        ("[objectives]", "[objective]", 14, "unknown section [objective]"),
        ('method = "lhs"', 'method = "grid"', 10, "a grid needs steps"),
        ("payload_kg = 1.0", "payload_kg = { min = 2, max = 1 }", 12, "min < max"),
    ],
)
def test_bad_design_files_name_the_line(
    tmp_path: Path, old: str, new: str, line: int, words: str
) -> None:
    assert old in DESIGN
    message = refused(DESIGN.replace(old, new), tmp_path)
    assert f"c.toml:{line}:" in message and words in message


GRASP = """\
[campaign]
kind = "grasp"

[sampler]
method = "grid"

[parameters]
object = ["ball", "box"]
kp = [10.0, 20.0]
firmware = ["a"]

[firmware]
a = "a.elf"
"""


def test_grasp_files_are_checked_against_the_library_and_the_protocol(tmp_path: Path) -> None:
    (tmp_path / "a.elf").write_bytes(b"\x7fELF")
    msg = refused(GRASP.replace('"box"', '"anvil"'), tmp_path)
    assert "c.toml:8:" in msg and "unknown object 'anvil'" in msg
    msg = refused(GRASP.replace("20.0]", "2000.0]"), tmp_path)  # SetGains.kp <= 1000
    assert "c.toml:9:" in msg and "protocol" in msg
    msg = refused(GRASP.replace('["a"]', '["b"]'), tmp_path)
    assert "c.toml:10:" in msg and "unknown firmware label" in msg


def test_a_missing_firmware_is_refused_naming_its_line(tmp_path: Path) -> None:
    msg = refused(GRASP, tmp_path)  # a.elf does not exist
    assert "c.toml:13:" in msg and "no such ELF file" in msg
    # given on the command line instead, it is found
    elf = tmp_path / "x.elf"
    elf.write_bytes(b"\x7fELF")
    (tmp_path / "c.toml").write_text(GRASP)
    c = spec.load(tmp_path / "c.toml", firmware={"a": str(elf)})
    kinds.get(c.kind).check(c)
    assert c.firmware == {"a": str(elf.resolve())}


def test_the_digest_follows_the_firmwares_contents_not_their_paths(tmp_path: Path) -> None:
    (tmp_path / "x.elf").write_bytes(b"one")
    (tmp_path / "y.elf").write_bytes(b"one")
    (tmp_path / "c.toml").write_text(GRASP)
    a = spec.load(tmp_path / "c.toml", firmware={"a": str(tmp_path / "x.elf")})
    b = spec.load(tmp_path / "c.toml", firmware={"a": str(tmp_path / "y.elf")})
    assert a.digest == b.digest
    (tmp_path / "y.elf").write_bytes(b"two")
    assert spec.load(tmp_path / "c.toml", firmware={"a": str(tmp_path / "y.elf")}).digest != (
        a.digest
    )


def test_the_shipped_examples_read(tmp_path: Path) -> None:
    from importlib import resources

    folder = resources.files("utrf") / "data" / "campaigns"
    names = sorted(r.name for r in folder.iterdir() if r.name.endswith(".toml"))
    assert {"design-sweep.toml", "grasp-monte-carlo.toml", "firmware-ab.toml"} <= set(names)
    elf = tmp_path / "fw.elf"
    elf.write_bytes(b"\x7fELF")
    for name in names:
        with resources.as_file(folder / name) as path:
            c = spec.load(path, firmware={"a": str(elf), "b": str(elf)} if "ab" in name else None)
        if c.kind == "design":
            kinds.get(c.kind).check(c)
