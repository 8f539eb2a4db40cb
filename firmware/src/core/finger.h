// One finger: its control mode, target, PID, the safety rules that watch it, and the mapping
// of the controller's output onto its motor driver channels.
//
// Antagonistic rule (two motors, each can only pull its tendon): with controller output u
// (positive flexes) and pretension p,
//     flexor   A = p + max(u, 0)
//     extensor B = p + max(-u, 0)
// so the net pull A - B is u, and the side that is not working still pulls with p: its tendon
// stays taut and takes over without slack when u changes sign. The PID's limit is
// max_duty - p, so neither motor exceeds max_duty. Rotary (one motor winding both tendons):
// A = u signed, B off.
#ifndef UTRF_CORE_FINGER_H
#define UTRF_CORE_FINGER_H

#include <stdint.h>

#include "../hal/hal.h"
#include "config.h"
#include "encoder.h"
#include "path.h"
#include "pid.h"

namespace utrf {
namespace finger {

// Values match proto::ControlMode and proto::FaultBits.
enum Mode : uint8_t { COAST = 0, BRAKE = 1, POSITION = 2, DUTY = 3, GRASP = 4 };
enum Fault : uint8_t {
    ENCODER_RANGE = 1u << 0,
    ENCODER_JUMP = 1u << 1,
    STALL = 1u << 2,
    JOINT_LIMIT = 1u << 3,
    HOST_TIMEOUT = 1u << 4,
    OVERRUN = 1u << 5,
};
// The stall rule runs for each finger about every kStallEvery ticks, in loop() (Hand::
// stall_rules(): its window, the stall time, is some hundreds of ticks; loop() runs within
// kLoopHangTicks or the tick halts the hand).
static const uint8_t kStallEvery = 5;

// Faults that stop the finger: COAST, motors off; JOINT_LIMIT alone short-brakes them instead
// (finger.cpp, latch()). HOST_TIMEOUT instead applies the configured safe action (which may be
// to hold in closed loop).
static const uint8_t kStopFaults = ENCODER_RANGE | ENCODER_JUMP | STALL | JOINT_LIMIT | OVERRUN;

// A finger's configuration, ready for the tick (built in loop() context by compile(); the
// PID's coefficients go to its Pid). Angles in BU (core/fixed.h: 2 pi / 32768 rad), duties in
// Q15. The fields every tick reads come first (see Finger's fields).
struct Params {
    int16_t pretension;    // antagonistic pretension
    int16_t fault_low;     // JOINT_LIMIT below this (theta_min - margin)
    int16_t fault_high;    // ... or above this (theta_max + margin)
    int16_t jump;          // per tick
    uint16_t zero_turn;    // encoder reading at angle 0
    bool encoder_invert;
    hal::Drive pull;       // the drive that pulls a tendon: FORWARD, or REVERSE (motor_invert)
    bool rotary;
    // Read by the antagonistic output mapping every tick, by the stall rule, DUTY and loop().
    uint16_t pretension_counts;  // PWM counts of the pretension alone
    uint8_t hold_drives;         // hal::drives() of both channels holding the pretension alone

    int16_t max_duty;      // motor duty limit
    int16_t theta_min;     // joint limits
    int16_t theta_max;
    int16_t stall_error;
    int16_t stall_motion;
    uint16_t stall_ticks;  // stall time in ticks
    // The limits rule for setpoints (set_targets, move, new limits): a target asked for, in BU
    // as converted, is accepted within a count of a limit (a float round trip may land the
    // exact limit a count beyond), and every setpoint in use lies within the limits.
    bool accepts(int32_t bu) const {
        return bu >= (int32_t)theta_min - 1 && bu <= (int32_t)theta_max + 1;
    }
    int16_t clamp(int32_t bu) const { return (int16_t)fx::clamp32(bu, theta_min, theta_max); }
    int16_t clamp(int16_t bu) const { return fx::clamp16(bu, theta_min, theta_max); }
    // The controller's output limit: max_duty, less the pretension when antagonistic.
    int16_t limit() const {
        const int16_t l = rotary ? max_duty : (int16_t)(max_duty - pretension);
        return l < 0 ? (int16_t)0 : l;
    }
};

Params compile(const config::Finger& cfg, float dt_s, pid::Coeffs& coeffs);

class Finger {
   public:
    Finger();

