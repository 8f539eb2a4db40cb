// C ABI over the firmware core and the host hardware layer, for the pytest suite (ctypes).
//
// A simulated board: power it on, set encoder voltages, run ticks and loop() passes, feed the
// UART, read what it sent and what its motor pins do. Units at this boundary are the
// firmware's own: angles in 1e-4 rad (AU), duties in Q16 (65536 = 1), ADC counts.
#include <new>

#include "core/app.h"
#include "generated/config_layout.h"
#include "core/config.h"
#include "core/dispatch.h"
#include "core/encoder.h"
#include "core/kinematics.h"
#include "core/pid.h"
#include "core_check_seq.h"
#include "hal_host.h"

using namespace utrf;
using hal::host::state;

namespace {
// The line: what the UART sent, moved out of its transmit buffer after every loop() pass of
// fw_run/fw_loop (a real line drains it within a millisecond), until fw_tx reads it.
const uint32_t kLineBytes = 1u << 16;
uint8_t g_line[kLineBytes];
uint32_t g_line_len = 0;

void drain_to_line() {
    hal::host::State& s = state();
    if (s.tx_room_limit != 0xFFFF) return;  // a test holds the buffer full: leave it
    uint16_t n = s.tx_len;
    if (n > kLineBytes - g_line_len) n = (uint16_t)(kLineBytes - g_line_len);
    for (uint16_t i = 0; i < n; ++i) g_line[g_line_len + i] = s.tx[i];
    g_line_len += n;
    for (uint16_t i = n; i < s.tx_len; ++i) s.tx[i - n] = s.tx[i];
    s.tx_len = (uint16_t)(s.tx_len - n);
}
}  // namespace

