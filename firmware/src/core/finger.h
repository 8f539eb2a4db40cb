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
// Faults that turn the finger's motors off. HOST_TIMEOUT instead applies the configured safe
// action (which may be to hold in closed loop).
static const uint8_t kStopFaults = ENCODER_RANGE | ENCODER_JUMP | STALL | JOINT_LIMIT | OVERRUN;

// A finger's configuration, ready for the tick (built in loop() context by compile()).
struct Params {
    pid::Coeffs pid;
    int32_t max16;         // motor duty limit, Q16
    int32_t pretension16;  // antagonistic pretension, Q16
    int32_t theta_min;     // AU
    int32_t theta_max;     // AU
    int32_t margin;        // AU
    int32_t stall_error;   // AU
    int32_t stall_motion;  // AU
    uint16_t stall_ticks;
    int32_t jump;          // AU per tick
    uint16_t zero_turn;    // encoder reading at angle 0
    bool encoder_invert;
    bool motor_invert;
    bool rotary;
    // The controller's output limit: max_duty, less the pretension when antagonistic.
    int32_t limit16() const { return rotary ? max16 : max16 - pretension16; }
};

Params compile(const config::Finger& cfg, float dt_s);

class Finger {
   public:
    Finger();

    // ---- from loop(), under the tick lock, after validation ----
    void configure(const Params& p);  // bumpless when gains or limits change
    // Enter `mode`. duty16 (DUTY) and effort16 (GRASP) are Q16 fractions.
    void set_mode(uint8_t mode, int32_t duty16, int32_t effort16);
    void set_target(int32_t theta_au);
    void clear_faults();
    void set_zero_turn(uint16_t turn) { params_.zero_turn = turn; have_theta_ = false; }

    // ---- from the tick ----
    // Latch faults (the host-silence and overrun rules live at the hand level).
    void latch(uint8_t bits);
    // Safe action HOLD: hold the measured angle in closed loop, starting from the present output.
    void hold_here();
    // One control period: read the encoder, check the safety rules, run the mode, and fill
    // the driver commands. stby is the state for the finger's STBY pin.
    void tick(const hal::EncoderReading& enc, hal::MotorOut& a, hal::MotorOut& b, bool& stby);

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
    int32_t theta() const { return theta_; }      // measured, AU
    int32_t target() const { return target_; }    // AU
    int32_t duty_a() const { return duty_a16_; }  // Q16, signed, positive pulls
    int32_t duty_b() const { return duty_b16_; }
    int32_t output() const { return pid_.output(); }  // the controller's u, Q16
    bool contact() const { return contact_; }
    uint16_t last_turn() const { return last_turn_; }
    bool encoder_ok() const { return encoder_ok_; }
    const Params& params() const { return params_; }
    const pid::Pid& pid() const { return pid_; }

   private:
    int32_t limit_for(uint8_t mode) const;
    void enter_closed_loop(uint8_t mode);
    hal::MotorOut drive(int32_t duty16) const;

    Params params_;
    pid::Pid pid_;
    uint8_t mode_;
    uint8_t faults_;
    uint8_t new_faults_;
    bool have_theta_;
    bool target_valid_;  // a target was set since the finger last left closed loop
    bool contact_;       // GRASP: closed on something and holding
    bool encoder_ok_;
    uint16_t last_turn_;
    int32_t theta_;
    int32_t target_;
    int32_t duty_cmd16_;
    int32_t effort16_;
    int32_t duty_a16_;
    int32_t duty_b16_;
    int32_t stall_ref_;
    uint16_t stall_count_;
};

}  // namespace finger
}  // namespace utrf

#endif  // UTRF_CORE_FINGER_H
