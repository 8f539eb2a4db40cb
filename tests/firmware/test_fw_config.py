"""The configuration in EEPROM: layout, CRC, corruption, non-blocking save, load."""

from __future__ import annotations

import importlib.util
import struct
import sys
from pathlib import Path

import pytest
from fwsim import Sim, m

from utrf.protocol.framing import crc16_ccitt

MAGIC = 0x46525455
HEADER = struct.Struct("<IHH")
REPO_ROOT = Path(__file__).resolve().parents[2]


def layout_version() -> int:
    """The EEPROM layout version protocol/generate.py derives from the spec's [[config]]."""
    spec = importlib.util.spec_from_file_location(
        "utrf_generate", REPO_ROOT / "protocol" / "generate.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.layout_version(module.load_spec())


def image(sim: Sim) -> bytes:
    n = sim.lib.fw_config_image_bytes()
    return bytes(sim.eeprom()[:n])


def write_image(sim: Sim, data: bytes) -> None:
    e = sim.eeprom()
    for i, b in enumerate(data):
        e[i] = b


def reseal(data: bytes) -> bytes:
    """Recompute the CRC of an image whose contents were edited."""
    return data[:-2] + crc16_ccitt(data[:-2]).to_bytes(2, "little")


def save(sim: Sim, max_ms: int = 5000) -> m.Message:
    seq = sim.send(m.SaveConfig())
    for _ in range(max_ms):
        sim.run(1)
        got = [r for r in sim.frames if r.seq == seq]
        if got:
            sim.frames.remove(got[0])
            return got[0].msg
    raise AssertionError("save_config was never answered")


def custom_config(sim: Sim) -> None:
    sim.ok(
        m.SetGains(
            finger=2,
            kp=7.5,
            ki=0.25,
            kd=0.125,
            d_cutoff_hz=12.0,
            deadband_duty=0.033,
            slew_per_s=8.0,
            max_duty=0.65,
            pretension_duty=0.05,
        )
    )
    sim.ok(
        m.SetLimits(
            finger=4,
            theta2_min=-0.5,
            theta2_max=1.25,
            limit_margin=0.05,
            stall_error=0.3,
            stall_motion=0.01,
            stall_time=1.5,
            encoder_jump=0.1,
        )
    )
    sim.ok(m.SetSafety(heartbeat_timeout=0.75, safe_action=m.SafeAction.COAST))
    sim.ok(
        m.SetFingerConfig(
            finger=1,
            actuation=m.Actuation.ROTARY,
            encoder_offset=1.5,
            encoder_invert=1,
            motor_invert=1,
        )
    )


def settings(sim: Sim) -> list[m.Message]:
    out: list[m.Message] = [sim.ok(m.GetSafety())]
    for f in range(5):
        out += [
            sim.ok(m.GetGains(finger=f)),
            sim.ok(m.GetLimits(finger=f)),
            sim.ok(m.GetFingerConfig(finger=f)),
        ]
    return out


def test_blank_eeprom_loads_defaults_and_says_so(sim: Sim) -> None:
    assert sim.status().config_status == m.ConfigStatus.DEFAULTS_BLANK
    assert sim.ok(m.Identify()).config_status == m.ConfigStatus.DEFAULTS_BLANK


def test_image_layout_magic_version_length_crc(sim: Sim) -> None:
    assert isinstance(save(sim), m.Ack)
    data = image(sim)
    magic, version, length = HEADER.unpack_from(data)
    assert (magic, version) == (MAGIC, layout_version())
    assert length == sim.lib.fw_config_body_bytes() == len(data) - HEADER.size - 2
    assert int.from_bytes(data[-2:], "little") == crc16_ccitt(data[:-2])


def test_saved_configuration_comes_back_after_a_reset(sim: Sim) -> None:
    custom_config(sim)
    before = settings(sim)
    assert isinstance(save(sim), m.Ack)
    sim.power_on()
    assert sim.take(m.Boot)[0].msg.config_status == m.ConfigStatus.LOADED
    assert settings(sim) == before


@pytest.mark.parametrize("offset", [0, 5, 8, 40, 150, -3, -1])
def test_any_damaged_byte_loads_defaults(sim: Sim, offset: int) -> None:
    custom_config(sim)
    assert isinstance(save(sim), m.Ack)
    data = bytearray(image(sim))
    offset %= len(data)
    data[offset] ^= 0x5A
    write_image(sim, bytes(data))
    sim.power_on()
    status = sim.status().config_status
    if offset < 4:
        assert status == m.ConfigStatus.DEFAULTS_BLANK  # no magic: not ours
    elif offset < 8:
        assert status == m.ConfigStatus.DEFAULTS_VERSION
    else:
        assert status == m.ConfigStatus.DEFAULTS_CORRUPT
    assert sim.ok(m.GetGains(finger=2)).kp == 3.0  # the defaults, not the damaged image


def test_another_layout_version_loads_defaults(sim: Sim) -> None:
    assert isinstance(save(sim), m.Ack)
    data = bytearray(image(sim))
    struct.pack_into("<H", data, 4, layout_version() ^ 1)
    write_image(sim, reseal(bytes(data)))
    sim.power_on()
    assert sim.status().config_status == m.ConfigStatus.DEFAULTS_VERSION


def test_a_sealed_image_with_a_value_out_of_range_is_refused(sim: Sim) -> None:
    assert isinstance(save(sim), m.Ack)
    data = bytearray(image(sim))
    struct.pack_into("<f", data, HEADER.size, -5.0)  # finger 0's kp, with a valid CRC
    write_image(sim, reseal(bytes(data)))
    sim.power_on()
    assert sim.status().config_status == m.ConfigStatus.DEFAULTS_CORRUPT
    assert sim.ok(m.GetGains(finger=0)).kp == 3.0


def test_saving_does_not_block_and_refuses_changes_meanwhile(sim: Sim) -> None:
    sim.lib.fw_set_eeprom_busy_polls(3)  # ~3.4 ms a byte on the chip: the writer must wait
    seq = sim.send(m.SaveConfig())
    sim.run(20)
    assert not [r for r in sim.frames if r.seq == seq]  # not done yet: no ack
    assert sim.status().saving
    ticks = sim.ok(m.GetStats()).ticks
    nack = sim.nack(
        m.SetGains.ID,
        m.SetGains(
            finger=0,
            kp=1.0,
            ki=0.0,
            kd=0.0,
            d_cutoff_hz=10.0,
            deadband_duty=0.0,
            slew_per_s=1.0,
            max_duty=0.5,
            pretension_duty=0.0,
        ).encode(),
    )
    assert (nack.code, nack.detail) == (m.ErrorCode.BUSY, 0xFF)
    assert sim.ok(m.GetGains(finger=0)).kp == 3.0
    for _ in range(3000):
        sim.run(1)
        if [r for r in sim.frames if r.seq == seq]:
            break
    done = [r for r in sim.frames if r.seq == seq]
    assert done and isinstance(done[0].msg, m.Ack)
    assert sim.ok(m.GetStats()).ticks > ticks + 100  # the tick ran all along
    assert int.from_bytes(image(sim)[-2:], "little") == crc16_ccitt(image(sim)[:-2])


def test_an_unchanged_image_is_not_rewritten(sim: Sim) -> None:
    assert isinstance(save(sim), m.Ack)
    writes = sim.lib.fw_eeprom_writes()
    assert isinstance(save(sim), m.Ack)
    assert sim.lib.fw_eeprom_writes() == writes
    sim.ok(m.SetSafety(heartbeat_timeout=0.6, safe_action=m.SafeAction.HOLD))
    assert isinstance(save(sim), m.Ack)
    assert 1 <= sim.lib.fw_eeprom_writes() - writes <= 4  # the changed bytes and the CRC


def test_a_cell_that_does_not_take_the_write_is_reported(sim: Sim) -> None:
    sim.lib.fw_set_eeprom_stuck(20)
    reply = save(sim)
    assert isinstance(reply, m.Nack)
    assert reply.code == m.ErrorCode.BUSY


def test_load_config_from_eeprom_and_defaults(sim: Sim) -> None:
    custom_config(sim)
    assert isinstance(save(sim), m.Ack)
    sim.ok(m.LoadConfig(source=m.ConfigSource.DEFAULTS))
    assert sim.status().config_status == m.ConfigStatus.DEFAULTS_REQUESTED
    assert sim.ok(m.GetGains(finger=2)).kp == 3.0
    sim.ok(m.LoadConfig(source=m.ConfigSource.EEPROM))
    assert sim.status().config_status == m.ConfigStatus.LOADED
    assert sim.ok(m.GetGains(finger=2)).kp == 7.5
    assert sim.ok(m.Identify()).actuation[1] == m.Actuation.ROTARY


def test_load_config_needs_an_idle_hand(sim: Sim) -> None:
    sim.ok(m.SetMode(mask=0b1000, mode=(0, 0, 0, 2, 0), duty=(0,) * 5, effort=(0,) * 5))
    nack = sim.nack(m.LoadConfig.ID, m.LoadConfig(source=m.ConfigSource.DEFAULTS).encode())
    assert (nack.code, nack.detail) == (m.ErrorCode.BUSY, 3)