    // ---- from loop(), under the tick lock, after validation ----
    // Bumpless when gains or limits change. New limits hold every setpoint at once: the target
    // is clamped in, and a path that would leave them is ended (true: one was).
    bool configure(const Params& p, const pid::Coeffs& c);
    // Enter `mode`. duty (DUTY) and effort (GRASP) are Q15 fractions.
    void set_mode(uint8_t mode, int16_t duty, int16_t effort);
    void set_target(int16_t theta_bu);  // a step: ends a move's path
    // A move (core/path.h): the path starts from the present setpoint; the finger must be in
    // POSITION or GRASP. set_target, a mode change and any stopping fault end it.
    void start_path(const path::Plan& p, uint8_t first_segment) {
        path_.start(p, target_, first_segment);
        target_valid_ = true;
    }
    void clear_faults();
    // What the encoder sampler needs to judge this finger's readings (hal::encoder_setup()).
    hal::EncoderSetup encoder_setup() const {
        hal::EncoderSetup s;
        s.zero_turn = params_.zero_turn;
        s.invert = params_.encoder_invert;
        s.low = params_.fault_low;
        s.high = params_.fault_high;
        return s;
    }

    // ---- from the tick ----
    // Latch faults (the host-silence and overrun rules live at the hand level).
    void latch(uint8_t bits);
    // Safe action HOLD: hold the measured angle in closed loop, starting from the present output.
    void hold_here();
    // The host-silence tick (Hand::tick() at the timeout): the encoder's rules on this tick's
    // reading, then a driving finger latches HOST_TIMEOUT and takes the safe action (HOLD:
    // hold_here() at this reading; else COAST). Fast path (step_law false): no law step, since
    // right after hold_here() the law's step at zero error gives the present output; the
    // general one (true) runs it. Out of line: it replaces the five law steps of that tick.
    void tick_safe_action(const hal::EncoderReading& enc, hal::MotorCommand& out, bool hold,
                          bool step_law);
    // The board stops driving (the hand halted: its motors are all off): COAST, duties 0, so
    // the state reports what the motors do.
    void halt();
    // One control period: read the encoder, check the safety rules, run the mode, and fill
    // the driver command. Inline (below): the hand's tick runs it for five fingers.
    inline void tick(const hal::EncoderReading& enc, hal::MotorCommand& out);

    // ---- from loop(), under the tick lock ----
    // The stall rule, `elapsed` ticks (1..255) after its last check, on the output and angle
    // of the last tick: pushing (a large error, or a commanded duty, with the output at its
    // limit) with less motion than stall_motion for the stall time latches STALL and returns
    // true: the finger is in COAST, and the caller turns its motors off at once
    // (hal::motor_off()); in GRASP it is contact, held.
    bool stall_rule(uint8_t elapsed);

    // ---- state ----
    uint8_t mode() const { return mode_; }
    uint8_t faults() const { return faults_; }
    // Bits latched since the last call (for the fault report); clears them.
    uint8_t take_new_faults() {
        uint8_t n = new_faults_;
        new_faults_ = 0;
        return n;
    }
    uint8_t pending_new_faults() const { return new_faults_; }
    bool active() const { return mode_ == POSITION || mode_ == DUTY || mode_ == GRASP; }
    bool idle() const { return mode_ == COAST || mode_ == BRAKE; }
    bool has_theta() const { return have_theta_; }
    int16_t theta() const { return theta_; }    // measured, BU
    int16_t target() const { return target_; }  // BU: the setpoint in use (a path's, moving)
    bool moving() const { return path_.active(); }
    const path::Path& path() const { return path_; }
    // loop() context, without the lock: the path's next segment, when it needs one.
    // The next segment worked out if due; true while segments are left to work out.
    bool plan_path() {
        path_.plan_next();
        return path_.planning();
    }
    int16_t duty_a() const { return duty_a_; }  // Q15, signed, positive pulls
    int16_t duty_b() const { return duty_b_; }
    int16_t output() const { return pid_.output(); }  // the controller's u, Q15
    int16_t limit() const { return limit_; }    // the controller's limit in this mode
    bool contact() const { return contact_; }
    uint16_t last_turn() const { return last_turn_; }
    bool encoder_ok() const { return encoder_ok_; }
    const Params& params() const { return params_; }
    const pid::Pid& pid() const { return pid_; }

