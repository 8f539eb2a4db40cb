// Fixed-point arithmetic for the control tick.
//
// The ATmega2560 has no FPU (floats are slow: firmware/README.md, Timing) and every 32-bit
// operation costs four 8-bit ones, so the tick works in 16-bit integers wherever the range
// allows, and multiplies 16 x 16 -> 32 bits. Floats appear only where loop() turns
// configuration (SI units) into the coefficients below.
//
// Units inside the tick:
//   angle  int16 "BU", 2 pi / 32768 rad (1.92e-4 rad; the encoder's one-turn count / 2).
//          Angles stay within +-pi (+-16384), so the difference of any two fits int16: errors,
//          jumps and limit checks need no saturation. The protocol's 1e-4 rad ("AU") is
//          converted in loop() context.
//   duty   int16 Q15 (32768 = full duty, clamped to 32767) for outputs; Q23 and Q31 in int32
//          inside the PID, for resolution
#ifndef UTRF_CORE_FIXED_H
#define UTRF_CORE_FIXED_H

#include <stdint.h>
#include <string.h>

namespace utrf {
namespace fx {

static const int32_t kOne15 = 32768L;     // duty 1.0 in Q15
static const int16_t kMax15 = 32767;      // the largest duty an int16 Q15 holds
static const int32_t kOne23 = 8388608L;   // duty 1.0 in Q23
static const float kAuPerRad = 1e4f;
static const float kBuPerRad = 5215.18917f;  // 32768 / (2 pi)
static const int16_t kBuHalfTurn = 16384;    // pi

inline int32_t clamp32(int32_t v, int32_t lo, int32_t hi) {
    return v < lo ? lo : (v > hi ? hi : v);
}
inline int16_t clamp16(int16_t v, int16_t lo, int16_t hi) {
    return v < lo ? lo : (v > hi ? hi : v);
}
inline int16_t sat16(int32_t v) {
    return v > 32767 ? (int16_t)32767 : (v < -32767 ? (int16_t)-32767 : (int16_t)v);
}
inline int16_t abs16(int16_t v) { return v < 0 ? (int16_t)-v : v; }
// a + b saturated to +-32767, in 16 bits (an add and a branch on overflow).
inline int16_t sat_add16(int16_t a, int16_t b) {
    int16_t r;
    if (__builtin_add_overflow(a, b, &r)) return a < 0 ? (int16_t)-32767 : (int16_t)32767;
    return r == -32768 ? (int16_t)-32767 : r;
}

// A 24-bit signed integer for values known to fit (|x| < 2^23): on the AVR avr-gcc's __int24
// (three bytes: an add, a compare or a copy a byte shorter than int32's), elsewhere int32_t.
// The same values either way (each use states its bound).
#if defined(__AVR__)
typedef __int24 int24;
#else
typedef int32_t int24;
#endif

// Branch hints for the tick's usual paths (they change no result).
#define UTRF_LIKELY(x) __builtin_expect(!!(x), 1)
#define UTRF_UNLIKELY(x) __builtin_expect(!!(x), 0)

// 16 x 16 -> 32-bit multiplies, written so that avr-gcc sees a widening multiply (its MUL
// sequences, no 32 x 32 product).
inline int32_t mul_su(int16_t a, uint16_t b) { return (int32_t)a * (int32_t)b; }
inline uint32_t mul_uu(uint16_t a, uint16_t b) { return (uint32_t)a * (uint32_t)b; }
inline uint16_t mul8u(uint8_t a, uint8_t b) { return (uint16_t)((uint16_t)a * b); }
inline int16_t mul8su(int8_t a, uint8_t b) { return (int16_t)((int16_t)a * (uint16_t)b); }

// The bytes of a 16-bit value, through memcpy: avr-gcc then takes the register's byte, where
// from (x >> 8) it makes a 16-bit value again, and an 8 x 8 product of it a 16 x 16 one
// (three MULs). Little-endian (the AVR and the hosts the tests run on).
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "lo8() and hi8() are little-endian");
__attribute__((always_inline)) inline uint8_t lo8(uint16_t x) {
    uint8_t b[2];
    memcpy(b, &x, 2);
    return b[0];
}
__attribute__((always_inline)) inline uint8_t hi8(uint16_t x) {
    uint8_t b[2];
    memcpy(b, &x, 2);
    return b[1];
}

// A 16 x 16 product (a signed, b unsigned) from its four 8 x 8 ones, written out in C so the
// tick needs no libgcc call (whose call, return and sign correction cost as much as its
// four MULs): p = a b = hh 2^16 + (hl + t) 2^8 + l0, with t = lh + (ll >> 8), which fits 16
// bits. The slices the tick uses are taken from the pieces in 8- and 16-bit arithmetic,
// exactly (tests/firmware/test_fw_avr.py checks them against the 32-bit product, on the host
// and, through the core check, on the AVR).
struct ProdSU {
    int16_t hh;  // (a >> 8) (b >> 8)
    int16_t hl;  // (a >> 8) (b & 0xFF)
    uint16_t t;  // (a & 0xFF) (b >> 8) + ((a & 0xFF) (b & 0xFF) >> 8)
    uint8_t l0;  // the product's low byte
};
__attribute__((always_inline)) inline ProdSU prod_su(int16_t a, uint16_t b) {
    const uint8_t al = lo8((uint16_t)a);
    const int8_t ah = (int8_t)hi8((uint16_t)a);
    const uint8_t bl = lo8(b);
    const uint8_t bh = hi8(b);
    const uint16_t ll = mul8u(al, bl);
    ProdSU q;
    q.hh = mul8su(ah, bh);
    q.hl = mul8su(ah, bl);
    q.t = (uint16_t)(mul8u(al, bh) + hi8(ll));
    q.l0 = lo8(ll);
    return q;
}
// floor(p / 2^16), and floor((p + 2^15) / 2^16) with round (t + 128 still fits 16 bits).
__attribute__((always_inline)) inline int16_t prod_hi16(ProdSU q, bool round = false) {
    if (round) q.t = (uint16_t)(q.t + 128u);
    // floor((hl + t) / 256) = (hl >> 8) + (t >> 8) + the carry of their low bytes
    const uint8_t carry = hi8((uint16_t)((uint16_t)lo8((uint16_t)q.hl) + lo8(q.t)));
    return (int16_t)(q.hh + (int8_t)hi8((uint16_t)q.hl) + hi8(q.t) + carry);
}
// (int16_t)(p >> 8): hh 2^8 + hl + t, modulo 2^16.
__attribute__((always_inline)) inline int16_t prod_mid16(const ProdSU& q) {
    return (int16_t)(uint16_t)((uint16_t)((uint16_t)lo8((uint16_t)q.hh) << 8) +
                               (uint16_t)q.hl + q.t);
}
// (int16_t)p: the low byte of hl + t, then l0.
__attribute__((always_inline)) inline int16_t prod_lo16(const ProdSU& q) {
    return (int16_t)(uint16_t)((uint16_t)((uint16_t)lo8((uint16_t)((uint16_t)q.hl + q.t)) << 8) |
                               q.l0);
}

// A gain as a 16-bit mantissa and a byte-multiple exponent: y = x * m * 2^shift with shift
// one of 16, 8, 0, -8, -16, so the tick needs one 16 x 16 multiply and byte moves. make()
// picks the exponent that keeps the most mantissa bits (at least 8 for any gain the
// protocol allows) and the input bound beyond which the product saturates at ymax, so the
// saturation test is one 16-bit compare.
struct Gain {
    uint16_t m;
    int8_t shift;
    int16_t xlim;    // |x| > xlim: the product is beyond ymax
    uint16_t xspan;  // 2 xlim: |x| > xlim is (uint16_t)(x + xlim) > xspan, one compare
};
// |x| > g.xlim (0 <= xlim <= 32767) in one unsigned compare: x + xlim lies in [0, 2 xlim]
// exactly when |x| <= xlim; below -xlim it wraps to 32768 + xlim or more, above 2 xlim.
__attribute__((always_inline)) inline bool beyond(const Gain& g, int16_t x) {
    return (uint16_t)((uint16_t)x + (uint16_t)g.xlim) > g.xspan;
}

Gain make_gain(float value, int32_t ymax);
float gain_value(const Gain& g);

// x * gain, saturated to +-ymax (the ymax the gain was made for).
__attribute__((always_inline)) inline int32_t apply(const Gain& g, int16_t x, int32_t ymax) {
    if (__builtin_expect(beyond(g, x), 0)) return x > 0 ? ymax : -ymax;
    const int32_t p = mul_su(x, g.m);  // |p| < 2^31
    switch (g.shift) {
        case 16:
            return (int32_t)((uint32_t)p << 16);
        case 8:
            return (int32_t)((uint32_t)p << 8);
        case 0:
            return p;
        case -8:
            return p >> 8;
        default:
            return p >> 16;
    }
}

// apply()'s fast path for a gain that can never saturate, chosen once where the gain is
// compiled (plain()): shift 0 and |x m| <= ymax for every |x| <= 32767, so the product alone
// (no saturation test, no exponent switch). Equal to apply() for x != -32768.
inline bool plain(const Gain& g, int32_t ymax) {
    return g.shift == 0 && (int32_t)g.m * 32767L <= ymax;
}
__attribute__((always_inline)) inline int32_t apply_plain(const Gain& g, int16_t x) {
    return mul_su(x, g.m);
}

// The same for a term kept in 16 bits (ymax <= 32767): for gains of shift -16, -8 or 0 the
// result is a byte-aligned slice of the product; a larger gain saturates every x but 0
// (its xlim is 0).
__attribute__((always_inline)) inline int16_t apply16(const Gain& g, int16_t x, int16_t ymax) {
    if (__builtin_expect(beyond(g, x), 0)) return x > 0 ? ymax : (int16_t)-ymax;
    const ProdSU q = prod_su(x, g.m);  // |p >> -shift| <= ymax
    if (g.shift == -16) return prod_hi16(q);
    if (g.shift == -8) return prod_mid16(q);
    return prod_lo16(q);
}

// apply16()'s fast path for a gain of shift -16 that cannot saturate for |x| <= xmax, chosen
// once where the gain is compiled (hi16_plain()): the product's high word alone. Equal to
// apply16() for |x| <= xmax.
inline bool hi16_plain(const Gain& g, int16_t xmax) { return g.shift == -16 && g.xlim >= xmax; }
__attribute__((always_inline)) inline int16_t apply16_hi(const Gain& g, int16_t x) {
    return prod_hi16(prod_su(x, g.m));
}

// apply16() for a gain of shift -8 (mid16(): chosen once where the gain is compiled): the
// saturation test and the product's middle word, no exponent switch. Equal to apply16().
inline bool mid16(const Gain& g) { return g.shift == -8; }
__attribute__((always_inline)) inline int16_t apply16_mid(const Gain& g, int16_t x, int16_t ymax) {
    if (__builtin_expect(beyond(g, x), 0)) return x > 0 ? ymax : (int16_t)-ymax;
    return prod_mid16(prod_su(x, g.m));
}

// x * c / 65536 for any int32 x (the result must fit), c an unsigned Q16 fraction: two
// 16 x 16 multiplies instead of one 32 x 32 into 64 bits, which avr-gcc makes slow. Floors.
__attribute__((always_inline)) inline int32_t mul_q16(int32_t x, uint16_t c) {
    const int32_t hi = mul_su((int16_t)(x >> 16), c);
    const uint32_t lo = mul_uu((uint16_t)x, c) >> 16;
    return hi + (int32_t)lo;
}

// Float to the nearest integer, saturating to int32; NaN gives 0.
// Q15 duty to the state message's 1/128 counts, rounded: the high byte (a byte move on the
// AVR), +1 when the low byte is half or more, saturated at 127.
inline int8_t duty_counts(int16_t q15) {
    const uint8_t hi = (uint8_t)((uint16_t)q15 >> 8);
    const uint8_t lo = (uint8_t)q15;
    if ((lo & 0x80) && hi != 0x7F) return (int8_t)(hi + 1);
    return (int8_t)hi;
}

int32_t round_sat(float v);
// Radians to BU, clamped to +-pi.
int16_t bu(float rad);
// BU to the protocol's 1e-4 rad, rounded (x 62832 / 32768).
inline int16_t au_from_bu(int16_t b) {
    return (int16_t)((mul_su(b, 62832u) * 2 + 32768L) >> 16);
}

}  // namespace fx
}  // namespace utrf

#endif  // UTRF_CORE_FIXED_H
