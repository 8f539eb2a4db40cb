/* The hand's plant in C: five tendon-driven fingers, their DC linear actuators behind the
 * TB6612FNG truth table, and the AS5600 encoders, stepped in lockstep with the MCU without
 * crossing into Python (utrf_sim_run_plant). The model is the one utrf/emulator/README.md
 * describes ("The plant"); Python computes the constants from the geometry files
 * (utrf.emulator.plant) and reads and writes the state through utrf_plant_state().
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "harness_internal.h"

#define F UTRF_PLANT_FINGERS
#define MAX_PULSES 64
#define CPU_HZ 16e6

static const double SIDE[2] = {-1.0, 1.0}; /* Tendon 1 shortens as q grows, Tendon 4 lengthens */

typedef struct {
    int finger;
    double t0, t1, fx, fy;
} pulse_t;

struct utrf_plant {
    utrf_plant_params_t p;
    utrf_plant_state_t st;
    /* constants derived once */
    double c[F][3];        /* dφ_k/dq */
    double A[F][3][3];     /* centre of mass of link k: Σ_j A[k][j] (cos φ_j, sin φ_j) */
    double rot_inertia[F]; /* the links' own inertia about their centres, through the coupling */
    double joint_damping[F];
    double K, res;
    /* slowly varying terms */
    double M[F], inv_M[F], dM[F], Qg[F], q_terms[F], q_tip[F];
    double voltage[F][2], connected[F][2];
    double last_pins[UTRF_SIM_PIN_VALUES];
    int have_pins;
    double h, decay;
    pulse_t pulses[MAX_PULSES];
    int n_pulses;
    utrf_rng_t rng;
    utrf_as5600_t enc;
};


/* ---- the slowly varying terms -------------------------------------------------------------- */

/* The coupling stretch and the tip force's generalised force on q, for the force applied now
 * (two passes: the stretch moves the arms a little). */
static void tip_terms(utrf_plant_t *pl)
{
    utrf_plant_state_t *st = &pl->st;
    for (int f = 0; f < F; f++) {
        pl->q_tip[f] = st->q[f];
        double fx = st->applied_force[f][0], fy = st->applied_force[f][1];
        if (fx == 0.0 && fy == 0.0) {
            st->coupling_stretch[f][0] = st->coupling_stretch[f][1] = 0.0;
            st->q_ext[f] = 0.0;
            continue;
        }
        const double *R = pl->p.R[f], *L = pl->p.L[f];
        double phi[3];
        for (int pass = 0; pass < 3; pass++) {
            double e2 = st->coupling_stretch[f][0], e3 = st->coupling_stretch[f][1];
            double th1 = st->q[f] / R[0], th2 = (st->q[f] - e2) / R[1];
            double th3 = (st->q[f] - e2 - e3) / R[2];
            phi[0] = th1;
            phi[1] = th1 + th2;
            phi[2] = th1 + th2 + th3;
            if (pass == 2)
                break;
            double a3x = L[2] * cos(phi[2]), a3y = L[2] * sin(phi[2]);
            double a2x = L[1] * cos(phi[1]) + a3x, a2y = L[1] * sin(phi[1]) + a3y;
            double tau2 = a2x * fy - a2y * fx, tau3 = a3x * fy - a3y * fx;
            double n3 = -tau3 / R[2], n2 = n3 - tau2 / R[1];
            st->coupling_stretch[f][0] = n2 * pl->p.coupling_compliance[f][0];
            st->coupling_stretch[f][1] = n3 * pl->p.coupling_compliance[f][1];
        }
        /* d tip / d q: the stretch is held (quasi-static), so dθ_k/dq = 1/R_k as when rigid */
        double jx = 0.0, jy = 0.0;
        for (int k = 0; k < 3; k++) {
            jx -= L[k] * pl->c[f][k] * sin(phi[k]);
            jy += L[k] * pl->c[f][k] * cos(phi[k]);
        }
        st->q_ext[f] = jx * fx + jy * fy;
    }
}

