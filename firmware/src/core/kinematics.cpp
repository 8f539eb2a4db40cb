#include "kinematics.h"

#include <math.h>

#include "../generated/kinematics_table.h"  // included here only: one copy of the tables
#include "fixed.h"

namespace utrf {
namespace kin {

using namespace kin_table;

static_assert(sizeof(kFingerGeometry) == 5, "the table must map all five fingers");

namespace {
struct IntGeometry {
    int32_t min_au;        // angle of row 0
    uint32_t inv_step_q24;  // rows per AU, Q24
    uint32_t span_au;      // angle span of the table
};
IntGeometry g_int[kGeometryCount];

int16_t cell(uint8_t g, uint16_t row, uint8_t col) {
    return utrf_pgm_read_i16(&kGeometries[g].rows[row][col]);
}

float scale_of(uint8_t col) {
    return col == kQ ? kQScale : (col == kTipX || col == kTipY) ? kTipScale : kAngleScale;
}
}  // namespace

void init() {
    for (uint8_t g = 0; g < kGeometryCount; ++g) {
        const Geometry& geo = kGeometries[g];
        g_int[g].min_au = fx::round_sat(geo.theta2_min * fx::kAuPerRad);
        g_int[g].inv_step_q24 =
            (uint32_t)fx::round_sat(16777216.0f / (geo.theta2_step * fx::kAuPerRad));
        g_int[g].span_au =
            (uint32_t)fx::round_sat(geo.theta2_step * (float)(geo.count - 1) * fx::kAuPerRad);
    }
}

uint8_t finger_geometry(uint8_t finger) { return kFingerGeometry[finger]; }
uint8_t geometry_count() { return kGeometryCount; }
uint16_t table_bytes() { return kTableBytes; }

float theta2_min(uint8_t g) { return kGeometries[g].theta2_min; }
float theta2_max(uint8_t g) {
    return kGeometries[g].theta2_min + kGeometries[g].theta2_step * (float)(kGeometries[g].count - 1);
}

bool lookup(uint8_t g, float theta2, Point& out) {
    const Geometry& geo = kGeometries[g];
    float x = (theta2 - geo.theta2_min) / geo.theta2_step;
    const float last = (float)(geo.count - 1);
    bool inside = true;
    if (!(x >= 0.0f)) {  // NaN clamps low too
        x = 0.0f;
        inside = false;
    } else if (x > last) {
        x = last;
        inside = false;
    }
    uint16_t i = (uint16_t)x;
    if (i > geo.count - 2) i = (uint16_t)(geo.count - 2);
    const float frac = x - (float)i;
    float v[kColumns];
    for (uint8_t c = 0; c < kColumns; ++c) {
        const float lo = cell(g, i, c);
        const float hi = cell(g, (uint16_t)(i + 1), c);
        v[c] = (lo + (hi - lo) * frac) * scale_of(c);
    }
    out.q = v[kQ];
    out.theta1 = v[kTheta1];
    out.theta2 = geo.theta2_min + x * geo.theta2_step;
    out.theta3 = v[kTheta3];
    out.tip_x = v[kTipX];
    out.tip_y = v[kTipY];
    return inside;
}

bool theta2_from_q(uint8_t g, float q, float& theta2) {
    const Geometry& geo = kGeometries[g];
    const float raw = q / kQScale;
    const uint16_t n = geo.count;
    if (!(raw >= (float)cell(g, 0, kQ)) || !(raw <= (float)cell(g, (uint16_t)(n - 1), kQ))) {
        return false;
    }
    // q grows with theta2: binary search for the last row whose q is <= raw.
    uint16_t lo = 0;
    uint16_t hi = (uint16_t)(n - 1);
    while (hi - lo > 1) {
        const uint16_t mid = (uint16_t)((lo + hi) / 2);
        if ((float)cell(g, mid, kQ) <= raw) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    const float q0 = cell(g, lo, kQ);
    const float q1 = cell(g, hi, kQ);
    const float frac = q1 > q0 ? (raw - q0) / (q1 - q0) : 0.0f;
    theta2 = geo.theta2_min + ((float)lo + frac) * geo.theta2_step;
    return true;
}

float q_full_flexion(uint8_t g) {
    return (float)cell(g, (uint16_t)(kGeometries[g].count - 1), kQ) * kQScale;
}

void tip_raw(uint8_t g, int32_t theta2_au, int16_t& x, int16_t& y) {
    const IntGeometry& ig = g_int[g];
    int32_t d = theta2_au - ig.min_au;
    uint32_t ud = d < 0 ? 0u : (uint32_t)d;
    if (ud > ig.span_au) ud = ig.span_au;
    const uint32_t pos = ud * ig.inv_step_q24;  // Q24 rows; span 4e4 AU * 6.2e4 < 2^32
    uint16_t i = (uint16_t)(pos >> 24);
    uint16_t frac = (uint16_t)(pos >> 8);
    const uint16_t n = kGeometries[g].count;
    if (i > n - 2) {
        i = (uint16_t)(n - 2);
        frac = 0xFFFF;
    }
    const int32_t x0 = cell(g, i, kTipX);
    const int32_t y0 = cell(g, i, kTipY);
    x = (int16_t)(x0 + fx::mul_q16(cell(g, (uint16_t)(i + 1), kTipX) - x0, frac));
    y = (int16_t)(y0 + fx::mul_q16(cell(g, (uint16_t)(i + 1), kTipY) - y0, frac));
}

}  // namespace kin
}  // namespace utrf
