// The MEGA 2560 implementation of the hardware layer (hal.h): its one extra entry point.
#ifndef UTRF_HAL_AVR_HAL_AVR_H
#define UTRF_HAL_AVR_HAL_AVR_H

#ifndef UTRF_BAUD
#define UTRF_BAUD 1000000UL  // exact at 16 MHz with U2X; override with -DUTRF_BAUD=...
#endif

namespace utrf {
namespace hal {

// Pins (motors off, STBY low), the PWM timers (fast PWM mode 14, 20 kHz), the tick timer
// (stopped until tick_start()), the ADC sampler and UART0. Call first in setup().
void avr_init();

// After a loop() pass: with interrupts disabled, ask `idle` (app::idle) whether a pass run
// now would find work; while not, sleep (idle mode: the timers, the UART and the ADC run on)
// until the next interrupt, and ask again after it. The check and the sleep are one step for
// the interrupts: one that comes after the check wakes the sleep at once (interrupts are
// enabled by the instruction just before SLEEP, and one pending then is taken only after
// SLEEP has begun). An interrupt that gives loop() nothing to do (an ADC conversion, a byte
// of a frame going out) costs the check, not a pass. The sleep saves power on the board, and
// simavr skips the slept cycles instead of running loop()'s empty passes. While a frame comes
// in, `take_bytes` (app::take_bytes) takes its bytes into the decoder, a few at a time, in the
// sleep: its 0x00 then finds it decoded.
void sleep_until_interrupt(bool (*idle)(), void (*take_bytes)());

}  // namespace hal
}  // namespace utrf

#endif  // UTRF_HAL_AVR_HAL_AVR_H
