/* Cycle profiles of the firmware, with no change to it.
 *
 * An interrupt vector is timed from simavr's "running" signal (raised when the core jumps to
 * the vector, lowered at its RETI); its latency from its "pending" signal (its flag raised,
 * enabled or not) to the jump. A function is timed from its first instruction to the
 * return that lifts the stack pointer above its value at entry. Time spent in other
 * interrupts that nest inside is counted apart: "exclusive" figures leave it out.
 */
#include <string.h>

#include "harness_internal.h"

static void record(profile_state_t *p, uint64_t now)
{
    uint64_t incl = now - p->entry;
    p->p.count++;
    p->p.total += p->excl;
    p->p.total_incl += incl;
    if (p->excl > p->p.worst)
        p->p.worst = p->excl;
    if (p->p.count == 1 || p->excl < p->p.best)
        p->p.best = p->excl;
    if (incl > p->p.worst_incl)
        p->p.worst_incl = incl;
    p->active = 0;
}

static void enter(profile_state_t *p, uint64_t now)
{
    if (p->p.last_entry) {
        p->p.period_sum += now - p->p.last_entry;
        p->p.intervals++;
    }
    p->p.last_entry = now;
    p->active = 1;
    p->paused = 0;
    p->entry = p->seg = now;
    p->excl = 0;
}

/* The vector's flag is raised (whether enabled or not): its latency starts at the first raise. */
static void on_vector_pending(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    profile_state_t *p = &s->prof_vec;
    if (value && !p->waiting) {
        p->waiting = 1;
        p->raised_at = s->avr->cycle;
    }
}

static void on_vector_running(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    profile_state_t *p = &s->prof_vec;
    uint64_t now = s->avr->cycle;
    if (value) {
        if (p->waiting) {
            uint64_t latency = now - p->raised_at;
            p->p.latency_sum += latency;
            if (latency > p->p.latency_worst)
                p->p.latency_worst = latency;
            p->waiting = 0;
        }
        enter(p, now);
    } else if (p->active) {
        if (!p->paused)
            p->excl += now - p->seg;
        record(p, now);
    }
}

/* Exclusive time: a profiled span pauses while another vector is innermost (an interrupt
 * nested in it) and resumes when its own is innermost again. */
static void follow_innermost(profile_state_t *p, int mine, uint64_t now)
{
    if (!p->active)
        return;
    if (!mine && !p->paused) {
        p->excl += now - p->seg;
        p->paused = 1;
    } else if (mine && p->paused) {
        p->seg = now;
        p->paused = 0;
    }
}

/* The innermost running vector changed (0: none). */
static void on_any_running(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    uint64_t now = s->avr->cycle;
    follow_innermost(&s->prof_vec, (int)value == s->prof_vector, now);
    /* A function entered under prof_fn_vector (0: from the main loop). */
    follow_innermost(&s->prof_fn, (int)value == s->prof_fn_vector, now);
    s->running_vector = (int)value;
}

static uint16_t stack_pointer(const avr_t *avr)
{
    return (uint16_t)(avr->data[R_SPL] | (avr->data[R_SPH] << 8));
}

void profile_step_function(utrf_sim_t *s)
{
    avr_t *avr = s->avr;
    profile_state_t *p = &s->prof_fn;
    if (!p->active) {
        if (avr->pc == (uint32_t)s->prof_addr) {
            enter(p, avr->cycle);
            p->sp0 = stack_pointer(avr);
            s->prof_fn_vector = s->running_vector;
        }
    } else if (stack_pointer(avr) > p->sp0) {
        if (!p->paused)
            p->excl += avr->cycle - p->seg;
        record(p, avr->cycle);
    }
}

void profile_init(utrf_sim_t *s)
{
    s->prof_vector = 0;
    s->prof_addr = -1;
    avr_irq_register_notify(s->avr->interrupts.irq + AVR_INT_IRQ_RUNNING, on_any_running, s);
}

void profile_after_reset(utrf_sim_t *s)
{
    /* A reset abandons whatever was running or waiting. */
    s->prof_vec.active = 0;
    s->prof_vec.waiting = 0;
    s->prof_fn.active = 0;
    s->running_vector = 0;
}

int utrf_sim_profile_vector(utrf_sim_t *s, int vector)
{
    if (s->prof_vector > 0) {
        avr_irq_t *old = utrf_vector_irq(s->avr, s->prof_vector);
        if (old) {
            avr_irq_unregister_notify(old + AVR_INT_IRQ_RUNNING, on_vector_running, s);
            avr_irq_unregister_notify(old + AVR_INT_IRQ_PENDING, on_vector_pending, s);
        }
    }
    memset(&s->prof_vec, 0, sizeof s->prof_vec);
    s->prof_vector = 0;
    if (vector <= 0)
        return 0;
    avr_irq_t *irq = utrf_vector_irq(s->avr, vector);
    if (!irq)
        return -1;
    avr_irq_register_notify(irq + AVR_INT_IRQ_RUNNING, on_vector_running, s);
    avr_irq_register_notify(irq + AVR_INT_IRQ_PENDING, on_vector_pending, s);
    s->prof_vector = vector;
    return 0;
}

int utrf_sim_profile_function(utrf_sim_t *s, int64_t addr)
{
    memset(&s->prof_fn, 0, sizeof s->prof_fn);
    if (addr < 0) {
        s->prof_addr = -1;
        return 0;
    }
    if ((uint64_t)addr > s->avr->flashend || (addr & 1))
        return -1;
    s->prof_addr = addr;
    return 0;
}

void utrf_sim_profile_get(const utrf_sim_t *s, int which, utrf_sim_profile_t *out)
{
    *out = which ? s->prof_fn.p : s->prof_vec.p;
}
