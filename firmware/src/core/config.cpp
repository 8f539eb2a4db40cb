#include "config.h"

#include <string.h>

#include "../generated/protocol_messages.h"
#include "../hal/hal.h"
#include "framing.h"
#include "kinematics.h"

namespace utrf {
namespace config {

// The defaults are the spec's (conservative gains for a tendon finger on a geared DC motor:
// full duty at about 0.3 rad of error; the encoder mounted so the straight finger reads
// mid-band, clear of the sensor's wrap), but for what depends on the finger's geometry.
Gains default_gains() {
    Gains g;
    spec_defaults(g);
#ifdef UTRF_DEFAULT_MAX_DUTY  // a build with another duty cap (a firmware A/B: make firmware-b)
    g.max_duty = UTRF_DEFAULT_MAX_DUTY;
#endif
    return g;
}

Limits default_limits(uint8_t finger) {
    const uint8_t geo = kin::finger_geometry(finger);
    Limits l;
    spec_defaults(l);
    l.theta2_min = kin::theta2_min(geo);
    l.theta2_max = kin::theta2_max(geo);
    return l;
}

void defaults(Config& cfg) {
    memset(&cfg, 0, sizeof cfg);
    for (uint8_t f = 0; f < proto::kFingerCount; ++f) {
        cfg.finger[f].gains = default_gains();
        cfg.finger[f].limits = default_limits(f);
        spec_defaults(cfg.finger[f].hw);
        spec_defaults(cfg.finger[f].motion);
    }
    spec_defaults(cfg.safety);
}

uint8_t check_gains(const Gains& g) {
    if (g.pretension_duty > 0 && g.pretension_duty >= g.max_duty) return 8;
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

bool valid(const Config& cfg) {
    if (!within_spec_ranges(cfg)) return false;
    for (uint8_t f = 0; f < proto::kFingerCount; ++f) {
        if (check_gains(cfg.finger[f].gains) != 0xFF) return false;
        if (check_limits(f, cfg.finger[f].limits) != 0xFF) return false;
    }
    return true;
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
