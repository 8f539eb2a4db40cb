// UTRF-RoboHand firmware for the Arduino MEGA 2560: the Arduino entry, setup() and loop() only.
// The firmware itself is plain C++ in core/ (app.h); the hardware layer is hal/avr/.
#include <Arduino.h>

#include "core/app.h"
#include "hal/avr/hal_avr.h"

void setup() {
    utrf::hal::avr_init();
    utrf::app::setup();
}

void loop() {
    utrf::app::loop();
    utrf::hal::sleep_until_interrupt(utrf::app::idle, utrf::app::take_bytes);  // nothing to do: until an interrupt
}