extern "C" {

// ---- the board -------------------------------------------------------------------------------

void fw_power_on(uint8_t reset_cause) {
    hal::host::power_on();
    g_line_len = 0;
    state().reset_cause = reset_cause;
    app::Board* b = &app::board();
    b->~Board();
    new (b) app::Board();
    app::setup();
}

void fw_tick(uint32_t n) {
    for (uint32_t i = 0; i < n; ++i) {
        ++state().ms;
        state().tick_ms = state().ms;
        if (state().tick_locked) ++state().lock_errors;  // the tick cannot run while locked
        app::tick();
        // As the AVR's timer can tell: at most two periods, well within 16 bits.
        const uint32_t c = state().tick_cycles;
        app::tick_done((uint16_t)(c > 0xFFFFu ? 0xFFFFu : c), state().period_elapsed);
    }
}

void fw_loop(uint32_t n) {
    for (uint32_t i = 0; i < n; ++i) {
        app::loop();
        drain_to_line();
    }
}

// `ms` milliseconds of normal running: a tick, then kLoopsPerMs loop() passes, each millisecond.
static const uint8_t kLoopsPerMs = 4;
void fw_run(uint32_t ms) {
    for (uint32_t i = 0; i < ms; ++i) {
        fw_tick(1);
        // A few loop() passes a millisecond (the MEGA makes dozens), the line draining
        // between them: each sends at most one board-initiated frame.
        for (uint8_t k = 0; k < kLoopsPerMs; ++k) {
            app::loop();
            drain_to_line();
        }
    }
}

// `ms` milliseconds as the MEGA runs them: a tick, then loop() only if the tick asked for a
// pass (app::tick_done()), and more passes while app::idle() finds work (the AVR layer's idle
// sleep, hal_avr.cpp). woke[i]: whether tick i asked. Returns the passes run.
uint32_t fw_run_woken(uint32_t ms, uint8_t* woke) {
    uint32_t passes = 0;
    for (uint32_t i = 0; i < ms; ++i) {
        ++state().ms;
        state().tick_ms = state().ms;
        app::tick();
        const uint32_t c = state().tick_cycles;
        woke[i] = app::tick_done((uint16_t)(c > 0xFFFFu ? 0xFFFFu : c), state().period_elapsed);
        if (!woke[i]) continue;
        for (uint8_t k = 0; k < 8; ++k) {
            app::loop();
            drain_to_line();
            ++passes;
            if (app::idle()) break;
        }
    }
    return passes;
}

void fw_advance_ms(uint32_t ms) { state().ms += ms; }

void fw_set_adc(uint8_t f, uint16_t sample) { state().adc[f] = sample; }
// The sampler stops (no new ADC rounds): every encoder goes stale.
void fw_freeze_adc(int frozen) { state().adc_frozen = frozen != 0; }
// Every reading through the tick's general encoder path (Finger::judge_reading()), not its
// fast one: the two must judge alike.
void fw_encoder_general_path(int on) { state().adc_rejudge = on != 0; }
void fw_safe_action_general_path(int on) { app::board().hand.use_general_safe_action(on != 0); }
void fw_set_tick_cycles(uint32_t c) { state().tick_cycles = c; }
void fw_set_period_elapsed(int on) { state().period_elapsed = on != 0; }

uint16_t fw_rx(const uint8_t* data, uint16_t n) {
    hal::host::State& s = state();
    uint16_t k = 0;
    for (; k < n; ++k) {
        const uint16_t next = (uint16_t)((s.rx_head + 1) % hal::host::kRxBytes);
        if (next == s.rx_tail) break;
        s.rx[s.rx_head] = data[k];
        s.rx_head = next;
    }
    return k;
}

void fw_add_rx_lost(uint16_t n) { state().rx_lost = (uint16_t)(state().rx_lost + n); }
void fw_add_uart_errors(uint8_t overruns, uint8_t frame_errors) {
    state().uart_overruns = (uint8_t)(state().uart_overruns + overruns);
    state().uart_frame_errors = (uint8_t)(state().uart_frame_errors + frame_errors);
}

uint16_t fw_tx(uint8_t* out, uint16_t max) {
    if (g_line_len != 0) {  // the line first: it holds the older bytes
        const uint16_t n = (uint16_t)(g_line_len < max ? g_line_len : max);
        for (uint16_t i = 0; i < n; ++i) out[i] = g_line[i];
        for (uint32_t i = n; i < g_line_len; ++i) g_line[i - n] = g_line[i];
        g_line_len -= n;
        return n;
    }
    hal::host::State& s = state();
    const uint16_t n = s.tx_len < max ? s.tx_len : max;
    for (uint16_t i = 0; i < n; ++i) out[i] = s.tx[i];
    for (uint16_t i = n; i < s.tx_len; ++i) s.tx[i - n] = s.tx[i];
    s.tx_len = (uint16_t)(s.tx_len - n);
    return n;
}

void fw_set_tx_room(uint16_t n) { state().tx_room_limit = n; }

uint8_t* fw_eeprom(void) { return state().eeprom; }
uint16_t fw_eeprom_size(void) { return hal::host::kEepromBytes; }
void fw_set_eeprom_busy_polls(uint8_t n) { state().eeprom_busy_polls = n; }
void fw_set_eeprom_stuck(int32_t addr) { state().eeprom_stuck_addr = addr; }
uint32_t fw_eeprom_writes(void) { return state().eeprom_writes; }

struct FwMotor {
    uint8_t drive_a;
    uint8_t drive_b;
    uint16_t counts_a;
    uint16_t counts_b;
    uint8_t stby;
};

void fw_motor(uint8_t f, FwMotor* out) {
    out->drive_a = (uint8_t)state().motor[f][0].drive;
    out->drive_b = (uint8_t)state().motor[f][1].drive;
    out->counts_a = state().motor[f][0].on_counts;
    out->counts_b = state().motor[f][1].on_counts;
    out->stby = state().stby[f] ? 1 : 0;
}

struct FwFinger {
    uint8_t mode;
    uint8_t faults;
    uint8_t contact;
    uint8_t has_theta;
    uint8_t saturated;
    int16_t theta;
    int16_t target;
    int16_t duty_a;
    int16_t duty_b;
    int16_t output;
    int16_t limit;
    int32_t integrator31;
};

void fw_finger(uint8_t f, FwFinger* out) {
    const finger::Finger& fg = app::board().hand.finger(f);
    out->mode = fg.mode();
    out->faults = fg.faults();
    out->contact = fg.contact() ? 1 : 0;
    out->has_theta = fg.has_theta() ? 1 : 0;
    out->saturated = fg.pid().saturated() ? 1 : 0;
    out->theta = fg.theta();
    out->target = fg.target();
    out->duty_a = fg.duty_a();
    out->duty_b = fg.duty_b();
    out->output = fg.output();
    out->limit = fg.limit();
    out->integrator31 = fg.pid().integrator31();
}

// A move's path (core/path.h): its feedforward duty (Q15) and the ticks it has to go.
int16_t fw_path_ff(uint8_t f) { return app::board().hand.finger(f).path().feedforward(); }
uint16_t fw_path_left(uint8_t f) { return app::board().hand.finger(f).path().left(); }
// The state stream's ring (core/hand.h): samples that may wait for loop().
uint8_t fw_stream_slots() { return hand::kStreamSlots; }

struct FwStatus {
    uint32_t lock_errors;
    uint32_t wdt_feeds;
    uint32_t all_off_calls;
    uint8_t wdt_started;
    uint8_t hang_mark;
    uint8_t tick_started;
    uint8_t halted;
    uint8_t config_status;
    uint8_t reset_cause;
    uint8_t saving;
};

void fw_status(FwStatus* out) {
    const hal::host::State& s = state();
    out->lock_errors = s.lock_errors;
    out->wdt_feeds = s.wdt_feeds;
    out->all_off_calls = s.all_off_calls;
    out->wdt_started = s.wdt_started;
    out->hang_mark = s.hang_mark;
    out->tick_started = s.tick_started;
    out->halted = app::board().hand.halted() ? 1 : 0;
    out->config_status = app::board().config_status;
    out->reset_cause = app::board().reset_cause;
    out->saving = app::board().writer.busy() ? 1 : 0;
}

// ---- the PID alone ---------------------------------------------------------------------------

namespace {
pid::Coeffs g_pc;
pid::Pid g_pid;
int16_t g_plimit;

// A set_gains body (the host's encoding, every gain the spec has) to the coefficients, as the
// board compiles them: -1 when the body does not decode.
int gains_from_body(const uint8_t* body, uint8_t len, pid::Coeffs& out) {
    proto::SetGains m;
    uint8_t bad = 0xFF;
    if (proto::decode(body, len, m, bad) != proto::DecodeStatus::OK) return -1;
    config::Gains g;
    config::take(m, g);
    out = pid::compile(g, 1e-3f);
    return 0;
}
}  // namespace

int fw_pid_config(const uint8_t* set_gains_body, uint8_t len, int16_t limit) {
    if (gains_from_body(set_gains_body, len, g_pc) != 0) return -1;
    g_plimit = limit;
    g_pid.load(g_pc);
    return 0;
}

// New gains while running: rebased, so the output does not jump.
int fw_pid_regain(const uint8_t* set_gains_body, uint8_t len, int16_t limit) {
    if (gains_from_body(set_gains_body, len, g_pc) != 0) return -1;
    g_plimit = limit;
    g_pid.set_coeffs(g_pc, g_plimit);
    return 0;
}

// The PID's fast paths as compile() chose them for the gains (bit 0 ki_plain, bit 1 pd_plain);
// fw_pid_general_path() turns them off in the running Pid, state kept, so a test can run the
// general twins on the same inputs.
int fw_pid_fast_paths(void) { return (g_pc.ki_plain ? 1 : 0) | (g_pc.pd_plain ? 2 : 0); }
void fw_pid_general_path(void) {
    g_pc.ki_plain = false;
    g_pc.pd_plain = false;
    g_pid.load(g_pc);
}

void fw_pid_reset(int16_t u, int16_t measured) { g_pid.reset(g_plimit, u, measured); }
int16_t fw_pid_step(int16_t target, int16_t measured) {
    return g_pid.step(g_plimit, target, measured);
}
int16_t fw_pid_step_open(int16_t duty, int16_t measured) {
    return g_pid.step_open(g_plimit, duty, measured);
}
void fw_pid_state(int32_t* i31, int32_t* v8, int32_t* saturated) {
    *i31 = g_pid.integrator31();
    *v8 = g_pid.velocity8();
    *saturated = g_pid.saturated() ? 1 : 0;
}
int32_t fw_pid_add_deadband(int32_t v, int16_t db) { return db ? pid::add_deadband(v, db) : v; }
int16_t fw_pid_remove_deadband(int16_t u, int16_t db) {
    return pid::remove_deadband(u, db, pid::deadband_inverse(db));
}
// The gain representation: value -> (mantissa, shift) -> the value it stands for.
double fw_gain_roundtrip(double value) {
    return fx::gain_value(fx::make_gain((float)value, 2147483647L));
}
int32_t fw_gain_apply(double value, int16_t x, int32_t ymax) {
    return fx::apply(fx::make_gain((float)value, ymax), x, ymax);
}
// The gain's fast paths beside their general twins (fx::apply_plain(), apply16_hi(),
// apply16_mid()): which ones a gain takes (bit 0 plain() for ymax, bit 1 hi16_plain() for
// |x| <= pid::kMaxV8, bit 2 mid16()), and each path's result.
int fw_gain_paths(double value, int32_t ymax) {
    const fx::Gain g = fx::make_gain((float)value, ymax);
    return (fx::plain(g, ymax) ? 1 : 0) | (fx::hi16_plain(g, pid::kMaxV8) ? 2 : 0) |
           (fx::mid16(g) ? 4 : 0);
}
int32_t fw_gain_apply_plain(double value, int16_t x, int32_t ymax) {
    return fx::apply_plain(fx::make_gain((float)value, ymax), x);
}
int16_t fw_gain_apply16(double value, int16_t x, int16_t ymax) {
    return fx::apply16(fx::make_gain((float)value, ymax), x, ymax);
}
int16_t fw_gain_apply16_hi(double value, int16_t x, int16_t ymax) {
    return fx::apply16_hi(fx::make_gain((float)value, ymax), x);
}
int16_t fw_gain_apply16_mid(double value, int16_t x, int16_t ymax) {
    return fx::apply16_mid(fx::make_gain((float)value, ymax), x, ymax);
}
int32_t fw_mul_q16(int32_t x, uint16_t c) { return fx::mul_q16(x, c); }

// ---- kinematics, encoder, config -------------------------------------------------------------

void fw_kin_init(void) { kin::init(); }
uint8_t fw_kin_geometry(uint8_t finger) { return kin::finger_geometry(finger); }
uint8_t fw_kin_geometry_count(void) { return kin::geometry_count(); }
uint16_t fw_kin_table_bytes(void) { return kin::table_bytes(); }
void fw_kin_range(uint8_t g, double* lo, double* hi) {
    *lo = kin::theta2_min(g);
    *hi = kin::theta2_max(g);
}
int fw_kin_lookup(uint8_t g, double theta2, double* out6) {
    kin::Point p;
    const bool inside = kin::lookup(g, (float)theta2, p);
    out6[0] = p.q;
    out6[1] = p.theta1;
    out6[2] = p.theta2;
    out6[3] = p.theta3;
    out6[4] = p.tip_x;
    out6[5] = p.tip_y;
    return inside ? 1 : 0;
}
int fw_kin_theta2_from_q(uint8_t g, double q, double* theta2) {
    float t = 0;
    const bool ok = kin::theta2_from_q(g, (float)q, t);
    *theta2 = t;
    return ok ? 1 : 0;
}
double fw_kin_q_full(uint8_t g) { return kin::q_full_flexion(g); }
void fw_kin_tip_raw(uint8_t g, int32_t theta_au, int16_t* x, int16_t* y) {
    kin::tip_raw(g, theta_au, *x, *y);
}

int16_t fw_encoder_angle(uint16_t turn, uint16_t zero, int invert) {
    return encoder::angle_bu(turn, zero, invert != 0);
}
int16_t fw_au_from_bu(int16_t b) { return fx::au_from_bu(b); }
int16_t fw_bu(double rad) { return fx::bu((float)rad); }
uint16_t fw_encoder_turn_from_rad(double rad) { return encoder::turn_from_rad((float)rad); }

void fw_target_window(int16_t theta_min, int16_t theta_max, int32_t* lo, int32_t* hi) {
    dispatch::target_window(theta_min, theta_max, *lo, *hi);
}
// The general target range rule (finger::Params::accepts()) on a JOINT2_ANGLE value, as move
// applies it: the set_targets window (the fast path) must accept exactly these.
int fw_target_accepts(int16_t theta_min, int16_t theta_max, int32_t urad) {
    finger::Params p = finger::Params();
    p.theta_min = theta_min;
    p.theta_max = theta_max;
    if (urad < -dispatch::kMaxUrad || urad > dispatch::kMaxUrad) return 0;
    return p.accepts(dispatch::bu_from_urad(urad)) ? 1 : 0;
}

uint16_t fw_config_image_bytes(void) { return config::kImageBytes; }
uint32_t fw_core_check(void) { return check::core_check_run(); }
uint32_t fw_product_mismatches(void) { return check::product_mismatches(); }
uint16_t fw_config_body_bytes(void) { return sizeof(config::Config); }

}  // extern "C"
