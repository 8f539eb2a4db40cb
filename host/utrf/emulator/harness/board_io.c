/* What the board's pins show the motor drivers, and what the encoders show the ADC.
 *
 * Pins are read from the simulated registers, as the TB6612FNG would see them: a pin's
 * level is its PORT bit whether it is an output (driven) or an input (pull-up on, or the
 * TB6612's internal pull-down when off). A PWM pin connected to its timer (COMnX != 0, DDR
 * set) carries the duty the timer's mode makes of OCRnX. The pin map is board_pins.h,
 * shared with the firmware.
 */
#include <math.h>
#include <string.h>

#include "avr_adc.h"
#include "board_pins.h"
#include "harness_internal.h"

#include "avr_regs.h"

typedef struct {
    uint16_t port, ddr;
} port_regs_t;

static const port_regs_t *port_regs(char letter)
{
    static const port_regs_t ports[] = {
        ['A' - 'A'] = {PORTA, DDRA}, ['B' - 'A'] = {PORTB, DDRB}, ['C' - 'A'] = {PORTC, DDRC},
        ['D' - 'A'] = {PORTD, DDRD}, ['E' - 'A'] = {PORTE, DDRE}, ['F' - 'A'] = {PORTF, DDRF},
        ['G' - 'A'] = {PORTG, DDRG}, ['H' - 'A'] = {PORTH, DDRH}, ['J' - 'A'] = {PORTJ, DDRJ},
        ['K' - 'A'] = {PORTK, DDRK}, ['L' - 'A'] = {PORTL, DDRL},
    };
    if (letter < 'A' || letter > 'L' || letter == 'I')
        return NULL;
    return &ports[letter - 'A'];
}

typedef struct {
    uint16_t tccra, tccrb, icr, ocr[3];
} timer16_regs_t;

static const timer16_regs_t *timer_regs(uint8_t timer)
{
    static const timer16_regs_t t1 = {TCCR1A, TCCR1B, ICR1L, {OCR1AL, OCR1BL, OCR1CL}};
    static const timer16_regs_t t3 = {TCCR3A, TCCR3B, ICR3L, {OCR3AL, OCR3BL, OCR3CL}};
    static const timer16_regs_t t4 = {TCCR4A, TCCR4B, ICR4L, {OCR4AL, OCR4BL, OCR4CL}};
    static const timer16_regs_t t5 = {TCCR5A, TCCR5B, ICR5L, {OCR5AL, OCR5BL, OCR5CL}};
    switch (timer) {
    case 1: return &t1;
    case 3: return &t3;
    case 4: return &t4;
    case 5: return &t5;
    default: return NULL;
    }
}

static uint16_t reg16(const avr_t *avr, uint16_t low)
{
    return (uint16_t)(avr->data[low] | (avr->data[low + 1] << 8));
}

static int pin_level(const avr_t *avr, utrf_pin_t pin)
{
    const port_regs_t *r = port_regs(pin.port);
    if (!r)
        return 0;
    /* Output: the PORT bit drives it. Input: PORT = 1 is the pull-up (high); PORT = 0 leaves
     * it to the TB6612's internal pull-down (low). Either way the level is the PORT bit. */
    return (avr->data[r->port] >> pin.bit) & 1;
}

static int pin_is_output(const avr_t *avr, utrf_pin_t pin)
{
    const port_regs_t *r = port_regs(pin.port);
    return r && ((avr->data[r->ddr] >> pin.bit) & 1);
}

