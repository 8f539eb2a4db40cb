#include "finger.h"

#include <stddef.h>

#include "encoder.h"
#include "fixed.h"

namespace utrf {
namespace finger {

namespace {
int16_t q15_milli(uint16_t milli) {
    return (int16_t)fx::clamp32(((int32_t)milli * fx::kOne15 + 500) / 1000, 0, fx::kMax15);
}
}  // namespace

Params compile(const config::Finger& cfg, float dt_s, pid::Coeffs& coeffs) {
    Params p;
    coeffs = pid::compile(cfg.gains, dt_s);
    p.max_duty = q15_milli(cfg.gains.max_duty);
    p.pretension = q15_milli(cfg.gains.pretension_duty);
    p.theta_min = fx::bu(cfg.limits.theta2_min);
    p.theta_max = fx::bu(cfg.limits.theta2_max);
    const int16_t margin = fx::bu(cfg.limits.limit_margin);
    p.fault_low = fx::sat16((int32_t)p.theta_min - margin);
    p.fault_high = fx::sat16((int32_t)p.theta_max + margin);
    p.stall_error = fx::bu(cfg.limits.stall_error);
    p.stall_motion = fx::bu(cfg.limits.stall_motion);
    const uint32_t ticks = (uint32_t)((float)cfg.limits.stall_time * 1e-3f / dt_s + 0.5f);
    p.stall_ticks = (uint16_t)(ticks < 1 ? 1 : (ticks > 65535u ? 65535u : ticks));
    p.jump = fx::bu(cfg.limits.encoder_jump);
    p.zero_turn = encoder::turn_from_rad(cfg.hw.encoder_offset);
    p.encoder_invert = cfg.hw.encoder_invert != 0;
    p.pull = cfg.hw.motor_invert != 0 ? hal::Drive::REVERSE : hal::Drive::FORWARD;
    p.rotary = cfg.hw.actuation == 1;  // proto::Actuation::ROTARY
    p.pretension_counts = pwm_counts((uint16_t)p.pretension);
    const hal::Drive hold = p.pretension_counts == 0 ? hal::Drive::COAST : p.pull;
    p.hold_drives = hal::drives(hold, hold, true);
    return p;
}

Finger::Finger()
    : theta_(0),
      target_(0),
      limit_(0),
      duty_a_(0),
      duty_b_(0),
      last_turn_(0),
      mode_(COAST),
      have_theta_(false),
      encoder_ok_(false),
      faults_(0),
      new_faults_(0),
      contact_(false),
      target_valid_(false),
      stall_ref_(0),
      stall_count_(0),
      duty_cmd_(0),
      effort_(0) {
    params_ = Params();
}

int16_t Finger::limit_for(uint8_t mode) const {
    int16_t lim = params_.limit();
    if (mode == GRASP) {
        // The effort bounds the closing motor's duty: the flexor's, pretension included.
        const int16_t e = params_.rotary ? effort_ : (int16_t)(effort_ - params_.pretension);
        if (e < lim) lim = e;
    }
    return lim < 0 ? (int16_t)0 : lim;
}

bool Finger::configure(const Params& p, const pid::Coeffs& c) {
    const bool encoder_changed =
        p.zero_turn != params_.zero_turn || p.encoder_invert != params_.encoder_invert;
    params_ = p;
    if (encoder_changed) have_theta_ = false;  // the next reading is not a jump
    limit_ = limit_for(mode_);
    pid_.set_coeffs(c, limit_);
    // Ended, not clamped: the rest of a path lies between its setpoint now and its end (the
    // profile is monotonic), so it stays within the limits only if both do; a path bent to
    // new limits would be a move nobody asked for.
    const bool end_path =
        path_.active() && (target_ != p.clamp(target_) || path_.end() != p.clamp(path_.end()));
    if (end_path) path_.stop();
    target_ = p.clamp(target_);
    return end_path;
}

// Inline: the host-silence HOLD runs it from the tick for every finger (hold_here()).
__attribute__((always_inline)) inline void Finger::restart(uint8_t mode, int16_t u) {
    limit_ = limit_for(mode);
    pid_.reset(limit_, u, theta_);
    stall_count_ = 0;
    stall_ref_ = theta_;
}

void Finger::enter_closed_loop(uint8_t mode) {
    if (!target_valid_) {
        target_ = params_.clamp(theta_);
        target_valid_ = true;
    }
    restart(mode, present_output());
    contact_ = false;
}

void Finger::set_mode(uint8_t mode, int16_t duty, int16_t effort) {
    duty_cmd_ = duty;
    effort_ = effort;
    if (mode == mode_) {  // a resent frame changes nothing; a new duty or effort applies
        limit_ = limit_for(mode_);
        return;
    }
    path_.stop();
    if (mode == POSITION || mode == GRASP) {
        enter_closed_loop(mode);
    } else if (mode == DUTY) {
        restart(DUTY, present_output());
    } else {
        target_valid_ = false;
        restart(mode, 0);
    }
    contact_ = false;
    mode_ = mode;
}

void Finger::set_target(int16_t theta_bu) {
    path_.stop();
    target_ = theta_bu;
    target_valid_ = true;
}

void Finger::clear_faults() {
    faults_ = 0;
    new_faults_ = 0;
    have_theta_ = false;  // no jump check against a reading from before the fault
    stall_count_ = 0;
}

uint8_t Finger::judge_reading(const hal::EncoderReading& enc) {
    const hal::EncoderReading r = encoder::judge(enc, encoder_setup());
    if (r.flags & hal::kReadingOut) {
        encoder_ok_ = false;
        return ENCODER_RANGE;
    }
    encoder_ok_ = true;
    last_turn_ = r.turn;
    const uint8_t found = take_angle(r.angle);
    return (r.flags & hal::kReadingLimit) ? (uint8_t)(found | JOINT_LIMIT) : found;
}

void Finger::latch(uint8_t bits) {
    new_faults_ |= bits & (uint8_t)~faults_;
    faults_ |= bits;
    if ((bits & kStopFaults) && mode_ != COAST) {
        path_.stop();
        // JOINT_LIMIT alone short-brakes (firmware/README.md, Safety, says why); any other stop
        // fault coasts.
        mode_ = (faults_ & kStopFaults) == JOINT_LIMIT ? BRAKE : COAST;
        target_valid_ = false;
        contact_ = false;
        restart(COAST, 0);
    }
}

void Finger::hold_here() {
    const uint8_t mode = mode_ == GRASP ? GRASP : POSITION;
    path_.stop();
    target_ = params_.clamp(theta_);
    target_valid_ = true;
    restart(mode, pid_.output());  // a driving finger's (the tick holds only those)
    mode_ = mode;
}

void Finger::tick_safe_action(const hal::EncoderReading& enc, hal::MotorCommand& out,
                              bool hold, bool step_law) {
    const bool driving = active();  // nothing runs unsupervised on an idle finger
    const int16_t th = take_reading(enc);
    if (driving) {
        latch(HOST_TIMEOUT);
        if (!hold) set_mode(COAST, 0, 0);
    }
    const uint8_t mode = mode_;  // a stop fault of this reading has made it COAST
    if (mode == COAST || mode == BRAKE) {
        out = idle_outputs(mode);
        return;
    }
    hold_here();  // a driving finger (an idle one has returned): HOLD at this tick's reading
    drive(step_law ? pid_.step(limit_, target_, th, 0) : pid_.output(), out);
}

void Finger::halt() {
    set_mode(COAST, 0, 0);
    duty_a_ = duty_b_ = 0;
}

hal::MotorCommand Finger::idle_outputs(uint8_t mode) {
    duty_a_ = duty_b_ = 0;
    hal::MotorCommand out;
    out.a_counts = out.b_counts = 0;
    // Short brake needs the driver enabled: refused to a finger with a stop fault other than
    // JOINT_LIMIT (an encoder or stall fault, an overrun: nothing of it is trusted).
    out.drives = hal::drives(mode == BRAKE ? hal::Drive::BRAKE : hal::Drive::COAST,
                             (mode == BRAKE && !params_.rotary) ? hal::Drive::BRAKE
                                                                : hal::Drive::COAST,
                             mode == BRAKE && (faults_ & (kStopFaults & ~JOINT_LIMIT)) == 0);
    return out;
}

int16_t Finger::duty_step(int16_t th) {
    int16_t d = duty_cmd_;
    // Never drive further past a joint limit.
    if ((th >= params_.theta_max && d > 0) || (th <= params_.theta_min && d < 0)) d = 0;
    return pid_.step_open(limit_, d, th);
}

bool Finger::stall_rule(uint8_t elapsed) {
    // Pushing (a large error, or a commanded duty, with the output at its limit) without
    // moving for the stall time. The output and the angle are the last tick's.
    const uint8_t mode = mode_;
    if (mode != POSITION && mode != DUTY && mode != GRASP) return false;
    const int16_t u = pid_.output();
    const int16_t th = theta_;
    bool pushing;
    if (mode == DUTY) {
        pushing = u != 0 && fx::abs16(u) >= pid_.coeffs().deadband;
    } else {
        pushing = limit_ > 0 && fx::abs16(u) >= limit_ &&
                  fx::abs16((int16_t)(target_ - th)) > params_.stall_error;
    }
    if (pushing) {
        if (fx::abs16((int16_t)(th - stall_ref_)) > params_.stall_motion) {
            stall_ref_ = th;
            stall_count_ = 0;
        } else {
            const uint16_t n = (uint16_t)(stall_count_ + elapsed);
            stall_count_ = n < stall_count_ || n > params_.stall_ticks ? params_.stall_ticks : n;
        }
        if (stall_count_ >= params_.stall_ticks) {
            if (mode != GRASP) {
                latch(STALL);  // COAST; the motors go off with the caller's motor_off()
                duty_a_ = duty_b_ = 0;
                return true;
            }
            contact_ = true;  // closed on an object: hold it, the effort bounds the force
        }
    } else {
        stall_ref_ = th;
        stall_count_ = 0;
        contact_ = false;
    }
    return false;
}

}  // namespace finger
}  // namespace utrf
