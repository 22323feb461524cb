// The exact checks a candidate must pass (within the limits of limits.hpp, outside every VO,
// at least the margin from every VO), and the fallbacks when no plane QP gives a safe answer:
// the sampled reference's polar grid on the avoidance planes, then the least-bad velocity (the
// latest first intrusion).
#pragma once

#include <algorithm>
#include <numeric>

#include "limits.hpp"
#include "vo.hpp"

namespace vo3d {

//: Cap on the time to intrusion (s) when comparing least-bad candidates ("never").
constexpr double NEVER = 1e9;
//: The fallbacks' grid with an obstacle or a non-cooperative neighbour (fine_fallback): at least
//: the default grid's speeds and headings (rad).
constexpr int64_t FINE_SPEED_LEVELS = 9;
constexpr double FINE_HEADING_STEP = 10.0 * (kPi / 180.0);
//: Speed levels and headings per side of a grid block.
constexpr int64_t BLOCK = 3;
//: Steps of the ternary search of zone_clearance (it shrinks the interval by (2/3)^100).
constexpr int SEARCH_STEPS = 100;

// ------------------------------------------------------------------------------ intrusions

// When zone k (cones first) would be entered at velocity v (inf: never; 0: inside and closing).
inline double zone_time(const VOs& vos, int64_t k, const double* v) {
    int64_t n = vos.n();
    if (k >= n) {
        const Pyramid& py = vos.pyramids[k - n];
        if (py.inside) return pyramid_closing(py, v) > 0 ? 0.0 : kInf;
        return entry_time(py, v);
    }
    const Cone& c = vos.cones[k];
    double pu = closing_speed(c.apex, c.rel, v);
    if (c.inside) return pu > 0 ? 0.0 : kInf;
    double u0 = v[0] - c.apex[0], u1 = v[1] - c.apex[1], u2 = v[2] - c.apex[2];
    double uu = u0 * u0 + u1 * u1 + u2 * u2;
    double disc = pu * pu - uu * (sq(c.d_oi) - sq(c.r_pz));
    if (disc > 0 && pu > 0 && uu > 0) return std::max((pu - std::sqrt(disc)) / uu, 0.0);
    return kInf;
}

// A time by which cone k's zone is entered, as zone_time computes it, at every velocity within
// rho of c; inf when none is known. zone_time's root is Q / (pu + sqrt(pu^2 - |u|^2 Q)), Q =
// d_oi^2 - r_pz^2, which falls as pu and the root's argument rise: over the ball pu >= pu_c -
// |rel| rho and |u| <= |u_c| + rho bound both; widened far beyond the root's rounding.
inline double zone_time_bound(const VOs& vos, int64_t k, const double* c, double rho) {
    const Cone& cone = vos.cones[k];
    if (cone.inside) return kInf;
    const double *a = cone.apex, *rel = cone.rel;
    double u0 = c[0] - a[0], u1 = c[1] - a[1], u2 = c[2] - a[2];
    double nu = std::sqrt(u0 * u0 + u1 * u1 + u2 * u2);
    double nrel = std::sqrt(sq(rel[0]) + sq(rel[1]) + sq(rel[2]));
    double pu_lo = rel[0] * u0 + rel[1] * u1 + rel[2] * u2 - nrel * rho;
    double pu_hi = nrel * (nu + rho), Q = sq(cone.d_oi) - sq(cone.r_pz);
    double disc_lo = pu_lo * pu_lo - sq(nu + rho) * Q;
    // pu as computed is off by a few ulp of pu_hi, pu^2 - |u|^2 Q by a few ulp of pu_hi^2
    if (!(nu > rho && Q > 0.0 && pu_lo > 1e-13 * pu_hi && disc_lo > 1e-13 * sq(pu_hi)))
        return kInf;  // NaN fails too
    double t = Q / (pu_lo + std::sqrt(disc_lo)), uu_lo = sq(nu - rho);
    return t + 1e-9 * (t + pu_hi / uu_lo) + 1e-12 * pu_hi * pu_hi / std::sqrt(disc_lo) / uu_lo;
}

// The earliest time any zone would be entered at v (inf: never; 0: inside and closing); once
// known to be below ``floor`` it is returned at once (floor -1: always the earliest), and the
// zone that showed it goes into hint, where the next call starts: in a crowd most velocities
// are beaten by the same zone.
inline double time_to_intrusion(const VOs& vos, const double* v, double floor, int64_t& hint) {
    int64_t count = vos.count(), k = hint;
    double t = kInf;
    for (int64_t q = 0; q < count; ++q) {  // k wraps round by hand: cheaper than a modulo
        t = std::min(t, zone_time(vos, k, v));
        if (t < floor || t == 0.0) {
            hint = k;
            return t;
        }
        k = k + 1 < count ? k + 1 : 0;
    }
    return t;
}

// The fastest rate (m/s) at which v closes on a zone A is inside (a neighbour's centre along
// the line of centres; a prism's from its side and its top summed, prism_rates, so that the
// least-bad velocity under a top it cannot leave brakes without sinking); 0 when it closes on
// none.
inline double closing_rate(const VOs& vos, const double* v) {
    double worst = 0.0;
    for (const Cone& c : vos.cones)
        if (c.inside)
            worst = std::max(worst, closing_speed(c.apex, c.rel, v) / std::max(c.d_oi, 1e-12));
    for (const Pyramid& py : vos.pyramids) {
        if (py.inside) {
            PrismRates r = prism_rates(py, v);
            worst = std::max(worst, std::max(r.side, 0.0) + std::max(r.top, 0.0));
        }
    }
    return worst;
}

// ------------------------------------------------------------------------------ clearance

// Distance from v to zone k scaled by s about the apex: apex + s B(rel, r_pz) for a cone, the
// prism s C_pz for a pyramid.
inline double scaled_zone_distance(const VOs& vos, int64_t k, const double* v, double s) {
    if (k < vos.n()) {
        const Cone& c = vos.cones[k];
        double d0 = v[0] - c.apex[0] - s * c.rel[0], d1 = v[1] - c.apex[1] - s * c.rel[1],
               d2 = v[2] - c.apex[2] - s * c.rel[2];
        return std::max(std::sqrt(d0 * d0 + d1 * d1 + d2 * d2) - s * c.r_pz, 0.0);
    }
    const Pyramid& py = vos.pyramids[k - vos.n()];
    double total = 0.0;
    for (int ax = 0; ax < 3; ++ax) {
        const double* f = py.frame[ax];
        double x = f[0] * v[0] + f[1] * v[1] + f[2] * v[2];
        double gap = std::max(std::max(s * py.lo[ax] - x, x - s * py.hi[ax]), 0.0);
        total += gap * gap;
    }
    return std::sqrt(total);
}

// The distance from A to zone k (m): d_oi - r_pz for a sphere, to the prism for C_pz.
inline double zone_reach(const VOs& vos, int64_t k) {
    if (k < vos.n()) return vos.cones[k].d_oi - vos.cones[k].r_pz;
    const Pyramid& py = vos.pyramids[k - vos.n()];
    double total = 0.0;
    for (int ax = 0; ax < 3; ++ax) {
        double gap = std::max(std::max(py.lo[ax], -py.hi[ax]), 0.0);
        total += gap * gap;
    }
    return std::sqrt(total);
}

// The distance (m/s) from v to the VO of zone k (0 inside it). The VO is the union over t in
// (0, horizon] of apex + Z/t, Z the zone relative to A: with s = 1/t the zones scaled by
// s >= 1/horizon, whose distance to v is convex in s (a ternary search finds its minimum).
// Inside the zone the VO is the closing half-space: the escape margin.
inline double zone_clearance(const VOs& vos, int64_t k, const double* v, double horizon) {
    bool cone = k < vos.n();
    if (cone && vos.cones[k].inside) {
        const Cone& c = vos.cones[k];
        return -((v[0] - c.apex[0]) * c.rel[0] + (v[1] - c.apex[1]) * c.rel[1] +
                 (v[2] - c.apex[2]) * c.rel[2]) /
               std::max(c.d_oi, 1e-12);
    }
    if (!cone && vos.pyramids[k - vos.n()].inside)
        return -pyramid_closing(vos.pyramids[k - vos.n()], v);
    double reach_time = cone ? horizon : pyramid_horizon(vos, horizon);
    double lo = reach_time > 0.0 ? 1.0 / reach_time : 0.0;
    // Beyond hi the zone is farther than at lo: s dist(0, Z) - |v - apex| > f(lo).
    double f_lo = scaled_zone_distance(vos, k, v, lo);
    double reach = zone_reach(vos, k);
    const double* a = cone ? vos.cones[k].apex : nullptr;
    double speed = std::sqrt(sq(v[0]) + sq(v[1]) + sq(v[2])) +
                   (cone ? std::sqrt(sq(a[0]) + sq(a[1]) + sq(a[2])) : 0.0);
    double hi = std::max(lo, (f_lo + speed) / std::max(reach, 1e-12));
    for (int q = 0; q < SEARCH_STEPS; ++q) {
        double m1 = lo + (hi - lo) / 3.0, m2 = hi - (hi - lo) / 3.0;
        if (scaled_zone_distance(vos, k, v, m1) <= scaled_zone_distance(vos, k, v, m2)) hi = m2;
        else lo = m1;
    }
    return std::min(f_lo, scaled_zone_distance(vos, k, v, 0.5 * (lo + hi)));
}

// The least distance (m/s) from v to any VO (inf without VOs); <= 0 inside one.
inline double clearance(const VOs& vos, const double* v, double horizon) {
    double best = kInf;
    for (int64_t k = 0; k < vos.count(); ++k) best = std::min(best, zone_clearance(vos, k, v, horizon));
    return best;
}

// A lower bound on zone_clearance of a cone: the distance from v to the whole cone apex +
// s B(rel, r_pz), s >= 0, which holds the VO whatever the horizon. With u = v - apex at angle
// beta off the axis and alpha = asin(r_pz / d_oi) it is at least |u| sin(beta - alpha); lowered
// by far more than either computation's rounding. None (-inf) when A is inside the zone or
// within 1e-6 d_oi of it: the cone is then nearly a half-space, cos alpha cancels and
// zone_clearance's search is off by more than that.
inline double cone_clearance_floor(const Cone& c, const double* v) {
    if (!(c.d_oi - c.r_pz > 1e-6 * c.d_oi)) return -kInf;
    const double *a = c.apex, *rel = c.rel;
    double u0 = v[0] - a[0], u1 = v[1] - a[1], u2 = v[2] - a[2];
    double along = (u0 * rel[0] + u1 * rel[1] + u2 * rel[2]) / c.d_oi;
    double x0 = u1 * rel[2] - u2 * rel[1], x1 = u2 * rel[0] - u0 * rel[2],
           x2 = u0 * rel[1] - u1 * rel[0];
    double across = std::sqrt(x0 * x0 + x1 * x1 + x2 * x2) / c.d_oi;
    double sin_a = c.r_pz / c.d_oi, cos_a = std::sqrt(std::max(1.0 - sin_a * sin_a, 0.0));
    double scale = 1.0 + std::sqrt(u0 * u0 + u1 * u1 + u2 * u2) +
                   std::sqrt(sq(a[0]) + sq(a[1]) + sq(a[2])) +
                   std::sqrt(sq(v[0]) + sq(v[1]) + sq(v[2]));
    double floor = across * cos_a - along * sin_a - 1e-9 * scale;
    return floor == floor ? floor : -kInf;  // NaN: no bound
}

// clearance(v) >= least, without clearance's search for a cone whose floor already clears
// least (most of a crowd's cones).
inline bool clear_by(const VOs& vos, const double* v, double horizon, double least) {
    if (!(least == least)) return false;  // nothing is at least NaN away
    for (int64_t k = 0; k < vos.count(); ++k) {
        bool floor_clears = k < vos.n() && cone_clearance_floor(vos.cones[k], v) >= least;
        // NaN is skipped, as clearance's min skips it
        if (!floor_clears && zone_clearance(vos, k, v, horizon) < least) return false;
    }
    return true;
}

// Whether some VO holds v (the exact check), starting with hint, the VO that held the last
// velocity checked: in a crowd most candidates fail on the same VO.
inline bool in_any(const VOs& vos, const double* v, double horizon, int64_t& hint) {
    int64_t n = vos.n(), count = vos.count(), k = hint;
    double obstacle_horizon = pyramid_horizon(vos, horizon);
    for (int64_t q = 0; q < count; ++q) {
        bool inside = k < n ? in_cone(vos.cones[k], v, horizon, 0.0)
                            : in_pyramid(vos.pyramids[k - n], v, obstacle_horizon);
        if (inside) {
            hint = k;
            return true;
        }
        k = k + 1 < count ? k + 1 : 0;
    }
    return false;
}

// Within the limits, outside every VO by the exact check, and at least the margin (m/s) from
// every VO: the margin the linearised rows keep, so no answer lies on a VO's boundary.
inline bool safe_by_margin(const VOs& vos, const double* v, const LimitRows& L, const Bounds& b,
                           const Config& cfg, int64_t& hint) {
    if (!within_limits(v, L, b) || in_any(vos, v, cfg.horizon, hint)) return false;
    return clear_by(vos, v, cfg.horizon, cfg.margin * (1.0 - 1e-9));
}

// ------------------------------------------------------------------------------ the grid

// A polar grid on the planes (L speeds v_min..v_max, a heading every heading_step; speed 0
// once, repeated speeds once): the sampled selection's and the fallbacks' (sampled_grid,
// grid_of). Their points go in blocks (blocked) of BLOCK x BLOCK neighbouring points, each with
// a disc holding them: a VO cone that holds a block's disc holds each of its points
// (ball_in_cone), so the fallbacks skip them without checking them one by one.
struct Grid {
    std::vector<double> points;  // (M, 2) the in-plane candidates
    std::vector<int64_t> where;  // (M, 2) each point's speed level and heading index
    std::vector<int64_t> block;  // (M,) each point's block
    std::vector<double> discs;   // (B, 3) each block's disc: centre x, y, radius
    int64_t size() const { return int64_t(block.size()); }
    int64_t blocks() const { return int64_t(discs.size() / 3); }
};

inline Grid polar(const Bounds& b, int64_t L, double heading_step) {
    int64_t H = int64_t(std::ceil(2.0 * kPi / heading_step - 1e-9));
    std::vector<double> cos_h(H), sin_h(H);  // per heading, not per point
    for (int64_t k = 0; k < H; ++k) {
        cos_h[k] = std::cos(double(k) * heading_step);
        sin_h[k] = std::sin(double(k) * heading_step);
    }
    Grid g;
    for (int64_t a = 0; a < L; ++a) {
        double s = b.v_min + (b.v_max - b.v_min) * double(a) / double(L - 1);
        if (a > 0 && s == b.v_min + (b.v_max - b.v_min) * double(a - 1) / double(L - 1)) continue;
        for (int64_t k = 0; k < (s == 0.0 ? 1 : H); ++k) {  // rounded as numpy's round(12)
            g.points.push_back(std::rint(s * cos_h[k] * 1e12) / 1e12);
            g.points.push_back(std::rint(s * sin_h[k] * 1e12) / 1e12);
            g.where.push_back(a), g.where.push_back(k);
        }
    }
    return g;
}

// Whether the decision has something that does not avoid: an obstacle's VO pyramid in reach or
// a non-cooperative neighbour (nbrs column 7 is 0).
inline bool has_hazard(const VOs& vos, const Rows& nbrs) {
    if (!vos.pyramids.empty()) return true;
    for (int64_t i = 0; i < nbrs.n; ++i)
        if (!(nbrs(i, 7) > 0.0)) return true;
    return false;
}

// g's points in blocks of BLOCK x BLOCK neighbouring speeds and headings, each block's disc
// holding its points.
inline Grid blocked(Grid g) {
    int64_t M = int64_t(g.where.size() / 2), per_row = 1;
    if (M) {
        int64_t top = g.where[1];
        for (int64_t m = 1; m < M; ++m) top = std::max(top, g.where[2 * m + 1]);
        per_row = top / BLOCK + 1;
    }
    g.block.resize(M);
    int64_t B = 0;
    for (int64_t m = 0; m < M; ++m) {
        g.block[m] = (g.where[2 * m] / BLOCK) * per_row + g.where[2 * m + 1] / BLOCK;
        B = std::max(B, g.block[m] + 1);
    }
    g.discs.assign(3 * B, 0.0);
    std::vector<double> count(B, 0.0);
    for (int64_t m = 0; m < M; ++m) {  // centres: the mean of the members
        for (int j = 0; j < 2; ++j) g.discs[3 * g.block[m] + j] += g.points[2 * m + j];
        count[g.block[m]] += 1.0;
    }
    for (int64_t b2 = 0; b2 < B; ++b2)
        for (int j = 0; j < 2; ++j) g.discs[3 * b2 + j] /= std::max(count[b2], 1.0);
    for (int64_t m = 0; m < M; ++m) {  // radii: the farthest member, widened beyond a lift's rounding
        double* disc = &g.discs[3 * g.block[m]];
        double d = std::sqrt(sq(g.points[2 * m] - disc[0]) + sq(g.points[2 * m + 1] - disc[1]));
        disc[2] = std::max(disc[2], d * (1.0 + 1e-9) + 1e-9);
    }
    return g;
}

// The fallbacks' grid: cfg's, but with fine_fallback and a hazard at least the default grid's
// speeds and headings (denser, not a superset: 45 degree headings are not on a 10 degree grid).
inline Grid grid_of(const Bounds& b, const Config& cfg, bool hazard) {
    int64_t L = cfg.fallback_speed_levels;
    double step = cfg.fallback_heading_step;
    if (hazard && cfg.fine_fallback)
        L = std::max(L, FINE_SPEED_LEVELS), step = std::min(step, FINE_HEADING_STEP);
    return blocked(polar(b, L, step));
}

// The sampled selection's grid, in blocks (its least-bad fallback searches its own candidates).
inline Grid sampled_grid(const Bounds& b, const Config& cfg) {
    return blocked(polar(b, cfg.speed_levels, cfg.heading_step));
}

// Block b's disc centre on plane p, in 3D, lifted as a grid point is.
inline void disc_centre(const Planes& planes, const Grid& g, int64_t b, int64_t p, double* c) {
    const auto &T0 = planes.to_plane[0].m, &Tp = planes.to_plane[p].m;
    for (int j = 0; j < 3; ++j) c[j] = g.discs[3 * b] * T0[0][j] + g.discs[3 * b + 1] * Tp[1][j];
}

// Whether some VO cone holds block b's disc on plane p, trying first the cone in hint.
inline bool covered(const VOs& vos, const Planes& planes, const Grid& g, int64_t b, int64_t p,
                    int64_t& hint) {
    double c[3];
    disc_centre(planes, g, b, p, c);
    int64_t n = vos.n(), k = hint;
    for (int64_t q = 0; q < n; ++q) {
        if (ball_in_cone(vos.cones[k], c, g.discs[3 * b + 2])) {
            hint = k;
            return true;
        }
        k = k + 1 < n ? k + 1 : 0;
    }
    return false;
}

// The cone holding each block on each plane, as grid_search leaves it: >= 0 a cone, -1 none,
// -2 not looked at.
struct Cover {
    std::vector<int64_t> cone;  // (P, B)
    int64_t B = 0;
    int64_t& at(int64_t p, int64_t b) { return cone[p * B + b]; }
};

struct Found {
    bool found;
    double v[3];
    int64_t plane;  // -1 when not found
};

// The grid point on the planes nearest the preferred velocity that safe_by_margin accepts.
// Points equally far are tried plane by plane; a point whose block lies in a VO cone on that
// plane is skipped (the block is looked at once, without a horizon only: the cones'
// certificate's condition). ``cover`` is filled for least_bad.
inline Found grid_search(const VOs& vos, const Planes& planes, const Grid& g, const LimitRows& L,
                         const Bounds& b, const Config& cfg, Cover& cover) {
    const auto& T0 = planes.to_plane[0].m;
    int64_t M = g.size();
    double w0 = T0[0][0] * vos.v_pref[0] + T0[0][1] * vos.v_pref[1] + T0[0][2] * vos.v_pref[2];
    std::vector<double> dev(M);
    for (int64_t q = 0; q < M; ++q)  // |v - v_pref|: the planes are isometric
        dev[q] = std::sqrt(sq(g.points[2 * q] - w0) + sq(g.points[2 * q + 1]));
    std::vector<int64_t> order(M);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int64_t x, int64_t y) {
        return dev[x] < dev[y] || (std::isnan(dev[y]) && !std::isnan(dev[x]));  // numpy's order
    });
    int64_t hint = 0, block_hint = 0;
    cover.B = g.blocks();
    cover.cone.assign(planes.count() * cover.B, -2);
    bool by_block = cfg.horizon < 0.0 && vos.n() > 0;
    Found out{false, {0.0, 0.0, 0.0}, -1};
    for (int64_t a = 0, e = 0; a < M; a = e) {
        for (e = a; e < M && dev[order[e]] <= dev[order[a]] + 1e-12; ++e) {
        }
        for (int64_t p = 0; p < planes.count(); ++p) {
            const auto& Tp = planes.to_plane[p].m;
            for (int64_t q = a; q < e; ++q) {
                double x = g.points[2 * order[q]], y = g.points[2 * order[q] + 1];
                if (y == 0.0 && p > 0) continue;  // on e1: the same velocity on every plane
                if (by_block) {
                    int64_t k = g.block[order[q]];
                    if (cover.at(p, k) == -2)
                        cover.at(p, k) = covered(vos, planes, g, k, p, block_hint) ? block_hint : -1;
                    if (cover.at(p, k) >= 0) continue;
                }
                for (int j = 0; j < 3; ++j) out.v[j] = x * T0[0][j] + y * Tp[1][j];
                if (safe_by_margin(vos, out.v, L, b, cfg, hint)) {
                    out.found = true, out.plane = p;
                    return out;
                }
            }
        }
    }
    return out;
}

