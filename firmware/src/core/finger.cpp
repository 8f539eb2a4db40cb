#include "finger.h"

#include "encoder.h"
#include "fixed.h"

namespace utrf {
namespace finger {

namespace {
int32_t au(float rad) { return fx::round_sat(rad * fx::kAuPerRad); }
int32_t q16_milli(uint16_t milli) { return ((int32_t)milli * fx::kOne16 + 500) / 1000; }
}  // namespace

Params compile(const config::Finger& cfg, float dt_s) {
    Params p;
    pid::Gains g;
    g.kp = cfg.gains.kp;
    g.ki = cfg.gains.ki;
    g.kd = cfg.gains.kd;
    g.d_cutoff_hz = cfg.gains.d_cutoff_hz;
    g.deadband = cfg.gains.deadband_milli * 1e-3f;
    g.slew_per_s = cfg.gains.slew_per_s;
    p.pid = pid::compile(g, dt_s);
    p.max16 = q16_milli(cfg.gains.max_duty_milli);
    p.pretension16 = q16_milli(cfg.gains.pretension_milli);
    p.theta_min = au(cfg.limits.theta2_min);
    p.theta_max = au(cfg.limits.theta2_max);
    p.margin = au(cfg.limits.limit_margin);
    p.stall_error = au(cfg.limits.stall_error);
    p.stall_motion = au(cfg.limits.stall_motion);
    uint32_t ticks = (uint32_t)((float)cfg.limits.stall_time_ms * 1e-3f / dt_s + 0.5f);
    p.stall_ticks = (uint16_t)(ticks < 1 ? 1 : (ticks > 65535u ? 65535u : ticks));
    p.jump = au(cfg.limits.encoder_jump);
    p.zero_turn = encoder::turn_from_rad(cfg.hw.encoder_offset);
    p.encoder_invert = cfg.hw.encoder_invert != 0;
    p.motor_invert = cfg.hw.motor_invert != 0;
    p.rotary = cfg.hw.actuation == 1;  // proto::Actuation::ROTARY
    return p;
}

Finger::Finger()
    : mode_(COAST),
      faults_(0),
      new_faults_(0),
      have_theta_(false),
      target_valid_(false),
      contact_(false),
      encoder_ok_(false),
      last_turn_(0),
      theta_(0),
      target_(0),
      duty_cmd16_(0),
      effort16_(0),
      duty_a16_(0),
      duty_b16_(0),
      stall_ref_(0),
      stall_count_(0) {
    params_ = Params();
}

int32_t Finger::limit_for(uint8_t mode) const {
    int32_t lim = params_.limit16();
    if (mode == GRASP) {
        // The effort bounds the closing motor's duty: the flexor's, pretension included.
        const int32_t e = params_.rotary ? effort16_ : effort16_ - params_.pretension16;
        if (e < lim) lim = e;
    }
    return lim < 0 ? 0 : lim;
}

void Finger::configure(const Params& p) {
    const pid::Coeffs old = params_.pid;
    const bool encoder_changed = p.zero_turn != params_.zero_turn ||
                                 p.encoder_invert != params_.encoder_invert;
    params_ = p;
    if (encoder_changed) have_theta_ = false;  // the next reading is not a jump
    pid_.rebase(old, params_.pid, limit_for(mode_));
}

void Finger::enter_closed_loop(uint8_t mode) {
    if (!target_valid_) {
        target_ = fx::clamp(theta_, params_.theta_min, params_.theta_max);
        target_valid_ = true;
    }
    // Bumpless: the PID starts from the output the motors have now.
    const int32_t present = (mode_ == COAST || mode_ == BRAKE) ? 0 : pid_.output();
    pid_.reset(params_.pid, limit_for(mode), present, theta_);
    stall_count_ = 0;
    stall_ref_ = theta_;
    contact_ = false;
}

void Finger::set_mode(uint8_t mode, int32_t duty16, int32_t effort16) {
    duty_cmd16_ = duty16;
    effort16_ = effort16;
    if (mode == mode_) return;  // a resent frame changes nothing; new duty/effort apply
    if (mode == POSITION || mode == GRASP) {
        enter_closed_loop(mode);
    } else if (mode == DUTY) {
        const int32_t present = (mode_ == COAST || mode_ == BRAKE) ? 0 : pid_.output();
        pid_.reset(params_.pid, limit_for(DUTY), present, theta_);
        stall_count_ = 0;
        stall_ref_ = theta_;
    } else {
        target_valid_ = false;
        pid_.reset(params_.pid, limit_for(mode), 0, theta_);
    }
    contact_ = false;
    mode_ = mode;
}

void Finger::set_target(int32_t theta_au) {
    target_ = theta_au;
    target_valid_ = true;
}

void Finger::clear_faults() {
    faults_ = 0;
    new_faults_ = 0;
    have_theta_ = false;  // no jump check against a reading from before the fault
    stall_count_ = 0;
}

void Finger::latch(uint8_t bits) {
    const uint8_t fresh = bits & (uint8_t)~faults_;
    faults_ |= bits;
    new_faults_ |= fresh;
    if (bits & kStopFaults) {
        if (mode_ != COAST) {
            mode_ = COAST;
            target_valid_ = false;
            contact_ = false;
            pid_.reset(params_.pid, limit_for(COAST), 0, theta_);
        }
    }
}

void Finger::hold_here() {
    const uint8_t mode = mode_ == GRASP ? GRASP : POSITION;
    target_ = fx::clamp(theta_, params_.theta_min, params_.theta_max);
    target_valid_ = true;
    const int32_t present = pid_.output();
    pid_.reset(params_.pid, limit_for(mode), present, theta_);
    stall_count_ = 0;
    stall_ref_ = theta_;
    mode_ = mode;
}

hal::MotorOut Finger::drive(int32_t duty16) const {
    hal::MotorOut m;
    bool forward = duty16 > 0;
    uint32_t mag = (uint32_t)(duty16 < 0 ? -duty16 : duty16);
    if (mag > (uint32_t)fx::kOne16) mag = fx::kOne16;
    // Q16 duty to PWM counts, rounded: at most 65536 * 800, within uint32.
    m.on_counts = (uint16_t)((mag * hal::kPwmPeriod + 32768u) >> 16);
    if (m.on_counts == 0) {
        m.drive = hal::Drive::COAST;  // zero duty: really off
    } else {
        if (params_.motor_invert) forward = !forward;
        m.drive = forward ? hal::Drive::FORWARD : hal::Drive::REVERSE;
    }
    return m;
}

void Finger::tick(const hal::EncoderReading& enc, hal::MotorOut& a, hal::MotorOut& b,
                  bool& stby) {
    // ---- encoder: band and plausibility ----
    encoder_ok_ = enc.status == hal::EncoderStatus::OK;
    if (!encoder_ok_) {
        latch(ENCODER_RANGE);
    } else {
        last_turn_ = enc.turn;
        const int32_t th = encoder::angle_au(enc.turn, params_.zero_turn, params_.encoder_invert);
        if (have_theta_ && fx::abs32(th - theta_) > params_.jump) latch(ENCODER_JUMP);
        theta_ = th;
        have_theta_ = true;
        // ---- joint limits ----
        if (th < params_.theta_min - params_.margin || th > params_.theta_max + params_.margin) {
            latch(JOINT_LIMIT);
        }
    }

    // ---- the mode ----
    int32_t u = 0;
    switch (mode_) {
        case POSITION:
        case GRASP:
            u = pid_.step(params_.pid, limit_for(mode_), target_, theta_);
            break;
        case DUTY: {
            int32_t d = duty_cmd16_;
            // Never drive further past a joint limit.
            if ((theta_ >= params_.theta_max && d > 0) || (theta_ <= params_.theta_min && d < 0)) {
                d = 0;
            }
            u = pid_.step_open(params_.pid, limit_for(DUTY), d, theta_);
            break;
        }
        default:
            break;
    }

    // ---- stall: large error (or a commanded duty), output at its limit, no motion ----
    bool pushing = false;
    if (mode_ == POSITION || mode_ == GRASP) {
        const int32_t lim = limit_for(mode_);
        pushing = fx::abs32(target_ - theta_) > params_.stall_error && fx::abs32(u) >= lim &&
                  lim > 0;
    } else if (mode_ == DUTY) {
        pushing = u != 0 && fx::abs32(u) >= params_.pid.deadband;
    }
    if (pushing) {
        if (fx::abs32(theta_ - stall_ref_) > params_.stall_motion) {
            stall_ref_ = theta_;
            stall_count_ = 0;
        } else if (stall_count_ < params_.stall_ticks) {
            ++stall_count_;
        }
        if (stall_count_ >= params_.stall_ticks) {
            if (mode_ == GRASP) {
                contact_ = true;  // closed on an object: hold it with the effort limit
            } else {
                latch(STALL);
                u = 0;
            }
        }
    } else {
        stall_ref_ = theta_;
        stall_count_ = 0;
        if (mode_ == GRASP && fx::abs32(target_ - theta_) <= params_.stall_error) contact_ = false;
    }

    // ---- driver channels ----
    if (mode_ == POSITION || mode_ == GRASP || mode_ == DUTY) {
        if (params_.rotary) {
            duty_a16_ = u;
            duty_b16_ = 0;
        } else {
            duty_a16_ = params_.pretension16 + (u > 0 ? u : 0);
            duty_b16_ = params_.pretension16 + (u < 0 ? -u : 0);
        }
        a = drive(duty_a16_);
        b = drive(duty_b16_);
        if (params_.rotary) b.drive = hal::Drive::COAST;
    } else {
        duty_a16_ = 0;
        duty_b16_ = 0;
        a.on_counts = 0;
        b.on_counts = 0;
        a.drive = mode_ == BRAKE ? hal::Drive::BRAKE : hal::Drive::COAST;
        b.drive = (mode_ == BRAKE && !params_.rotary) ? hal::Drive::BRAKE : hal::Drive::COAST;
    }
    stby = mode_ != COAST && (faults_ & kStopFaults) == 0;
}

}  // namespace finger
}  // namespace utrf
