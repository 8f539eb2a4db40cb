// Fixed-point arithmetic for the control tick.
//
// The ATmega2560 has no FPU: a float multiply-add costs some 200 cycles, and five PID loops in
// float would take most of a 1 ms tick. The tick therefore works in integers; floats appear
// only where loop() turns configuration (SI units) into the coefficients below.
//
// Units inside the tick:
//   angle: int32, 1e-4 rad per count ("AU"), the protocol's and the kinematics table's unit;
//   duty:  Q16 (65536 = full duty) for outputs, Q24 inside the PID for resolution.
#ifndef UTRF_CORE_FIXED_H
#define UTRF_CORE_FIXED_H

#include <stdint.h>

namespace utrf {
namespace fx {

static const int32_t kOne16 = 65536L;     // duty 1.0 in Q16
static const int32_t kOne24 = 16777216L;  // duty 1.0 in Q24
static const float kAuPerRad = 1e4f;      // angle units per radian

inline int32_t clamp(int32_t v, int32_t lo, int32_t hi) {
    return v < lo ? lo : (v > hi ? hi : v);
}

inline int32_t abs32(int32_t v) { return v < 0 ? -v : v; }

// Arithmetic right shift with rounding to nearest, so small negative and positive values
// are treated alike (a plain >> floors, which biases integrators toward -inf).
inline int32_t shr_round(int32_t v, uint8_t n) { return (v + (1L << (n - 1))) >> n; }

// A gain with a saturating product: gain * x is limited to +-ymax without overflowing int32.
// xlim = ymax / coef is precomputed, so the tick needs no division.
struct SatGain {
    int32_t coef;
    int32_t xlim;  // |x| > xlim saturates
    int32_t ymax;
};

SatGain make_sat_gain(float coef, int32_t ymax);

inline int32_t sat_mul(const SatGain& g, int32_t x) {
    if (x > g.xlim) return g.ymax;
    if (x < -g.xlim) return -g.ymax;
    return g.coef * x;
}

// x * c / 65536 for any int32 x (the result must fit), c an unsigned Q16 fraction. Two 16x16
// multiplies instead of one 32x32 into 64 bits, which avr-gcc makes slow. Floors.
inline int32_t mul_q16(int32_t x, uint16_t c) {
    int32_t hi = (x >> 16) * (int32_t)c;                       // signed high half
    uint32_t lo = ((uint32_t)(uint16_t)(x & 0xFFFF) * c) >> 16;  // unsigned low half
    return hi + (int32_t)lo;
}

// Float to the nearest integer, saturating to int32.
int32_t round_sat(float v);

}  // namespace fx
}  // namespace utrf

#endif  // UTRF_CORE_FIXED_H
