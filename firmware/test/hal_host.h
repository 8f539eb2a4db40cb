// The host implementation of the hardware layer: plain memory that the tests drive and read
// through the C ABI (capi.cpp). One simulated board per process.
#ifndef UTRF_TEST_HAL_HOST_H
#define UTRF_TEST_HAL_HOST_H

#include <stdint.h>

#include "hal/hal.h"

namespace utrf {
namespace hal {
namespace host {

static const uint16_t kEepromBytes = 4096;  // the ATmega2560's
static const uint16_t kRxBytes = 4096;
static const uint16_t kTxBytes = 8192;

struct State {
    // motors, as last written by the tick
    MotorOut motor[5][2];
    bool stby[5];
    uint32_t motor_writes;
    uint32_t all_off_calls;
    // ADC: the sample per channel; the round counter moves each tick unless frozen
    uint16_t adc[5];
    uint8_t adc_seq;
    bool adc_frozen;
    // every reading flagged as judged with an earlier setup: the tick's general encoder path
    bool adc_rejudge;
    uint32_t sample_rounds;
    // tick
    bool tick_started;
    bool tick_locked;
    uint32_t lock_errors;   // nested lock, unlock without lock, tick while locked
    uint32_t tick_cycles;   // each tick's length, as fw_tick() reports it to app::tick_done()
    bool period_elapsed;    // what tick_period_elapsed() reports
    uint32_t ms;
    uint32_t tick_ms;       // ms as the last tick ran (tick_millis())
    // serial
    uint8_t rx[kRxBytes];
    uint16_t rx_head, rx_tail;
    uint16_t rx_lost;
    uint8_t uart_overruns, uart_frame_errors;  // what serial_take_uart_errors() reports next
    uint8_t tx[kTxBytes];
    uint16_t tx_len;
    uint16_t tx_room_limit;  // serial_tx_room() reports at most this
    // EEPROM: a write keeps the EEPROM busy for eeprom_busy_polls calls of eeprom_ready()
    uint8_t eeprom[kEepromBytes];
    uint8_t eeprom_busy;
    uint8_t eeprom_busy_polls;
    uint32_t eeprom_writes;
    int32_t eeprom_stuck_addr;  // a cell that ignores writes (-1: none)
    // watchdog and reset cause
    bool wdt_started;
    uint32_t wdt_feeds;
    bool hang_mark;
    uint8_t reset_cause;
};

State& state();
// Power-on: everything but the EEPROM (and the hang mark, which survives a watchdog reset).
void power_on();

}  // namespace host
}  // namespace hal
}  // namespace utrf

#endif  // UTRF_TEST_HAL_HOST_H
