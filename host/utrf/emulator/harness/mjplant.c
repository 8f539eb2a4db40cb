/* The MuJoCo hand as the board's plant, stepped in C in lockstep with the MCU.
 *
 * Python builds the model (utrf.models.mjcf, drive "force": each actuator's control is its
 * motor's force in N) and its data with the mujoco package, and hands this file their
 * addresses: MuJoCo's state stays in the Python objects (observation, rendering, object
 * poses and contacts are read there, live), and only the stepping runs here. libmujoco is the
 * one the mujoco package loaded; its mj_step is found with dlsym, so the harness does not
 * link MuJoCo and builds without it (utrf_mjplant_new then says why it cannot run).
 *
 * Per exchange: the pins through the TB6612FNG truth table give each motor's voltage (coast:
 * the circuit open); the DC motor's current follows L di/dt = u V − R i − K v exactly over
 * the period with the carriage speed v held (from MuJoCo's state); its force K i is the
 * actuator's control; tip loads and hammer pulses go into xfrc_applied at their points; then
 * mj_step, as many times as the model's timestep fits in the exchange period (two of 0.5 ms
 * in the default 1 ms exchange), the pins held. Joint 2's angle gives the
 * AS5600's analog voltage: 12-bit quantisation, 10-90 % band, seeded Gaussian noise.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "harness_internal.h"

#ifdef UTRF_WITH_MUJOCO
#include <mujoco/mujoco.h>
#endif

#define F UTRF_PLANT_FINGERS
#define MAX_PULSES 64


typedef struct {
    int body, site;
    double t0, t1, f[3];
} mj_pulse_t;

struct utrf_mjplant {
    utrf_mjplant_params_t p;
    utrf_mjplant_state_t st;
    void *lib;
#ifdef UTRF_WITH_MUJOCO
    const mjModel *m;
    mjData *d;
    void (*step)(const mjModel *, mjData *);
    mjfTime *timer; /* MuJoCo's profiling clock (the mujoco package sets one): off while stepping */
#endif
    double voltage[F][2], connected[F][2];
    double decay, decay_dt;
    mj_pulse_t pulses[MAX_PULSES];
    int n_pulses;
    /* bodies whose xfrc_applied the last step wrote (loads and pulses): cleared before the
     * next, so a pulse that has ended leaves no force behind */
    int written[MAX_PULSES + UTRF_MJPLANT_LOADS];
    int n_written;
    utrf_rng_t rng;
    utrf_as5600_t enc;
    int truth_site[F]; /* the sites whose positions a stop records (-1: none) */
};

utrf_mjplant_t *utrf_mjplant_new(const char *libmujoco, void *model, void *data,
                                 const utrf_mjplant_params_t *params, uint64_t seed, char *err,
                                 size_t errlen)
{
#ifndef UTRF_WITH_MUJOCO
    (void)libmujoco;
    (void)model;
    (void)data;
    (void)params;
    (void)seed;
    snprintf(err, errlen, "the harness was built without MuJoCo's headers (pip install mujoco, "
                          "then make emulator)");
    return NULL;
#else
    utrf_mjplant_t *mp = calloc(1, sizeof *mp);
    if (!mp) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    mp->lib = dlopen(libmujoco, RTLD_NOW | RTLD_NOLOAD);
    if (!mp->lib)
        mp->lib = dlopen(libmujoco, RTLD_NOW);
    if (!mp->lib) {
        snprintf(err, errlen, "cannot load %s: %s", libmujoco, dlerror());
        free(mp);
        return NULL;
    }
    *(void **)&mp->step = dlsym(mp->lib, "mj_step");
    if (!mp->step) {
        snprintf(err, errlen, "%s has no mj_step", libmujoco);
        dlclose(mp->lib);
        free(mp);
        return NULL;
    }
    mp->timer = (mjfTime *)dlsym(mp->lib, "mjcb_time");
    mp->m = model;
    mp->d = data;
    mp->p = *params;
    for (int f = 0; f < F; f++) {
        mp->st.plugged[f] = 1.0;
        mp->st.unplugged_v[f] = params->enc_unplugged_v;
        mp->st.build_motor_from[f] = f; /* built as designed */
        mp->st.build_encoder_from[f] = f;
        for (int c = 0; c < 2; c++) {
            mp->st.build_lead[f][c] = mp->st.build_powered[f][c] = 1.0;
            mp->st.build_k_scale[f][c] = mp->st.build_r_scale[f][c] = 1.0;
        }
    }
    for (int f = 0; f < F; f++)
        mp->truth_site[f] = -1;
    utrf_rng_init(&mp->rng, seed);
    mp->enc = (utrf_as5600_t){params->enc_supply, params->enc_offset,
                              {params->enc_band[0], params->enc_band[1]}, params->enc_noise_v,
                              params->enc_invert, params->enc_bits};
    return mp;
#endif
}

void utrf_mjplant_free(utrf_mjplant_t *mp)
{
    if (!mp)
        return;
    if (mp->lib)
        dlclose(mp->lib);
    free(mp);
}

