"""A control-law parameter is added in at most three places (issue 23): its line in
protocol/spec.toml, its use in the law (core/pid.h's Coeffs and step, core/pid.cpp's compile),
and its test. Everything between is generated from the spec or derived from it: the
configuration struct and its EEPROM layout, the copy from set_gains, the host's message, and
the test C API (capi.cpp's fw_pid_config takes a set_gains body; fwsim.pid_config fills it
from the spec's defaults).

The test does it: a copy of the firmware sources and the spec, a gain added (a constant duty
bias), the generated files rendered from the copied spec, the whole host build of the core
and its C API compiled from the copy, and the new gain driven through the C API. It counts
the files it had to edit by hand."""

from __future__ import annotations

import ctypes
import filecmp
import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from fwsim import Q15, REPO

from protocol import generate

SPEC_LINE = (
    '  { name = "bias_duty", type = "f32", min = -0.5, max = 0.5, unit = "1", '
    'doc = "a constant duty added to the output", default = 0.0 },\n'
)
# The law's edits: (file, text after which a line goes, the line)
LAW = [
    ("firmware/src/core/pid.h", "    uint16_t db_inverse;", "\n    int16_t bias;"),
    (
        "firmware/src/core/pid.h",
        "    sum_t v = p_minus_d(c, e, v8_) * 2 + (int16_t)(i31_ >> 16) + ff;",
        "\n    v += c.bias;",
    ),
    (
        "firmware/src/core/pid.cpp",
        "    c.db_inverse = deadband_inverse(c.deadband);",
        "\n    c.bias = q15(g.bias_duty);",
    ),
]


def _insert_after(path: Path, anchor: str, line: str) -> None:
    text = path.read_text(encoding="utf-8")
    assert text.count(anchor) == 1, (path, anchor)
    path.write_text(text.replace(anchor, anchor + line), encoding="utf-8")


def _hand_edited(tree: Path, generated: set[str]) -> set[str]:
    """Files of the copy that differ from the checkout, the generated ones left out."""
    out = set()
    for p in tree.rglob("*"):
        rel = p.relative_to(tree).as_posix()
        if p.is_file() and rel not in generated and not filecmp.cmp(p, REPO / rel, shallow=False):
            out.add(rel)
    return out


@pytest.mark.slow
def test_a_gain_added_to_the_spec_needs_three_hand_edits(tmp_path: Path) -> None:
    tree = tmp_path / "repo"
    for rel in ("firmware/src", "firmware/test"):
        shutil.copytree(REPO / rel, tree / rel, ignore=shutil.ignore_patterns("avr"))
    (tree / "protocol").mkdir()
    shutil.copy2(REPO / "protocol/spec.toml", tree / "protocol/spec.toml")

    # 1. the spec's line: set_gains gets the field (the gains config block and reply follow)
    _insert_after(
        tree / "protocol/spec.toml",
        'doc = "antagonistic: the duty that keeps the slack-side tendon taut", default = 0.1 },\n',
        SPEC_LINE,
    )
    # 2. its use in the law
    for rel, anchor, line in LAW:
        _insert_after(tree / rel, anchor, line)
    # what `make generate` writes, from the copied spec
    spec = generate.load_spec(tree / "protocol/spec.toml")
    generated = {
        "firmware/src/generated/protocol_messages.h": generate.render_header(spec),
        "firmware/src/generated/config_layout.h": generate.render_config(spec),
        "host/utrf/protocol/messages.py": generate.render_messages(spec),
    }
    for rel, text in generated.items():
        (tree / rel).parent.mkdir(parents=True, exist_ok=True)
        (tree / rel).write_text(text, encoding="utf-8")

    edited = _hand_edited(tree, set(generated))
    assert edited == {
        "protocol/spec.toml",
        "firmware/src/core/pid.h",
        "firmware/src/core/pid.cpp",
    }, edited

    # The whole core and the test C API build from the copy as they are (-O0: quick).
    srcs = [
        *sorted((tree / "firmware/src/core").glob("*.cpp")),
        tree / "firmware/test/capi.cpp",
        tree / "firmware/test/hal_host.cpp",
    ]
    lib_path = tmp_path / "libgain.so"
    subprocess.run(
        [
            "g++",
            "-std=gnu++11",
            "-O0",
            "-fPIC",
            "-shared",
            "-fno-exceptions",
            "-fno-rtti",
            f"-I{tree / 'firmware/src'}",
            "-o",
            str(lib_path),
            *map(str, srcs),
            "-lm",
        ],
        check=True,
        capture_output=True,
        timeout=600,
    )
    # The new gain through the C API, its body encoded by the regenerated host message.
    mod_spec = importlib.util.spec_from_file_location(
        "messages_with_bias", tree / "host/utrf/protocol/messages.py"
    )
    assert mod_spec and mod_spec.loader
    msgs = importlib.util.module_from_spec(mod_spec)
    sys.modules[mod_spec.name] = msgs  # its dataclasses look their module up
    try:
        mod_spec.loader.exec_module(msgs)
    finally:
        del sys.modules[mod_spec.name]
    lib = ctypes.CDLL(str(lib_path))
    lib.fw_pid_config.argtypes = [ctypes.c_char_p, ctypes.c_uint8, ctypes.c_int16]
    lib.fw_pid_step.restype = ctypes.c_int16
    lib.fw_pid_step.argtypes = [ctypes.c_int16, ctypes.c_int16]
    limit = round(0.7 * Q15)
    outputs = {}
    for bias in (0.0, 0.25):
        body = msgs.SetGains(
            finger=0,
            kp=3.0,
            ki=0.0,
            kd=0.0,
            d_cutoff_hz=30.0,
            deadband_duty=0.0,
            slew_per_s=1000.0,
            max_duty=0.8,
            pretension_duty=0.1,
            bias_duty=bias,
        ).encode()
        assert lib.fw_pid_config(body, len(body), limit) == 0
        lib.fw_pid_reset(0, 0)
        outputs[bias] = lib.fw_pid_step(0, 0)  # no error: the output is the bias alone
    assert outputs == {0.0: 0, 0.25: round(0.25 * Q15)}
