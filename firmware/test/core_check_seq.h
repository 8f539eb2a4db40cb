// A fixed workload over the core's fixed-point arithmetic, folded into one checksum. The AVR
// build (firmware/test/avr/core_check.cpp, run on simavr) and the host build (capi.cpp) run
// the same sequence: equal checksums show the AVR (its 16-bit int, avr-gcc's multiplies) gives
// exactly the host-tested results.
#ifndef UTRF_TEST_CORE_CHECK_SEQ_H
#define UTRF_TEST_CORE_CHECK_SEQ_H

#include <stdint.h>

#include "core/encoder.h"
#include "core/finger.h"
#include "core/fixed.h"
#include "core/pid.h"

namespace utrf {
namespace check {

struct Fnv {
    uint32_t h;
    Fnv() : h(2166136261UL) {}
    void add(uint32_t v) {
        for (uint8_t i = 0; i < 4; ++i) {
            h ^= (uint8_t)(v >> (8 * i));
            h *= 16777619UL;
        }
    }
};

struct Lcg {
    uint32_t s;
    explicit Lcg(uint32_t seed) : s(seed) {}
    uint16_t next() {
        s = s * 1664525UL + 1013904223UL;
        return (uint16_t)(s >> 16);
    }
};

// The slices of a 16 x 16 product taken from its 8 x 8 pieces (fixed.h, ProdSU) against the
// 32-bit product, for a's of every high byte and low byte pattern against a sweep of b's:
// the number of slices that differ (0 expected).
inline uint32_t product_mismatches() {
    uint32_t bad = 0;
    for (int32_t a = -32768; a < 32768; a += 37) {
        for (int32_t b = 0; b < 65536; b += 251) {
            const int32_t p = fx::mul_su((int16_t)a, (uint16_t)b);
            const fx::ProdSU q = fx::prod_su((int16_t)a, (uint16_t)b);
            bad += fx::prod_hi16(q) != (int16_t)(p >> 16);
            bad += fx::prod_hi16(q, true) != (int16_t)((p + 32768L) >> 16);
            bad += fx::prod_mid16(q) != (int16_t)(p >> 8);
            bad += fx::prod_lo16(q) != (int16_t)p;
        }
    }
    // and the edges: a and b at their extremes and next to them
    const int32_t as[] = {-32768, -32767, -257, -256, -255, -129, -128, -1, 0, 1, 127, 128,
                          255, 256, 32766, 32767};
    const int32_t bs[] = {0, 1, 127, 128, 255, 256, 257, 32767, 32768, 65279, 65280, 65534, 65535};
    for (uint8_t i = 0; i < sizeof as / sizeof as[0]; ++i) {
        for (uint8_t j = 0; j < sizeof bs / sizeof bs[0]; ++j) {
            const int32_t p = fx::mul_su((int16_t)as[i], (uint16_t)bs[j]);
            const fx::ProdSU q = fx::prod_su((int16_t)as[i], (uint16_t)bs[j]);
            bad += fx::prod_hi16(q) != (int16_t)(p >> 16);
            bad += fx::prod_hi16(q, true) != (int16_t)((p + 32768L) >> 16);
            bad += fx::prod_mid16(q) != (int16_t)(p >> 8);
            bad += fx::prod_lo16(q) != (int16_t)p;
        }
    }
    // apply(): x * gain, every shift, against the 32-bit product shifted
    const float gains[] = {0.37f, 2.5f, 100.3f, 838.9f, 12345.0f, 1.6e6f, 8.4e7f, 4.0e9f};
    for (uint8_t k = 0; k < sizeof gains / sizeof gains[0]; ++k) {
        const fx::Gain g = fx::make_gain(gains[k], 1L << 30);
        for (int32_t x = -32768; x < 32768; x += 7) {
            int32_t want;
            if (x > g.xlim) {
                want = 1L << 30;
            } else if (x < -g.xlim) {
                want = -(1L << 30);
            } else {
                const int32_t p = fx::mul_su((int16_t)x, g.m);
                want = g.shift == 16  ? (int32_t)((uint32_t)p << 16)
                       : g.shift == 8 ? (int32_t)((uint32_t)p << 8)
                       : g.shift == 0 ? p
                       : g.shift == -8 ? p >> 8
                                       : p >> 16;
            }
            bad += fx::apply(g, (int16_t)x, 1L << 30) != want;
        }
    }
    return bad;
}

inline uint32_t core_check_run() {
    Fnv f;
    Lcg r(12345);
    for (uint16_t i = 0; i < 3000; ++i) {
        const int16_t a = (int16_t)r.next();
        const uint16_t b = r.next();
        f.add((uint32_t)fx::mul_su(a, b));
        f.add(fx::mul_uu(b, r.next()));
        f.add((uint32_t)fx::mul_q16((int32_t)(((uint32_t)r.next() << 16) | r.next()), r.next()));
        f.add((uint16_t)fx::au_from_bu((int16_t)(a >> 1)));
        // The product's slices from its 8 x 8 pieces (the tick's P, D and filter).
        const fx::ProdSU q = fx::prod_su(a, b);
        f.add((uint16_t)fx::prod_hi16(q));
        f.add((uint16_t)fx::prod_hi16(q, true));
        f.add((uint16_t)fx::prod_mid16(q));
        f.add((uint16_t)fx::prod_lo16(q));
    }
    // Byte products, and Q15 duty to PWM counts (both 8 x 8 multiplies on the AVR).
    for (uint16_t i = 0; i < 2000; ++i) {
        const uint16_t x = r.next();
        f.add(fx::mul8u((uint8_t)x, (uint8_t)(x >> 8)));
        f.add(finger::pwm_counts((uint16_t)(x >> 1)));
    }
    // Gains over the protocol's range, applied with their saturation.
    const float values[] = {0.0f, 1e-3f, 0.37f, 2.5f, 838.9f, 12345.0f, 1.6e6f, 8.4e7f};
    for (uint8_t k = 0; k < sizeof values / sizeof values[0]; ++k) {
        const fx::Gain g = fx::make_gain(values[k], pid::kTermMax14);
        f.add(g.m);
        f.add((uint32_t)(int32_t)g.shift);
        f.add((uint32_t)(int32_t)g.xlim);
        for (uint8_t i = 0; i < 50; ++i) f.add((uint32_t)fx::apply16(g, (int16_t)r.next(), pid::kTermMax14));
    }
    // The PID on a random walk of target and measurement, coefficients given as integers.
    pid::Coeffs c = pid::Coeffs();
    c.kp = fx::make_gain(1677.7f, pid::kTermMax14);
    c.ki = fx::make_gain(429.5f, pid::kIStepMax31);
    c.kd = fx::make_gain(6283.2f, pid::kTermMax14);
    c.alpha = 11000;
    c.slew = 655;
    c.deadband = 1311;
    c.db_inverse = (uint16_t)(65536UL * pid::kDeadbandRamp15 / (pid::kDeadbandRamp15 + 1311));
    pid::Pid p;
    p.load(c);
    p.reset(22937, 3000, 0);
    int16_t target = 0;
    int16_t meas = 0;
    for (uint16_t i = 0; i < 4000; ++i) {
        target = (int16_t)(target + (int16_t)(r.next() % 41) - 20);
        meas = (int16_t)(meas + (int16_t)(r.next() % 9) - 4);
        target = fx::clamp16(target, -12000, 12000);
        meas = fx::clamp16(meas, -12000, 12000);
        const int16_t u = (i % 500) < 450 ? p.step(22937, target, meas)
                                          : p.step_open(22937, (int16_t)r.next(), meas);
        f.add((uint16_t)u);
        f.add((uint32_t)p.integrator31());
        f.add((uint16_t)p.velocity8());
        if (i % 1000 == 999) p.set_coeffs(c, 16000);
    }
    // Every path of the step: gains of each shift (16, 8, 0, -8, -16) and zero, their terms
    // saturated by large errors and speeds, the deadband's ramp and none, a slew limit that
    // binds and one that never does, limits from 0 to full, and a limit lowered without a
    // rebase (the integrator left beyond it).
    // (kp, ki, kd): each shift of ki in a set whose output is often free, so it integrates.
    const float sets[][3] = {{1677.7f, 429.5f, 6283.2f}, {0.37f, 100.3f, 100.3f},
                             {1.6e6f, 4.0e6f, 8.4e7f},   {0.0f, 0.5f, 0.37f},
                             {8.4e7f, 0.37f, 1.6e6f},    {100.3f, 8.4e7f, 0.0f}};
    const uint16_t alphas[] = {11000, 65535, 1, 30000, 5000, 40000};
    const int16_t slews[] = {655, 32767, 1, 100, 3000, 20};
    const int16_t deadbands[] = {1311, 0, 16384, 0, 200, 100};
    const int16_t limits[] = {22937, 32767, 0, 3000};
    for (uint8_t k = 0; k < 6; ++k) {
        pid::Coeffs ck = pid::Coeffs();
        ck.kp = fx::make_gain(sets[k][0], pid::kTermMax14);
        ck.ki = fx::make_gain(sets[k][1], pid::kIStepMax31);
        ck.kd = fx::make_gain(sets[k][2], pid::kTermMax14);
        ck.alpha = alphas[k];
        ck.slew = slews[k];
        ck.deadband = deadbands[k];
        ck.db_inverse =
            (uint16_t)(65536UL * pid::kDeadbandRamp15 / (pid::kDeadbandRamp15 + deadbands[k]));
        for (uint8_t l = 0; l < 4; ++l) {
            int16_t limit = limits[l];
            pid::Pid q;
            q.load(ck);
            q.reset(limit, (int16_t)(limit / 3), 0);
            target = 0;
            meas = 0;
            for (uint16_t i = 0; i < 500; ++i) {
                const uint16_t n = r.next();
                if (n % 64 == 0) {
                    target = (int16_t)((int16_t)(r.next() % 24001) - 12000);  // a step
                } else {
                    target = (int16_t)(target + (int16_t)(r.next() % 41) - 20);
                }
                meas = (int16_t)(meas + (int16_t)(r.next() % 61) - 30);
                if (n % 97 == 1) meas = (int16_t)(meas + (int16_t)(r.next() % 400) - 200);
                target = fx::clamp16(target, -16000, 16000);
                meas = fx::clamp16(meas, -16000, 16000);
                if (i == 250) limit = (int16_t)(limit / 2);  // lowered without a rebase
                if (i == 400) q.set_coeffs(ck, limit);
                const int16_t u = q.step(limit, target, meas);
                f.add((uint16_t)u);
                f.add((uint32_t)q.integrator31());
                f.add((uint16_t)q.velocity8());
                f.add(q.saturated() ? 1u : 0u);
            }
        }
    }
    // Edges the random walks seldom meet: with kp = 256 (shift 0) and no I or D term the
    // unlimited output v equals e, swept across the deadband's ramp (+-256) and the limit;
    // d(measured) swept across its clamp (+-63); and integrator steps of about 2^16 from next
    // to the integrator's bound, where its compares come down to the low bytes.
    const int16_t edge_db[] = {0, 100, 1311};
    for (uint8_t k = 0; k < 6; ++k) {
        const int16_t db = edge_db[k % 3];
        const int16_t limit = k < 3 ? 200 : 32767;
        pid::Coeffs ce = pid::Coeffs();
        ce.kp = fx::make_gain(256.0f, pid::kTermMax14);
        ce.ki = fx::make_gain(0.0f, pid::kIStepMax31);
        ce.kd = fx::make_gain(6283.2f, pid::kTermMax14);
        ce.alpha = 11000;
        ce.slew = (k & 1) ? 32767 : 150;
        ce.deadband = db;
        ce.db_inverse = (uint16_t)(65536UL * pid::kDeadbandRamp15 / (pid::kDeadbandRamp15 + db));
        pid::Pid q;
        q.load(ce);
        for (int16_t e = -300; e <= 300; ++e) {
            q.reset(limit, 0, 0);
            f.add((uint16_t)q.step(limit, e, 0));
            f.add(q.saturated() ? 1u : 0u);
        }
        for (int16_t dm = -70; dm <= 70; ++dm) {
            q.reset(limit, 0, 0);
            f.add((uint16_t)q.step(limit, 0, dm));
            f.add((uint16_t)q.velocity8());
        }
        // ki = 4 (shift -8): step = 4 e. From a count inside the bound, +-8001 then
        // +-(8300..8500) end within 2^8 either side of it (its low bytes decide).
        ce.kp = fx::make_gain(0.0f, pid::kTermMax14);
        ce.ki = fx::make_gain(4.0f, pid::kIStepMax31);
        ce.kd = fx::make_gain(0.0f, pid::kTermMax14);
        ce.slew = 32767;
        q.load(ce);
        for (int16_t e = 8300; e <= 8500; ++e) {
            for (int8_t side = -1; side <= 1; side += 2) {
                q.reset(limit, (int16_t)(side * (limit - 1)), 0);
                q.step(limit, (int16_t)(side * 8001), 0);
                f.add((uint32_t)q.integrator31());
                q.step(limit, (int16_t)(side * e), 0);
                f.add((uint32_t)q.integrator31());
            }
        }
    }
    // The derivative term at its saturation bound, where it can show: kp = kd, and e set to the
    // filtered speed v8, so the P term cancels an unsaturated D term exactly and a saturated
    // one leaves its remainder in the output. (alpha < 1: v8 has low bits.)
    {
        pid::Coeffs cd = pid::Coeffs();
        cd.kp = fx::make_gain(3001.0f, pid::kTermMax14);
        cd.ki = fx::make_gain(0.0f, pid::kIStepMax31);
        cd.kd = fx::make_gain(3001.0f, pid::kTermMax14);  // xlim 11181
        cd.alpha = 65000;
        cd.slew = 32767;
        cd.deadband = 0;
        cd.db_inverse = 65535;
        pid::Pid q;
        q.load(cd);
        for (int16_t dm = -63; dm <= 63; ++dm) {
            q.reset(32767, 0, 0);
            const int16_t v8 = (int16_t)(((int32_t)(dm * 256) * 65000L + 32768L) >> 16);
            f.add((uint16_t)q.step(32767, (int16_t)(dm + v8), dm));
            f.add((uint16_t)q.velocity8());
        }
    }
    // The encoder's judgement and angle for every ADC count.
    for (uint16_t adc = 0; adc < 1024; ++adc) {
        const hal::EncoderReading e = encoder::as5600_reading(adc);
        f.add(e.turn);
        f.add((uint8_t)e.status);
        f.add((uint16_t)encoder::angle_bu(e.turn, 40000u, adc & 1));
        hal::EncoderSetup su;
        su.zero_turn = (uint16_t)(adc * 61u);
        su.invert = (adc & 2) != 0;
        su.low = -9000;
        su.high = 7000;
        const hal::EncoderReading j = encoder::judge(adc, su);
        f.add((uint16_t)j.angle);
        f.add(j.flags);
    }
    return f.h;
}

}  // namespace check
}  // namespace utrf

#endif  // UTRF_TEST_CORE_CHECK_SEQ_H
