// The board's configuration: per-finger gains, limits and hardware, and the board-wide safety
// settings; its defaults, its checks, and its EEPROM image.
//
// The structs, the layout's version, the spec's defaults and the copies to and from the
// messages are generated from protocol/spec.toml (generated/config_layout.h). Values are kept
// as the protocol carries them (SI floats; durations and duties as the wire's scaled
// integers), so get_* replies give back exactly what set_* stored.
//
// EEPROM image (little-endian, at address 0):
//   offset 0  u32 magic 'UTRF' (0x46525455)
//   offset 4  u16 layout version (kLayoutVersion)
//   offset 6  u16 body length (sizeof(Config))
//   offset 8  body: Config, packed
//   then      u16 CRC-16/CCITT-FALSE over the header and the body
// A blank (erased) EEPROM, a failed CRC, another version or length, or a value out of range
// loads the defaults and says why (ConfigStatus); garbage is never used.
#ifndef UTRF_CORE_CONFIG_H
#define UTRF_CORE_CONFIG_H

#include <stdint.h>

#include "../generated/config_layout.h"

namespace utrf {
namespace config {

#pragma pack(push, 1)
struct Header {
    uint32_t magic;
    uint16_t version;
    uint16_t length;
};
#pragma pack(pop)

static const uint32_t kMagic = 0x46525455UL;  // "UTRF" in little-endian bytes
static const uint16_t kImageBytes = sizeof(Header) + sizeof(Config) + 2;

void defaults(Config& cfg);
Gains default_gains();
Limits default_limits(uint8_t finger);

// Checks beyond the protocol's per-field ranges. They return 0xFF when the values are
// acceptable, or the field index (the nack detail) of the first field that is not.
//   gains: a pretension of at least max_duty leaves the antagonistic controller no range;
//   limits: theta2_min < theta2_max, both within the finger's geometric range.
uint8_t check_gains(const Gains& g);
uint8_t check_limits(uint8_t finger, const Limits& l);
// Every value within the protocol's ranges and the checks above (an EEPROM image's body).
bool valid(const Config& cfg);

// The checks of a set_ request beyond the spec's ranges, by message (the generic handler in
// dispatch.cpp calls the one its request has): 0xFF, or the nack detail.
inline uint8_t check(const proto::SetGains&, const Gains& g) { return check_gains(g); }
inline uint8_t check(const proto::SetLimits& m, const Limits& l) { return check_limits(m.finger, l); }
inline uint8_t check(const proto::SetFingerConfig&, const Hardware&) { return 0xFF; }
inline uint8_t check(const proto::SetSafety&, const Safety&) { return 0xFF; }

// ---- EEPROM ------------------------------------------------------------------------------------
enum class LoadStatus : uint8_t {  // values match proto::ConfigStatus
    LOADED = 0,
    DEFAULTS_BLANK = 1,
    DEFAULTS_CORRUPT = 2,
    DEFAULTS_VERSION = 3,
};

// Reads the image (a few hundred byte reads: fast, loop() or start-up context). On any
// problem `out` holds the defaults.
LoadStatus load(Config& out);

// Writes the image a byte at a time without blocking: start(), then step() from loop() until
// it returns true. Bytes that already hold the right value are not rewritten (EEPROM wear,
// and ~3.4 ms per written byte). The configuration must not change while busy().
class Writer {
   public:
    Writer() : cfg_(0), pos_(0), crc_(0), passes_(0), failed_(false) {}
    void start(const Config& cfg);
    bool busy() const { return cfg_ != 0; }
    // Returns true once, when the write is over: then failed() tells whether the image read
    // back equal (a byte that does not take is rewritten, at most kMaxPasses times).
    bool step();
    bool failed() const { return failed_; }
    static const uint8_t kMaxPasses = 3;

   private:
    uint8_t image_byte(uint16_t i) const;
    const Config* cfg_;
    uint16_t pos_;
    uint16_t crc_;
    uint8_t passes_;
    bool failed_;
};

}  // namespace config
}  // namespace utrf

#endif  // UTRF_CORE_CONFIG_H
