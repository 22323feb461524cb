// The limits as linear rows: the altitude band with room to brake, the acceleration box and
// the closing guard; the check of a candidate against them, and the limits applied last.
#pragma once

#include <algorithm>

#include "vo.hpp"

namespace vo3d {

//: Tolerance (m/s) on the speed and altitude limits when checking a candidate.
constexpr double LIMIT_TOL = 1e-6;

// The linear limits G v <= h in 3D (row j at G[3j..3j+2]).
struct LimitRows {
    std::vector<double> G, h;
    int64_t count() const { return int64_t(h.size()); }
};

struct VzRange {
    double lo, hi;
};

// The fastest approach to a band edge d away (d > 0) that can still stop short of it with the
// acceleration limit a: one step at s, then braking at a, covers s dt + s^2 / (2 a) <= d, so
// s = 2 d / (dt + sqrt(dt^2 + 2 d / a)). (Braking by a dt per step stops sooner: the band is
// kept, step after step.) inf without a limit.
inline double braking_speed(double d, const Bounds& b) {
    if (std::isnan(b.acceleration)) return kInf;
    double dt = b.dt;
    return d > 0.0 ? 2.0 * d / (dt + std::sqrt(dt * dt + 2.0 * d / b.acceleration)) : 0.0;
}

// Vertical speeds that keep z + v_z dt within [z_min, z_max] and, with an acceleration limit,
// leave room to brake before either edge. Out of the band already: back towards it, as fast as
// the far edge allows (v_max without an acceleration limit). The limits win over the
// acceleration box: a vehicle too fast for the room left gets no answer within both, and the
// limits applied last command the braking the band needs (a lagging vehicle follows a larger
// command faster; RotorPy's commands are rate-limited by the simulator).
inline VzRange vz_range(double z, const Bounds& b) {
    double lo = std::max({(b.z_min - z) / b.dt, -b.v_max, -braking_speed(z - b.z_min, b)});
    double hi = std::min({(b.z_max - z) / b.dt, b.v_max, braking_speed(b.z_max - z, b)});
    if (lo > hi) {  // out of the band
        if (z < b.z_min) lo = hi;
        else hi = lo;
    }
    return {lo, hi};
}

// The component in [v - dv, v + dv] nearest 0.
inline double brake(double v, double dv) { return std::min(std::max(0.0, v - dv), v + dv); }

// The closing guard's row u.v <= c for neighbour i, u the unit vector towards it (c = inf: no
// row). c is half the gap (d - r_pz, 0 inside) per dt: B runs the same rule, so the pair closes
// by at most the gap within the step. No row for a neighbour that does not avoid or when
// c >= v_max; with an acceleration limit c is raised to u.v_brake, v_brake the point of the box
// |v - v_now| <= a dt nearest hovering, so that the box and every guard row share it.
struct GuardRow {
    double u[3], c;
};

inline GuardRow closing_row(const double* p, const double* v_now, const Rows& nbrs, int64_t i,
                            const Bounds& b) {
    double dx = nbrs(i, 0) - p[0], dy = nbrs(i, 1) - p[1], dz = nbrs(i, 2) - p[2];
    double d = std::sqrt(dx * dx + dy * dy + dz * dz);
    if (!(nbrs(i, 7) > 0.0 && d > 0.0)) return {{0.0, 0.0, 0.0}, kInf};
    double ux = dx / d, uy = dy / d, uz = dz / d;
    double c = 0.5 * std::max(d - nbrs(i, 6), 0.0) / b.dt;
    if (!std::isnan(b.acceleration)) {
        double dv = b.acceleration * b.dt;
        double br = ux * brake(v_now[0], dv) + uy * brake(v_now[1], dv) + uz * brake(v_now[2], dv);
        c = std::max(c, br);
    }
    return {{ux, uy, uz}, c < b.v_max ? c : kInf};
}

// The altitude band, the acceleration box |v - v_now| <= a dt per axis (with an acceleration
// limit) and, with closing_guard, one row per cooperative neighbour whose zone could be reached
// within dt.
inline LimitRows limit_rows(const double* p, const double* v_now, const Rows& nbrs, const Bounds& b,
                            const Config& cfg) {
    int64_t rows = std::isnan(b.acceleration) ? 2 : 8, guards = 0;
    if (cfg.closing_guard)
        for (int64_t i = 0; i < nbrs.n; ++i) guards += closing_row(p, v_now, nbrs, i, b).c < kInf;
    LimitRows L;
    L.G.assign(3 * (rows + guards), 0.0);
    L.h.assign(rows + guards, 0.0);
    VzRange vz = vz_range(p[2], b);
    L.G[2] = 1.0, L.h[0] = vz.hi, L.G[5] = -1.0, L.h[1] = -vz.lo;
    if (rows == 8) {
        double dv = b.acceleration * b.dt;
        for (int k = 0; k < 3; ++k) {
            L.G[3 * (2 + 2 * k) + k] = 1.0, L.h[2 + 2 * k] = v_now[k] + dv;
            L.G[3 * (3 + 2 * k) + k] = -1.0, L.h[3 + 2 * k] = dv - v_now[k];
        }
    }
    for (int64_t i = 0; i < (guards ? nbrs.n : 0); ++i) {
        GuardRow g = closing_row(p, v_now, nbrs, i, b);
        if (g.c < kInf) {
            for (int k = 0; k < 3; ++k) L.G[3 * rows + k] = g.u[k];
            L.h[rows++] = g.c;
        }
    }
    return L;
}

// Whether A is inside some prism under its top (prism_rates).
inline bool under_a_top(const VOs& vos) {
    for (const Pyramid& py : vos.pyramids)
        if (py.inside && under_top(py)) return true;
    return false;
}

// The plane QPs' limits: ``limits`` and, inside a prism under its top, the escape's second
// row -v_z <= -margin. The side's half-plane is the prism's own row (sections.hpp); with this
// one the QPs hold the escape set {h . v <= 0, v_z >= 0}, by the margin as every VO row. Not a
// limit of the fallbacks: the clearance checks their candidates.
inline LimitRows qp_limit_rows(const LimitRows& limits, const VOs& vos, double margin) {
    LimitRows L = limits;
    if (under_a_top(vos)) {  // one row for every such prism
        L.G.insert(L.G.end(), {0.0, 0.0, -1.0});
        L.h.push_back(-margin);
    }
    return L;
}

// Speed in [v_min, v_max] and G v <= h, each within LIMIT_TOL.
inline bool within_limits(const double* v, const LimitRows& L, const Bounds& b) {
    double speed = std::sqrt(sq(v[0]) + sq(v[1]) + sq(v[2]));
    if (!(b.v_min - LIMIT_TOL <= speed && speed <= b.v_max + LIMIT_TOL)) return false;
    for (int64_t j = 0; j < L.count(); ++j) {
        const double* g = &L.G[3 * j];
        if (g[0] * v[0] + g[1] * v[1] + g[2] * v[2] > L.h[j] + LIMIT_TOL) return false;
    }
    return true;
}

// The limits, whatever came before: never above v_max, never leaving [z_min, z_max] within dt
// with room to brake (vz_range; from an in-bounds start); non-finite components become 0.
inline void enforce_limits(const double* v, const double* p, const Bounds& b, double* out) {
    for (int c = 0; c < 3; ++c) out[c] = std::isfinite(v[c]) ? v[c] : 0.0;
    VzRange vz = vz_range(p[2], b);
    out[2] = std::min(std::max(out[2], vz.lo), vz.hi);
    double speed = std::sqrt(sq(out[0]) + sq(out[1]) + sq(out[2]));
    if (speed > b.v_max)
        for (int c = 0; c < 3; ++c) out[c] *= b.v_max / speed;
}

}  // namespace vo3d