   private:
    int16_t limit_for(uint8_t mode) const;
    // The encoder's rule that needs the last angle (the jump), on a reading's angle: takes it
    // as theta_; returns ENCODER_JUMP or 0. The tick's both paths call it.
    inline uint8_t take_angle(int16_t th);
    // The tick's general path, for a reading the sampler flagged (out of band, beyond a joint
    // limit, or judged with an earlier setup): judged again with this finger's setup
    // (encoder::judge()), then its faults. The tick's fast path takes an unflagged reading.
    uint8_t judge_reading(const hal::EncoderReading& enc);
    // The encoder's rules on a reading (the sampler's judgment taken as it is, or the general
    // path), faults latched; returns the angle. Both ticks run it.
    inline int16_t take_reading(const hal::EncoderReading& enc);
    // The driver command for the controller's output u (the finger drives).
    inline void drive(int16_t u, hal::MotorCommand& out);
    // Bumpless re-entry into `mode`: its output limit, the PID restarted from the output `u`
    // at the measured angle, the stall watch from here. Every mode change goes through it.
    void restart(uint8_t mode, int16_t u);
    // The output the motors have now (0 when idle): where a bumpless start begins.
    int16_t present_output() const { return idle() ? (int16_t)0 : pid_.output(); }
    void enter_closed_loop(uint8_t mode);
    // DUTY: the commanded duty, never further past a joint limit, through the PID's limit and
    // slew limiter.
    int16_t duty_step(int16_t th);
    hal::MotorCommand idle_outputs(uint8_t mode);  // by value: the tick's command stays in registers

