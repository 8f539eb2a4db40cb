/* The plant's side of the board (mjplant.c steps it): the seeded noise, the TB6612FNG's truth
 * table and the AS5600's analog output: what the firmware's pins become and what its ADC
 * reads.
 */
#include <math.h>

#include "harness_internal.h"

#define TWO_PI 6.28318530717958647692

void utrf_rng_init(utrf_rng_t *r, uint64_t seed)
{
    uint64_t z = seed + 0x9E3779B97F4A7C15ULL; /* splitmix64: never a zero state */
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    z ^= z >> 31;
    r->state = z ? z : 1;
    r->have_spare = 0;
    r->spare = 0.0;
}

/* Marsaglia's polar method: two Gaussians a round, the second kept for the next call. */
double utrf_rng_normal(utrf_rng_t *r)
{
    if (r->have_spare) {
        r->have_spare = 0;
        return r->spare;
    }
    double u, v, s;
    do {
        u = 2.0 * utrf_xorshift64s_uniform(&r->state) - 1.0;
        v = 2.0 * utrf_xorshift64s_uniform(&r->state) - 1.0;
        s = u * u + v * v;
    } while (s >= 1.0 || s == 0.0);
    double k = sqrt(-2.0 * log(s) / s);
    r->spare = v * k;
    r->have_spare = 1;
    return u * k;
}

int utrf_tb6612(const double *block, double *signed_duty)
{
    double duty = block[0] < 0.0 ? 0.0 : block[0] > 1.0 ? 1.0 : block[0];
    int in1 = block[1] > 0.5, in2 = block[2] > 0.5, on = block[3] > 0.5;
    int mode = UTRF_DRIVE_COAST;
    if (on && in1 && !in2)
        mode = UTRF_DRIVE_FORWARD;
    else if (on && !in1 && in2)
        mode = UTRF_DRIVE_REVERSE;
    else if (on && in1 && in2)
        mode = UTRF_DRIVE_BRAKE;
    *signed_duty = mode == UTRF_DRIVE_FORWARD ? duty : mode == UTRF_DRIVE_REVERSE ? -duty : 0.0;
    return mode;
}

double utrf_as5600_volts(const utrf_as5600_t *e, double theta2, utrf_rng_t *r)
{
    double steps = (double)(1u << e->bits);
    double turns = (e->offset + (e->invert ? -theta2 : theta2)) / TWO_PI;
    turns -= floor(turns); /* the angle within one turn, as a fraction */
    double counts = floor(turns * steps);
    double v = e->supply * e->band[0] + (e->supply * (e->band[1] - e->band[0]) / steps) * counts;
    if (e->noise_v > 0.0)
        v += e->noise_v * utrf_rng_normal(r);
    return v;
}
