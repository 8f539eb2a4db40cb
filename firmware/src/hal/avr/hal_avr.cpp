// Hardware layer for the Arduino MEGA 2560 (ATmega2560, 16 MHz).
//
//   timers 1, 3, 4, 5  fast PWM mode 14, TOP = ICRn = 799: 20 kHz, prescaler 1
//   timer 2            CTC, clk/64, OCR2A = 249: the 1 kHz control tick
//   timer 0            the firmware's own millisecond (init(), below: the core's wiring.c is
//                      not linked)
//   ADC                interrupt-driven round robin over the five encoder channels
//   UART0              own interrupt-driven driver: counts lost bytes, never blocks
//   idle sleep         loop() sleeps (idle mode) until an interrupt gives it work
//   watchdog           30 ms, reset mode; fed by loop() only while the tick runs
#include "hal_avr.h"

#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <util/atomic.h>

#include "../../board_pins.h"
#include "../../core/app.h"
#include "../../core/encoder.h"
#include "../../core/fixed.h"
#include "../../generated/protocol_messages.h"
#include "../hal.h"


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

// A change of drive (direction, coast, brake): rare, so not inlined.
void __attribute__((noinline)) motor_change(MotorHw& m, Drive drive) {
    if (drive == Drive::FORWARD || drive == Drive::REVERSE) {
        const bool fwd = drive == Drive::FORWARD;
        pin_set(m.in1, fwd);
        pin_set(m.in2, !fwd);
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { *m.tccra |= m.com; }
    } else {
        // COAST or BRAKE: the compare output is disconnected, so the pin is its PORT bit, low.
        // Fast PWM at OCR = 0 would still give a one-count spike every period.
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { *m.tccra &= (uint8_t)~m.com; }
        const bool brake = drive == Drive::BRAKE;
        pin_set(m.in1, brake);
        pin_set(m.in2, brake);
    }
    m.last = (uint8_t)drive;
}

// A change of a finger's drive byte (a channel's drive or STBY): rare, so not inlined. STBY
// goes low before the channels change and high after them.
void drives_change_hw(FingerHw& h, uint8_t& last, uint8_t d) {
    const uint8_t stby = stby_of(d) ? 1 : 0;
    if (!stby && h.stby_last) {
        pin_set(h.stby, false);  // off first
        h.stby_last = 0;
    }
    if ((uint8_t)drive_a(d) != h.m[0].last) motor_change(h.m[0], drive_a(d));
    if ((uint8_t)drive_b(d) != h.m[1].last) motor_change(h.m[1], drive_b(d));
    if (stby && !h.stby_last) {
        pin_set(h.stby, true);
        h.stby_last = 1;
    }
    last = d;
}

// ---- ADC: one round over the five encoder channels between two ticks ------------------------
// Each finger's ADMUX value (AVCC reference: ratiometric with the sensor; its channel A0..A7,
// MUX5 0), worked out once by avr_init().
uint8_t g_admux[UTRF_FINGER_COUNT];
// Two rounds of readings, judged in the ADC interrupt: it fills one while the tick reads the
// other, the last complete one (a round starts only at the end of a tick, so the one the tick
// reads is not written under it). g_adc_done points to it and g_adc_fill to the other; both
// change together, with g_adc_round, when a round completes.
EncoderReading g_reading[2][UTRF_FINGER_COUNT];
EncoderReading* volatile g_adc_fill = g_reading[0];
const EncoderReading* volatile g_adc_done = g_reading[1];
// What the tick gets while the sampling stands still.
const EncoderReading kNoData[UTRF_FINGER_COUNT] = {
    {0, EncoderStatus::NO_DATA, 0, kReadingOut}, {0, EncoderStatus::NO_DATA, 0, kReadingOut},
    {0, EncoderStatus::NO_DATA, 0, kReadingOut}, {0, EncoderStatus::NO_DATA, 0, kReadingOut},
    {0, EncoderStatus::NO_DATA, 0, kReadingOut}};