/* M(q), M'(q) and the gravity force at the present q (rigid coupling). */
static void geometry_terms(utrf_plant_t *pl)
{
    utrf_plant_state_t *st = &pl->st;
    for (int f = 0; f < F; f++) {
        double s[3], co[3];
        for (int j = 0; j < 3; j++) {
            double phi = st->q[f] * pl->c[f][j];
            s[j] = sin(phi);
            co[j] = cos(phi);
        }
        double M = pl->rot_inertia[f], dM = 0.0, Qg = 0.0;
        for (int k = 0; k < 3; k++) {
            double Jx = 0, Jy = 0, dJx = 0, dJy = 0;
            for (int j = 0; j < 3; j++) {
                double a = pl->A[f][k][j] * pl->c[f][j];
                Jx -= a * s[j];
                Jy += a * co[j];
                dJx -= a * pl->c[f][j] * co[j];
                dJy -= a * pl->c[f][j] * s[j];
            }
            double m = pl->p.link_mass[f][k];
            M += m * (Jx * Jx + Jy * Jy);
            dM += 2.0 * m * (Jx * dJx + Jy * dJy);
            Qg += m * (Jx * pl->p.gravity[0] + Jy * pl->p.gravity[1]);
        }
        pl->M[f] = M;
        pl->inv_M[f] = 1.0 / M;
        pl->dM[f] = dM;
        pl->Qg[f] = Qg;
        pl->q_terms[f] = st->q[f];
    }
    tip_terms(pl);
}

void utrf_plant_refresh(utrf_plant_t *pl)
{
    geometry_terms(pl);
    pl->have_pins = 0;
}

double utrf_plant_inertia(const utrf_plant_t *pl, int finger)
{
    return (finger >= 0 && finger < F) ? pl->M[finger] : NAN;
}

/* ---- life ------------------------------------------------------------------------------------ */

utrf_plant_t *utrf_plant_new(const utrf_plant_params_t *params, uint64_t seed)
{
    utrf_plant_t *pl = calloc(1, sizeof *pl);
    if (!pl)
        return NULL;
    pl->p = *params;
    for (int f = 0; f < F; f++) {
        double acc = 0.0;
        for (int k = 0; k < 3; k++) {
            acc += 1.0 / pl->p.R[f][k];
            pl->c[f][k] = acc;
        }
        double rot = 0.0, jd = 0.0;
        for (int k = 0; k < 3; k++) {
            for (int j = 0; j < k; j++)
                pl->A[f][k][j] = pl->p.L[f][j];
            pl->A[f][k][k] = pl->p.com[f][k] * pl->p.L[f][k];
            double rod = pl->p.link_mass[f][k] * pl->p.L[f][k] * pl->p.L[f][k] / 12.0;
            rot += rod * pl->c[f][k] * pl->c[f][k];
            jd += pl->p.joint_damping / (pl->p.R[f][k] * pl->p.R[f][k]);
        }
        pl->rot_inertia[f] = rot;
        pl->joint_damping[f] = jd;
        pl->st.block[f][0] = pl->p.q_limits[f][0];
        pl->st.block[f][1] = pl->p.q_limits[f][1];
        pl->st.plugged[f] = 1.0;
        pl->st.unplugged_v[f] = pl->p.enc_unplugged_v;
        pl->st.tip_rate[f] = INFINITY;
    }
    pl->K = pl->p.supply_v / pl->p.no_load_speed;
    pl->res = pl->p.supply_v / (pl->p.stall_force / pl->K);
    utrf_rng_init(&pl->rng, seed);
    pl->enc = (utrf_as5600_t){pl->p.enc_supply, pl->p.enc_offset,
                              {pl->p.enc_band[0], pl->p.enc_band[1]}, pl->p.enc_noise_v,
                              pl->p.enc_invert, pl->p.enc_bits};
    geometry_terms(pl);
    return pl;
}

void utrf_plant_free(utrf_plant_t *pl)
{
    free(pl);
}

utrf_plant_state_t *utrf_plant_state(utrf_plant_t *pl)
{
    return &pl->st;
}

/* ---- the board's side -------------------------------------------------------------------------- */

