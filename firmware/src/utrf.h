// The UTRF-RoboHand firmware as an Arduino library (firmware/library.properties): a sketch
// that includes this header gets the whole firmware, setup() and loop() included
// (utrf_main.cpp); it must not define them itself. See firmware/examples/utrf/utrf.ino.
#ifndef UTRF_H
#define UTRF_H

#include "core/app.h"

#endif  // UTRF_H
