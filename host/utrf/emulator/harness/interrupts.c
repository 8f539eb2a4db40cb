/* Interrupts enabled while their flag is already set.
 *
 * On the chip an interrupt is requested while its flag and its enable bit are both set, so
 * enabling it with the flag set runs the handler at once. simavr 1.6 only requests one when
 * the flag is raised: a flag set while the interrupt was masked was forgotten until the next
 * event. The firmware masks its 1 kHz tick around shared data, and a compare match in that
 * window cost it a whole tick. Here, writes to the enable registers that no simavr module
 * watches (TIMSKn, EIMSK, PCICR, ...) look for such flags and request the interrupt.
 * Registers simavr already watches (the UARTs', the ADC's, the EEPROM's, ...) are left to its
 * modules: simavr allows only four shared registers.
 */
#include "harness_internal.h"

static void enable_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param)
{
    utrf_sim_t *s = param;
    uint8_t before = avr->data[addr];
    avr_core_watch_write(avr, addr, v);
    uint8_t enabled = (uint8_t)(v & ~before);
    if (!enabled)
        return;
    avr_int_table_p table = &avr->interrupts;
    for (int i = 0; i < table->vector_count; i++) {
        avr_int_vector_t *vec = table->vector[i];
        if (vec->enable.reg != addr || !((enabled >> vec->enable.bit) & vec->enable.mask))
            continue;
        if (vec->raised.reg && avr_regbit_get(avr, vec->raised) && !vec->pending) {
            s->stats.late_interrupts++;
            avr_raise_interrupt(avr, vec);
        }
    }
}

void interrupts_init(utrf_sim_t *s)
{
    avr_t *avr = s->avr;
    avr_int_table_p table = &avr->interrupts;
    for (int i = 0; i < table->vector_count; i++) {
        avr_int_vector_t *vec = table->vector[i];
        uint16_t reg = vec->enable.reg;
        if (!reg || !vec->raised.reg || reg < 32 || reg >= 32 + MAX_IOs)
            continue;
        avr_io_addr_t io = AVR_DATA_TO_IO(reg);
        if (avr->io[io].w.c == enable_write)
            continue; /* another vector of the same register */
        if (avr->io[io].w.c)
            continue; /* simavr's module handles this register */
        avr_register_io_write(avr, reg, enable_write, s);
    }
}
