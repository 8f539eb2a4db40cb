/* Cycle profiles of the firmware, with no change to it.
 *
 * An interrupt vector is timed from simavr's "running" signal (raised when the core jumps to
 * the vector, lowered at its RETI); its latency from its "pending" signal (its flag raised,
 * enabled or not) to the jump. A function is timed from its first instruction to the
 * return that lifts the stack pointer above its value at entry; several at once, one a slot.
 * Time spent in other interrupts that nest inside is counted apart: "exclusive" figures
 * leave it out, and the nested interrupts are counted (those that interrupt the profiled code
 * itself, a call's own work: an interrupt nested in a nested one is part of the latter's).
 * Entry to entry, the longest interval and where it began are kept too (a function called in
 * a loop: its longest pass).
 */
#include <stdlib.h>
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
    if (incl - p->excl > p->p.nested_worst)
        p->p.nested_worst = incl - p->excl;
    p->active = 0;
}

static void enter(profile_state_t *p, uint64_t now, int depth)
{
    p->depth = depth;
    if (p->p.last_entry) {
        uint64_t interval = now - p->p.last_entry;
        p->p.period_sum += interval;
        p->p.intervals++;
        if (interval > p->p.period_worst) {
            p->p.period_worst = interval;
            p->p.period_worst_at = p->p.last_entry;
        }
    }
    p->p.last_entry = now;
    p->active = 1;
    p->paused = 0;
    p->entry = p->seg = now;
    p->excl = 0;
}

/* An interrupt signal is an entry when the PC stands at its vector (simavr raises it as it
 * jumps there; a RETI raises the vector that is innermost after it, or 0). */
static int is_entry(const avr_t *avr, int vector)
{
    return vector > 0 && avr->pc == (uint32_t)vector * avr->vector_size;
}

/* The cycle an interrupt signal stands for. simavr signals an interrupt's return from inside
 * its RETI, before it adds that instruction's cycles (2 + the PC's bytes: 5 on the
 * ATmega2560, as the datasheet gives): they are the interrupt's, so its end is counted after
 * them. (Its entry is signalled after the
 * instruction it interrupted, with the PC at the vector; simavr charges no cycles for the
 * entry itself.) */
static uint64_t signal_cycle(const avr_t *avr, int vector)
{
    uint32_t pc = avr->pc;
    if (is_entry(avr, vector))
        return avr->cycle;
    if (pc + 1 <= avr->flashend && (avr->flash[pc] | (avr->flash[pc + 1] << 8)) == 0x9518)
        return avr->cycle + 2 + avr->address_size;
    return avr->cycle;
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
    uint64_t now = signal_cycle(s->avr, value ? s->prof_vector : 0);
    if (value) {
        if (p->waiting) {
            uint64_t latency = now - p->raised_at;
            p->p.latency_sum += latency;
            if (latency > p->p.latency_worst)
                p->p.latency_worst = latency;
            p->waiting = 0;
        }
        enter(p, now, s->avr->interrupts.running_ptr + 1); /* simavr pushes it after this */
    } else if (p->active) {
        if (!p->paused)
            p->excl += now - p->seg;
        if (s->prof_requires >= 0 && s->prof_fn[s->prof_requires].p.last_entry < p->entry)
            p->active = 0; /* it did not enter the required function: not counted */
        else
            record(p, now);
    }
}

/* Exclusive time: a profiled call pauses while an interrupt nests in it (the nesting depth
 * is above the call's) and resumes when the depth is its own again. (Below it: the call's
 * own RETI, which ends it.) */
static void follow_depth(profile_state_t *p, int depth, uint64_t now)
{
    if (!p->active)
        return;
    int mine = depth == p->depth;
    if (depth > p->depth && !p->paused) {
        p->excl += now - p->seg;
        p->paused = 1;
        p->p.nested++;
    } else if (mine && p->paused) {
        p->seg = now;
        p->paused = 0;
    }
}

/* The innermost running vector changed (0: none): an interrupt entered or returned. simavr
 * signals an entry before it pushes the vector on its stack of running ones, a return after
 * it pops it. */
static void on_any_running(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    uint64_t now = signal_cycle(s->avr, (int)value);
    int depth = s->avr->interrupts.running_ptr + (is_entry(s->avr, (int)value) ? 1 : 0);
    follow_depth(&s->prof_vec, depth, now);
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++)
        follow_depth(&s->prof_fn[k], depth, now);
    s->depth = depth;
}

static uint16_t stack_pointer(const avr_t *avr)
{
    return (uint16_t)(avr->data[R_SPL] | (avr->data[R_SPH] << 8));
}