/* The duty at an OCnX pin: the fraction of each period it is high. */
static double pwm_duty(const avr_t *avr, utrf_pwm_t pwm)
{
    const timer16_regs_t *t = timer_regs(pwm.timer);
    if (!t || pwm.channel < 'A' || pwm.channel > 'C')
        return 0.0;
    int ch = pwm.channel - 'A';
    uint8_t tccra = avr->data[t->tccra], tccrb = avr->data[t->tccrb];
    int com = (tccra >> (6 - 2 * ch)) & 3;
    int wgm = (tccra & 3) | (((tccrb >> 3) & 3) << 2);
    int clock = tccrb & 7;

    if (com == 0) /* disconnected from the timer: a plain GPIO */
        return pin_level(avr, pwm.pin);
    if (!pin_is_output(avr, pwm.pin) || clock == 0)
        return 0.0; /* the OC pin is not driven, or the timer is stopped */

    uint32_t top;
    int fast;
    switch (wgm) {
    case 5: top = 0xFF, fast = 1; break;
    case 6: top = 0x1FF, fast = 1; break;
    case 7: top = 0x3FF, fast = 1; break;
    case 14: top = reg16(avr, t->icr), fast = 1; break;
    case 15: top = reg16(avr, t->ocr[0]), fast = 1; break;
    case 1: top = 0xFF, fast = 0; break;
    case 2: top = 0x1FF, fast = 0; break;
    case 3: top = 0x3FF, fast = 0; break;
    case 8:
    case 10: top = reg16(avr, t->icr), fast = 0; break;
    case 9:
    case 11: top = reg16(avr, t->ocr[0]), fast = 0; break;
    default: return 0.0; /* normal or CTC: compare outputs toggle/set/clear, no duty */
    }
    if (com == 1) {
        /* Toggle on match: only OCnA in the modes with TOP in OCRnA (a 50 % square wave);
         * elsewhere the pin stays a GPIO. */
        if (ch == 0 && (wgm == 15 || wgm == 9 || wgm == 11))
            return 0.5;
        return pin_level(avr, pwm.pin);
    }
    if (top == 0)
        return com == 2 ? 0.0 : 1.0;
    uint32_t ocr = reg16(avr, t->ocr[ch]);
    double high;
    if (fast) /* set at BOTTOM, cleared when TCNT = OCR: OCR + 1 of TOP + 1 clocks */
        high = ocr >= top ? 1.0 : (double)(ocr + 1) / (double)(top + 1);
    else /* phase correct: OCR of TOP up and down */
        high = ocr >= top ? 1.0 : (double)ocr / (double)top;
    return com == 2 ? high : 1.0 - high;
}

void board_io_read_pins(utrf_sim_t *s)
{
    const avr_t *avr = s->avr;
    for (int f = 0; f < UTRF_FINGER_COUNT; f++) {
        const utrf_finger_pins_t *fp = &UTRF_FINGER_PINS[f];
        int stby = pin_level(avr, fp->stby);
        for (int c = 0; c < 2; c++) {
            const utrf_motor_pins_t *m = c ? &fp->b : &fp->a;
            double *out = &s->pins[(f * 2 + c) * UTRF_SIM_PIN_FIELDS];
            out[0] = pwm_duty(avr, m->pwm);
            out[1] = pin_level(avr, m->in1);
            out[2] = pin_level(avr, m->in2);
            out[3] = stby;
        }
    }
}

static utrf_sim_motor_regs_t motor_registers(const avr_t *avr, const utrf_motor_pins_t *m)
{
    utrf_sim_motor_regs_t r = {0};
    const timer16_regs_t *t = timer_regs(m->pwm.timer);
    int ch = m->pwm.channel - 'A';
    if (t && ch >= 0 && ch <= 2) {
        uint8_t tccra = avr->data[t->tccra], tccrb = avr->data[t->tccrb];
        r.com = (tccra >> (6 - 2 * ch)) & 3;
        r.ocr = reg16(avr, t->ocr[ch]);
        r.icr = reg16(avr, t->icr);
        r.wgm = (uint32_t)((tccra & 3) | (((tccrb >> 3) & 3) << 2));
        r.cs = tccrb & 7;
    }
    r.in1 = (uint32_t)pin_level(avr, m->in1);
    r.in2 = (uint32_t)pin_level(avr, m->in2);
    r.pwm_pin = (uint32_t)pin_level(avr, m->pwm.pin);
    r.outputs = pin_is_output(avr, m->in1) && pin_is_output(avr, m->in2) &&
                pin_is_output(avr, m->pwm.pin);
    return r;
}

void utrf_sim_pin_registers(const utrf_sim_t *s, utrf_sim_finger_regs_t *out5)
{
    for (int f = 0; f < UTRF_FINGER_COUNT; f++) {
        const utrf_finger_pins_t *fp = &UTRF_FINGER_PINS[f];
        out5[f].motor[0] = motor_registers(s->avr, &fp->a);
        out5[f].motor[1] = motor_registers(s->avr, &fp->b);
        out5[f].stby = (uint32_t)pin_level(s->avr, fp->stby);
        out5[f].stby_out = (uint32_t)pin_is_output(s->avr, fp->stby);
    }
}

