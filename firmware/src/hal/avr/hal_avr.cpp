// Hardware layer for the Arduino MEGA 2560 (ATmega2560, 16 MHz).
//
//   timers 1, 3, 4, 5  fast PWM mode 14, TOP = ICRn = 799: 20 kHz, prescaler 1
//   timer 2            CTC, clk/64, OCR2A = 249: the 1 kHz control tick
//   timer 0            left to the Arduino core (millis)
//   ADC                interrupt-driven round robin over the five encoder channels
//   UART0              own interrupt-driven driver: counts lost bytes, never blocks
//   watchdog           120 ms, reset mode; fed by loop() only while the tick runs
#include "hal_avr.h"

#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/wdt.h>
#include <util/atomic.h>

#include "../../board_pins.h"
#include "../../core/app.h"
#include "../../core/encoder.h"
#include "../hal.h"

extern "C" unsigned long millis(void);  // Arduino core (timer 0)

namespace utrf {
namespace hal {

static_assert(kPwmPeriod == UTRF_PWM_TOP + 1, "hal.h and board_pins.h disagree on the PWM period");
static_assert(UTRF_F_CPU_HZ == F_CPU, "board_pins.h is for a 16 MHz board");

namespace {

// ---- reset cause, read before anything else runs -----------------------------------------------
uint8_t g_mcusr __attribute__((section(".noinit")));
uint32_t g_hang_mark __attribute__((section(".noinit")));
const uint32_t kHangMagic = 0x48414E47UL;  // "HANG"

// ---- motor pins, derived from board_pins.h once at start ---------------------------------------
struct Pin {
    volatile uint8_t* port;
    uint8_t mask;
};
struct MotorHw {
    Pin in1;
    Pin in2;
    Pin pwm;
    volatile uint8_t* tccra;
    volatile uint16_t* ocr;
    uint8_t com;       // COMnX1 bit in TCCRnA: connects the compare output
    uint8_t last;      // last Drive written, 0xFF: unknown
};
struct FingerHw {
    MotorHw m[2];
    Pin stby;
    uint8_t stby_last;
};
FingerHw g_hw[UTRF_FINGER_COUNT];

volatile uint8_t* port_reg(char port) {
    switch (port) {
        case 'A': return &PORTA;
        case 'B': return &PORTB;
        case 'C': return &PORTC;
        case 'D': return &PORTD;
        case 'E': return &PORTE;
        case 'F': return &PORTF;
        case 'G': return &PORTG;
        case 'H': return &PORTH;
        case 'J': return &PORTJ;
        case 'K': return &PORTK;
        default: return &PORTL;
    }
}

// On the ATmega2560 every DDRx sits one address below its PORTx.
Pin output_pin(const utrf_pin_t& p) {
    Pin r;
    r.port = port_reg(p.port);
    r.mask = (uint8_t)(1u << p.bit);
    *(r.port) &= (uint8_t)~r.mask;     // low first,
    *(r.port - 1) |= r.mask;           // then an output
    return r;
}

inline void pin_set(const Pin& p, bool high) {
    // Read-modify-write of a port shared with other pins: atomic against the other contexts
    // (the tick interrupt and loop()'s emergency stop).
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        if (high) {
            *p.port |= p.mask;
        } else {
            *p.port &= (uint8_t)~p.mask;
        }
    }
}

void timer_regs(uint8_t timer, char channel, volatile uint8_t*& tccra, volatile uint16_t*& ocr,
                uint8_t& com) {
    const uint8_t ch = (uint8_t)(channel - 'A');  // 0, 1, 2
    com = (uint8_t)(0x80u >> (2 * ch));           // COMnA1 bit 7, COMnB1 bit 5, COMnC1 bit 3
    switch (timer) {
        case 1:
            tccra = &TCCR1A;
            ocr = ch == 0 ? &OCR1A : ch == 1 ? &OCR1B : &OCR1C;
            break;
        case 3:
            tccra = &TCCR3A;
            ocr = ch == 0 ? &OCR3A : ch == 1 ? &OCR3B : &OCR3C;
            break;
        case 4:
            tccra = &TCCR4A;
            ocr = ch == 0 ? &OCR4A : ch == 1 ? &OCR4B : &OCR4C;
            break;
        default:
            tccra = &TCCR5A;
            ocr = ch == 0 ? &OCR5A : ch == 1 ? &OCR5B : &OCR5C;
            break;
    }
}

MotorHw motor_hw(const utrf_motor_pins_t& p) {
    MotorHw m;
    m.in1 = output_pin(p.in1);
    m.in2 = output_pin(p.in2);
    m.pwm = output_pin(p.pwm.pin);
    timer_regs(p.pwm.timer, p.pwm.channel, m.tccra, m.ocr, m.com);
    m.last = 0xFF;
    return m;
}

void motor_apply(MotorHw& m, const MotorOut& out) {
    const uint8_t d = (uint8_t)out.drive;
    const bool drives = out.drive == Drive::FORWARD || out.drive == Drive::REVERSE;
    if (drives && out.on_counts > 0) {
        const uint16_t c = out.on_counts > kPwmPeriod ? kPwmPeriod : out.on_counts;
        *m.ocr = (uint16_t)(c - 1);  // double-buffered: takes effect at the next period
        if (d != m.last) {
            const bool fwd = out.drive == Drive::FORWARD;
            pin_set(m.in1, fwd);
            pin_set(m.in2, !fwd);
            ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { *m.tccra |= m.com; }
            m.last = d;
        }
        return;
    }
    // COAST or BRAKE (and zero duty): the compare output is disconnected, so the pin is the
    // PORT bit, low. Fast PWM at OCR = 0 would still give a one-count spike every period.
    const uint8_t want = out.drive == Drive::BRAKE ? (uint8_t)Drive::BRAKE : (uint8_t)Drive::COAST;
    if (want == m.last) return;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { *m.tccra &= (uint8_t)~m.com; }
    const bool brake = want == (uint8_t)Drive::BRAKE;
    pin_set(m.in1, brake);
    pin_set(m.in2, brake);
    m.last = want;
}

// ---- ADC round robin -----------------------------------------------------------------------
uint8_t g_adc_mux[UTRF_FINGER_COUNT];
volatile uint16_t g_adc_last[UTRF_FINGER_COUNT];
volatile uint16_t g_adc_prev[UTRF_FINGER_COUNT];
volatile uint8_t g_adc_seq[UTRF_FINGER_COUNT];
volatile uint8_t g_adc_at;
encoder::As5600Analog g_enc[UTRF_FINGER_COUNT];

void adc_select(uint8_t finger) {
    const uint8_t ch = g_adc_mux[finger];  // 0..7 (A0..A7): MUX5 stays 0
    ADMUX = (uint8_t)(_BV(REFS0) | (ch & 0x07));  // AVCC reference: ratiometric with the sensor
}

// ---- UART0 -----------------------------------------------------------------------------------
const uint8_t kRxSize = 128;  // powers of two: the index arithmetic wraps with a mask
const uint16_t kTxSize = 256;
uint8_t g_rx[kRxSize];
uint8_t g_tx[kTxSize];
volatile uint8_t g_rx_head, g_rx_tail;
volatile uint8_t g_tx_head, g_tx_tail;
volatile uint16_t g_rx_lost;

}  // namespace

// ---- interrupts --------------------------------------------------------------------------------
extern "C" void utrf_read_reset_flags(void) __attribute__((naked, used, section(".init3")));
extern "C" void utrf_read_reset_flags(void) {
    // Before the C runtime and the Arduino core: keep the flags, clear them (so the next reset
    // reports its own), and stop a watchdog left running by a watchdog reset.
    g_mcusr = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

ISR(TIMER2_COMPA_vect) {
    // The tick runs with interrupts enabled, so the UART and the ADC are served during it.
    // Its own interrupt is masked meanwhile: a tick never nests in itself.
    TIMSK2 &= (uint8_t)~_BV(OCIE2A);
    sei();
    app::tick();
    cli();
    TIMSK2 |= _BV(OCIE2A);
}

ISR(ADC_vect) {
    const uint16_t v = ADC;
    uint8_t i = g_adc_at;
    g_adc_prev[i] = g_adc_last[i];
    g_adc_last[i] = v;
    g_adc_seq[i] = (uint8_t)(g_adc_seq[i] + 1);
    if (++i == UTRF_FINGER_COUNT) i = 0;
    g_adc_at = i;
    adc_select(i);
    ADCSRA |= _BV(ADSC);
}

ISR(USART0_RX_vect) {
    const uint8_t status = UCSR0A;
    const uint8_t c = UDR0;
    if (status & _BV(DOR0)) ++g_rx_lost;  // the UART itself lost at least one byte
    const uint8_t head = g_rx_head;
    const uint8_t next = (uint8_t)((head + 1) & (kRxSize - 1));
    if (next == g_rx_tail) {
        ++g_rx_lost;
        return;
    }
    g_rx[head] = c;
    g_rx_head = next;
}

ISR(USART0_UDRE_vect) {
    const uint8_t tail = g_tx_tail;
    if (tail == g_tx_head) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = g_tx[tail];
    g_tx_tail = (uint8_t)(tail + 1);  // kTxSize is 256: wraps by itself
}

// ---- hal.h -------------------------------------------------------------------------------------
void avr_init() {
    for (uint8_t f = 0; f < UTRF_FINGER_COUNT; ++f) {
        const utrf_finger_pins_t& p = UTRF_FINGER_PINS[f];
        g_hw[f].m[0] = motor_hw(p.a);
        g_hw[f].m[1] = motor_hw(p.b);
        g_hw[f].stby = output_pin(p.stby);
        g_hw[f].stby_last = 0;
        g_adc_mux[f] = p.adc_channel;
        if (p.adc_channel < 8) DIDR0 |= (uint8_t)(1u << p.adc_channel);  // analog only
    }

    // PWM timers: fast PWM mode 14 (WGM = 1110), TOP = ICRn, clk/1, outputs disconnected.
    TCCR1B = 0;
    TCCR1A = _BV(WGM11);
    ICR1 = UTRF_PWM_TOP;
    TCNT1 = 0;
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS10);
    TCCR3B = 0;
    TCCR3A = _BV(WGM31);
    ICR3 = UTRF_PWM_TOP;
    TCNT3 = 0;
    TCCR3B = _BV(WGM33) | _BV(WGM32) | _BV(CS30);
    TCCR4B = 0;
    TCCR4A = _BV(WGM41);
    ICR4 = UTRF_PWM_TOP;
    TCNT4 = 0;
    TCCR4B = _BV(WGM43) | _BV(WGM42) | _BV(CS40);
    TCCR5B = 0;
    TCCR5A = _BV(WGM51);
    ICR5 = UTRF_PWM_TOP;
    TCNT5 = 0;
    TCCR5B = _BV(WGM53) | _BV(WGM52) | _BV(CS50);

    // Tick timer: CTC on OCR2A, clk/64: 250 counts = 1 ms. Interrupt off until tick_start().
    TIMSK2 = 0;
    TCCR2A = _BV(WGM21);
    TCCR2B = _BV(CS22);
    OCR2A = (uint8_t)(F_CPU / 64 / UTRF_TICK_HZ - 1);
    TCNT2 = 0;

    // ADC: clk/128 (125 kHz, 104 us a conversion), interrupt-driven round robin.
    ADCSRB = 0;
    g_adc_at = 0;
    adc_select(0);
    ADCSRA = _BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
    ADCSRA |= _BV(ADSC);

    // UART0, 8N1, double speed: UBRR = F_CPU / (8 baud) - 1 (1 at 1 Mbaud, exact).
    static_assert(F_CPU / 8 / UTRF_BAUD >= 1, "UTRF_BAUD is too fast for U2X at this clock");
    UCSR0B = 0;
    UCSR0A = _BV(U2X0);
    UBRR0 = (uint16_t)((F_CPU + 4UL * UTRF_BAUD) / (8UL * UTRF_BAUD) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    g_rx_head = g_rx_tail = 0;
    g_tx_head = g_tx_tail = 0;
    g_rx_lost = 0;
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

void motor_write(uint8_t finger, const MotorOut& a, const MotorOut& b, bool standby_high) {
    FingerHw& h = g_hw[finger];
    if (!standby_high && h.stby_last) {
        pin_set(h.stby, false);  // off first
        h.stby_last = 0;
    }
    motor_apply(h.m[0], a);
    motor_apply(h.m[1], b);
    if (standby_high && !h.stby_last) {
        pin_set(h.stby, true);
        h.stby_last = 1;
    }
}

void motors_all_off() {
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        for (uint8_t f = 0; f < UTRF_FINGER_COUNT; ++f) {
            FingerHw& h = g_hw[f];
            *h.stby.port &= (uint8_t)~h.stby.mask;
            h.stby_last = 0;
            for (uint8_t k = 0; k < 2; ++k) {
                MotorHw& m = h.m[k];
                *m.tccra &= (uint8_t)~m.com;
                *m.in1.port &= (uint8_t)~m.in1.mask;
                *m.in2.port &= (uint8_t)~m.in2.mask;
                m.last = (uint8_t)Drive::COAST;
            }
        }
    }
}

void encoders_read(EncoderReading* out) {
    for (uint8_t f = 0; f < UTRF_FINGER_COUNT; ++f) {
        uint16_t last, prev;
        uint8_t seq;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            last = g_adc_last[f];
            prev = g_adc_prev[f];
            seq = g_adc_seq[f];
        }
        out[f] = g_enc[f].update(last, prev, seq);
    }
}

void tick_start() {
    TCNT2 = 0;
    TIFR2 = _BV(OCF2A);
    TIMSK2 = _BV(OCIE2A);
}

void tick_lock() { TIMSK2 &= (uint8_t)~_BV(OCIE2A); }
void tick_unlock() { TIMSK2 |= _BV(OCIE2A); }

Stamp stamp() {
    Stamp s;
    s.coarse = TCNT2;
    s.fine = TCNT1;
    return s;
}

uint32_t cycles_since(const Stamp& start) {
    const uint8_t c2 = TCNT2;
    const uint16_t c1 = TCNT1;
    int16_t d2 = (int16_t)c2 - (int16_t)start.coarse;
    if ((TIFR2 & _BV(OCF2A)) || d2 < 0) d2 = (int16_t)(d2 + (F_CPU / 64 / UTRF_TICK_HZ));
    // The tick timer gives the time to within 64 cycles; timer 1 (modulo 800) gives it exactly
    // modulo 800: take the value of the second that lies within 400 cycles of the first.
    const uint16_t coarse = (uint16_t)d2 * 64u;
    uint16_t cycles = c1 >= start.fine ? (uint16_t)(c1 - start.fine)
                                       : (uint16_t)(c1 + (UTRF_PWM_TOP + 1) - start.fine);
    while ((uint16_t)(cycles + (UTRF_PWM_TOP + 1) / 2) < coarse) cycles += UTRF_PWM_TOP + 1;
    return cycles;
}

bool tick_period_elapsed() { return (TIFR2 & _BV(OCF2A)) != 0; }

uint32_t millis() { return ::millis(); }

uint16_t serial_read(uint8_t* buf, uint16_t max) {
    uint16_t n = 0;
    uint8_t tail = g_rx_tail;
    while (n < max && tail != g_rx_head) {
        buf[n++] = g_rx[tail];
        tail = (uint8_t)((tail + 1) & (kRxSize - 1));
    }
    g_rx_tail = tail;
    return n;
}

uint16_t serial_tx_room() {
    return (uint16_t)((uint8_t)(g_tx_tail - g_tx_head - 1));  // 256-byte ring
}

void serial_write(const uint8_t* data, uint16_t len) {
    uint8_t head = g_tx_head;
    for (uint16_t i = 0; i < len; ++i) g_tx[head++] = data[i];
    g_tx_head = head;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { UCSR0B |= _BV(UDRIE0); }
}

uint16_t serial_take_overruns() {
    uint16_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        n = g_rx_lost;
        g_rx_lost = 0;
    }
    return n;
}

