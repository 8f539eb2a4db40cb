#include "hal_host.h"

#include <string.h>

#include "core/encoder.h"

namespace utrf {
namespace hal {

namespace host {
namespace {
State g_state;
encoder::Staleness g_staleness;
}  // namespace

State& state() { return g_state; }

void power_on() {
    State& s = g_state;
    uint8_t eeprom[kEepromBytes];
    memcpy(eeprom, s.eeprom, sizeof eeprom);
    const bool mark = s.hang_mark;
    const uint8_t polls = s.eeprom_busy_polls;
    const int32_t stuck = s.eeprom_stuck_addr;
    memset(&s, 0, sizeof s);
    g_staleness = encoder::Staleness();
    memcpy(s.eeprom, eeprom, sizeof eeprom);
    s.hang_mark = mark;
    s.eeprom_busy_polls = polls;
    s.eeprom_stuck_addr = stuck;
    s.tx_room_limit = 0xFFFF;
    s.reset_cause = 0;
    for (uint8_t f = 0; f < 5; ++f) {
        s.adc[f] = 512;  // mid-band: a sensor at half a turn
        s.motor[f][0].drive = s.motor[f][1].drive = Drive::COAST;
    }
}
}  // namespace host

using host::g_state;

void motor_write_at(uint8_t f, const MotorCommand& c) {
    const MotorOut ch[2] = {{drive_a(c.drives), c.a_counts}, {drive_b(c.drives), c.b_counts}};
    // The rule the AVR layer relies on: a driving channel has at least one count; and the
    // core's: a channel that does not drive has none.
    for (uint8_t k = 0; k < 2; ++k) {
        const MotorOut& m = ch[k];
        const bool drives = m.drive == Drive::FORWARD || m.drive == Drive::REVERSE;
        if (drives ? (m.on_counts == 0 || m.on_counts > kPwmPeriod) : m.on_counts != 0) {
            ++g_state.lock_errors;
        }
        g_state.motor[f][k] = m;
    }
    g_state.stby[f] = stby_of(c.drives);
    if (f == 4) ++g_state.motor_writes;  // a tick's five
}

void motor_off(uint8_t f) {
    MotorCommand c;
    c.a_counts = c.b_counts = 0;
    c.drives = drives(Drive::COAST, Drive::COAST, false);
    motor_write_at(f, c);
}

void motors_all_off() {
    for (uint8_t f = 0; f < 5; ++f) {
        g_state.motor[f][0].drive = g_state.motor[f][1].drive = Drive::COAST;
        g_state.motor[f][0].on_counts = g_state.motor[f][1].on_counts = 0;
        g_state.stby[f] = false;
    }
    ++g_state.all_off_calls;
}

namespace {
EncoderSetup g_setup[5];
}  // namespace

void encoder_setup(uint8_t finger, const EncoderSetup& s) { g_setup[finger] = s; }

// Judged here, as the tick reads them: the setup in force is the one they are judged with.
const EncoderReading* encoders_read() {
    static EncoderReading out[5];
    const bool stale = host::g_staleness.stale(g_state.adc_seq);
    for (uint8_t f = 0; f < 5; ++f) {
        out[f] = stale ? encoder::no_data() : encoder::judge(g_state.adc[f], g_setup[f]);
        if (g_state.adc_rejudge) out[f].flags |= kReadingRejudge;
    }
    return out;
}

void encoders_sample() {
    ++g_state.sample_rounds;
    if (!g_state.adc_frozen) g_state.adc_seq = (uint8_t)(g_state.adc_seq + 1);
}

void tick_start() {
    g_state.tick_started = true;
    g_state.tick_ms = g_state.ms;
}

void tick_lock() {
    if (g_state.tick_locked) ++g_state.lock_errors;
    g_state.tick_locked = true;
}

void tick_unlock() {
    if (!g_state.tick_locked) ++g_state.lock_errors;
    g_state.tick_locked = false;
}

Stamp stamp() {
    Stamp s;
    s.coarse = 0;
    s.fine = 0;
    return s;
}

bool tick_period_elapsed() { return g_state.period_elapsed; }
uint32_t millis() { return g_state.ms; }
uint32_t tick_millis() { return g_state.tick_ms; }

uint8_t serial_rx_peek(const uint8_t** data) {
    const uint16_t tail = g_state.rx_tail;
    const uint16_t head = g_state.rx_head;
    *data = g_state.rx + tail;
    const uint16_t n = head >= tail ? (uint16_t)(head - tail) : (uint16_t)(host::kRxBytes - tail);
    return (uint8_t)(n > 255 ? 255 : n);
}

bool serial_rx_waiting() { return g_state.rx_head != g_state.rx_tail; }

void serial_rx_take(uint8_t n) {
    g_state.rx_tail = (uint16_t)((g_state.rx_tail + n) % host::kRxBytes);
}

uint16_t serial_tx_room() {
    const uint16_t free = (uint16_t)(host::kTxBytes - g_state.tx_len);
    return free < g_state.tx_room_limit ? free : g_state.tx_room_limit;
}

void serial_write(const uint8_t* data, uint16_t len) {
    if (len > serial_tx_room()) {
        ++g_state.lock_errors;  // a write without room: the firmware broke its own rule
        return;
    }
    memcpy(g_state.tx + g_state.tx_len, data, len);
    g_state.tx_len = (uint16_t)(g_state.tx_len + len);
}

// The host's transmit buffer is linear: a frame is written into a ring of its own from 0 and
// copied over at the commit.
namespace {
uint8_t g_tx_ring[256];
}
uint8_t* serial_tx_ring() { return g_tx_ring; }
uint8_t serial_tx_head() { return 0; }
void serial_tx_commit(uint8_t end) { serial_write(g_tx_ring, end); }

uint16_t serial_take_overruns() {
    const uint16_t n = g_state.rx_lost;
    g_state.rx_lost = 0;
    return n;
}

UartErrors serial_take_uart_errors() {
    const UartErrors e = {g_state.uart_overruns, g_state.uart_frame_errors};
    g_state.uart_overruns = g_state.uart_frame_errors = 0;
    return e;
}

uint8_t eeprom_read(uint16_t addr) { return g_state.eeprom[addr % host::kEepromBytes]; }

bool eeprom_ready() {
    if (g_state.eeprom_busy == 0) return true;
    --g_state.eeprom_busy;
    return false;
}

void eeprom_write(uint16_t addr, uint8_t value) {
    if (g_state.eeprom_busy) ++g_state.lock_errors;  // a write while busy: not allowed
    ++g_state.eeprom_writes;
    if ((int32_t)addr != g_state.eeprom_stuck_addr) g_state.eeprom[addr % host::kEepromBytes] = value;
    g_state.eeprom_busy = g_state.eeprom_busy_polls;
}

void watchdog_start() { g_state.wdt_started = true; }
void watchdog_feed() { ++g_state.wdt_feeds; }
void watchdog_mark_hang() { g_state.hang_mark = true; }
void watchdog_clear_hang_mark() { g_state.hang_mark = false; }
uint8_t reset_cause() { return g_state.hang_mark ? 3 : g_state.reset_cause; }

}  // namespace hal
}  // namespace utrf