// Each finger's setup, the ADC interrupt judges its samples with (encoder_setup()).
EncoderSetup g_setup[UTRF_FINGER_COUNT];
volatile uint8_t g_adc_round;    // completed rounds (wraps)
volatile uint8_t g_adc_at = 0xFF;  // channel being converted, 0xFF: idle
// The slot of g_adc_fill and the setup of channel g_adc_at (of channel 0 between rounds: the
// round's end sets them for the next, so encoders_sample(), which runs in the tick, does not).
EncoderReading* g_adc_slot = g_reading[0];
const EncoderSetup* g_adc_setup = g_setup;
encoder::Staleness g_staleness;

// The finger's channel, and a conversion started (ADSC set in ADCSRA as it stands: an ADC
// that was stopped, ADEN cleared, stays stopped).
void adc_start(uint8_t finger) {
    ADMUX = g_admux[finger];
    ADCSRA |= _BV(ADSC);
}

}  // namespace

// motors_inline.h's register addresses are <avr/io.h>'s.
static_assert(_SFR_MEM_ADDR(OCR1A) == 0x88 && _SFR_MEM_ADDR(OCR3A) == 0x98 &&
                  _SFR_MEM_ADDR(OCR4A) == 0xA8 && _SFR_MEM_ADDR(OCR5A) == 0x128 &&
                  _SFR_MEM_ADDR(OCR5C) == 0x12C,
              "motors_inline.h's OCR addresses");

// motors_inline.h: the tick's per-finger writes, inline; a change of drive comes here.
namespace avr_motors {
uint8_t g_drives_last[UTRF_FINGER_COUNT];
void drives_change(uint8_t f, uint8_t d) { drives_change_hw(g_hw[f], g_drives_last[f], d); }
}  // namespace avr_motors

// ---- UART0 ---------------------------------------------------------------------------------
// Ring buffers shared with the interrupt routines below. The receive ring's head and tail live
// in the general-purpose I/O registers GPIOR1 (head, written by the interrupt) and GPIOR2
// (tail, written by serial_rx_take()): single-cycle in/out, nothing else uses them, and the
// receive interrupt, which nests in the control tick once for each byte that arrives while it
// runs, touches no other memory on its usual path.
// GPIOR0 bit 0, set (sbi: two cycles, no register) by the interrupts that give loop() work:
// a frame's last byte (0x00) received, a tick that asks for a pass (app::tick_done()), the
// transmit buffer emptied.
// sleep_until_interrupt() sleeps again after any other (an ADC conversion, a byte going out)
// without a loop() pass.
static const uint8_t kWake = 0;
// GPIOR0 bit 1, set by every tick: timer 0's overflow wakes loop() only when no tick came
// since the last one (below).
static const uint8_t kTickSeen = 1;
// GPIOR0 bit 2, set by every other byte received: while a frame comes in, its bytes are taken
// into the decoder (decoded, their CRC run) in the sleep, kRxEarly at a time, so that its
// 0x00 finds it all but done.
static const uint8_t kRxByte = 2;
static const uint8_t kRxEarly = 8;
namespace {
uint8_t g_rx_buf[128];
uint8_t g_tx_buf[256];
volatile uint8_t g_tx_head, g_tx_tail;
volatile uint8_t g_rx_lost;  // bytes lost since serial_take_overruns() (8 bits: one register)
volatile uint8_t g_rx_dor, g_rx_fe;  // DOR0 and FE0 seen since serial_take_uart_errors()
}  // namespace
static_assert(sizeof g_tx_buf == 256, "the transmit index wraps by itself at 256");
static_assert(sizeof g_rx_buf == 128, "the receive ring is 128 slots");

// ---- timer 0: the millisecond of loop()'s tick-alive rule and its wake-up ---------------------
// The firmware's own, in place of the Arduino core's (wiring.c: init(), millis() and a timer-0
// overflow handler that runs its ~100 cycles with interrupts off, above the UART's receive
// interrupt in priority). Defining init() here keeps wiring.c's object out of the link: the
// core is an archive (the Makefile's, PlatformIO's and the IDE's), and nothing else names a
// symbol of it (firmware/README.md, Timing). The count is the core's: 1.024 ms an overflow,
// a millisecond more each time its fraction passes 1.
namespace {
volatile uint32_t g_ms;
uint8_t g_ms_fract;           // each overflow's 24 us past a millisecond, in 8 us (125: 1 ms)
volatile uint8_t g_t0_overflows;  // wraps: the idle sleep's "a millisecond since"
volatile uint32_t g_tick_ms;      // g_ms as the last tick ended (tick_millis())
}  // namespace