// ------------------------------------------------------------------------------ least-bad

// The best candidate so far: its key is (-time to intrusion, deviation, closing rate).
struct LeastBad {
    double best[3] = {kNaN, 0.0, 0.0};
    double key[3] = {kInf, kInf, kInf};
    int64_t hint = 0;
    bool escape;
};

// Keep v (first clipped into the reachable box |v - v_now| <= a dt if ``clip``) if it is within
// the limits and its (latest intrusion, slowest closing, least deviation) beats the best's. The
// closing rate on the zones A is inside counts only with least_bad_escape and only among
// velocities that enter a zone at once (time 0).
inline void consider(const VOs& vos, double* v, bool clip, const double* v_now, const LimitRows& L,
                     const Bounds& b, LeastBad& lb) {
    if (clip) {
        double dv = b.acceleration * b.dt;
        for (int c = 0; c < 3; ++c) v[c] = std::min(std::max(v[c], v_now[c] - dv), v_now[c] + dv);
    }
    if (!within_limits(v, L, b)) return;
    // A velocity whose intrusion comes before the best one's cannot win: its time is only
    // computed far enough to know that.
    double t = -std::min(time_to_intrusion(vos, v, -lb.key[0], lb.hint), NEVER);
    if (t > lb.key[0]) return;
    double dev = std::sqrt(sq(v[0] - vos.v_pref[0]) + sq(v[1] - vos.v_pref[1]) + sq(v[2] - vos.v_pref[2]));
    double cl = lb.escape && t == 0.0 ? closing_rate(vos, v) : 0.0;
    double* key = lb.key;
    if (t < key[0] || (t == key[0] && (cl < key[2] || (cl == key[2] && dev < key[1])))) {
        for (int c = 0; c < 3; ++c) lb.best[c] = v[c];
        key[0] = t, key[1] = dev, key[2] = cl;
    }
}