/* After each instruction while a function is profiled. */
void profile_step_functions(utrf_sim_t *s)
{
    avr_t *avr = s->avr;
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++) {
        profile_state_t *p = &s->prof_fn[k];
        if (!p->active) {
            if (avr->pc == (uint32_t)s->prof_addr[k]) {
                enter(p, avr->cycle, s->depth);
                p->sp0 = stack_pointer(avr);
            }
        } else if (stack_pointer(avr) > p->sp0) {
            if (!p->paused)
                p->excl += avr->cycle - p->seg;
            record(p, avr->cycle);
        }
    }
}

void profile_init(utrf_sim_t *s)
{
    s->prof_vector = 0;
    s->prof_requires = -1;
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++)
        s->prof_addr[k] = -1;
    avr_irq_register_notify(s->avr->interrupts.irq + AVR_INT_IRQ_RUNNING, on_any_running, s);
}

void profile_after_reset(utrf_sim_t *s)
{
    /* A reset abandons whatever was running or waiting. */
    s->prof_vec.active = 0;
    s->prof_vec.waiting = 0;
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++)
        s->prof_fn[k].active = 0;
    s->depth = 0;
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

int utrf_sim_profile_vector_requires(utrf_sim_t *s, int slot)
{
    if (slot < -1 || slot >= UTRF_SIM_FUNCTION_PROFILES)
        return -1;
    s->prof_requires = slot;
    return 0;
}

int utrf_sim_profile_function_slot(utrf_sim_t *s, int slot, int64_t addr)
{
    if (slot < 0 || slot >= UTRF_SIM_FUNCTION_PROFILES)
        return -1;
    if (addr >= 0 && ((uint64_t)addr > s->avr->flashend || (addr & 1)))
        return -1;
    memset(&s->prof_fn[slot], 0, sizeof s->prof_fn[slot]);
    s->prof_addr[slot] = addr < 0 ? -1 : addr;
    s->prof_functions = 0;
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++)
        s->prof_functions += s->prof_addr[k] >= 0;
    return 0;
}

int utrf_sim_profile_function(utrf_sim_t *s, int64_t addr)
{
    return utrf_sim_profile_function_slot(s, 0, addr);
}

void utrf_sim_profile_get(const utrf_sim_t *s, int which, utrf_sim_profile_t *out)
{
    if (which >= 1 && which <= UTRF_SIM_FUNCTION_PROFILES)
        *out = s->prof_fn[which - 1].p;
    else
        *out = s->prof_vec.p;
}

static void clear_figures(profile_state_t *p)
{
    uint64_t last_entry = p->p.last_entry;
    memset(&p->p, 0, sizeof p->p);
    p->p.last_entry = last_entry;
}

void utrf_sim_profile_clear(utrf_sim_t *s)
{
    clear_figures(&s->prof_vec);
    for (int k = 0; k < UTRF_SIM_FUNCTION_PROFILES; k++)
        clear_figures(&s->prof_fn[k]);
}

/* ---- where the cycles go (utrf_sim_pc_histogram) ------------------------------------------ */

/* Whether the instruction about to run is the histogram's: every one, or the slot's own work
 * (its call under way and no interrupt nested in it). */
int profile_in_own_work(const utrf_sim_t *s)
{
    if (s->pc_hist_slot < 0)
        return 1;
    const profile_state_t *p = &s->prof_fn[s->pc_hist_slot];
    return p->active && !p->paused;
}

/* After each instruction: its cycles at its address (an interrupt accepted after it adds none:
 * simavr charges no cycles for the entry). */
void profile_step_histogram(utrf_sim_t *s, uint32_t pc0, uint64_t c0, int own0)
{
    if (own0 && pc0 / 2 < s->pc_hist_words)
        s->pc_hist[pc0 / 2] += s->avr->cycle - c0;
}

int utrf_sim_pc_histogram(utrf_sim_t *s, int slot)
{
    if (slot >= UTRF_SIM_FUNCTION_PROFILES)
        return -1;
    if (slot < -1) {
        profile_close(s);
        return 0;
    }
    size_t words = (s->avr->flashend + 1) / 2;
    if (!s->pc_hist) {
        s->pc_hist = calloc(words, sizeof *s->pc_hist);
        if (!s->pc_hist)
            return -1;
        s->pc_hist_words = words;
    } else {
        memset(s->pc_hist, 0, words * sizeof *s->pc_hist);
    }
    s->pc_hist_slot = slot;
    return 0;
}

size_t utrf_sim_pc_histogram_get(const utrf_sim_t *s, uint64_t *out, size_t n)
{
    if (!s->pc_hist)
        return 0;
    if (out && n)
        memcpy(out, s->pc_hist, (n < s->pc_hist_words ? n : s->pc_hist_words) * sizeof *out);
    return s->pc_hist_words;
}

void profile_close(utrf_sim_t *s)
{
    free(s->pc_hist);
    s->pc_hist = NULL;
    s->pc_hist_words = 0;
}