uint16_t eeprom_size() { return E2END + 1; }
uint8_t eeprom_read(uint16_t addr) { return eeprom_read_byte((const uint8_t*)addr); }
bool eeprom_ready() { return eeprom_is_ready(); }
void eeprom_write(uint16_t addr, uint8_t value) { eeprom_write_byte((uint8_t*)addr, value); }

void watchdog_start() { wdt_enable(WDTO_120MS); }
void watchdog_feed() { wdt_reset(); }
void watchdog_mark_hang() { g_hang_mark = kHangMagic; }
void watchdog_clear_hang_mark() { g_hang_mark = 0; }

uint8_t reset_cause() {
    // Protocol ResetCause: POWER_ON 0, EXTERNAL 1, BROWN_OUT 2, WATCHDOG 3, JTAG 4, UNKNOWN 5.
    // The MEGA's stk500v2 bootloader reads MCUSR and clears it before it starts us, so with
    // the bootloader the flags are gone (UNKNOWN); a watchdog reset this firmware provoked
    // (a hung loop or tick) is still known from the mark it left in .noinit RAM.
    const uint8_t f = g_mcusr;
    if (f & _BV(PORF)) return 0;
    if (f & _BV(BORF)) return 2;
    if ((f & _BV(WDRF)) || g_hang_mark == kHangMagic) return 3;
    if (f & _BV(EXTRF)) return 1;
    if (f & _BV(JTRF)) return 4;
    return 5;
}

}  // namespace hal
}  // namespace utrf