/* TB6612FNG truth table, per channel, from the pin block (duty, IN1, IN2, STBY). */
static void decode_drive(utrf_plant_t *pl, const double *pins)
{
    if (pl->have_pins && !memcmp(pins, pl->last_pins, sizeof pl->last_pins))
        return;
    memcpy(pl->last_pins, pins, sizeof pl->last_pins);
    pl->have_pins = 1;
    for (int f = 0; f < F; f++) {
        for (int c = 0; c < 2; c++) {
            const double *b = &pins[(f * 2 + c) * UTRF_SIM_PIN_FIELDS];
            double signed_duty;
            int mode = utrf_tb6612(b, &signed_duty);
            if (c == 1 && pl->p.rotary[f]) {
                mode = UTRF_DRIVE_COAST; /* a rotary finger has no motor B */
                signed_duty = 0.0;
            }
            pl->st.drive_mode[f][c] = mode;
            pl->st.drive_duty[f][c] = signed_duty;
            pl->connected[f][c] = mode != UTRF_DRIVE_COAST;
            pl->voltage[f][c] = signed_duty * pl->p.supply_v;
        }
    }
}

void utrf_plant_decode(utrf_plant_t *pl, const double *pins)
{
    decode_drive(pl, pins);
}

/* The tip force over the coming step: the steady part ramped toward its goal, plus each
 * pulse's force times the fraction of the step it covers. Nonzero when it changed. */
static int update_tip_force(utrf_plant_t *pl, double dt)
{
    utrf_plant_state_t *st = &pl->st;
    int any = pl->n_pulses > 0;
    for (int f = 0; f < F && !any; f++)
        any = st->tip_force[f][0] != 0.0 || st->tip_force[f][1] != 0.0 ||
              st->tip_goal[f][0] != 0.0 || st->tip_goal[f][1] != 0.0 ||
              st->applied_force[f][0] != 0.0 || st->applied_force[f][1] != 0.0;
    if (!any)
        return 0;
    double force[F][2];
    for (int f = 0; f < F; f++) {
        double gx = st->tip_goal[f][0] - st->tip_force[f][0];
        double gy = st->tip_goal[f][1] - st->tip_force[f][1];
        double dist = hypot(gx, gy), reach = st->tip_rate[f] * dt;
        double frac = dist > reach ? reach / (dist > 0 ? dist : 1.0) : 1.0;
        st->tip_force[f][0] += gx * frac;
        st->tip_force[f][1] += gy * frac;
        force[f][0] = st->tip_force[f][0];
        force[f][1] = st->tip_force[f][1];
    }
    double t0 = st->time, t1 = st->time + dt;
    int keep = 0;
    for (int i = 0; i < pl->n_pulses; i++) {
        pulse_t *pu = &pl->pulses[i];
        double overlap = (t1 < pu->t1 ? t1 : pu->t1) - (t0 > pu->t0 ? t0 : pu->t0);
        if (overlap > 0) {
            force[pu->finger][0] += pu->fx * (overlap / dt);
            force[pu->finger][1] += pu->fy * (overlap / dt);
        }
        if (pu->t1 > t1)
            pl->pulses[keep++] = *pu;
    }
    pl->n_pulses = keep;
    int changed = memcmp(force, st->applied_force, sizeof force) != 0;
    memcpy(st->applied_force, force, sizeof force);
    return changed;
}

/* One semi-implicit Euler step: forces from the present state, velocities, then positions
 * from the new velocities, then the hard stops. */
static void substep(utrf_plant_t *pl, double h)
{
    utrf_plant_state_t *st = &pl->st;
    const utrf_plant_params_t *p = &pl->p;
    double stick = h * p->coulomb_friction / p->moving_mass;
    for (int f = 0; f < F; f++) {
        double q = st->q[f], qd = st->qd[f];
        double k = p->tendon_stiffness[f];
        double tension[2], force[2];
        for (int c = 0; c < 2; c++) {
            double stretch = st->x[f][c] + q * SIDE[c];
            double t = k * stretch + p->tendon_damping * (st->xd[f][c] + qd * SIDE[c]);
            tension[c] = (stretch > 0.0 && t > 0.0) ? t : 0.0;
            st->tension[f][c] = tension[c];
        }
        for (int c = 0; c < 2; c++) {
            double xd = st->xd[f][c];
            double i_ss = (pl->voltage[f][c] - pl->K * xd) / pl->res;
            st->current[f][c] =
                (i_ss + (st->current[f][c] - i_ss) * pl->decay) * pl->connected[f][c];
            force[c] = pl->K * st->current[f][c] - p->viscous_friction * xd - tension[c];
        }
        if (p->rotary[f]) { /* one pulley: Tendon 4 pulls motor A back the other way */
            force[0] += tension[1];
            force[1] = 0.0;
        }
        double gen = tension[0] - tension[1] + pl->Qg[f] + st->q_ext[f] -
                     (pl->joint_damping[f] + 0.5 * pl->dM[f] * qd) * qd;
        qd += h * gen * pl->inv_M[f];
        q += h * qd;
        double lo = st->block[f][0], hi = st->block[f][1];
        if (q < lo) { /* a joint limit or a block: a hard stop */
            if (qd < 0.0)
                qd = 0.0;
            q = lo;
        } else if (q > hi) {
            if (qd > 0.0)
                qd = 0.0;
            q = hi;
        }
        st->q[f] = q;
        st->qd[f] = qd;
        for (int c = 0; c < 2; c++) {
            double v_free = st->xd[f][c] + (h / p->moving_mass) * force[c];
            double xd = fabs(v_free) <= stick ? 0.0 : v_free - copysign(stick, v_free);
            double x = st->x[f][c] + h * xd;
            if (x < p->stroke[0] || x > p->stroke[1]) { /* the end of its stroke */
                xd = 0.0;
                x = x < p->stroke[0] ? p->stroke[0] : p->stroke[1];
            }
            st->x[f][c] = x;
            st->xd[f][c] = xd;
        }
        if (p->rotary[f]) {
            st->x[f][1] = -st->x[f][0];
            st->xd[f][1] = -st->xd[f][0];
        }
    }
}

