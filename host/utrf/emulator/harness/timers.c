/* Quiet PWM timers: simavr's timer events the firmware cannot observe, left out.
 *
 * simavr runs each timer on cycle-timer events: an overflow and each compare match, every
 * period. The four 20 kHz PWM timers make about 240,000 of them a simulated second, and each
 * one ends simavr's run of instructions (and, while the firmware sleeps, its skip over the
 * idle cycles). Their only effects are interrupt flags and the OCnX pins' waveforms; the
 * harness takes the duty from the registers (board_io.c), not from the waveforms. So a timer
 * whose interrupts are all disabled has its events cancelled before each run; its registers,
 * and the duty they give, are untouched. What differs from the chip: such a timer's TOVn and
 * OCFnx flags stay clear (the firmware polls none).
 *
 * Its counter stays right: simavr computes TCNT from the cycles since the last overflow
 * (tov_base, which the overflow event would have moved), so a read of TCNT first moves
 * tov_base to the last overflow on the timer's own period grid, where the events would have
 * put it; the firmware reads TCNT1 for its fine clock and gets the chip's value. A write of an
 * OCRnX makes simavr re-arm the timer's events from tov_base: moved the same way first, and
 * the events cancelled again after it. Measured (line's idle-sleeping firmware, five fingers
 * under position control, telemetry at 100 Hz): timer 1 alone made 51,000 events a simulated
 * second, timers 3-5 (re-armed by each OCR write until the next run) 7,000; leaving them out
 * took the emulator from 0.046 to 0.038 s of CPU time per simulated second.
 * A timer whose interrupts get enabled is given its events back by a write of its clock
 * select, as the firmware's own set-up would (its phase restarts then).
 */
#include <string.h>

#include "avr_timer.h"
#include "harness_internal.h"

static const char QUIET_TIMERS[] = {'1', '3', '4', '5'};

static avr_timer_t *timer_named(avr_t *avr, char name)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next)
        if (!strcmp(io->kind, "timer") && ((avr_timer_t *)io)->name == name)
            return (avr_timer_t *)io;
    return NULL;
}

static int enabled(avr_t *avr, const avr_int_vector_t *v)
{
    return v->enable.reg && avr_regbit_get(avr, v->enable);
}

static int observable(avr_t *avr, const avr_timer_t *t)
{
    if (enabled(avr, &t->overflow) || enabled(avr, &t->icr))
        return 1;
    for (int c = 0; c < AVR_TIMER_COMP_COUNT; c++)
        if (enabled(avr, &t->comp[c].interrupt))
            return 1;
    return 0;
}

static int io_register(uint16_t reg)
{
    return reg >= 32 && reg < 32 + MAX_IOs;
}

static void restart(avr_t *avr, const avr_timer_t *t)
{
    uint16_t reg = t->cs[0].reg;
    if (!io_register(reg))
        return;
    avr_io_addr_t io = AVR_DATA_TO_IO(reg);
    if (avr->io[io].w.c)
        avr->io[io].w.c(avr, reg, avr->data[reg], avr->io[io].w.param);
}

/* tov_base to the last overflow at or before now, on the period grid the events keep. */
static void catch_up(avr_t *avr, avr_timer_t *t)
{
    if (t->tov_cycles > 1 && t->tov_base && avr->cycle > t->tov_base)
        t->tov_base += (avr->cycle - t->tov_base) / t->tov_cycles * t->tov_cycles;
}

/* The timer's events are simavr's static callbacks: found by their parameter. */
static int cancel_events(avr_t *avr, avr_timer_t *t)
{
    avr_cycle_timer_t found[8];
    int n = 0;
    for (avr_cycle_timer_slot_p slot = avr->cycle_timers.timer; slot && n < 8; slot = slot->next)
        if (slot->param == t)
            found[n++] = slot->timer;
    for (int k = 0; k < n; k++)
        avr_cycle_timer_cancel(avr, found[k], t);
    return n;
}

static uint8_t tcnt_read(avr_t *avr, avr_io_addr_t addr, void *param)
{
    quiet_timer_t *q = param;
    if (q->quieted)
        catch_up(avr, q->timer);
    return q->orig_read ? q->orig_read(avr, addr, q->orig_param) : avr->data[addr];
}

/* An OCRnX write (its low byte, which simavr acts on). */
static void ocr_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    quiet_timer_t *q = param;
    avr_timer_t *t = q->timer;
    int ch = 0;
    while (ch < 2 && t->comp[ch].r_ocr != addr)
        ch++;
    if (q->quieted)
        catch_up(avr, t);
    if (q->orig_ocr[ch].c)
        q->orig_ocr[ch].c(avr, addr, v, q->orig_ocr[ch].param);
    else
        avr->data[addr] = v;
    if (q->quieted) {
        utrf_sim_t *s = avr->custom.data;
        s->stats.quieted_timer_events += (uint64_t)cancel_events(avr, t);
    }
}

void timers_init(utrf_sim_t *s)
{
    avr_t *avr = s->avr;
    s->n_quiet = 0;
    for (size_t i = 0; i < sizeof QUIET_TIMERS; i++) {
        avr_timer_t *t = timer_named(avr, QUIET_TIMERS[i]);
        if (!t || !io_register(t->r_tcnt))
            continue;
        quiet_timer_t *q = &s->quiet[s->n_quiet++];
        avr_io_addr_t io = AVR_DATA_TO_IO(t->r_tcnt);
        memset(q, 0, sizeof *q);
        q->timer = t;
        q->orig_read = avr->io[io].r.c;
        q->orig_param = avr->io[io].r.param;
        avr->io[io].r.c = tcnt_read;
        avr->io[io].r.param = q;
        for (int c = 0; c < AVR_TIMER_COMP_COUNT && c < 3; c++) {
            uint16_t reg = t->comp[c].r_ocr;
            if (!io_register(reg))
                continue;
            avr_io_addr_t w = AVR_DATA_TO_IO(reg);
            q->orig_ocr[c] = (io_write_hook_t){avr->io[w].w.c, avr->io[w].w.param};
            avr->io[w].w.c = ocr_write;
            avr->io[w].w.param = q;
        }
    }
}

void timers_quiet(utrf_sim_t *s)
{
    if (!s->quiet_timers)
        return;
    avr_t *avr = s->avr;
    for (int i = 0; i < s->n_quiet; i++) {
        quiet_timer_t *q = &s->quiet[i];
        if (observable(avr, q->timer)) {
            if (q->quieted)
                restart(avr, q->timer);
            q->quieted = 0;
            continue;
        }
        if (q->quieted)
            catch_up(avr, q->timer);
        s->stats.quieted_timer_events += (uint64_t)cancel_events(avr, q->timer);
        q->quieted = 1;
    }
}

void utrf_sim_set_quiet_timers(utrf_sim_t *s, int on)
{
    s->quiet_timers = on != 0;
    if (!on) /* give every quieted timer its events back */
        for (int i = 0; i < s->n_quiet; i++) {
            if (s->quiet[i].quieted)
                restart(s->avr, s->quiet[i].timer);
            s->quiet[i].quieted = 0;
        }
}
