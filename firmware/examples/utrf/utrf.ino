// UTRF-RoboHand for the Arduino IDE and arduino-cli: the firmware is the UTRF-RoboHand
// library (the firmware/ directory), which defines setup() and loop() itself. Select
// "Arduino Mega or Mega 2560" (ATmega2560) and upload. See firmware/README.md, "Arduino IDE".
#include <utrf.h>
