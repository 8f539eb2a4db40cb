// Coupled-kinematics lookup over the generated PROGMEM table (generated/kinematics_table.h).
//
// The routing couples the joints (theta_i = q / R_i), so the Joint-2 angle alone fixes the
// finger: the table maps it to q, theta1, theta3 and the tip (x, y). Lookups clamp to the
// table's range and interpolate linearly between rows.
#ifndef UTRF_CORE_KINEMATICS_H
#define UTRF_CORE_KINEMATICS_H

#include <stdint.h>

namespace utrf {
namespace kin {

struct Point {  // SI: m and rad
    float q;
    float theta1;
    float theta2;
    float theta3;
    float tip_x;
    float tip_y;
};

// Call once at start: derives the integer lookup constants.
void init();

uint8_t finger_geometry(uint8_t finger);
uint8_t geometry_count();
uint16_t table_bytes();

// The Joint-2 range the table covers (from theta1 in its range), rad.
float theta2_min(uint8_t geometry);
float theta2_max(uint8_t geometry);

// Float lookup (loop context and tests). Returns false when theta2 was clamped.
bool lookup(uint8_t geometry, float theta2, Point& out);

// Inverse: the Joint-2 angle at tendon displacement q (m). False when q is off the table.
bool theta2_from_q(uint8_t geometry, float q, float& theta2);
// q at theta1's upper limit: normalised flexion 1.
float q_full_flexion(uint8_t geometry);

// Integer lookup for telemetry: tip (x, y) in 1e-5 m from the angle in 1e-4 rad. No floats,
// no division: a few hundred cycles, cheap enough for a 500 Hz stream of five fingers.
void tip_raw(uint8_t geometry, int32_t theta2_au, int16_t& x, int16_t& y);

}  // namespace kin
}  // namespace utrf

#endif  // UTRF_CORE_KINEMATICS_H
