"""Which firmware a board runs, in words (utrf.artifacts.describe_firmware): its build id and
where it came from, so that a cached build is never taken silently."""

from __future__ import annotations

from pathlib import Path

import pytest

from utrf import artifacts


def fake_build(d: Path, build_id: str | None) -> Path:
    d.mkdir(parents=True)
    elf = d / "utrf.elf"
    elf.write_bytes(b"\x7fELF")
    if build_id is not None:
        (d / "build_id.h").write_text(f"#define UTRF_BUILD_ID 0x{build_id}UL\n")
    return elf


def test_a_cached_build_says_so_with_its_build_id(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # no checkout here
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("UTRF_FIRMWARE_ELF", raising=False)
    elf = fake_build(tmp_path / "cache" / "utrf" / "1a2b3c4d5e6f7a8b" / "firmware", "1a2b3c4d")
    assert artifacts.firmware_build_id(elf) == 0x1A2B3C4D
    text = artifacts.describe_firmware(elf)
    assert "build 1a2b3c4d" in text
    assert "built from the sources packaged with utrf" in text
    assert str(tmp_path / "cache" / "utrf" / "1a2b3c4d5e6f7a8b") in text


def test_the_origin_is_named_for_each_source(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    elf = fake_build(tmp_path / "mine", None)
    assert artifacts.firmware_build_id(elf) is None
    assert artifacts.describe_firmware(elf, given=True).endswith(
        "(build id unknown, given explicitly)"
    )
    monkeypatch.setenv("UTRF_FIRMWARE_ELF", str(elf))
    assert "from UTRF_FIRMWARE_ELF" in artifacts.describe_firmware(elf)
    monkeypatch.delenv("UTRF_FIRMWARE_ELF")
    (tmp_path / "firmware").mkdir()
    (tmp_path / "firmware" / "firmware.mk").write_text("")
    (tmp_path / "host" / "utrf").mkdir(parents=True)
    built = fake_build(tmp_path / "build" / "firmware", "00c0ffee")
    text = artifacts.describe_firmware(built)
    assert "build 00c0ffee" in text and "this checkout's `make firmware`" in text
