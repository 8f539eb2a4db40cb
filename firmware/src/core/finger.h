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
// The stall rule runs for each finger every kStallEvery ticks (one finger a tick).
static const uint8_t kStallEvery = 5;

// Faults that turn the finger's motors off. HOST_TIMEOUT instead applies the configured safe
// action (which may be to hold in closed loop).
static const uint8_t kStopFaults = ENCODER_RANGE | ENCODER_JUMP | STALL | JOINT_LIMIT | OVERRUN;

// A finger's configuration, ready for the tick (built in loop() context by compile()).
// Angles in BU (core/fixed.h: 2 pi / 32768 rad), duties in Q15.
struct Params {
    pid::Coeffs pid;
    int16_t max_duty;      // motor duty limit
    int16_t pretension;    // antagonistic pretension
    int16_t theta_min;     // joint limits
    int16_t theta_max;
    int16_t fault_low;     // JOINT_LIMIT below this (theta_min - margin)
    int16_t fault_high;    // ... or above this (theta_max + margin)
    int16_t stall_error;
    int16_t stall_motion;
    uint16_t stall_checks;  // stall time in stall-rule turns (kStallEvery ticks each)
    int16_t jump;          // per tick
    uint16_t zero_turn;    // encoder reading at angle 0
    bool encoder_invert;
    bool motor_invert;
    bool rotary;
    // The controller's output limit: max_duty, less the pretension when antagonistic.
    int16_t limit() const {
        const int16_t l = rotary ? max_duty : (int16_t)(max_duty - pretension);
        return l < 0 ? (int16_t)0 : l;
    }
};

Params compile(const config::Finger& cfg, float dt_s);

class Finger {
   public:
    Finger();

    // ---- from loop(), under the tick lock, after validation ----
    void configure(const Params& p);  // bumpless when gains or limits change
    // Enter `mode`. duty (DUTY) and effort (GRASP) are Q15 fractions.
    void set_mode(uint8_t mode, int16_t duty, int16_t effort);
    void set_target(int16_t theta_bu);
    void clear_faults();
    void set_zero_turn(uint16_t turn) { params_.zero_turn = turn; have_theta_ = false; }

    // ---- from the tick ----
    // Latch faults (the host-silence and overrun rules live at the hand level).
    void latch(uint8_t bits);
    // Safe action HOLD: hold the measured angle in closed loop, starting from the present output.
    void hold_here();
    // One control period: read the encoder, check the safety rules, run the mode, and fill
    // the driver command. Inline (below): the hand's tick runs it for five fingers.
    // `stall_check`: this tick also runs the stall rule (the hand gives each finger its turn
    // every kStallEvery ticks, which keeps the tick within its time budget).
    inline void tick(const hal::EncoderReading& enc, hal::MotorCommand& out, bool stall_check);

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
    int16_t target() const { return target_; }  // BU
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
    void enter_closed_loop(uint8_t mode);
    inline hal::MotorOut drive(int16_t duty) const;
    void stop_now(hal::MotorCommand& out);

    // The tick's working state first: short offsets from the object's address.
    int16_t theta_;
    int16_t target_;
    int16_t limit_;      // limit_for(mode_), kept current
    int16_t duty_a_;
    int16_t duty_b_;
    int16_t stall_ref_;
    uint16_t stall_count_;
    uint16_t last_turn_;
    uint8_t mode_;
    uint8_t faults_;
    uint8_t new_faults_;
    bool have_theta_;
    bool encoder_ok_;
    bool contact_;       // GRASP: closed on something and holding
    bool target_valid_;  // a target was set since the finger last left closed loop
    int16_t duty_cmd_;
    int16_t effort_;
    pid::Pid pid_;
    Params params_;
};

UTRF_HOT hal::MotorOut Finger::drive(int16_t duty) const {
    hal::MotorOut m;
    bool forward = duty > 0;
    const uint16_t mag = (uint16_t)(duty < 0 ? -duty : duty);
    // Q15 duty to PWM counts, rounded: one 16 x 16 multiply and a byte shift.
    m.on_counts = (uint16_t)((fx::mul_uu(mag, 2u * hal::kPwmPeriod) + 32768u) >> 16);
    if (m.on_counts == 0) {
        m.drive = hal::Drive::COAST;  // zero duty: really off
    } else {
        if (params_.motor_invert) forward = !forward;
        m.drive = forward ? hal::Drive::FORWARD : hal::Drive::REVERSE;
    }
    return m;
}

