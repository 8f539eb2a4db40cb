#include "config.h"

#include <string.h>

#include "../generated/protocol_messages.h"
#include "../hal/hal.h"
#include "framing.h"
#include "kinematics.h"

namespace utrf {
namespace config {

static_assert(sizeof(Gains) == 26 && sizeof(Limits) == 26 && sizeof(Hardware) == 7,
              "the EEPROM layout is packed: no padding may creep in");
static_assert(sizeof(Config) == 5 * 59 + 3, "a change of layout needs a new kLayoutVersion");

Gains default_gains() {
    // Conservative gains for a tendon finger on a geared DC motor: full duty at about 0.3 rad
    // of error, a little integral and damping. Tune per hand with set_gains.
    Gains g;
    g.kp = 3.0f;
    g.ki = 2.0f;
    g.kd = 0.05f;
    g.d_cutoff_hz = 30.0f;
    g.deadband_milli = 40;
    g.slew_per_s = 20.0f;
    g.max_duty_milli = 800;
    g.pretension_milli = 100;
    return g;
}

Limits default_limits(uint8_t finger) {
    const uint8_t geo = kin::finger_geometry(finger);
    Limits l;
    l.theta2_min = kin::theta2_min(geo);
    l.theta2_max = kin::theta2_max(geo);
    l.limit_margin = 0.1f;
    l.stall_error = 0.2f;
    l.stall_motion = 0.02f;
    l.stall_time_ms = 500;
    l.encoder_jump = 0.2f;
    return l;
}

void defaults(Config& cfg) {
    memset(&cfg, 0, sizeof cfg);
    for (uint8_t f = 0; f < proto::kFingerCount; ++f) {
        cfg.finger[f].gains = default_gains();
        cfg.finger[f].limits = default_limits(f);
        cfg.finger[f].hw.actuation = (uint8_t)proto::Actuation::ANTAGONISTIC;
        // Mounted so the straight finger reads mid-band (2.5 V): the Joint-2 range then stays
        // clear of the sensor's wrap from 90 % to 10 %.
        cfg.finger[f].hw.encoder_offset = 3.14159265f;
        cfg.finger[f].hw.encoder_invert = 0;
        cfg.finger[f].hw.motor_invert = 0;
    }
    cfg.safety.heartbeat_timeout_ms = proto::kDefaultHeartbeatTimeoutMs;
    cfg.safety.safe_action = (uint8_t)proto::SafeAction::HOLD;
}

uint8_t check_gains(const Gains& g) {
    if (g.pretension_milli > 0 && g.pretension_milli >= g.max_duty_milli) return 8;
    return 0xFF;
}

uint8_t check_limits(uint8_t finger, const Limits& l) {
    const uint8_t geo = kin::finger_geometry(finger);
    // The table's range is quantised to float; allow it a hair of slack.
    const float lo = kin::theta2_min(geo) - 1e-5f;
    const float hi = kin::theta2_max(geo) + 1e-5f;
    if (!(l.theta2_min >= lo && l.theta2_min < hi)) return 1;
    if (!(l.theta2_max > l.theta2_min && l.theta2_max <= hi)) return 2;
    return 0xFF;
}

namespace {
// Range checks shared with the protocol: encode as the set_* message, decode it back.
template <typename Msg>
bool passes(const Msg& m) {
    uint8_t body[proto::kMaxPayload];
    Msg back;
    uint8_t bad;
    const uint8_t n = proto::encode(m, body);
    return proto::decode(body, n, back, bad) == proto::DecodeStatus::OK;
}
}  // namespace

bool valid(const Config& cfg) {
    for (uint8_t f = 0; f < proto::kFingerCount; ++f) {
        const Finger& c = cfg.finger[f];
        proto::SetGains g;
        fill_gains(c.gains, f, g);
        if (!passes(g) || check_gains(c.gains) != 0xFF) return false;
        proto::SetLimits l;
        fill_limits(c.limits, f, l);
        if (!passes(l) || check_limits(f, c.limits) != 0xFF) return false;
        proto::SetFingerConfig h;
        fill_hardware(c.hw, f, h);
        if (!passes(h)) return false;
    }
    proto::SetSafety s;
    s.heartbeat_timeout = cfg.safety.heartbeat_timeout_ms;
    s.safe_action = cfg.safety.safe_action;
    return passes(s);
}

LoadStatus load(Config& out) {
    Header h;
    uint8_t* hp = reinterpret_cast<uint8_t*>(&h);
    for (uint16_t i = 0; i < sizeof h; ++i) hp[i] = hal::eeprom_read(i);
    LoadStatus st = LoadStatus::LOADED;
    if (h.magic != kMagic) {
        st = LoadStatus::DEFAULTS_BLANK;
    } else if (h.version != kLayoutVersion || h.length != sizeof(Config)) {
        st = LoadStatus::DEFAULTS_VERSION;
    } else {
        uint8_t* cp = reinterpret_cast<uint8_t*>(&out);
        for (uint16_t i = 0; i < sizeof(Config); ++i) cp[i] = hal::eeprom_read(sizeof h + i);
        uint16_t crc = framing::crc16_ccitt(hp, sizeof h);
        crc = framing::crc16_ccitt(cp, sizeof(Config), crc);
        const uint16_t at = sizeof h + sizeof(Config);
        const uint16_t stored =
            (uint16_t)(hal::eeprom_read(at) | ((uint16_t)hal::eeprom_read(at + 1) << 8));
        if (crc != stored || !valid(out)) st = LoadStatus::DEFAULTS_CORRUPT;
    }
    if (st != LoadStatus::LOADED) defaults(out);
    return st;
}

void Writer::start(const Config& cfg) {
    Header h;
    h.magic = kMagic;
    h.version = kLayoutVersion;
    h.length = sizeof(Config);
    crc_ = framing::crc16_ccitt(reinterpret_cast<const uint8_t*>(&h), sizeof h);
    crc_ = framing::crc16_ccitt(reinterpret_cast<const uint8_t*>(&cfg), sizeof(Config), crc_);
    cfg_ = &cfg;
    pos_ = 0;
    passes_ = 0;
    failed_ = false;
}

uint8_t Writer::image_byte(uint16_t i) const {
    if (i < sizeof(Header)) {
        Header h;
        h.magic = kMagic;
        h.version = kLayoutVersion;
        h.length = sizeof(Config);
        return reinterpret_cast<const uint8_t*>(&h)[i];
    }
    i = (uint16_t)(i - sizeof(Header));
    if (i < sizeof(Config)) return reinterpret_cast<const uint8_t*>(cfg_)[i];
    return i == sizeof(Config) ? (uint8_t)crc_ : (uint8_t)(crc_ >> 8);
}

bool Writer::step() {
    if (!cfg_ || !hal::eeprom_ready()) return false;
    // Skip the bytes that already match (a few per call keeps loop() short), write one.
    for (uint8_t n = 0; n < 16 && pos_ < kImageBytes; ++n, ++pos_) {
        const uint8_t want = image_byte(pos_);
        if (hal::eeprom_read(pos_) != want) {
            hal::eeprom_write(pos_, want);
            ++pos_;
            return false;
        }
    }
    if (pos_ < kImageBytes) return false;
    // Read back: a byte that did not take (worn cell, power dip) is written again.
    for (uint16_t i = 0; i < kImageBytes; ++i) {
        if (hal::eeprom_read(i) != image_byte(i)) {
            if (++passes_ < kMaxPasses) {
                pos_ = i;
                return false;
            }
            failed_ = true;
            break;
        }
    }
    cfg_ = 0;
    return true;
}

}  // namespace config
}  // namespace utrf