// The Arduino core's main() calls init() before setup(): interrupts on, timer 0 as the core
// sets it (fast PWM, clk/64: an overflow every 1.024 ms) with its overflow interrupt. The
// other timers, the ADC and UART0 are set in full by avr_init().
extern "C" void init(void) {
    sei();
    TCCR0A = _BV(WGM01) | _BV(WGM00);
    TCCR0B = _BV(CS01) | _BV(CS00);
    TIMSK0 = _BV(TOIE0);
}

// With interrupts on from its first instruction: a received byte waits for its vector and
// sei only. The overflow masks itself while it counts, so another cannot nest in it (a tick
// that nests here may run past the next overflow).
ISR(TIMER0_OVF_vect, ISR_NOBLOCK) {
    TIMSK0 = 0;
    uint32_t m = g_ms + 1;
    uint8_t f = (uint8_t)(g_ms_fract + 3);  // 24 us in units of 8 us
    if (f >= 125) {                         // 1000 us
        f = (uint8_t)(f - 125);
        ++m;
    }
    g_ms_fract = f;
    cli();  // the tick, which nests here, reads g_ms whole (g_tick_ms)
    g_ms = m;
    sei();
    g_t0_overflows = (uint8_t)(g_t0_overflows + 1);
    TIMSK0 = _BV(TOIE0);
}