/* A conversion starts: sample its channel now (the ADC's sample-and-hold) and hand simavr a
 * value that its own arithmetic, floor(mV * 1023 / Vref), turns into the ideal converter of
 * the datasheet's "ADC Accuracy Definitions": the first transition (0x000 -> 0x001) at
 * 0.5 LSB and the last (0x3FE -> 0x3FF) at 1.5 LSB below Vref, i.e. code c for inputs within
 * half an LSB of c * Vref / 1024: code = floor(1024 V / Vref + 1/2), within 0..1023. (The
 * result formula ADC = V * 1024 / Vref is that converter's nominal value; taken as floor() it
 * would read every input half an LSB low, 3.8 mrad of Joint-2 angle.) */
static void on_adc_trigger(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    avr_t *avr = s->avr;
    union {
        avr_adc_mux_t mux;
        uint32_t v;
    } e = {.v = value};
    s->stats.adc_conversions++;
    if (e.mux.kind != ADC_MUX_SINGLE || e.mux.src >= UTRF_SIM_ADC_CHANNELS)
        return;
    uint32_t vref_mv;
    switch ((avr->data[ADMUX] >> REFS0) & 3) {
    case 0: vref_mv = avr->aref; break;
    case 1: vref_mv = avr->avcc; break;
    case 2: vref_mv = 1100; break;
    default: vref_mv = 2560; break;
    }
    double volts = s->adc_volts[e.mux.src];
    double code = floor(volts * 1024.0 / (vref_mv * 1e-3) + 0.5);
    if (!(code > 0.0)) /* also NaN */
        code = 0.0;
    if (code > 1023.0)
        code = 1023.0;
    uint32_t mv = (uint32_t)ceil(code * vref_mv / 1023.0);
    avr_raise_irq(s->adc_irq + ADC_IRQ_ADC0 + e.mux.src, mv);
}

void board_io_init(utrf_sim_t *s)
{
    avr_irq_register_notify(s->adc_irq + ADC_IRQ_OUT_TRIGGER, on_adc_trigger, s);
}

uint64_t board_io_uart0_frame_cycles(const avr_t *avr, int *rx_enabled)
{
    static const int data_bits[8] = {5, 6, 7, 8, 8, 8, 8, 9};
    uint8_t a = avr->data[UCSR0A], b = avr->data[UCSR0B], c = avr->data[UCSR0C];
    uint32_t ubrr = (uint32_t)(avr->data[UBRR0L] | ((avr->data[UBRR0H] & 0x0F) << 8));
    uint64_t cycles_per_bit = (uint64_t)(ubrr + 1) * ((a & (1 << U2X0)) ? 8 : 16);
    int size = ((c >> UCSZ00) & 3) | ((b & (1 << UCSZ02)) ? 4 : 0);
    int parity = ((c >> UPM00) & 3) ? 1 : 0;
    int stop = (c & (1 << USBS0)) ? 2 : 1;
    if (rx_enabled)
        *rx_enabled = (b >> RXEN0) & 1;
    return cycles_per_bit * (uint64_t)(1 + data_bits[size] + parity + stop);
}

void board_io_apply_reset_flag(avr_t *avr, int cause)
{
    if (cause == UTRF_SIM_RESET_POWER_ON)
        avr->data[MCUSR] |= (uint8_t)(1 << PORF);
    else if (cause == UTRF_SIM_RESET_PIN)
        avr->data[MCUSR] |= (uint8_t)(1 << EXTRF);
}

uint8_t board_io_mcusr(const avr_t *avr)
{
    return avr->data[MCUSR];
}

int board_io_is_watchdog_reset(uint8_t mcusr)
{
    return (mcusr >> WDRF) & 1;
}

uint16_t board_io_eecr(void)
{
    return EECR;
}

uint8_t board_io_eempe_mask(void)
{
    return (uint8_t)(1 << EEMPE);
}

uint8_t board_io_eepe_mask(void)
{
    return (uint8_t)(1 << EEPE);
}

uint32_t board_io_sram_start(void)
{
    return RAMSTART;
}