utrf_mjplant_state_t *utrf_mjplant_state(utrf_mjplant_t *mp)
{
    return &mp->st;
}

/* A finger index from a build field (a double in the shared state), or f when out of range. */
static int build_finger(double v, int f)
{
    int g = (int)v;
    return g >= 0 && g < F ? g : f;
}

static void decode(utrf_mjplant_t *mp, const double *pins)
{
    const utrf_mjplant_state_t *st = &mp->st;
    for (int f = 0; f < F; f++) {
        int src = build_finger(st->build_motor_from[f], f); /* the driver its cable goes to */
        for (int c = 0; c < 2; c++) {
            const double *b = &pins[(src * 2 + c) * UTRF_SIM_PIN_FIELDS];
            double sd;
            int mode = utrf_tb6612(b, &sd);
            if (mp->p.actuator[f][c] < 0) {
                mode = UTRF_DRIVE_COAST; /* no such motor (a rotary finger's B) */
                sd = 0.0;
            }
            mp->st.drive_mode[f][c] = mode;
            mp->st.drive_duty[f][c] = sd;
            double powered = st->build_powered[f][c] > 0.5;
            mp->connected[f][c] = mode != UTRF_DRIVE_COAST && powered;
            mp->voltage[f][c] = sd * mp->p.supply_v * powered * (st->build_lead[f][c] < 0 ? -1 : 1);
        }
    }
}

int utrf_mjplant_hit(utrf_mjplant_t *mp, int body, int site, double jx, double jy, double jz,
                     double duration)
{
    if (!(duration > 0.0) || body < 0)
        return -1;
    if (mp->n_pulses >= MAX_PULSES)
        return -2;
    double t = mp->st.time;
    mp->pulses[mp->n_pulses++] =
        (mj_pulse_t){body, site, t, t + duration, {jx / duration, jy / duration, jz / duration}};
    return 0;
}

int utrf_mjplant_pulses(const utrf_mjplant_t *mp)
{
    return mp->n_pulses;
}

#ifdef UTRF_WITH_MUJOCO
/* A force at a point of a body: MuJoCo applies xfrc_applied at the body's centre of mass, so
 * the point's offset adds a torque. */
static void apply_at(utrf_mjplant_t *mp, int body, int site, const double *force, double scale)
{
    const mjData *d = mp->d;
    if (mp->n_written < MAX_PULSES + UTRF_MJPLANT_LOADS)
        mp->written[mp->n_written++] = body;
    double *x = mp->d->xfrc_applied + 6 * body;
    const double *com = d->xipos + 3 * body;
    const double *pt = site >= 0 ? d->site_xpos + 3 * site : com;
    double fx = force[0] * scale, fy = force[1] * scale, fz = force[2] * scale;
    double rx = pt[0] - com[0], ry = pt[1] - com[1], rz = pt[2] - com[2];
    x[0] += fx;
    x[1] += fy;
    x[2] += fz;
    x[3] += ry * fz - rz * fy;
    x[4] += rz * fx - rx * fz;
    x[5] += rx * fy - ry * fx;
}

static void apply_loads(utrf_mjplant_t *mp, double dt)
{
    utrf_mjplant_state_t *st = &mp->st;
    /* clear what the loads and pulses wrote last step (a pulse that ended then included) */
    for (int i = 0; i < mp->n_written; i++)
        memset(mp->d->xfrc_applied + 6 * mp->written[i], 0, 6 * sizeof(double));
    mp->n_written = 0;
    for (int i = 0; i < UTRF_MJPLANT_LOADS; i++) {
        if (st->load_body[i] < 0)
            continue;
        double f[3], a = 1.0, span = st->load_t1[i] - st->load_t0[i];
        if (span > 0.0) {
            a = (st->time - st->load_t0[i]) / span;
            a = a < 0.0 ? 0.0 : a > 1.0 ? 1.0 : a;
        }
        for (int k = 0; k < 3; k++)
            f[k] = st->load_from[i][k] + a * (st->load_force[i][k] - st->load_from[i][k]);
        apply_at(mp, (int)st->load_body[i], (int)st->load_site[i], f, 1.0);
    }
    double t0 = st->time, t1 = st->time + dt;
    int keep = 0;
    for (int i = 0; i < mp->n_pulses; i++) {
        mj_pulse_t *pu = &mp->pulses[i];
        double overlap = (t1 < pu->t1 ? t1 : pu->t1) - (t0 > pu->t0 ? t0 : pu->t0);
        if (overlap > 0)
            apply_at(mp, pu->body, pu->site, pu->f, overlap / dt);
        if (pu->t1 > t1)
            mp->pulses[keep++] = *pu;
    }
    mp->n_pulses = keep;
}
#endif