// ---- interrupts --------------------------------------------------------------------------------
extern "C" void utrf_read_reset_flags(void) __attribute__((naked, used, section(".init3")));
extern "C" void utrf_read_reset_flags(void) {
    // Before the C runtime and the Arduino core: keep the flags, clear them (so the next reset
    // reports its own), and stop a watchdog left running by a watchdog reset.
    g_mcusr = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

// The tick lock is a flag, not the interrupt mask: a compare that arrives while loop() holds
// the lock, or while a tick still runs, is remembered and its tick runs as soon as the lock is
// released or the running tick ends (late; a second one meanwhile is a lost period, reported
// as an overrun: g_tick_lost). Masking OCIE2A would do the same on
// the chip, but simavr drops an interrupt raised while its enable bit is clear.
static volatile uint8_t g_tick_locked;
static volatile uint8_t g_tick_running;
static volatile uint8_t g_tick_deferred;
// A compare that came while one was already deferred: a whole period passed without its tick
// (the lock held, or the interrupt itself held up, that long). The next tick reports an overrun.
static volatile uint8_t g_tick_lost;

namespace {
__attribute__((always_inline)) inline Stamp read_stamp() {
    Stamp s;
    s.coarse = TCNT2;
    s.fine = TCNT1;
    return s;
}

// Cycles since `start`, up to two tick periods. The tick timer gives the time to within 64
// cycles; timer 1 (modulo 800) gives it exactly modulo 800: take the value of the second that
// lies within 400 cycles of the first. Inline: the timer interrupt runs it after every tick.
__attribute__((always_inline)) inline uint16_t cycles_from(const Stamp& start) {
    const uint8_t c2 = TCNT2;
    const uint16_t c1 = TCNT1;
    int16_t d2 = (int16_t)c2 - (int16_t)start.coarse;
    if (g_tick_deferred || d2 < 0) d2 = (int16_t)(d2 + (F_CPU / 64 / UTRF_TICK_HZ));
    const uint16_t coarse = (uint16_t)d2 * 64u;
    const uint16_t fine = c1 >= start.fine ? (uint16_t)(c1 - start.fine)
                                           : (uint16_t)(c1 + (UTRF_PWM_TOP + 1) - start.fine);
    // Whole periods of 800: (coarse - fine + 400) / 800, as x * 82 >> 16 (0 when x < 0). With
    // 0 <= x < 2^15 that is two 8 x 8 multiplies, not a 32-bit product:
    // floor((256 xh + xl) * 82 / 2^16) = (82 xh + (82 xl >> 8)) >> 8.
    const int16_t x = (int16_t)((int16_t)(coarse - fine) + 400);
    uint8_t k = 0;
    if (x > 0) {
        const uint16_t t = (uint16_t)(fx::mul8u((uint8_t)((uint16_t)x >> 8), 82u) +
                                      (fx::mul8u((uint8_t)x, 82u) >> 8));
        k = (uint8_t)(t >> 8);
    }
    return (uint16_t)(fine + fx::mul8u(k, 25u) * 32u);  // k <= 40 periods of 800
}

// Runs ticks while any is due. Called with interrupts disabled; returns with them disabled.
// Timer 0's overflow nests in the tick (it blocks nothing). The UART's interrupts stay on:
// receiving, or bytes would be lost; transmitting, or the line would stand idle for the tick's
// 250-370 us and the 1 kHz state stream (39 bytes, 0.39 ms of line a frame) would lose frames
// behind replies.
// The tick's measured time includes those nested interrupts.
// One tick, timed. Out of line, so that its timing arithmetic is not hoisted into registers
// the loop below would keep (and save) across the tick's call; the start is in memory for the
// same reason.
Stamp g_tick_start;
__attribute__((noinline)) void run_one_tick() {
    const uint8_t lost = g_tick_lost;  // interrupts are off here: read and cleared as one
    g_tick_lost = 0;
    g_tick_deferred = 0;
    g_tick_running = 1;
    g_tick_start = read_stamp();
    sei();
    app::tick();
    const uint16_t cycles = cycles_from(g_tick_start);
    const bool overran = g_tick_deferred != 0 || lost != 0;
    // loop() after the tick only when it gave loop() work (sleep_until_interrupt()).
    if (app::tick_done(cycles, overran)) GPIOR0 |= _BV(kWake);
    cli();
    g_tick_running = 0;
    // As the tick ends (where a loop() pass after each tick read millis() before): interrupts
    // off, so whole (timer 0's handler stores g_ms so too).
    g_tick_ms = g_ms;
}

inline __attribute__((always_inline)) void run_due_ticks() {
    do {
        run_one_tick();
    } while (g_tick_deferred && !g_tick_locked);
}

// A compare: its tick, or, while one runs (or a lock the mask below missed), a deferred one.
inline __attribute__((always_inline)) void take_compare() {
    GPIOR0 |= _BV(kTickSeen);  // the tick runs: timer 0 need not wake loop() (the idle sleep)
    if (g_tick_running || g_tick_locked) {
        if (g_tick_deferred) g_tick_lost = 1;
        g_tick_deferred = 1;
        return;
    }
    run_due_ticks();
}
}  // namespace

ISR(TIMER2_COMPA_vect) { take_compare(); }

// With the interrupts on from its first instruction (ISR_NOBLOCK, before the register saves):
// the UART's two-byte receive FIFO gives a byte two byte times (20 us at 1 Mbaud) and this
// handler takes about 14. It holds no tick lock: the tick reads only the last complete round
// (g_adc_done), never the one filled here, and starts a round only when none runs
// (encoders_sample()); the round's hand-over is one short stretch with interrupts off.
ISR(ADC_vect, ISR_NOBLOCK) {
    const uint8_t i = g_adc_at;
    // Judged here, between ticks (the round runs after each tick), not in the tick: the band,
    // the angle and the joint limits (core/encoder.h, judge()). Through the two running
    // pointers (no index arithmetic), each field stored as it is worked out: few registers,
    // so few to save and restore around this handler, five times a tick.
    EncoderReading* const r = g_adc_slot;
    const EncoderSetup* const s = g_adc_setup;
    *r = encoder::judge(ADC, *s);
    const uint8_t next = (uint8_t)(i + 1);
    cli();
    if (next < UTRF_FINGER_COUNT) {
        g_adc_at = next;
        g_adc_slot = r + 1;
        g_adc_setup = s + 1;
        adc_start(next);
    } else {
        g_adc_at = 0xFF;
        EncoderReading* const fill = g_adc_fill;
        EncoderReading* const next_fill = const_cast<EncoderReading*>(g_adc_done);
        g_adc_fill = next_fill;
        g_adc_done = fill;
        g_adc_slot = next_fill;  // the next round's first slot and setup
        g_adc_setup = g_setup;
        g_adc_round = (uint8_t)(g_adc_round + 1);
    }
    sei();  // the register restores with the interrupts on
}

// A received byte into the ring; a byte that finds the ring full is counted in g_rx_lost.
// UCSR0A, read before UDR0 as the datasheet asks, tells of bytes the UART itself lost before
// this one (DOR0) and of this byte's bad stop bit (FE0): counted, the byte kept (the frame's
// CRC drops it).
ISR(USART0_RX_vect) {
    const uint8_t status = UCSR0A;
    const uint8_t byte = UDR0;
    const uint8_t head = GPIOR1;
    const uint8_t next = (uint8_t)((head + 1) & 0x7F);
    if (__builtin_expect((status & (_BV(DOR0) | _BV(FE0))) != 0, 0)) {
        if (status & _BV(DOR0)) g_rx_dor = (uint8_t)(g_rx_dor + 1);
        if (status & _BV(FE0)) g_rx_fe = (uint8_t)(g_rx_fe + 1);
    }
    if (__builtin_expect(next == GPIOR2, 0)) {
        g_rx_lost = (uint8_t)(g_rx_lost + 1);  // full: the byte is not kept
        return;
    }
    g_rx_buf[head] = byte;
    GPIOR1 = next;
    // A frame's 0x00 wakes loop(): it reads the whole frame then (the bytes before it wait in
    // the ring, and hold the stream's next frame back meanwhile). A pass a byte would cost more
    // than the frame's decoding.
    if (byte == 0) {
        GPIOR0 |= _BV(kWake);
    } else {
        GPIOR0 |= _BV(kRxByte);
    }
}

// The next byte of the ring into UDR0; when the ring is empty, this interrupt goes off.
ISR(USART0_UDRE_vect) {
    const uint8_t tail = g_tx_tail;
    if (tail == g_tx_head) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        GPIOR0 |= _BV(kWake);  // the buffer is empty: a board frame may start
        return;
    }
    UDR0 = g_tx_buf[tail];
    g_tx_tail = (uint8_t)(tail + 1);
}