    // The tick's working state first, then the PID (its state and coefficients), then the
    // configuration (Params: the fields the tick reads first): close together for the code
    // that reaches a finger through a pointer (ldd/std reach 64 bytes).
    int16_t theta_;
    int16_t target_;
    int16_t limit_;  // limit_for(mode_), kept current
    int16_t duty_a_;
    int16_t duty_b_;
    uint16_t last_turn_;
    uint8_t mode_;
    bool have_theta_;
    bool encoder_ok_;
    pid::Pid pid_;
    Params params_;
    // Read less often: by the stall rule, DUTY and loop().
    uint8_t faults_;
    uint8_t new_faults_;
    bool contact_;       // GRASP: closed on something and holding
    bool target_valid_;  // a target was set since the finger last left closed loop
    int16_t stall_ref_;
    uint16_t stall_count_;  // ticks pushing without moving
    int16_t duty_cmd_;
    int16_t effort_;
    path::Path path_;  // a move under way: the setpoint and feedforward each tick

};

// Q15 duty magnitude (0..32767) to PWM counts, rounded: (mag * 2 kPwmPeriod + 2^15) >> 16, which
// for 800 counts is (25 mag + 512) >> 10. Two 8 x 8 multiplies, all in 16 bits: with
// hi = 25 (mag >> 8) <= 3175 and lo = 25 (mag & 0xFF) <= 6375,
// floor((256 hi + lo + 512) / 1024) = (hi + ((lo + 512) >> 8)) >> 2.
static_assert(hal::kPwmPeriod == 800, "pwm_counts() is written for 800 counts a period");
// (lo + 512) >> 8 is (lo >> 8) + 2: on the AVR the high byte of the second product, added
// with the 2, in one sequence (tested against the C in the AVR check).
UTRF_HOT uint16_t pwm_counts(uint16_t mag) {
    const uint16_t hi = fx::mul8u(fx::hi8(mag), 25u);
    const uint16_t lo = fx::mul8u(fx::lo8(mag), 25u);
    return (uint16_t)((uint16_t)(hi + (uint16_t)((uint16_t)(lo + 512u) >> 8)) >> 2);
}

UTRF_HOT uint8_t Finger::take_angle(int16_t th) {
    uint8_t found = 0;
    if (UTRF_LIKELY(have_theta_) &&
        UTRF_UNLIKELY(fx::abs16((int16_t)(th - theta_)) > params_.jump)) {
        found = ENCODER_JUMP;
    }
    theta_ = th;
    have_theta_ = true;
    return found;
}

UTRF_HOT int16_t Finger::take_reading(const hal::EncoderReading& enc) {
    // ---- encoder: band and plausibility; joint limits ----
    // Angles are BU within +-pi, so every difference below fits int16. The faults found are
    // latched together, after theta_ took the new reading: the same bits as one at a time, and
    // the PID reset that stops the finger is repeated (from theta_) whenever it drives again.
    // (The band and the limits were judged by the sampler: hal.h, EncoderReading.)
    // The usual paths are told to the compiler (UTRF_LIKELY), so they run straight through.
    int16_t th;
    uint8_t found;
    if (UTRF_LIKELY(enc.flags == 0)) {
        // Fast path: in band and within the joint limits, its angle worked out by the sampler
        // with this finger's setup (core/encoder.h, judge()): only the jump rule is left.
        encoder_ok_ = true;
        last_turn_ = enc.turn;
        th = enc.angle;
        found = take_angle(th);
    } else {
        found = judge_reading(enc);  // general path: every rule, from turn and status
        th = theta_;
    }
    if (UTRF_UNLIKELY(found)) latch(found);
    return th;
}

UTRF_HOT void Finger::tick(const hal::EncoderReading& enc, hal::MotorCommand& out) {
    const int16_t th = take_reading(enc);
    const uint8_t mode = mode_;  // after the latches: a stop fault has made it COAST
    if (UTRF_UNLIKELY(mode == COAST || mode == BRAKE)) {
        out = idle_outputs(mode);
        return;
    }

    // ---- the mode's output u (Q15, positive flexes) ----
    int16_t u;
    if (UTRF_UNLIKELY(mode == DUTY)) {
        u = duty_step(th);
    } else {
        // A move: the path sets the setpoint, and its feedforward enters the PID's sum.
        const int16_t ff = UTRF_UNLIKELY(path_.active()) ? path_.tick(target_) : 0;
        u = pid_.step(limit_, target_, th, ff);
    }
    drive(u, out);
}

UTRF_HOT void Finger::drive(int16_t u, hal::MotorCommand& out) {
    // ---- driver channels (the finger drives: no stop fault, or its mode would be COAST) ----
    const hal::Drive pull = params_.pull;
    if (UTRF_UNLIKELY(params_.rotary)) {
        duty_a_ = u;
        duty_b_ = 0;
        const bool neg = u < 0;
        const uint16_t c = pwm_counts((uint16_t)(neg ? -u : u));
        out.a_counts = c;
        out.b_counts = 0;
        // Forward flexes; motor_invert swaps the directions (pull is then REVERSE).
        const hal::Drive extend =
            pull == hal::Drive::FORWARD ? hal::Drive::REVERSE : hal::Drive::FORWARD;
        out.drives = hal::drives(c == 0 ? hal::Drive::COAST : (neg ? extend : pull),
                                 hal::Drive::COAST, true);
    } else {
        // Both motors pull (duties >= 0): the flexor takes u > 0 on top of the pretension, the
        // extensor u < 0; the other one holds the pretension alone, whose counts (and drive
        // byte, both channels holding it) were worked out with the configuration.
        const int16_t p = params_.pretension;
        const uint16_t cp = params_.pretension_counts;
        uint8_t d = params_.hold_drives;
        if (u > 0) {
            const int16_t a = (int16_t)(p + u);
            const uint16_t ca = pwm_counts((uint16_t)a);
            duty_a_ = a;
            duty_b_ = p;
            out.a_counts = ca;
            out.b_counts = cp;
            // ca >= cp (a >= p): A drives unless both are 0, when hold_drives has it coast.
            if (ca != 0) d = (uint8_t)((d & (uint8_t)~3u) | (uint8_t)pull);
        } else if (u < 0) {
            const int16_t b = (int16_t)(p - u);
            const uint16_t cb = pwm_counts((uint16_t)b);
            duty_a_ = p;
            duty_b_ = b;
            out.a_counts = cp;
            out.b_counts = cb;
            if (cb != 0) d = (uint8_t)((d & (uint8_t)~12u) | (uint8_t)((uint8_t)pull << 2));
        } else {
            duty_a_ = duty_b_ = p;
            out.a_counts = out.b_counts = cp;
        }
        out.drives = d;
    }
}

}  // namespace finger
}  // namespace utrf

#endif  // UTRF_CORE_FINGER_H
