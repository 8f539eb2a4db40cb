"""A rig run that cannot start writes nothing, so the same command can simply be run again;
the reason is one line on stderr and exit 2 (no traceback)."""

from __future__ import annotations

import builtins
import sys
from pathlib import Path

import pytest

from utrf.cli import main


@pytest.mark.parametrize("run", ["static-loading", "grasp-hold"])
def test_missing_firmware_is_one_line_and_writes_nothing(
    run: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["hil", run, "--emulated", "--out", str(out), "--elf", str(tmp_path / "no.elf")]
    if run == "static-loading":
        argv += ["--loads-kg", "0.5"]  # a payload the planner accepts: the firmware is next
    for _ in range(2):  # the retry meets the same error, not "already holds a run"
        assert main([*argv, "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"firmware ELF {tmp_path / 'no.elf'} not found" in err
        assert not out.exists()


def test_missing_tracker_package_writes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real_import = builtins.__import__

    def no_ndi(name: str, *args: object, **kwargs: object) -> object:
        if name.startswith("sksurgerynditracker"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "sksurgerynditracker", raising=False)
    monkeypatch.delitem(sys.modules, "sksurgerynditracker.nditracker", raising=False)
    monkeypatch.setattr(builtins, "__import__", no_ndi)
    out = tmp_path / "out"
    argv = ["hil", "static-loading", "--port", "loop://", "--out", str(out), "--quiet"]
    argv += ["--loads-kg", "0.5", "--actuator-rating-n", "1000"]
    for _ in range(2):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "pip install -e '.[rig]'" in err and "already holds" not in err
        assert not out.exists()


def test_an_existing_run_is_refused_before_the_board_is_opened(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "meta.json").write_text("{}")
    argv = [
        "hil",
        "static-loading",
        "--emulated",
        "--out",
        str(out),
        "--quiet",
        "--loads-kg",
        "0.5",
    ]
    assert main([*argv, "--elf", str(tmp_path / "no.elf")]) == 2
    assert "already holds a run" in capsys.readouterr().err


def test_the_hit_impulse_option_names_its_unit(capsys: pytest.CaptureFixture[str]) -> None:
    from utrf.cli import build_parser

    parser = build_parser()
    args = parser.parse_args(["hil", "grasp-hold", "--emulated", "--out", "o",
                              "--hit-impulse", "0.5"])  # fmt: skip
    assert args.hit_impulse == 0.5
    with pytest.raises(SystemExit):
        parser.parse_args(["hil", "grasp-hold", "--emulated", "--out", "o", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--hit-impulse N_S" in text and "newton-seconds (N·s" in text
    assert "--hit-impulse-ns" not in text