// ---- hal.h -------------------------------------------------------------------------------------
void avr_init() {
    for (uint8_t f = 0; f < UTRF_FINGER_COUNT; ++f) {
        const utrf_finger_pins_t& p = UTRF_FINGER_PINS[f];
        g_hw[f].m[0] = motor_hw(p.a);
        g_hw[f].m[1] = motor_hw(p.b);
        g_hw[f].stby = output_pin(p.stby);
        g_hw[f].stby_last = 0;
        avr_motors::g_drives_last[f] = 0xFF;
        g_admux[f] = (uint8_t)(_BV(REFS0) | (p.adc_channel & 0x07));
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

    // ADC: clk/128 (125 kHz, 104 us a conversion); a round of five takes ~0.52 ms.
    ADCSRB = 0;
    ADCSRA = _BV(ADEN) | _BV(ADIE) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
    g_adc_at = 0xFF;
    encoders_sample();

    // UART0, 8N1, double speed: UBRR = F_CPU / (8 baud) - 1 (1 at 1 Mbaud, exact).
    static_assert(F_CPU / 8 / UTRF_BAUD >= 1, "UTRF_BAUD is too fast for U2X at this clock");
    UCSR0B = 0;
    UCSR0A = _BV(U2X0);
    UBRR0 = (uint16_t)((F_CPU + 4UL * UTRF_BAUD) / (8UL * UTRF_BAUD) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    GPIOR0 = 0;  // bit kWake: see sleep_until_interrupt()
    GPIOR1 = 0;  // receive head: empty
    GPIOR2 = 0;  // receive tail
    g_tx_head = g_tx_tail = 0;
    g_rx_lost = 0;
    g_rx_dor = g_rx_fe = 0;
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

void motor_off(uint8_t f) {
    // The compare outputs are disconnected by the change to COAST: the counts do not matter.
    avr_motors::drives_change(f, drives(Drive::COAST, Drive::COAST, false));
}

void motors_all_off() {
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        for (uint8_t f = 0; f < UTRF_FINGER_COUNT; ++f) {
            FingerHw& h = g_hw[f];
            *h.stby.port &= (uint8_t)~h.stby.mask;
            h.stby_last = 0;
            avr_motors::g_drives_last[f] = drives(Drive::COAST, Drive::COAST, false);
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

const EncoderReading* encoders_read() {
    const EncoderReading* done;
    uint8_t round;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        done = g_adc_done;
        round = g_adc_round;
    }
    return g_staleness.stale(round) ? kNoData : done;
}

void encoder_setup(uint8_t finger, const EncoderSetup& s) {
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        g_setup[finger] = s;
        // Readings judged with the earlier setup: the tick judges them again itself.
        g_reading[0][finger].flags |= kReadingRejudge;
        g_reading[1][finger].flags |= kReadingRejudge;
    }
}

void encoders_sample() {
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        if (g_adc_at == 0xFF) {  // a round still running (ADC slower than it should be) goes on
            g_adc_at = 0;
            adc_start(0);
        }
    }
}

void tick_start() {
    // Let the ADC finish a round first, so the first tick judges real readings (an encoder
    // that is really unplugged is still caught then). At most ~5 ms.
    const uint32_t t0 = millis();
    encoders_sample();
    while (g_adc_round == 0 && millis() - t0 < 5) {
    }
    g_tick_locked = 0;
    g_tick_running = 0;
    g_tick_deferred = 0;
    g_tick_lost = 0;
    g_tick_ms = millis();
    TCNT2 = 0;
    TIFR2 = _BV(OCF2A);
    TIMSK2 = _BV(OCIE2A);
}

// The lock masks the compare interrupt as well as setting the flag: a compare meanwhile
// raises only OCF2A, and no handler runs (its register saves would hold a received byte up
// for some 100 cycles). The unlock takes that compare itself: its tick runs now, late.
// (simavr drops an interrupt raised while masked, so the flag is read, not left to the
// hardware; on the chip it would fire at the unmask: cleared first.)
// Only a started tick is masked (setup() takes the lock before tick_start()). No handler
// writes TIMSK2: no lock needed around it.
static uint8_t g_tick_masked;
void tick_lock() {
    g_tick_locked = 1;
    if (TIMSK2 & _BV(OCIE2A)) {
        TIMSK2 &= (uint8_t)~_BV(OCIE2A);
        g_tick_masked = 1;
    }
}

void tick_unlock() {
    cli();
    g_tick_locked = 0;
    if (g_tick_masked) {
        g_tick_masked = 0;
        TIMSK2 |= _BV(OCIE2A);
        if (TIFR2 & _BV(OCF2A)) {
            TIFR2 = _BV(OCF2A);
            take_compare();
        }
    }
    // A compare whose handler found the flag (raised before the mask took).
    if (g_tick_deferred && !g_tick_running) run_due_ticks();
    sei();
}

Stamp stamp() { return read_stamp(); }

bool tick_period_elapsed() { return g_tick_deferred != 0; }

uint32_t millis() {
    uint32_t m;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { m = g_ms; }
    return m;
}

uint32_t tick_millis() {
    uint32_t m;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { m = g_tick_ms; }
    return m;
}

uint8_t serial_rx_peek(const uint8_t** data) {
    const uint8_t tail = GPIOR2;
    const uint8_t head = GPIOR1;  // one read: bytes arriving meanwhile come at the next call
    *data = g_rx_buf + tail;
    return head >= tail ? (uint8_t)(head - tail) : (uint8_t)(sizeof g_rx_buf - tail);
}

void serial_rx_take(uint8_t n) { GPIOR2 = (uint8_t)((GPIOR2 + n) & 0x7F); }

bool serial_rx_waiting() { return GPIOR1 != GPIOR2; }

uint16_t serial_tx_room() {
    return (uint16_t)((uint8_t)(g_tx_tail - g_tx_head - 1));  // 256-byte ring
}

void serial_write(const uint8_t* data, uint16_t len) {
    // At most the ring's 255 free bytes (room checked): an 8-bit count and a moving pointer,
    // a reply's bytes copied in about half the cycles of the 16-bit indexed loop.
    uint8_t head = g_tx_head;
    const uint8_t* const end = data + (uint8_t)len;
    while (data != end) g_tx_buf[head++] = *data++;
    g_tx_head = head;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { UCSR0B |= _BV(UDRIE0); }
}

uint8_t* serial_tx_ring() { return g_tx_buf; }
uint8_t serial_tx_head() { return g_tx_head; }

void serial_tx_commit(uint8_t end) {
    g_tx_head = end;
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

UartErrors serial_take_uart_errors() {
    UartErrors e;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        e.overruns = g_rx_dor;
        e.frame_errors = g_rx_fe;
        g_rx_dor = g_rx_fe = 0;
    }
    return e;
}

void sleep_until_interrupt(bool (*idle)(), void (*take_bytes)()) {
    set_sleep_mode(SLEEP_MODE_IDLE);
    cli();
    GPIOR0 &= (uint8_t)~_BV(kWake);  // before the check: what comes after it wakes us
    uint8_t ms = g_t0_overflows;
    // The check runs with interrupts on: it takes some 300 cycles, and a byte the UART
    // received may wait at most two byte times (320 cycles at 1 Mbaud). Whatever the check
    // saw and an interrupt changed meanwhile raises kWake (a tick, a frame's end, the transmit
    // buffer empty) or moves timer 0 on (millis): then no sleep. A byte of a frame sets kRxByte,
    // which the loop below takes care of after the first wake-up.
    sei();
    const bool go = idle();
    cli();
    if (go && !(GPIOR0 & _BV(kWake)) && g_t0_overflows == ms) {
        for (;;) {
            sleep_enable();
            sei();  // SLEEP runs before any interrupt pending now, which then wakes it at once
            sleep_cpu();
            sleep_disable();
            cli();
            if (GPIOR0 & _BV(kWake)) break;
            if (GPIOR0 & _BV(kRxByte)) {
                // A byte of a frame (not its end): once kRxEarly wait, they are taken now,
                // with interrupts on, and the sleep goes on.
                GPIOR0 &= (uint8_t)~_BV(kRxByte);
                if ((uint8_t)((GPIOR1 - GPIOR2) & 0x7F) >= kRxEarly) {
                    sei();
                    take_bytes();
                    cli();
                    if (GPIOR0 & _BV(kWake)) break;
                }
            }
            const uint8_t now = g_t0_overflows;
            if (now == ms) continue;
            // Timer 0's overflow: a new millisecond for the tick-alive check. While the tick
            // runs, it wakes loop() at least every 5 ticks (app::tick_done()), and the check
            // (against the last tick's end, tick_millis()) cannot fire; once a whole overflow
            // period passed with no tick, every overflow wakes loop(), so a stopped tick is
            // seen at the same millisecond as by a loop() that never sleeps.
            ms = now;
            if (!(GPIOR0 & _BV(kTickSeen))) break;
            GPIOR0 &= (uint8_t)~_BV(kTickSeen);
        }
    }
    sei();
}

uint8_t eeprom_read(uint16_t addr) { return eeprom_read_byte((const uint8_t*)addr); }
bool eeprom_ready() { return eeprom_is_ready(); }
void eeprom_write(uint16_t addr, uint8_t value) { eeprom_write_byte((uint8_t*)addr, value); }

// 30 ms (WDTO_30MS: 4K cycles of the 128 kHz watchdog oscillator, 32 ms nominal): the longest
// a hang with interrupts off leaves the motors at their last duty (nothing of the firmware
// runs then). loop() feeds it every pass (at least every 5 ticks while the tick runs; a pass
// takes a few ms at most), and the loop-alive rule (hand.h, 20 ticks) turns the motors off
// before it fires when the tick still runs.
void watchdog_start() { wdt_enable(WDTO_30MS); }
void watchdog_feed() { wdt_reset(); }
void watchdog_mark_hang() { g_hang_mark = kHangMagic; }
void watchdog_clear_hang_mark() { g_hang_mark = 0; }

uint8_t reset_cause() {
    // The MEGA's stk500v2 bootloader reads MCUSR and clears it before it starts us, so with
    // the bootloader the flags are gone (UNKNOWN); a watchdog reset this firmware provoked
    // (a hung loop or tick) is still known from the mark it left in .noinit RAM.
    typedef proto::ResetCause C;
    const uint8_t f = g_mcusr;
    if (f & _BV(PORF)) return (uint8_t)C::POWER_ON;
    if (f & _BV(BORF)) return (uint8_t)C::BROWN_OUT;
    if ((f & _BV(WDRF)) || g_hang_mark == kHangMagic) return (uint8_t)C::WATCHDOG;
    if (f & _BV(EXTRF)) return (uint8_t)C::RESET_PIN;
    if (f & _BV(JTRF)) return (uint8_t)C::JTAG;
    return (uint8_t)C::UNKNOWN;
}

}  // namespace hal
}  // namespace utrf
