// The velocity obstacles of one decision: the VO cones of moving neighbours (eqs 1-6, with the
// virtual sphere of section 3.1.6), the VO pyramids of static obstacles (section 4), the
// avoidance planes (eq. 8), the exact 3D membership that judges every answer, and build_vos,
// which turns a decision's inputs into its VOs.
//
// Arithmetic note: every expression keeps the operation order of the formulas as first written
// in numpy (x*x for a square, left to right sums, std::max/std::min as Python's max/min: the
// first argument unless the second is strictly greater/less), and the module is compiled
// without contraction into fused multiply-adds, so answers are the same to the last bit.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

namespace vo3d {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.141592653589793;
//: ``horizon`` meaning "none".
constexpr double NO_HORIZON = -1.0;
//: A VOs' ``obstacle_horizon`` meaning "the horizon the caller gives" (VOs built outside a
//: decision, e.g. from Python's arrays).
constexpr double SAME_HORIZON = -2.0;
//: The paper's smallest virtual-sphere factor (section 3.1.6: tau >= 1.5).
constexpr double TAU_MIN = 1.5;
//: ``reach`` of build_cones: no virtual sphere (NaN: the paper's rule; >= 0: a speed).
constexpr double NO_VIRTUAL_SPHERE = -1.0;
//: With pz_buffer, the planning sphere grows by at most this share of the gap left.
constexpr double BUFFER_GAP_SHARE = 0.9;
//: Inside the inner half of a cooperative neighbour's buffer, the apex moves away from it by
//: this share of v_max at the zone's edge, in proportion to the depth into that half.
constexpr double BUFFER_OPENING = 0.5;
//: A prism reaching the ceiling is planned this much (m) above the vehicle and the ceiling.
constexpr double OVER_THE_CEILING = 1e3;

inline double sq(double x) { return x * x; }

// ------------------------------------------------------------------------------ inputs

// A read-only 2D array of doubles as numpy hands it over (strides in elements).
struct Rows {
    const double* data = nullptr;
    int64_t n = 0, m = 0, s0 = 0, s1 = 1;
    double operator()(int64_t i, int64_t j) const { return data[i * s0 + j * s1]; }
    static Rows of(const std::vector<double>& v, int64_t m) {
        return Rows{v.data(), int64_t(v.size()) / m, m, m, 1};
    }
};

// The limits of one decision.
struct Bounds {
    double v_min, v_max, z_min, z_max;
    double acceleration;  // m/s^2 per axis; NaN for none
    double dt;
};

// Which of the six corrections of section 3.1 apply (all by default).
struct Corrections {
    bool tg_range = true, symmetry_abs = true, triangle = true;
    bool base_chord = true, vo_lines = true, virtual_sphere = true;
};

// The formulation options as the core reads them (Options.config).
struct Config {
    bool reciprocal = false;
    double horizon = NO_HORIZON;  // s; NO_HORIZON for none
    // s, the obstacles' own (RVO2-3D's timeHorizonObst): a pyramid's VO reaches this far;
    // NO_HORIZON for none. A vehicle that ignores a neighbour's late meeting can still turn
    // when the neighbour does; a prism does not turn, and a late turn under lag sinks into it.
    double obstacle_horizon = NO_HORIZON;
    double pz_buffer = 0.0;       // m
    double margin = 1e-3;         // m/s
    Corrections corrections;
    std::vector<double> phi, cos_phi, sin_phi;  // the avoidance planes' angles (eq. 8)
    std::vector<double> t, cos_t, sin_t;        // the generator angles rows linearise at (eq. 12)
    int64_t speed_levels = 9;                   // the sampled grid: speeds v_min..v_max ...
    double heading_step = 0.0;                  // ... every this many rad on each plane
    int64_t fallback_speed_levels = 9;          // the fallbacks' grid, likewise (grid_of)
    double fallback_heading_step = 0.0;
    bool closing_guard = false, least_bad_escape = true, fine_fallback = true;
    // The same options on at least the default planes and tangent samples (fine_planes), for a
    // decision with something that does not avoid; null: these planes everywhere.
    std::shared_ptr<const Config> fine;
    int64_t planes() const { return int64_t(phi.size()); }
    int64_t samples() const { return int64_t(t.size()); }
};

// ------------------------------------------------------------------------------ VO cones

// One VO cone seen from A; velocities in m/s, d_vo drawn to scale in velocity space.
struct Cone {
    double rel[3];   // p_B - p_A
    double apex[3];  // A_vo = V_B (eq. 3), or (V_A + V_B)/2 when reciprocal
    double r_pz;
    double d_oi, theta_el, psi_az;  // eq. (1)
    double R[3][3];                 // eq. (6); column 0 is the cone axis
    double d_vo, r_vo;              // eq. (2), times tau
    double tau;                     // the virtual-sphere factor (3.1.6); 1 when not expanded
    double sin_alpha;               // r_pz / d_oi (1 inside the zone)
    bool inside;                    // A is inside B's protected zone (d_oi <= r_pz)
};

// p_B - p_A into rel, and its length d_oi (eq. 1).
inline double offset(const double* p_B, const double* p_A, double* rel) {
    for (int k = 0; k < 3; ++k) rel[k] = p_B[k] - p_A[k];
    return std::sqrt(sq(rel[0]) + sq(rel[1]) + sq(rel[2]));
}

// Eqs (1), (2), (6) and the virtual-sphere factor for one neighbour. ``reach``: the largest own
// speed; NaN for the paper's rule (tau_min within 2 r_pz), NO_VIRTUAL_SPHERE for none.
inline Cone build_cone(const double* p_A, const double* p_B, const double* apex, double r_pz,
                       double reach, double tau_min) {
    Cone c;
    double d = offset(p_B, p_A, c.rel);  // eq. (1)
    double safe_d = std::max(d, 1e-12);
    double th = std::asin(std::min(std::max(c.rel[2] / safe_d, -1.0), 1.0));  // atan(dz / dxy)
    double ps = std::atan2(c.rel[1], c.rel[0]);
    double ct = std::cos(th), st = std::sin(th), cp = std::cos(ps), sp = std::sin(ps);
    // eq. (6): columns are the axis, the horizontal side and the 'up' side
    c.R[0][0] = cp * ct, c.R[0][1] = -sp, c.R[0][2] = -cp * st;
    c.R[1][0] = sp * ct, c.R[1][1] = cp, c.R[1][2] = -sp * st;
    c.R[2][0] = st, c.R[2][1] = 0.0, c.R[2][2] = ct;
    // eq. (2): the tangent circle of the cone on the sphere, at distance d_vo along the axis
    double dd = std::max(d * d - sq(r_pz), 0.0);
    double dv = dd / safe_d, rv = r_pz * std::sqrt(dd) / safe_d;
    double t = 1.0;
    if (d > r_pz) {  // never expanded when A is inside the zone
        if (std::isnan(reach)) {
            t = d < 2.0 * r_pz ? tau_min : 1.0;
        } else if (reach >= 0.0) {
            // The base must lie beyond every |v| <= reach: axial(v - apex) <= reach + |apex|.
            double a_len = std::sqrt(sq(apex[0]) + sq(apex[1]) + sq(apex[2]));
            double needed = (reach + a_len) / std::max(dv, 1e-12);
            t = needed > 1.0 ? std::max(tau_min, needed * 1.01) : 1.0;
        }
    }
    for (int k = 0; k < 3; ++k) c.apex[k] = apex[k];
    c.r_pz = r_pz, c.d_oi = d, c.theta_el = th, c.psi_az = ps;
    c.d_vo = dv * t, c.r_vo = rv * t, c.tau = t;
    c.sin_alpha = std::min(std::max(r_pz / safe_d, 0.0), 1.0);
    c.inside = d <= r_pz;
    return c;
}

// The cone's unit outward normal along the generator through B_vo(t): R (eq. 6) applied to
// (-sin alpha, cos alpha cos t, cos alpha sin t). The plane through the apex with this normal
// touches the cone along the whole generator: a supporting plane of the (convex) VO.
inline void outward_normal(const double (&R)[3][3], double sin_alpha, double cos_t, double sin_t,
                           double* N) {
    double ca = std::sqrt(1.0 - sin_alpha * sin_alpha);
    double b0 = -sin_alpha, b1 = ca * cos_t, b2 = ca * sin_t;
    for (int r = 0; r < 3; ++r) N[r] = R[r][0] * b0 + R[r][1] * b1 + R[r][2] * b2;
}

// The smallest |v| inside the cone: the distance from the velocity origin to the (infinite)
// cone; 0 when A is inside the zone or the origin is in the cone.
inline double min_speed(const Cone& c) {
    if (c.inside) return 0.0;
    const double* a = c.apex;
    double L = std::sqrt(sq(a[0]) + sq(a[1]) + sq(a[2]));
    double cos_b = -(a[0] * c.R[0][0] + a[1] * c.R[1][0] + a[2] * c.R[2][0]) / std::max(L, 1e-12);
    double beta = std::acos(std::min(std::max(cos_b, -1.0), 1.0));
    double alpha = std::asin(c.sin_alpha);
    if (beta <= alpha) return 0.0;               // the origin is in the cone
    if (beta >= alpha + kPi / 2) return L;       // the apex is the nearest point
    return L * std::sin(beta - alpha);
}

// ------------------------------------------------------------------------------ VO pyramids

// One VO pyramid (section 4): the protected prism C_pz turned square to A's line of sight.
// ``frame`` rows: h (horizontal, towards the obstacle), s (horizontal, left), z (up); the prism
// is [lo, hi] in frame coordinates relative to p_A.
struct Pyramid {
    double frame[3][3];
    double lo[3], hi[3];
    double L_pz, h_pz;
    bool inside;     // A is already inside C_pz
    bool over_roof;  // ... and over the obstacle's roof: within its rim, at or above its height
};

// A prism row: x, y, L_pz, h_pz and, when known (6 columns), the obstacle's height and rim (the
// largest distance from its axis to its footprint's edge: a cylinder's radius, half a box's
// diagonal).
constexpr int64_t PRISM_ROW = 4, PRISM_ROOF_ROW = 6;

//: How far C_pz reaches below the ground (m). An obstacle stands on the ground: a velocity
//: whose ray would pass under it, below the floor, does not pass it (the vehicle levels off at
//: the floor and flies into it). Only a ray falling more than (D + z_A) / (dist - L/2) metres
//: per metre it closes in (over 500 at 20 m) still passes under (formulations/geometry.md).
constexpr double UNDERGROUND = 1e4;

// Section 4.1 for a prism (x, y, L_pz, h_pz); ``roof`` and ``rim`` the obstacle's height and rim
// (inf and 0 when unknown: never over the roof).
inline Pyramid build_pyramid(const double* p_A, double x, double y, double L, double H,
                             double roof = kInf, double rim = 0.0) {
    Pyramid py{};
    double dx = x - p_A[0], dy = y - p_A[1];
    double dist = std::sqrt(dx * dx + dy * dy);
    double hx = 1.0, hy = 0.0;
    if (dist > 1e-9) hx = dx / dist, hy = dy / dist;
    py.frame[0][0] = hx, py.frame[0][1] = hy;   // h: horizontal, towards the obstacle
    py.frame[1][0] = -hy, py.frame[1][1] = hx;  // s: horizontal, left
    py.frame[2][2] = 1.0;                       // z: up
    py.lo[0] = dist - L / 2, py.lo[1] = -L / 2, py.lo[2] = -p_A[2] - UNDERGROUND;
    py.hi[0] = dist + L / 2, py.hi[1] = L / 2, py.hi[2] = H - p_A[2];
    py.L_pz = L, py.h_pz = H;
    // Turned to face A, the square contains A exactly when A is within its apothem L/2.
    py.inside = dist < L / 2 && p_A[2] < H;
    py.over_roof = py.inside && dist < rim && p_A[2] >= roof;
    return py;
}

// Row j of ``prisms`` (4 or 6 columns) as a pyramid seen from p_A, its top at H (m).
inline Pyramid pyramid_of_row(const double* p_A, const Rows& prisms, int64_t j, double H) {
    bool roofed = prisms.m >= PRISM_ROOF_ROW;
    return build_pyramid(p_A, prisms(j, 0), prisms(j, 1), prisms(j, 2), H,
                         roofed ? prisms(j, 4) : kInf, roofed ? prisms(j, 5) : 0.0);
}

// Inside C_pz, the rates (m/s) at which v goes deeper from its side (towards the centre
// horizontally, h . v) and from its top (down, -v_z; -inf unless A is under the top: the top
// nearer than the side, H - z_A < L/2 - dist, or A over the obstacle's roof, where a descent
// meets the roof whichever margin is nearer): a vehicle under the top must not sink, its way
// out is up or back. The side counts under the top too: the turned square reaches beyond a
// box's walls and the rim's circle beyond its sides, so a vehicle under the top may still be
// beside the obstacle, and going towards the centre closes in everywhere.
struct PrismRates {
    double side, top;
};

inline bool under_top(const Pyramid& py) { return py.hi[2] < -py.lo[0] || py.over_roof; }

inline PrismRates prism_rates(const Pyramid& py, const double* v) {
    const double* h = py.frame[0];
    double side = h[0] * v[0] + h[1] * v[1] + h[2] * v[2];
    return {side, under_top(py) ? -v[2] : -kInf};
}

// Inside C_pz, the rate (m/s) at which v closes in: the faster of prism_rates (negative:
// escaping, as fast as the slower of the two ways out).
inline double pyramid_closing(const Pyramid& py, const double* v) {
    PrismRates r = prism_rates(py, v);
    return std::max(r.side, r.top);
}

// ------------------------------------------------------------------------------ the VOs

// The VO cones and pyramids of one decision (cones first wherever they are numbered together)
// and the preferred velocity clamped to v_max.
struct VOs {
    std::vector<Cone> cones;
    std::vector<Pyramid> pyramids;
    double v_pref[3];
    double obstacle_horizon = SAME_HORIZON;  // the pyramids' horizon (Config::obstacle_horizon)
    int64_t n() const { return int64_t(cones.size()); }
    int64_t count() const { return int64_t(cones.size() + pyramids.size()); }
};

// ------------------------------------------------------------------------------ planes (eq. 8)

struct Mat3 {
    double m[3][3];
};

// P avoidance planes through the velocity origin sharing the axis e1 (the preferred
// direction). to_plane[p] rows: e1, e2(phi) = cos phi e_y0 + sin phi e_z0, the normal n(phi).
struct Planes {
    std::vector<double> phi;  // rad
    double frame[3][3];       // rows e_x, e_y0, e_z0
    std::vector<Mat3> to_plane;
    int64_t count() const { return int64_t(phi.size()); }
};

// Rows e_x (unit direction), e_y0 (horizontal, left of e_x), e_z0 = e_x x e_y0 (up).
inline void avoidance_frame(const double* direction, double (&out)[3][3]) {
    double x = direction[0], y = direction[1], z = direction[2];
    double norm = std::sqrt(x * x + y * y + z * z);
    if (norm > 1e-12) {
        x = x / norm, y = y / norm, z = z / norm;
    } else {
        x = 1.0, y = 0.0, z = 0.0;
    }
    double hy = std::sqrt(x * x + y * y);  // e_y0 = z_world x e_x, normalised
    double ly = 0.0, my = 1.0;             // vertical e_x: any side works
    if (hy >= 1e-9) ly = -y / hy, my = x / hy;
    out[0][0] = x, out[0][1] = y, out[0][2] = z;
    out[1][0] = ly, out[1][1] = my, out[1][2] = 0.0;
    out[2][0] = -z * my, out[2][1] = z * ly, out[2][2] = x * my - y * ly;
}

// The planes P_phi about ``direction``: eq. (8), R_{P_phi} @ frame; it only mixes e_y0, e_z0.
inline Planes build_planes(const double* direction, const std::vector<double>& phi,
                           const std::vector<double>& cos_phi, const std::vector<double>& sin_phi) {
    Planes pl;
    pl.phi = phi;
    avoidance_frame(direction, pl.frame);
    pl.to_plane.resize(phi.size());
    for (size_t p = 0; p < phi.size(); ++p) {
        double c = cos_phi[p], s = sin_phi[p];
        auto& T = pl.to_plane[p].m;
        for (int k = 0; k < 3; ++k) {
            T[0][k] = pl.frame[0][k];
            T[1][k] = c * pl.frame[1][k] + s * pl.frame[2][k];
            T[2][k] = c * pl.frame[2][k] - s * pl.frame[1][k];
        }
    }
    return pl;
}

// Plane coordinates w on plane p to the world velocity out.
inline void lift(const Planes& planes, const double* w, int64_t p, double* out) {
    const auto& T = planes.to_plane[p].m;
    for (int c = 0; c < 3; ++c) out[c] = w[0] * T[0][c] + w[1] * T[1][c];
}

// ------------------------------------------------------------------------------ membership

// Velocity v against a cone of apex a, B at rel from A, u = v - a the relative velocity.
struct Approach {
    double closest;  // the closest distance to B's centre over t in [0, horizon]
    double t;        // its time t*
    double pu;       // the closing rate rel.u
};

// The closing rate rel.u alone, as approach() computes it.
inline double closing_speed(const double* a, const double* rel, const double* v) {
    double u0 = v[0] - a[0], u1 = v[1] - a[1], u2 = v[2] - a[2];
    return rel[0] * u0 + rel[1] * u1 + rel[2] * u2;
}

inline Approach approach(const double* a, const double* rel, const double* v, double horizon) {
    double u0 = v[0] - a[0], u1 = v[1] - a[1], u2 = v[2] - a[2];
    double uu = u0 * u0 + u1 * u1 + u2 * u2;
    double pu = rel[0] * u0 + rel[1] * u1 + rel[2] * u2;
    double t = uu > 0 ? std::max(pu, 0.0) / std::max(uu, 1e-300) : 0.0;
    if (horizon >= 0.0) t = std::min(t, horizon);
    double d0 = rel[0] - u0 * t, d1 = rel[1] - u1 * t, d2 = rel[2] - u2 * t;
    return {std::sqrt(d0 * d0 + d1 * d1 + d2 * d2), t, pu};
}

// Whether v passes within r_pz + tol of B at a positive time (A outside the zone).
inline bool heads_into(const double* a, const double* rel, double r_pz, const double* v,
                       double horizon, double tol) {
    Approach ap = approach(a, rel, v, horizon);
    return ap.closest < r_pz + tol && ap.t > 0.0;
}

// Whether v lies in the VO cone (inside the zone: whether it still closes in). ``tol`` (m)
// widens (> 0) or shrinks (< 0) the protected sphere.
inline bool in_cone(const Cone& c, const double* v, double horizon, double tol) {
    if (c.inside) return closing_speed(c.apex, c.rel, v) > 0.0;
    return heads_into(c.apex, c.rel, c.r_pz, v, horizon, tol);
}

// Slab test: when the ray p_A + v t enters the prism; inf if never.
inline double entry_time(const Pyramid& py, const double* v) {
    double t_enter = -kInf, t_exit = kInf;
    for (int a = 0; a < 3; ++a) {
        const double* f = py.frame[a];
        double w = f[0] * v[0] + f[1] * v[1] + f[2] * v[2];
        if (w != w) return kInf;  // NaN: no ray to speak of, it enters nothing
        if (w == 0.0) {           // inside the slab forever or never
            if (!(py.lo[a] <= 0.0 && 0.0 <= py.hi[a])) return kInf;
        } else {
            double t1 = py.lo[a] / w, t2 = py.hi[a] / w;
            t_enter = std::max(t_enter, std::min(t1, t2));
            t_exit = std::min(t_exit, std::max(t1, t2));
        }
    }
    double t0 = std::max(t_enter, 0.0);
    return t_exit > t0 ? t0 : kInf;
}

// Whether v lies in the VO pyramid (inside C_pz: whether it closes in, pyramid_closing).
inline bool in_pyramid(const Pyramid& py, const double* v, double horizon) {
    if (py.inside) return pyramid_closing(py, v) > 0.0;
    double t = entry_time(py, v);
    return horizon < 0.0 ? t < kInf : t <= horizon;
}

// The horizon the pyramids of vos plan with, given the cones' ``horizon``.
inline double pyramid_horizon(const VOs& vos, double horizon) {
    return vos.obstacle_horizon == SAME_HORIZON ? horizon : vos.obstacle_horizon;
}

// Which VOs (cones first) contain v, by the exact 3D membership, into out; whether any.
inline bool containing(const VOs& vos, const double* v, double horizon, uint8_t* out) {
    bool any = false;
    int64_t n = vos.n();
    double obstacle_horizon = pyramid_horizon(vos, horizon);
    for (int64_t i = 0; i < n; ++i) any |= (out[i] = in_cone(vos.cones[i], v, horizon, 0.0));
    for (size_t j = 0; j < vos.pyramids.size(); ++j)
        any |= (out[n + j] = in_pyramid(vos.pyramids[j], v, obstacle_horizon));
    return any;
}

// Whether every velocity within rho of c lies in the cone without a horizon, with a margin
// that outlasts rounding (in_cone then holds for each as computed). Sufficient, not necessary.
// The ball is seen from the apex under the half-angle beta (sin beta = rho/|u|) and its centre
// at theta from rel: no velocity in it is farther than theta + beta from rel; below 90 degrees
// it closes in, and its closest approach |rel| sin(theta + beta) is below r_pz by 1e-9 (r_pz +
// |rel|), a million times the rounding of approach().
inline bool ball_in_cone(const Cone& cone, const double* c, double rho) {
    if (cone.inside) return false;
    const double *a = cone.apex, *rel = cone.rel;
    double u0 = c[0] - a[0], u1 = c[1] - a[1], u2 = c[2] - a[2];
    double nu = std::sqrt(u0 * u0 + u1 * u1 + u2 * u2);
    double nrel = std::sqrt(sq(rel[0]) + sq(rel[1]) + sq(rel[2]));
    double pu = rel[0] * u0 + rel[1] * u1 + rel[2] * u2;
    if (!(nu > rho && pu > 0.0 && nrel < kInf)) return false;  // NaN fails too
    // |u x rel| for the sine: no cancellation at small angles
    double x0 = u1 * rel[2] - u2 * rel[1], x1 = u2 * rel[0] - u0 * rel[2],
           x2 = u0 * rel[1] - u1 * rel[0];
    double sin_t = std::sqrt(x0 * x0 + x1 * x1 + x2 * x2) / (nu * nrel);
    double cos_t = pu / (nu * nrel);
    double sin_b = rho / nu;
    double cos_b = std::sqrt(1.0 - sin_b * sin_b);
    if (!(cos_t * cos_b - sin_t * sin_b > 1e-6)) return false;  // theta + beta below 90 deg
    double r = cone.r_pz;
    return nrel * (sin_t * cos_b + cos_t * sin_b) <= r - 1e-9 * (r + nrel);
}

// ------------------------------------------------------------------------------ build_vos

// A neighbour as build_vos keeps it before the cones' geometry: p_B, the cone's apex and the
// planning radius (the horizon, the buffer and reciprocity applied).
struct NeighbourRow {
    double p_B[3], apex[3], r_pz;
};

// The preferred velocity clamped to v_max (beyond reach it is aimed at the reachable one).
inline void aimed(const double* v_pref, const Bounds& b, double* pref) {
    double speed = std::sqrt(sq(v_pref[0]) + sq(v_pref[1]) + sq(v_pref[2]));
    for (int k = 0; k < 3; ++k) pref[k] = speed > b.v_max ? v_pref[k] * (b.v_max / speed) : v_pref[k];
}

// Inside the inner half of a cooperative neighbour's buffer (``depth`` m into the buffer, at
// distance d): the apex moves away from B by BUFFER_OPENING * v_max * (depth - pz_buffer / 2) /
// (pz_buffer / 2), so that holding the gap there is inside the cone: holding it lets two
// vehicles fly side by side while noise in the sensed positions ratchets the distance down.
// The moved cone contains the unmoved one, so no velocity it allows enters the real zone. The
// outer half of the buffer still lets a pair hold its gap: two vehicles whose goals lie within
// each other's buffer, but outside its inner half, can both be home. Inside the zone itself
// (depth >= pz_buffer) the cone is an escape cone and the row is left as it is. A vehicle that
// does not decide (hovering at its goal, or not avoiding) gets no push: it will not move aside.
inline void opened(NeighbourRow& row, const double* p_A, double d, double depth, double v_max,
                   double pz_buffer) {
    double half = 0.5 * pz_buffer;
    if (!(depth > half) || !(depth < pz_buffer)) return;  // outer half, or inside the zone
    double s = BUFFER_OPENING * v_max * (depth - half) / half;
    for (int k = 0; k < 3; ++k) row.apex[k] -= s * (row.p_B[k] - p_A[k]) / d;
}

// Each neighbour's row (nbrs: position, velocity, r_pz, cooperative 1/0). With a horizon, zones
// that cannot be reached in time are dropped; reciprocal (RVO): the apex at (V_A + V_B)/2 for
// a cooperative neighbour; pz_buffer: a larger planning sphere, never so large that A is
// 'inside' it while outside the real one (at most 90 % of the gap left), and deep inside a
// cooperative neighbour's buffer an apex moved away from it (opened).
inline std::vector<NeighbourRow> cone_rows(const double* p, const double* v_now, const Rows& nbrs,
                                           const Bounds& b, const Config& cfg) {
    std::vector<NeighbourRow> rows;
    rows.reserve(nbrs.n);
    for (int64_t i = 0; i < nbrs.n; ++i) {
        double d = std::sqrt(sq(nbrs(i, 0) - p[0]) + sq(nbrs(i, 1) - p[1]) + sq(nbrs(i, 2) - p[2]));
        double r_pz = nbrs(i, 6);
        double v_b = std::sqrt(sq(nbrs(i, 3)) + sq(nbrs(i, 4)) + sq(nbrs(i, 5)));
        if (cfg.horizon >= 0.0 && d - r_pz > cfg.horizon * (b.v_max + v_b)) continue;
        bool cooperative = cfg.reciprocal && nbrs(i, 7) > 0.0;
        NeighbourRow row;
        for (int k = 0; k < 3; ++k) {
            row.p_B[k] = nbrs(i, k);
            row.apex[k] = cooperative ? 0.5 * (nbrs(i, 3 + k) + v_now[k]) : nbrs(i, 3 + k);
        }
        row.r_pz = cfg.pz_buffer > 0.0 && d > r_pz
                       ? r_pz + std::min(cfg.pz_buffer, BUFFER_GAP_SHARE * (d - r_pz))
                       : r_pz;
        if (nbrs(i, 7) > 0.0) opened(row, p, d, r_pz + cfg.pz_buffer - d, b.v_max, cfg.pz_buffer);
        rows.push_back(row);
    }
    return rows;
}

// The VO pyramids of the prisms (PRISM_ROW or PRISM_ROOF_ROW columns) within reach (all without
// an obstacle horizon); a prism whose top reaches the ceiling cannot be flown over: planned as
// reaching far above, with no roof to be over.
inline std::vector<Pyramid> pyramids_in_reach(const double* p, const Rows& prisms, const Bounds& b,
                                              const Config& cfg) {
    std::vector<Pyramid> out;
    out.reserve(prisms.n);
    for (int64_t j = 0; j < prisms.n; ++j) {
        double dist = std::sqrt(sq(prisms(j, 0) - p[0]) + sq(prisms(j, 1) - p[1]));
        double reach = cfg.obstacle_horizon;
        if (reach < 0.0 || dist - prisms(j, 2) / std::sqrt(2.0) <= reach * b.v_max) {
            double H = prisms(j, 3);
            if (H < b.z_max) {
                out.push_back(pyramid_of_row(p, prisms, j, H));
            } else {
                H = std::max(H, p[2]) + OVER_THE_CEILING;
                out.push_back(build_pyramid(p, prisms(j, 0), prisms(j, 1), prisms(j, 2), H));
            }
        }
    }
    return out;
}

// The VOs from their parts: the cones of ``rows`` (eqs 1, 2, 6; the virtual sphere sized for
// every speed up to v_max), less those no velocity within v_max reaches (they can neither hold
// an answer nor constrain one).
inline VOs vos_of(const double* p, const double* pref, const std::vector<NeighbourRow>& rows,
                  std::vector<Pyramid> pyramids, const Bounds& b, const Config& cfg) {
    double reach = cfg.corrections.virtual_sphere ? b.v_max : NO_VIRTUAL_SPHERE;
    VOs vos;
    vos.cones.reserve(rows.size());
    for (const auto& r : rows) {
        Cone c = build_cone(p, r.p_B, r.apex, r.r_pz, reach, TAU_MIN);
        if (min_speed(c) <= b.v_max + 1e-6) vos.cones.push_back(c);
    }
    vos.pyramids = std::move(pyramids);
    vos.obstacle_horizon = cfg.obstacle_horizon;
    for (int k = 0; k < 3; ++k) vos.v_pref[k] = pref[k];
    return vos;
}

// Whether A is inside no zone and pref lies in no VO, from the neighbours' rows before the
// cones' geometry: the same numbers as build_cone's d_oi and in_cone's test, so the same answer
// as the exact check on the cones (the cones vos_of leaves out hold no velocity within v_max).
inline bool pref_clear(const double* p, const std::vector<NeighbourRow>& rows,
                       const std::vector<Pyramid>& pyramids, const double* pref, double horizon,
                       double obstacle_horizon) {
    double rel[3];
    for (const auto& r : rows) {
        if (offset(r.p_B, p, rel) <= r.r_pz) return false;  // inside: d_oi <= r_pz
        if (heads_into(r.apex, rel, r.r_pz, pref, horizon, 0.0)) return false;
    }
    for (const auto& py : pyramids)
        if (py.inside || in_pyramid(py, pref, obstacle_horizon)) return false;
    return true;
}

// build_vos: the VOs of one decision (nbrs (n, 8), prisms (m, 4 or 6)).
inline VOs build_vos(const double* p, const double* v_now, const double* v_pref, const Rows& nbrs,
                     const Rows& prisms, const Bounds& b, const Config& cfg) {
    double pref[3];
    aimed(v_pref, b, pref);
    return vos_of(p, pref, cone_rows(p, v_now, nbrs, b, cfg), pyramids_in_reach(p, prisms, b, cfg),
                  b, cfg);
}

// Planes every plane step about the preferred direction (or the current heading, or world x
// when both are zero).
inline Planes decision_planes(const VOs& vos, const double* v_now, const Config& cfg) {
    const double* vp = vos.v_pref;
    bool use_pref = sq(vp[0]) + sq(vp[1]) + sq(vp[2]) >= 1e-18;
    bool use_now = sq(v_now[0]) + sq(v_now[1]) + sq(v_now[2]) > 1e-18;
    double direction[3];
    for (int k = 0; k < 3; ++k)
        direction[k] = use_pref ? vp[k] : (use_now ? v_now[k] : (k == 0 ? 1.0 : 0.0));
    return build_planes(direction, cfg.phi, cfg.cos_phi, cfg.sin_phi);
}

}  // namespace vo3d