UTRF_HOT void Finger::tick(const hal::EncoderReading& enc, hal::MotorCommand& out,
                           bool stall_check) {
    // ---- encoder: band and plausibility; joint limits ----
    // Angles are BU within +-pi, so every difference below fits int16.
    int16_t th = theta_;
    encoder_ok_ = enc.status == hal::EncoderStatus::OK;
    if (!encoder_ok_) {
        latch(ENCODER_RANGE);
    } else {
        last_turn_ = enc.turn;
        th = encoder::angle_bu(enc.turn, params_.zero_turn, params_.encoder_invert);
        if (have_theta_ && fx::abs16((int16_t)(th - theta_)) > params_.jump) latch(ENCODER_JUMP);
        theta_ = th;
        have_theta_ = true;
        if (th < params_.fault_low || th > params_.fault_high) latch(JOINT_LIMIT);
    }

    const uint8_t mode = mode_;
    if (mode == COAST || mode == BRAKE) {
        duty_a_ = duty_b_ = 0;
        out.a.on_counts = out.b.on_counts = 0;
        out.a.drive = mode == BRAKE ? hal::Drive::BRAKE : hal::Drive::COAST;
        out.b.drive = (mode == BRAKE && !params_.rotary) ? hal::Drive::BRAKE : hal::Drive::COAST;
        out.stby = mode == BRAKE && (faults_ & kStopFaults) == 0;
        return;
    }

    // ---- the mode's output u (Q15, positive flexes) ----
    int16_t u;
    if (mode == DUTY) {
        int16_t d = duty_cmd_;
        // Never drive further past a joint limit.
        if ((th >= params_.theta_max && d > 0) || (th <= params_.theta_min && d < 0)) d = 0;
        u = pid_.step_open(params_.pid, limit_, d, th);
    } else {
        u = pid_.step(params_.pid, limit_, target_, th);
    }

    // ---- stall: pushing (large error, or a commanded duty, with the output at its limit)
    // without moving for the stall time ----
    if (stall_check) {
        bool pushing;
        if (mode == DUTY) {
            pushing = u != 0 && fx::abs16(u) >= params_.pid.deadband;
        } else {
            pushing = limit_ > 0 && fx::abs16(u) >= limit_ &&
                      fx::abs16((int16_t)(target_ - th)) > params_.stall_error;
        }
        if (pushing) {
            if (fx::abs16((int16_t)(th - stall_ref_)) > params_.stall_motion) {
                stall_ref_ = th;
                stall_count_ = 0;
            } else if (stall_count_ < params_.stall_checks) {
                ++stall_count_;
            }
            if (stall_count_ >= params_.stall_checks) {
                if (mode != GRASP) {
                    latch(STALL);
                    stop_now(out);
                    return;
                }
                contact_ = true;  // closed on an object: hold it, the effort bounds the force
            }
        } else {
            stall_ref_ = th;
            stall_count_ = 0;
            contact_ = false;
        }
    }
    if (mode_ == COAST) {  // a fault latched in this tick: off now
        stop_now(out);
        return;
    }

    // ---- driver channels ----
    if (params_.rotary) {
        duty_a_ = u;
        duty_b_ = 0;
        out.a = drive(u);
        out.b.drive = hal::Drive::COAST;
        out.b.on_counts = 0;
    } else {
        duty_a_ = (int16_t)(params_.pretension + (u > 0 ? u : 0));
        duty_b_ = (int16_t)(params_.pretension + (u < 0 ? -u : 0));
        out.a = drive(duty_a_);
        out.b = drive(duty_b_);
    }
    out.stby = true;  // no stop fault latched, or the mode would be COAST
}

}  // namespace finger
}  // namespace utrf

#endif  // UTRF_CORE_FINGER_H