void utrf_mjplant_step(utrf_mjplant_t *mp, double dt, const double *pins)
{
#ifdef UTRF_WITH_MUJOCO
    if (!(dt > 0.0))
        return;
    if (pins)
        decode(mp, pins);
    /* As many mj_steps as the model's timestep fits in dt (the exchange period: 1 ms, two
     * steps of the MJCF's 0.5 ms), the pins held; the motors' currents follow each step. A dt
     * that is not a whole number of timesteps (a run that ends between exchanges) is cut
     * into equal steps MuJoCo takes as they are: its clock stays the plant's. */
    mjModel *m = (mjModel *)mp->m;
    double ts = m->opt.timestep;
    int n = ts > 0.0 ? (int)lround(dt / ts) : 1;
    if (n < 1)
        n = 1;
    double h = dt / n;
    if (h != ts)
        m->opt.timestep = h;
    if (h != mp->decay_dt) {
        mp->decay_dt = h;
        mp->decay = exp(-h / mp->p.electrical_time_constant);
    }
    const double K = mp->p.force_constant, R = mp->p.resistance, limit = mp->p.stall_force;
    /* MuJoCo reads its profiling clock (mjData.timer) twice for each part of a step when
     * mjcb_time is set, as the mujoco package sets it: off for the twin's steps, back after */
    mjfTime timer = mp->timer ? *mp->timer : NULL;
    if (timer)
        *mp->timer = NULL;
    for (int k = 0; k < n; k++) {
        for (int f = 0; f < F; f++) {
            for (int c = 0; c < 2; c++) {
                int act = mp->p.actuator[f][c];
                if (act < 0)
                    continue;
                double v = mp->p.gear[f][c] * mp->d->qvel[mp->p.dof[f][c]]; /* pulling speed */
                double km = K * mp->st.build_k_scale[f][c], rm = R * mp->st.build_r_scale[f][c];
                double i_ss = (mp->voltage[f][c] - km * v) / rm;
                double i = (i_ss + (mp->st.current[f][c] - i_ss) * mp->decay) *
                           mp->connected[f][c];
                mp->st.current[f][c] = i;
                double force = km * i; /* within the driver's peak current (params) */
                mp->d->ctrl[act] = force > limit ? limit : force < -limit ? -limit : force;
            }
        }
        apply_loads(mp, h);
        mp->step(m, mp->d);
        mp->st.time += h;
    }
    if (timer)
        *mp->timer = timer;
    m->opt.timestep = ts;
#else
    (void)mp;
    (void)dt;
    (void)pins;
#endif
}

void utrf_mjplant_encoder_volts(utrf_mjplant_t *mp, double *out)
{
#ifdef UTRF_WITH_MUJOCO
    const utrf_mjplant_state_t *st = &mp->st;
    for (int f = 0; f < F; f++) {
        int src = build_finger(st->build_encoder_from[f], f); /* the encoder its cable is */
        double theta2 = mp->d->qpos[mp->p.j2_qpos[src]] + st->encoder_shift[src];
        if (st->build_encoder_invert[src] > 0.5)
            theta2 = -theta2; /* the magnet glued the other way round */
        theta2 += st->build_encoder_offset[src] +
                  st->build_encoder_eccentric[src] * sin(theta2 + st->build_encoder_offset[src]);
        double v = utrf_as5600_volts(&mp->enc, theta2, &mp->rng);
        out[f] = mp->st.plugged[f] > 0.5 ? v : mp->st.unplugged_v[f];
    }
#else
    (void)mp;
    memset(out, 0, F * sizeof(double));
#endif
}

int utrf_mjplant_truth_sites(utrf_mjplant_t *mp, const int32_t *sites, int n)
{
    if (n < 0 || n > F)
        return -1;
    for (int f = 0; f < F; f++)
        mp->truth_site[f] = f < n ? sites[f] : -1;
    return 0;
}

static void mj_ops_truth(void *ctx, double *out)
{
    utrf_mjplant_t *mp = ctx;
    memset(out, 0, UTRF_SIM_TRUTH * sizeof(double));
#ifdef UTRF_WITH_MUJOCO
    for (int f = 0; f < F; f++)
        if (mp->truth_site[f] >= 0)
            memcpy(out + 3 * f, mp->d->site_xpos + 3 * mp->truth_site[f], 3 * sizeof(double));
#endif
    memcpy(out + 3 * F, mp->st.current, sizeof mp->st.current);
}

static int mj_ops_hit(void *ctx, const utrf_sim_hit_t *h)
{
    return utrf_mjplant_hit(ctx, h->body, h->site, h->impulse[0], h->impulse[1], h->impulse[2],
                            h->duration);
}

static void mj_ops_step(void *ctx, double dt, const double *pins)
{
    utrf_mjplant_step(ctx, dt, pins);
}

static void mj_ops_volts(void *ctx, double *out)
{
    utrf_mjplant_encoder_volts(ctx, out);
}

void utrf_sim_attach_mjplant(utrf_sim_t *s, utrf_mjplant_t *mp)
{
    utrf_sim_attach_ops(s, mp, mj_ops_step, mj_ops_volts, mj_ops_truth, mj_ops_hit);
}
