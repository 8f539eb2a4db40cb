/* Faults of the board itself, for the safety tests: a slow interrupt handler (the tick
 * overruns), a register written behind the firmware's back (a stopped timer), a raw write to
 * the data space (a stopped ADC), none of them a change to the firmware.
 *
 * A stall makes simavr's clock jump forward at the vector's entry: time passes as if the
 * handler ran that many more cycles, the timers run on and raise their flags meanwhile, and
 * the firmware, finding its next tick already due, sees an overrun as it would on the chip.
 */
#include "harness_internal.h"

static void on_stall_running(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    utrf_sim_t *s = param;
    if (!value || s->stall_count == 0)
        return;
    s->avr->cycle += s->stall_cycles;
    /* avr_run_one would run on as far as the next event lay before the jump (harness.c's
     * run_cycle_limit): one instruction, then the events that came due meanwhile. */
    s->avr->run_cycle_count = 1;
    s->stats.stalls++;
    if (s->stall_count > 0)
        s->stall_count--;
}

int utrf_sim_stall_vector(utrf_sim_t *s, int vector, uint64_t cycles, int64_t count)
{
    if (s->stall_vector > 0) {
        avr_irq_t *old = utrf_vector_irq(s->avr, s->stall_vector);
        if (old)
            avr_irq_unregister_notify(old + AVR_INT_IRQ_RUNNING, on_stall_running, s);
    }
    s->stall_vector = 0;
    s->stall_count = 0;
    if (vector <= 0 || count == 0 || cycles == 0)
        return 0;
    avr_irq_t *irq = utrf_vector_irq(s->avr, vector);
    if (!irq)
        return -1;
    avr_irq_register_notify(irq + AVR_INT_IRQ_RUNNING, on_stall_running, s);
    s->stall_vector = vector;
    s->stall_cycles = cycles;
    s->stall_count = count;
    return 0;
}

int64_t utrf_sim_stalls_left(const utrf_sim_t *s)
{
    return s->stall_vector > 0 ? s->stall_count : 0;
}

int utrf_sim_write_io(utrf_sim_t *s, uint32_t addr, uint8_t value)
{
    avr_t *avr = s->avr;
    if (addr < 32 || addr > avr->ramend)
        return -1;
    if (addr < 32 + MAX_IOs) {
        avr_io_addr_t io = AVR_DATA_TO_IO(addr);
        if (avr->io[io].w.c) {
            avr->io[io].w.c(avr, (avr_io_addr_t)addr, value, avr->io[io].w.param);
            return 0;
        }
    }
    avr->data[addr] = value;
    return 0;
}

int utrf_sim_poke(utrf_sim_t *s, uint32_t addr, uint8_t value)
{
    if (addr > s->avr->ramend)
        return -1;
    s->avr->data[addr] = value;
    return 0;
}
