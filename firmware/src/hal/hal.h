// The thin hardware layer: everything the core needs from the board, and nothing more.
//
// Two implementations: hal/avr/ (the MEGA 2560: timers, pins, ADC, UART0, EEPROM, watchdog)
// and firmware/test/hal_host.cpp (memory the host tests read and write). Core modules include
// this header only; they never see an Arduino or AVR header.
#ifndef UTRF_HAL_HAL_H
#define UTRF_HAL_HAL_H

#include <stdint.h>

namespace utrf {
namespace hal {

// ---- motors ----------------------------------------------------------------------------------
// One TB6612FNG channel. The PWM runs at 20 kHz with kPwmPeriod counts per period.
static const uint16_t kPwmPeriod = 800;  // TOP + 1 (board_pins.h: UTRF_PWM_TOP = 799)

enum class Drive : uint8_t {
    COAST = 0,    // IN1 = L, IN2 = L, PWM pin held low: outputs off (high impedance)
    BRAKE = 1,    // IN1 = H, IN2 = H, PWM pin held low: short brake
    FORWARD = 2,  // IN1 = H, IN2 = L, PWM = on_counts: pull the tendon
    REVERSE = 3,  // IN1 = L, IN2 = H, PWM = on_counts: release it
};

struct MotorOut {
    Drive drive;
    uint16_t on_counts;  // FORWARD/REVERSE: 1..kPwmPeriod counts high per period
};

// One finger's driver as the tick leaves it: each channel's counts (0 when it does not drive)
// and, in one byte, both channels' drives and the STBY pin (drives()), so that the layer
// compares one byte with the last one to know whether a pin must change.
struct MotorCommand {
    uint16_t a_counts;  // motor A: flexor (Tendon 1), or the rotary motor
    uint16_t b_counts;  // motor B: extensor (Tendon 4)
    uint8_t drives;     // drives(a, b, stby)
};
static const uint8_t kStbyBit = 1u << 4;  // STBY high: the driver's outputs enabled
inline uint8_t drives(Drive a, Drive b, bool stby) {
    return (uint8_t)((uint8_t)a | (uint8_t)((uint8_t)b << 2) | (stby ? kStbyBit : 0));
}
inline Drive drive_a(uint8_t d) { return (Drive)(d & 3u); }
inline Drive drive_b(uint8_t d) { return (Drive)((d >> 2) & 3u); }
inline bool stby_of(uint8_t d) { return (d & kStbyBit) != 0; }

// Drive finger F's channels and STBY pin (the tick calls it for each finger, as it has the
// finger's command). The core sends FORWARD/REVERSE only with counts >= 1; COAST and BRAKE
// disconnect the compare output, so fast PWM's one-count spike at OCR = 0 never reaches the
// driver (the AVR layer writes every channel's compare register every tick, whatever its
// drive). On the AVR inline (avr/motors_inline.h, included at the end of this file).
template <uint8_t F>
inline void motor_write(const MotorCommand& c);
#if !defined(__AVR__)
void motor_write_at(uint8_t finger, const MotorCommand& c);
template <uint8_t F>
inline void motor_write(const MotorCommand& c) {
    motor_write_at(F, c);
}
#endif

// Every channel to COAST and every STBY low. Safe from any context, interrupts included.
void motors_all_off();
// One finger's channels to COAST and its STBY low, at once (loop() context, under the tick
// lock: the stall rule, which runs there, stops its finger without waiting for the tick).
void motor_off(uint8_t finger);

// ---- encoders ----------------------------------------------------------------------------------
// One Joint-2 encoder reading, already checked by its driver (and judged: the angle and the
// stateless fault rules run where the sample is taken, the AVR's ADC interrupt, not in the
// tick).
enum class EncoderStatus : uint8_t {
    OK = 0,
    OUT_OF_BAND = 1,  // the signal is outside the sensor's valid band (unplugged, shorted)
    NO_DATA = 2,      // no new sample since the last tick (the sampler stopped)
};

struct EncoderReading {
    uint16_t turn;  // angle as a fraction of one turn: 65536 = 360 degrees
    EncoderStatus status;
    // Judged by the sampler, with the finger's EncoderSetup (core/encoder.h, judge()):
    int16_t angle;   // BU (core/fixed.h): the Joint-2 angle, zero and direction applied
    uint8_t flags;   // 0: status OK and the angle within the setup's fault limits
};
// Flags of a reading: the tick takes a reading with none as it is, and judges any other
// itself from `turn` and `status` (rare: a fault, or a reading judged before a new setup).
static const uint8_t kReadingOut = 1u << 0;      // status not OK
static const uint8_t kReadingLimit = 1u << 1;    // angle outside [low, high]
static const uint8_t kReadingRejudge = 1u << 7;  // judged with an earlier setup

// What the sampler needs to judge a finger's readings: its encoder's zero and direction, and
// the finger's fault limits (BU).
struct EncoderSetup {
    uint16_t zero_turn;
    bool invert;
    int16_t low;
    int16_t high;
};
// loop() context: the setup for the readings to come; a reading already judged with an
// earlier one is flagged kReadingRejudge.
void encoder_setup(uint8_t finger, const EncoderSetup& s);

// The readings of all fingers [UTRF_FINGER_COUNT], from one sampling round: called once per
// control tick, from the tick; they stay valid until encoders_sample(). All NO_DATA when the
// sampling has stopped.
const EncoderReading* encoders_read();
// Start sampling every encoder once (the AVR's ADC round, ~0.5 ms), to be read by the next
// tick. Called at the end of each tick, so the sampling interrupts fall between ticks.
void encoders_sample();

// ---- control tick ------------------------------------------------------------------------------
// The tick is a hardware timer interrupt at UTRF_TICK_HZ that calls app::tick().
void tick_start();
// Keep the tick from running while loop() changes state it reads: a tick that falls due
// meanwhile runs at tick_unlock(), late but not lost; UART and ADC interrupts keep running.
// Not nestable; loop() context only.
void tick_lock();
void tick_unlock();
// The tick timer's count (4 us each) and timer 1's (16 MHz, modulo 800): cycle-exact. The
// AVR layer times each tick with them itself and reports it to app::tick_done().
struct Stamp {
    uint8_t coarse;
    uint16_t fine;
};
Stamp stamp();
static const uint32_t kCpuHz = 16000000UL;
// True when the tick timer reached its period again before the tick finished (an overrun).
bool tick_period_elapsed();
// Milliseconds since start, for loop()'s own time-outs.
uint32_t millis();
// millis() as the last tick ended (as tick_start() ran, before the first): loop()'s tick-alive
// rule, which loop() checks only at the passes the tick asks for (app::tick_done()).
uint32_t tick_millis();

// ---- serial (UART0) ----------------------------------------------------------------------------
// Never blocks. Reads what has arrived; writes only when serial_tx_room() says it fits.
// The bytes received and not yet taken, read in place: the length of the first contiguous
// run of them in the receive buffer (0: none), *data pointing at it; when the run wraps round
// the buffer, the rest comes at the next call. serial_rx_take(n) then frees the first n of
// them (n at most that length).
uint8_t serial_rx_peek(const uint8_t** data);
void serial_rx_take(uint8_t n);
// Whether any received byte waits (serial_rx_peek() would give a run): no pointer to fill.
bool serial_rx_waiting();
uint16_t serial_tx_room();
void serial_write(const uint8_t* data, uint16_t len);
// A frame written in place: the transmit ring (256 bytes: a uint8_t index wraps by itself)
// and the index of its first free byte; serial_tx_commit(end) sends the bytes from there up to
// `end`, at most serial_tx_room() of them. No copy through a buffer of the caller's.
uint8_t* serial_tx_ring();
uint8_t serial_tx_head();
void serial_tx_commit(uint8_t end);
// Bytes lost since the last call because the receive ring was full.
uint16_t serial_take_overruns();
// What the UART's receiver reported since the last call: data overruns (DOR0: its two-byte
// buffer was full when a third byte came; one or more bytes lost) and frame errors (FE0: a
// byte with a bad stop bit).
struct UartErrors {
    uint8_t overruns;
    uint8_t frame_errors;
};
UartErrors serial_take_uart_errors();

// ---- EEPROM ------------------------------------------------------------------------------------
uint8_t eeprom_read(uint16_t addr);
bool eeprom_ready();                           // no write under way
void eeprom_write(uint16_t addr, uint8_t value);  // starts one byte's write; needs eeprom_ready()

// ---- watchdog and reset cause ----------------------------------------------------------------
void watchdog_start();
void watchdog_feed();
// Leave a mark that survives a reset: the firmware stopped itself because loop() or the tick
// hung, and the watchdog is about to reset the board. Read back by reset_cause().
void watchdog_mark_hang();
void watchdog_clear_hang_mark();
// Why the board last started, as a proto::ResetCause value.
uint8_t reset_cause();

}  // namespace hal
}  // namespace utrf

#if defined(__AVR__)
#include "avr/motors_inline.h"
#endif

#endif  // UTRF_HAL_HAL_H