void utrf_plant_step(utrf_plant_t *pl, double dt, const double *pins)
{
    if (!(dt > 0.0))
        return;
    utrf_plant_state_t *st = &pl->st;
    if (pins)
        decode_drive(pl, pins);
    int changed = update_tip_force(pl, dt);
    double moved = 0.0, moved_tip = 0.0;
    int loaded = 0;
    for (int f = 0; f < F; f++) {
        moved = fmax(moved, fabs(st->q[f] - pl->q_terms[f]));
        moved_tip = fmax(moved_tip, fabs(st->q[f] - pl->q_tip[f]));
        loaded |= st->applied_force[f][0] != 0.0 || st->applied_force[f][1] != 0.0;
    }
    if (moved > 2e-5) /* M, M', gravity vary slowly */
        geometry_terms(pl);
    else if (changed || (loaded && moved_tip > 2e-6)) /* the arms: finer (the stretch is a
                                                          small difference of them) */
        tip_terms(pl);
    int n = (int)ceil(dt / pl->p.max_substep);
    if (n < 1)
        n = 1;
    double h = dt / n;
    if (h != pl->h) {
        pl->h = h;
        pl->decay = exp(-h / pl->p.electrical_time_constant);
    }
    for (int i = 0; i < n; i++)
        substep(pl, h);
    st->time += dt;
}

int utrf_plant_hit(utrf_plant_t *pl, int finger, double jx, double jy, double duration)
{
    if (finger < 0 || finger >= F || !(duration > 0.0))
        return -1;
    if (pl->n_pulses >= MAX_PULSES)
        return -2;
    pl->pulses[pl->n_pulses++] =
        (pulse_t){finger, pl->st.time, pl->st.time + duration, jx / duration, jy / duration};
    return 0;
}

int utrf_plant_pulses(const utrf_plant_t *pl)
{
    return pl->n_pulses;
}

/* Each finger's AS5600 output (V), noise included: the ADC0..4 inputs. */
void utrf_plant_encoder_volts(utrf_plant_t *pl, double *out)
{
    const utrf_plant_params_t *p = &pl->p;
    utrf_plant_state_t *st = &pl->st;
    for (int f = 0; f < F; f++) {
        double theta2 =
            (st->q[f] - st->coupling_stretch[f][0]) / p->R[f][1] + st->encoder_shift[f];
        double v = utrf_as5600_volts(&pl->enc, theta2, &pl->rng);
        out[f] = st->plugged[f] > 0.5 ? v : st->unplugged_v[f];
    }
}

/* ---- lockstep with the MCU ---------------------------------------------------------------------- */

static void ops_step(void *ctx, double dt, const double *pins)
{
    utrf_plant_step(ctx, dt, pins);
}

static void ops_volts(void *ctx, double *out)
{
    utrf_plant_encoder_volts(ctx, out);
}

void utrf_sim_attach_plant(utrf_sim_t *s, utrf_plant_t *pl)
{
    utrf_sim_attach_ops(s, pl, ops_step, ops_volts);
}

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
