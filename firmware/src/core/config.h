// The board's configuration: per-finger gains, limits and hardware, and the board-wide safety
// settings; its defaults, its checks, and its EEPROM image.
//
// Values are kept as the protocol carries them (SI floats; durations and duties as the wire's
// scaled integers), so get_* replies give back exactly what set_* stored.
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

namespace utrf {
namespace config {

#pragma pack(push, 1)
struct Gains {
    float kp;                   // duty / rad
    float ki;                   // duty / (rad s)
    float kd;                   // duty s / rad
    float d_cutoff_hz;          // Hz
    uint16_t deadband_milli;    // duty * 1000
    float slew_per_s;           // duty / s
    uint16_t max_duty_milli;    // duty * 1000
    uint16_t pretension_milli;  // duty * 1000
};

struct Limits {
    float theta2_min;        // rad
    float theta2_max;        // rad
    float limit_margin;      // rad
    float stall_error;       // rad
    float stall_motion;      // rad
    uint16_t stall_time_ms;  // ms
    float encoder_jump;      // rad per tick
};

struct Hardware {
    uint8_t actuation;  // proto::Actuation
    float encoder_offset;  // rad: the encoder's reading at Joint-2 angle 0
    uint8_t encoder_invert;
    uint8_t motor_invert;
};

// Moves (set_motion; core/path.h): the limits a move's path keeps, and the feedforward gains.
struct Motion {
    float max_speed;  // rad/s
    float max_accel;  // rad/s^2
    float kv;         // duty per rad/s of the path's speed
    float ka;         // duty per rad/s^2 of its acceleration
};

struct Finger {
    Gains gains;
    Limits limits;
    Hardware hw;
    Motion motion;
};

struct Safety {
    uint16_t heartbeat_timeout_ms;
    uint8_t safe_action;  // proto::SafeAction
};

struct Config {
    Finger finger[5];
    Safety safety;
};

struct Header {
    uint32_t magic;
    uint16_t version;
    uint16_t length;
};
#pragma pack(pop)

static const uint32_t kMagic = 0x46525455UL;  // "UTRF" in little-endian bytes
static const uint16_t kLayoutVersion = 2;  // 2: Motion added
static const uint16_t kImageBytes = sizeof(Header) + sizeof(Config) + 2;

void defaults(Config& cfg);
Gains default_gains();
Limits default_limits(uint8_t finger);
Motion default_motion();

// Checks beyond the protocol's per-field ranges. They return 0xFF when the values are
// acceptable, or the field index (the nack detail) of the first field that is not.
//   gains: a pretension of at least max_duty leaves the antagonistic controller no range;
//   limits: theta2_min < theta2_max, both within the finger's geometric range.
uint8_t check_gains(const Gains& g);
uint8_t check_limits(uint8_t finger, const Limits& l);
// Every value within the protocol's ranges and the checks above (an EEPROM image's body).
bool valid(const Config& cfg);

// A finger's settings into the protocol message that carries them: the get_* reply or the
// set_* request (the two have the same fields).
template <typename Msg>
void fill_gains(const Gains& g, uint8_t f, Msg& m) {
    m.finger = f;
    m.kp = g.kp;
    m.ki = g.ki;
    m.kd = g.kd;
    m.d_cutoff_hz = g.d_cutoff_hz;
    m.deadband_duty = g.deadband_milli;
    m.slew_per_s = g.slew_per_s;
    m.max_duty = g.max_duty_milli;
    m.pretension_duty = g.pretension_milli;
}

template <typename Msg>
void fill_limits(const Limits& l, uint8_t f, Msg& m) {
    m.finger = f;
    m.theta2_min = l.theta2_min;
    m.theta2_max = l.theta2_max;
    m.limit_margin = l.limit_margin;
    m.stall_error = l.stall_error;
    m.stall_motion = l.stall_motion;
    m.stall_time = l.stall_time_ms;
    m.encoder_jump = l.encoder_jump;
}

template <typename Msg>
void fill_hardware(const Hardware& h, uint8_t f, Msg& m) {
    m.finger = f;
    m.actuation = h.actuation;
    m.encoder_offset = h.encoder_offset;
    m.encoder_invert = h.encoder_invert;
    m.motor_invert = h.motor_invert;
}

template <typename Msg>
void fill_motion(const Motion& v, uint8_t f, Msg& m) {
    m.finger = f;
    m.max_speed = v.max_speed;
    m.max_accel = v.max_accel;
    m.kv = v.kv;
    m.ka = v.ka;
}

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
