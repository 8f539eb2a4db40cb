/* UTRF-RoboHand board pin map: the one definition, for the firmware and the emulator harness.
 *
 * Plain C99 data with no AVR or Arduino headers, so the simavr harness (C) includes this
 * same file and cannot disagree with the firmware. firmware/README.md has the wiring table.
 *
 * One TB6612FNG per finger. Channel A drives motor A (flexor, Tendon 1; or the single rotary
 * motor), channel B drives motor B (extensor, Tendon 4). PWM runs on the 16-bit timers
 * 1, 3, 4, 5 in fast PWM mode 14 with TOP in ICRn; timer 0 stays with millis(), timer 2
 * (CTC) runs the 1 kHz control tick.
 */
#ifndef UTRF_BOARD_PINS_H
#define UTRF_BOARD_PINS_H

#include <stdint.h>

#define UTRF_FINGER_COUNT 5
#define UTRF_F_CPU_HZ 16000000UL
#define UTRF_PWM_TOP 799u /* 16 MHz / (1 + 799) = 20 kHz, prescaler 1 */
#define UTRF_TICK_HZ 1000u

typedef struct {
    char port;           /* 'A'..'L': the AVR port */
    uint8_t bit;         /* 0..7 */
    uint8_t arduino_pin; /* Dn on the MEGA's silkscreen (54.. for A0..) */
} utrf_pin_t;

typedef struct {
    uint8_t timer;  /* 16-bit timer: 1, 3, 4 or 5 */
    char channel;   /* output compare 'A', 'B' or 'C' */
    utrf_pin_t pin; /* the OCnX pin */
} utrf_pwm_t;

typedef struct {
    utrf_pwm_t pwm;
    utrf_pin_t in1;
    utrf_pin_t in2;
} utrf_motor_pins_t;

typedef struct {
    utrf_motor_pins_t a;  /* flexor (Tendon 1), or the rotary motor */
    utrf_motor_pins_t b;  /* extensor (Tendon 4); unused by a rotary finger */
    utrf_pin_t stby;      /* the finger's TB6612 STBY: low turns both channels off */
    uint8_t adc_channel;  /* Joint-2 encoder, AS5600 analog output: ADC0..ADC4 (A0..A4) */
} utrf_finger_pins_t;

/* Finger order on the wire: 0 thumb, 1 index, 2 middle, 3 ring, 4 little. */
static const utrf_finger_pins_t UTRF_FINGER_PINS[UTRF_FINGER_COUNT] = {
    /* 0 thumb */
    {{{3, 'A', {'E', 3, 5}}, {'A', 0, 22}, {'A', 1, 23}},
     {{3, 'B', {'E', 4, 2}}, {'A', 2, 24}, {'A', 3, 25}},
     {'D', 7, 38}, 0},
    /* 1 index */
    {{{3, 'C', {'E', 5, 3}}, {'A', 4, 26}, {'A', 5, 27}},
     {{4, 'A', {'H', 3, 6}}, {'A', 6, 28}, {'A', 7, 29}},
     {'G', 2, 39}, 1},
    /* 2 middle */
    {{{4, 'B', {'H', 4, 7}}, {'C', 0, 37}, {'C', 1, 36}},
     {{4, 'C', {'H', 5, 8}}, {'C', 2, 35}, {'C', 3, 34}},
     {'G', 1, 40}, 2},
    /* 3 ring */
    {{{5, 'A', {'L', 3, 46}}, {'C', 4, 33}, {'C', 5, 32}},
     {{5, 'B', {'L', 4, 45}}, {'C', 6, 31}, {'C', 7, 30}},
     {'G', 0, 41}, 3},
    /* 4 little */
    {{{5, 'C', {'L', 5, 44}}, {'L', 0, 49}, {'L', 1, 48}},
     {{1, 'A', {'B', 5, 11}}, {'L', 2, 47}, {'L', 6, 43}},
     {'L', 7, 42}, 4},
};

#endif /* UTRF_BOARD_PINS_H */