// zone_time_bound of block b's disc on plane p for zone k (inf when k is a pyramid).
inline double block_time(const VOs& vos, const Planes& planes, const Grid& g, int64_t b, int64_t p,
                         int64_t k) {
    if (k >= vos.n()) return kInf;
    double c[3];
    disc_centre(planes, g, b, p, c);
    return zone_time_bound(vos, k, c, g.discs[3 * b + 2]);
}

// Among the tried answers (rows of ``tried``), the grid on every plane, zero and v_now, within
// the limits: the velocity whose first intrusion comes latest (ties at once: the one closing
// slowest on the zones A is inside, with least_bad_escape; then the nearest the preferred
// one). With an acceleration limit each is tried again clipped into the reachable box. None
// within the limits: the limits' own closest point to hovering. A block is skipped once a
// zone's time bound for it (the cone holding it, or the zone that beat the last point) comes
// before the best so far: the best only gets later, so the answer is the same.
inline void least_bad(const VOs& vos, const Planes& planes, const Grid& g, Cover& cover,
                      const Rows& tried, const double* p, const double* v_now, const LimitRows& L,
                      const Bounds& b, const Config& cfg, double* out) {
    LeastBad lb;
    lb.escape = cfg.least_bad_escape;
    int64_t P = planes.count(), B = g.blocks(), n = vos.n();
    std::vector<double> by(P * B, kInf);    // per plane and block: a time by which each point
    std::vector<int64_t> by_zone(P * B, -1);  // enters a zone, and the zone last tried on it
    double v[3];
    for (int pass = 0; pass < (std::isnan(b.acceleration) ? 1 : 2); ++pass) {
        bool clip = pass == 1;  // the second pass: each clipped into the reachable box
        for (int64_t q = 0; q < tried.n; ++q) {
            for (int c = 0; c < 3; ++c) v[c] = tried(q, c);
            consider(vos, v, clip, v_now, L, b, lb);
        }
        for (int64_t pl = 0; pl < P; ++pl) {
            const auto &T = planes.to_plane[pl].m;
            for (int64_t q = 0; q < g.size(); ++q) {
                if (g.points[2 * q + 1] == 0.0 && pl > 0) continue;  // on e1: plane 0's velocity
                if (!clip && n > 0) {  // its block enters a zone before the best so far: skip
                    int64_t bk = g.block[q], i = pl * B + bk;
                    if (by_zone[i] == -1 && cover.at(pl, bk) >= 0) {  // first, the cone holding it
                        by[i] = block_time(vos, planes, g, bk, pl, cover.at(pl, bk));
                        by_zone[i] = cover.at(pl, bk);
                    }
                    if (by[i] < -lb.key[0]) continue;  // for good: the best only gets later
                    if (by_zone[i] != lb.hint) {       // a zone not tried on this block yet
                        double t = block_time(vos, planes, g, bk, pl, lb.hint);
                        by[i] = std::min(by[i], t), by_zone[i] = lb.hint;
                        if (by[i] < -lb.key[0]) continue;
                    }
                }
                for (int c = 0; c < 3; ++c) v[c] = g.points[2 * q] * T[0][c] + g.points[2 * q + 1] * T[1][c];
                consider(vos, v, clip, v_now, L, b, lb);
            }
        }
        v[0] = v[1] = v[2] = 0.0;
        consider(vos, v, clip, v_now, L, b, lb);
        for (int c = 0; c < 3; ++c) v[c] = v_now[c];
        consider(vos, v, clip, v_now, L, b, lb);
    }
    if (std::isnan(lb.best[0])) {
        VzRange vz = vz_range(p[2], b);
        lb.best[0] = 0.0, lb.best[1] = 0.0, lb.best[2] = std::min(std::max(0.0, vz.lo), vz.hi);
    }
    for (int c = 0; c < 3; ++c) out[c] = lb.best[c];
}

}  // namespace vo3d
