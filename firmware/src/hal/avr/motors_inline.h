// hal::motor_write<F>() on the MEGA, inline (hal.h includes this on the AVR): each finger's
// driver command goes from the tick's registers to the compare registers, with no call and no
// copy of the command on the stack (the tick's own work: firmware/README.md, Timing).
#ifndef UTRF_HAL_AVR_MOTORS_INLINE_H
#define UTRF_HAL_AVR_MOTORS_INLINE_H

#include "../../board_pins.h"

namespace utrf {
namespace hal {
namespace avr_motors {

// The last drive byte written per finger (0xFF: unknown), and a change of it (rare: out of
// line, hal_avr.cpp): STBY goes low before the channels change and high after them.
extern uint8_t g_drives_last[UTRF_FINGER_COUNT];
void drives_change(uint8_t f, uint8_t d);

// The registers of finger F's pins are constants of board_pins.h: with F a template argument
// the compiler folds the table and the switches below into fixed addresses, so each tick writes
// the compare registers with plain stores (no pointer, no loop). The ATmega2560's data
// addresses of OCRnA (OCRnB, OCRnC follow, two bytes each), not <avr/io.h>'s names: its
// macros (PING, ...) would reach every file of the core through hal.h. hal_avr.cpp checks
// them against <avr/io.h> (a static_assert).
__attribute__((always_inline)) inline volatile uint16_t* ocr_reg(uint8_t timer, char channel) {
    const uint16_t base = timer == 1 ? 0x88u : timer == 3 ? 0x98u : timer == 4 ? 0xA8u : 0x128u;
    return (volatile uint16_t*)(uintptr_t)(base + 2u * (uint8_t)(channel - 'A'));
}

// OCRnx from a channel's counts: counts - 1 (fast PWM: OCR + 1 counts high). 1..kPwmPeriod
// is the core's range when the channel drives; anything else is clamped into it, one compare
// for both ends (0, a channel that does not drive, would wrap to 0xFFFF: 0 instead; its compare
// output is disconnected, so the value does not reach the pin).
__attribute__((always_inline)) inline uint16_t ocr_of(uint16_t counts) {
    uint16_t ocr = (uint16_t)(counts - 1u);
    if (__builtin_expect(ocr >= UTRF_PWM_TOP + 1u, 0)) ocr = counts == 0 ? 0 : UTRF_PWM_TOP;
    return ocr;
}

template <uint8_t F>
__attribute__((always_inline)) inline void finger_write(const MotorCommand& c) {
    // OCRnx is double-buffered in fast PWM: the new duty starts with the next period.
    const utrf_finger_pins_t& pins = UTRF_FINGER_PINS[F];
    *ocr_reg(pins.a.pwm.timer, pins.a.pwm.channel) = ocr_of(c.a_counts);
    *ocr_reg(pins.b.pwm.timer, pins.b.pwm.channel) = ocr_of(c.b_counts);
    if (__builtin_expect(c.drives != g_drives_last[F], 0)) drives_change(F, c.drives);
}

}  // namespace avr_motors

template <uint8_t F>
__attribute__((always_inline)) inline void motor_write(const MotorCommand& c) {
    static_assert(F < UTRF_FINGER_COUNT, "a finger of board_pins.h");
    avr_motors::finger_write<F>(c);
}

}  // namespace hal
}  // namespace utrf

#endif  // UTRF_HAL_AVR_MOTORS_INLINE_H
