/* Lockstep of the MCU with the plant attached to the board (mjplant.c attaches the MuJoCo
 * hand): the MCU runs each exchange period with the encoders as the plant had them at its
 * start, then the plant the same period with the pins as they were at its start.
 */
#include <string.h>

#include "harness_internal.h"

#define CPU_HZ 16e6

int utrf_sim_run_plant(utrf_sim_t *s, uint64_t target, uint64_t period)
{
    return utrf_sim_run_plant_until(s, target, period, -1);
}

int utrf_sim_run_plant_until(utrf_sim_t *s, uint64_t target, uint64_t period, int wake)
{
    int status = utrf_sim_status(s);
    if (!period)
        period = 1;
    s->wake_byte = wake >= 0 && wake <= 255 ? wake : -1;
    s->woke = 0;
    while (s->avr->cycle < target && !s->woke) {
        uint64_t start = s->avr->cycle, end = start + period;
        if (end > target)
            end = target;
        double hold[UTRF_SIM_PIN_VALUES];
        memcpy(hold, s->pins, sizeof hold);
        if (s->plant_volts)
            s->plant_volts(s->plant_ctx, s->adc_volts);
        int now = utrf_sim_run_to(s, end);
        if (s->plant_step)
            s->plant_step(s->plant_ctx, (double)(s->avr->cycle - start) / CPU_HZ, hold);
        if (now != status) {
            status = now;
            break;
        }
    }
    s->wake_byte = -1;
    return status;
}
