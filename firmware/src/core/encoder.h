// Joint-2 encoders: the AS5600 analog driver's checks and the reading-to-angle map.
//
// The hardware layer samples; this module judges the samples, so the rules are host-tested.
// Another sensor (AS5600 over I2C behind a TCA9548A, AS5048A over SPI) is a different driver
// producing the same hal::EncoderReading: a one-turn fraction and a status.
#ifndef UTRF_CORE_ENCODER_H
#define UTRF_CORE_ENCODER_H

#include <stdint.h>

#include "../hal/hal.h"
#include "fixed.h"

namespace utrf {
namespace encoder {

// AS5600 in analog mode drives 10 % of its supply at 0 degrees and 90 % at 360. The ADC uses
// the same 5 V as reference, so the reading is ratiometric: count = 1024 * (0.1 + 0.8 * turn).
// Valid band: 10-90 % with 1 % (10 counts) of tolerance each side for divider and ADC errors.
static const uint16_t kAdcBandLow = 92;
static const uint16_t kAdcBandHigh = 932;
// A sampler whose round counter has not moved for this many ticks has stopped (NO_DATA).
static const uint8_t kStaleTicks = 3;

// One AS5600 analog sample: its angle as a turn fraction and whether it lies in the sensor's
// valid band (judge(), below, adds the finger's angle and limits).
__attribute__((always_inline)) inline hal::EncoderReading as5600_reading(uint16_t sample) {
    hal::EncoderReading r;
    // 102.4..921.6 counts mapped to 0..65536, i.e. sample * 80 - 8192, modulo 2^16 (16-bit
    // arithmetic wraps exactly so). Code c goes to the angle of the input c * Vref / 1024: the
    // centre of the inputs that give c on the datasheet's ideal converter (first transition at
    // 0.5 LSB, last at 1.5 LSB below Vref), so the reading is unbiased. (Against a floor
    // converter it would be the bottom, half a count, 3.8 mrad, low.)
    r.turn = (uint16_t)((uint16_t)(sample * 80u) - 8192u);
    r.status = (sample < kAdcBandLow || sample > kAdcBandHigh) ? hal::EncoderStatus::OUT_OF_BAND
                                                               : hal::EncoderStatus::OK;
    r.angle = 0;
    r.flags = r.status == hal::EncoderStatus::OK ? 0 : hal::kReadingOut;  // see judge()
    return r;
}

// Joint-2 angle in BU (2 pi / 32768 rad, within +-pi) from a one-turn reading: the reading
// minus the reading at angle 0, wrapped to +-half a turn, counted against flexion for an
// encoder mounted the other way round. Two instructions' worth of 16-bit arithmetic.
__attribute__((always_inline)) inline int16_t angle_bu(uint16_t turn, uint16_t zero_turn,
                                                       bool invert) {
    const uint16_t d =
        UTRF_UNLIKELY(invert) ? (uint16_t)(zero_turn - turn) : (uint16_t)(turn - zero_turn);
    return (int16_t)((int16_t)d >> 1);  // -16384..16383
}

// The encoder's rules that need no memory of earlier readings, on a reading's turn and status:
// out of band (or no data) is kReadingOut; otherwise the angle with the finger's setup, and
// kReadingLimit beyond its fault limits. The one home of these rules: the sampler runs it on
// each sample (the AVR's ADC interrupt, between ticks, so the tick takes a ready angle) and
// the tick on a reading judged with an earlier setup (Finger::judge_reading()). The jump rule
// needs the finger's last angle: Finger::take_angle().
__attribute__((always_inline)) inline hal::EncoderReading judge(hal::EncoderReading r,
                                                                const hal::EncoderSetup& s) {
    if (r.status != hal::EncoderStatus::OK) {
        r.angle = 0;
        r.flags = hal::kReadingOut;
        return r;
    }
    r.angle = angle_bu(r.turn, s.zero_turn, s.invert);
    r.flags = (r.angle < s.low || r.angle > s.high) ? hal::kReadingLimit : 0;
    return r;
}
// A sample judged for the tick.
__attribute__((always_inline)) inline hal::EncoderReading judge(uint16_t sample,
                                                                const hal::EncoderSetup& s) {
    return judge(as5600_reading(sample), s);
}

// A reading with no data (the sampler stopped).
inline hal::EncoderReading no_data() {
    hal::EncoderReading r;
    r.turn = 0;
    r.status = hal::EncoderStatus::NO_DATA;
    r.angle = 0;
    r.flags = hal::kReadingOut;
    return r;
}

// Watches the sampler's round counter: a counter that stands still for kStaleTicks ticks
// means the sampling stopped, and every reading is NO_DATA.
class Staleness {
   public:
    Staleness() : last_seq_(0), stale_(0) {}
    // Once per tick, with the counter; true while the readings are stale.
    bool stale(uint8_t seq) {
        if (seq != last_seq_) {
            last_seq_ = seq;
            stale_ = 0;
        } else if (stale_ < kStaleTicks) {
            ++stale_;
        }
        return stale_ >= kStaleTicks;
    }

   private:
    uint8_t last_seq_;
    uint8_t stale_;
};

// Angle (rad) <-> one-turn count, for configuration (loop() context).
uint16_t turn_from_rad(float rad);
float rad_from_turn(uint16_t turn);

}  // namespace encoder
}  // namespace utrf

#endif  // UTRF_CORE_ENCODER_H
