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

}  // namespace hal
}  // namespace utrf

#endif  // UTRF_HAL_AVR_HAL_AVR_H
