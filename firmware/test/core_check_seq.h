// A fixed workload over the core's fixed-point arithmetic, folded into one checksum. The AVR
// build (firmware/test/avr/core_check.cpp, run on simavr) and the host build (capi.cpp) run
// the same sequence: equal checksums show the AVR's inline-assembly multiplies and its 16-bit
// int give exactly the host-tested results.
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
        const fx::Gain g = fx::make_gain(values[k], pid::kPMax23);
        f.add(g.m);
        f.add((uint32_t)(int32_t)g.shift);
        f.add((uint32_t)(int32_t)g.xlim);
        for (uint8_t i = 0; i < 50; ++i) f.add((uint32_t)fx::apply(g, (int16_t)r.next(), pid::kPMax23));
    }
    // The PID on a random walk of target and measurement, coefficients given as integers.
    pid::Coeffs c;
    c.kp = fx::make_gain(1677.7f, pid::kPMax23);
    c.ki = fx::make_gain(429.5f, pid::kIStepMax31);
    c.kd = fx::make_gain(6283.2f, pid::kDMax23);
    c.alpha = 11000;
    c.slew = 655;
    c.deadband = 1311;
    c.db_inverse = (uint16_t)(65536UL * pid::kDeadbandRamp15 / (pid::kDeadbandRamp15 + 1311));
    pid::Pid p;
    p.reset(c, 22937, 3000, 0);
    int16_t target = 0;
    int16_t meas = 0;
    for (uint16_t i = 0; i < 4000; ++i) {
        target = (int16_t)(target + (int16_t)(r.next() % 41) - 20);
        meas = (int16_t)(meas + (int16_t)(r.next() % 9) - 4);
        target = fx::clamp16(target, -12000, 12000);
        meas = fx::clamp16(meas, -12000, 12000);
        const int16_t u = (i % 500) < 450 ? p.step(c, 22937, target, meas)
                                          : p.step_open(c, 22937, (int16_t)r.next(), meas);
        f.add((uint16_t)u);
        f.add((uint32_t)p.integrator31());
        f.add((uint16_t)p.velocity8());
        if (i % 1000 == 999) p.rebase(c, c, 16000);
    }
    // The encoder's judgement and angle for every ADC count.
    for (uint16_t adc = 0; adc < 1024; ++adc) {
        const hal::EncoderReading e = encoder::as5600_reading(adc);
        f.add(e.turn);
        f.add((uint8_t)e.status);
        f.add((uint16_t)encoder::angle_bu(e.turn, 40000u, adc & 1));
    }
    return f.h;
}

}  // namespace check
}  // namespace utrf

#endif  // UTRF_TEST_CORE_CHECK_SEQ_H
