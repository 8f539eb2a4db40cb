"""The generated bindings and vectors are fresh, the spec is checked, the schema hash ignores
docs only, and the firmware side compiles for the ATmega2560 without a warning."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import sys
import tomllib
import zlib
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from proto_helpers import REPO_ROOT, CppCodec

from utrf.protocol import messages as M

SPEC = REPO_ROOT / "protocol" / "spec.toml"
HEADER = REPO_ROOT / "firmware" / "src" / "generated" / "protocol_messages.h"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        f"utrf_{name}", REPO_ROOT / "protocol" / f"{name}.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


generate = _load("generate")


def test_generated_files_are_fresh() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "protocol.generate", "--check"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr


def test_vectors_are_fresh() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "protocol.make_vectors", "--check"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr


def _spec_with(tmp_path: Path, old: str, new: str) -> Path:
    text = SPEC.read_text(encoding="utf-8")
    assert old in text, f"the spec no longer contains {old!r}"
    path = tmp_path / "spec.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


def test_check_names_stale_outputs_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = HEADER.read_bytes()
    spec = _spec_with(
        tmp_path,
        'name = "rate_hz", type = "u16", max = 1000',
        'name = "rate_hz", type = "u16", max = 400',
    )
    assert generate.main(["--check", "--spec", str(spec)]) == 1
    err = capsys.readouterr().err
    for out in ("protocol_messages.h", "messages.py", "README.md"):
        assert out in err
    assert HEADER.read_bytes() == before


def test_schema_hash_is_crc32_of_the_spec_without_docs(tmp_path: Path) -> None:
    raw = tomllib.loads(SPEC.read_text(encoding="utf-8"))

    def strip(obj: Any) -> Any:
        if isinstance(obj, dict):
            return {k: strip(v) for k, v in obj.items() if k != "doc"}
        if isinstance(obj, list):
            return [strip(v) for v in obj]
        return obj

    canonical = json.dumps(strip(raw), sort_keys=True, separators=(",", ":"))
    assert zlib.crc32(canonical.encode()) == M.SCHEMA_HASH
    assert '"doc"' not in canonical
    # A doc edit keeps the hash; a range edit changes it.
    doc_edit = _spec_with(tmp_path, 'doc = "any value, echoed"', 'doc = "any value at all, echoed"')
    assert generate.load_spec(doc_edit).schema_hash == M.SCHEMA_HASH
    range_edit = _spec_with(tmp_path, 'type = "u16", max = 1000', 'type = "u16", max = 999')
    assert generate.load_spec(range_edit).schema_hash != M.SCHEMA_HASH


def test_every_side_carries_the_same_version_and_hash(cpp: CppCodec) -> None:
    header = HEADER.read_text(encoding="utf-8")
    assert f"kSchemaHash = 0x{M.SCHEMA_HASH:08X}UL;" in header
    assert f"kProtocolVersion = {M.PROTOCOL_VERSION};" in header
    assert cpp.lib.utrf_schema_hash() == M.SCHEMA_HASH
    assert cpp.lib.utrf_protocol_version() == M.PROTOCOL_VERSION
    readme = (REPO_ROOT / "protocol" / "README.md").read_text(encoding="utf-8")
    assert f"`0x{M.SCHEMA_HASH:08X}`" in readme


@pytest.mark.parametrize(
    ("old", "new", "complaint"),
    [
        (
            'name = "value", type = "i32", count = 5',
            'name = "value", type = "i32", count = 16',
            "above max_payload 64",
        ),
        ("id = 0x02\n", "id = 0x01\n", "share id 0x01"),
        ('enum = "TargetKind"', 'enum = "TargetKinds"', "enum 'TargetKinds' is not defined"),
        (
            'min = -1.0, max = 1.0, unit = "1"',
            'min = 1.0, max = -1.0, unit = "1"',
            "min 1.0 is above max -1.0",
        ),
        ('reply = "pong"', 'reply = "ping"', "reply 'ping' is not a board_to_host message"),
        (
            '{ name = "protocol_version", type = "u16" },\n',
            "",
            "must start with u16 protocol_version",
        ),
        ('type = "u16", max = 1000', 'type = "u16", max = 70000', "outside u16"),
        ('type = "u16", max = 1000', 'type = "u16", max = 1000, maxx = 3', "unknown key(s) maxx"),
        (
            'crc = "CRC-16/CCITT-FALSE"',
            'crc = "CRC-16/XMODEM"',
            "the codecs implement 'CRC-16/CCITT-FALSE'",
        ),
    ],
    ids=["size", "dup-id", "enum", "min-max", "reply", "identity-head", "range", "key", "crc"],
)
def test_inconsistent_spec_is_refused_by_name(
    tmp_path: Path, old: str, new: str, complaint: str
) -> None:
    with pytest.raises(generate.SpecError) as info:
        generate.load_spec(_spec_with(tmp_path, old, new))
    assert complaint in str(info.value)


def test_same_fields_as_gives_the_same_layout() -> None:
    for reply, request in [(M.Gains, M.SetGains), (M.Limits, M.SetLimits), (M.Safety, M.SetSafety)]:
        assert reply.FIELDS == request.FIELDS and reply.SIZE == request.SIZE
    header = HEADER.read_text(encoding="utf-8")
    gains = re.search(r"struct Gains \{(.*?)\};", header, re.S)
    set_gains = re.search(r"struct SetGains \{(.*?)\};", header, re.S)
    assert gains and set_gains
    # the request alone names its reply
    reply_line = "  static const uint8_t kReplyId = 0xF0;  // ack\n"
    assert reply_line in set_gains.group(1)
    body = set_gains.group(1).replace(reply_line, "")
    assert gains.group(1).replace("0xA0", "ID") == body.replace("0x21", "ID")


AVR_FLAGS = [
    "-mmcu=atmega2560",
    "-std=gnu++11",
    "-Os",
    "-Wall",
    "-Wextra",
    "-Werror",
    "-fno-exceptions",
]
CPP_SOURCES = [
    REPO_ROOT / "firmware" / "src" / "core" / "framing.cpp",
    REPO_ROOT / "tests" / "protocol" / "cpp" / "all_messages.cpp",
]


@pytest.mark.parametrize(
    "compiler",
    [
        ["avr-g++", *AVR_FLAGS],
        ["g++", "-std=gnu++11", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic"],
    ],
    ids=["avr-gcc", "host-g++"],
)
def test_firmware_side_compiles_without_warnings(tmp_path: Path, compiler: list[str]) -> None:
    if shutil.which(compiler[0]) is None:
        pytest.fail(f"{compiler[0]} is not installed: run `make setup`")
    for source in CPP_SOURCES:
        result = subprocess.run(
            [*compiler, "-c", str(source), "-o", str(tmp_path / (source.stem + ".o"))],
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, f"{source.name}:\n{result.stderr}"
        assert result.stderr == ""


ARDUINO = Path("/usr/share/arduino/hardware/arduino/avr")
ARDUINO_FLAGS = [
    *AVR_FLAGS,
    "-DF_CPU=16000000L",
    "-DARDUINO=10819",
    "-DARDUINO_AVR_MEGA2560",
    "-DARDUINO_ARCH_AVR",
    f"-I{ARDUINO / 'cores' / 'arduino'}",
    f"-I{ARDUINO / 'variants' / 'mega'}",
]


def test_header_lives_with_the_avr_and_arduino_macros(tmp_path: Path) -> None:
    """<avr/io.h> and <Arduino.h> define macros such as PING and EXTERNAL: the header must
    compile after them, and every name it defines must stay usable there (MsgId names that a
    macro shadows are suspended inside the header, and reached as Struct::kId instead)."""
    if (
        shutil.which("avr-g++") is None
        or not (ARDUINO / "cores" / "arduino" / "Arduino.h").exists()
    ):
        pytest.fail("avr-g++ or the Arduino core is not installed: run `make setup`")
    probe = tmp_path / "macros.cpp"
    probe.write_text("#include <Arduino.h>\n")
    macros = subprocess.run(
        ["avr-g++", *ARDUINO_FLAGS, "-E", "-dM", str(probe)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    macro_names = {
        line.split()[1].split("(")[0] for line in macros.splitlines() if line.startswith("#define")
    }
    header = HEADER.read_text(encoding="utf-8")
    suspended = set(re.findall(r'#pragma push_macro\("(\w+)"\)', header))
    uses: list[str] = []
    for cls in M.MESSAGES:
        uses.append(f"proto::{cls.__name__}::kId")
        if cls.NAME.upper() not in suspended:
            uses.append(f"proto::MsgId::{cls.NAME.upper()}")
    for enum in (
        M.TargetKind,
        M.ControlMode,
        M.Actuation,
        M.SafeAction,
        M.ResetCause,
        M.ConfigStatus,
        M.ConfigSource,
        M.ErrorCode,
    ):
        uses += [f"static_cast<uint8_t>(proto::{enum.__name__}::{m.name})" for m in enum]
    uses += [f"proto::FaultBits::{m.name}" for m in M.FaultBits]
    names = {u.split("::")[-1].rstrip(")") for u in uses}
    assert names & macro_names <= suspended, "a generated name is a macro in Arduino code"
    assert suspended <= macro_names, "a suspended name that is no macro"
    source = tmp_path / "with_arduino.cpp"
    source.write_text(
        "#include <Arduino.h>\n"
        f'#include "{REPO_ROOT}/firmware/src/core/framing.h"\n'
        f'#include "{HEADER}"\n'
        "using namespace utrf;\n"
        "uint16_t sum_of_names() {\n  uint16_t s = 0;\n"
        + "".join(f"  s = static_cast<uint16_t>(s + {u});\n" for u in uses)
        + "  return s;\n}\n"
        + "uint8_t port_g() { return PING; }  // the macro still works after the header\n"
    )
    result = subprocess.run(
        ["avr-g++", *ARDUINO_FLAGS, "-c", str(source), "-o", str(tmp_path / "a.o")],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""


# --- the configuration from the spec ----------------------------------------------------------


def test_a_new_gain_is_one_spec_line_for_struct_layout_defaults_and_handlers(
    tmp_path: Path,
) -> None:
    line = '  { name = "pretension_duty", type = "u16", scale = 1e-3, max = 0.5'
    text = SPEC.read_text(encoding="utf-8")
    assert line in text
    new = '  { name = "kff", type = "f32", min = 0.0, max = 10.0, unit = "s", default = 0.5 },\n'
    spec_path = tmp_path / "spec.toml"
    spec_path.write_text(text.replace(line, new + line), encoding="utf-8")
    old, edited = generate.load_spec(SPEC), generate.load_spec(spec_path)
    header = generate.render_config(edited)
    assert "  float kff;  // s; [0.0, 10.0]" in header  # the stored field, in the struct
    assert "  c.kff = 0.5f;" in header  # its default
    assert "  m.kff = c.kff;" in header and "  c.kff = m.kff;" in header  # get and set
    # another layout: an image saved before loads the defaults (DEFAULTS_VERSION)
    assert generate.layout_version(edited) != generate.layout_version(old)
    # 5 x 4 bytes more than today's layout
    today = int(re.search(r"kConfigBytes = (\d+);", generate.render_config(old)).group(1))
    assert f"kConfigBytes = {today + 5 * 4};" in header
    # the gets and sets are one table, whatever the fields
    assert "X(SetGains, SET_GAINS)" in header and "X(GetGains, GET_GAINS, Gains)" in header


def test_config_layout_is_generated_and_checked_for_staleness() -> None:
    committed = (REPO_ROOT / "firmware/src/generated/config_layout.h").read_text("utf-8")
    assert committed == generate.render_config(generate.load_spec(SPEC))
    assert generate.CONFIG_PATH in generate.outputs(generate.load_spec(SPEC))


@pytest.mark.parametrize(
    "old,new,words",
    [
        ('set = "set_gains"', 'set = "set_limits"', "same fields as set_limits"),
        ('struct = "Gains"', 'struct = "gains"', "CamelCase"),
        ("per_finger = false", "per_finger = true", "starts with u8 finger"),
        ("default = 3.0 }", "default = 3000.0 }", "outside"),
        ('name = "hw"\n', 'name = "hw"\nsize = 3\n', "unknown key(s) size"),
    ],
)
def test_inconsistent_config_blocks_are_refused_by_name(
    tmp_path: Path, old: str, new: str, words: str
) -> None:
    text = SPEC.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "spec.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(generate.SpecError, match=re.escape(words)):
        generate.load_spec(path)
