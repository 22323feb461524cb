// The exact solver of one plane QP (solvers/exact2d.py explains the method):
//
//     minimise ||w - w0||^2 over w in R^2 subject to ||w|| <= r_max, G[k].w <= h[k] (k < m),
//     and, when r_min > 0, ||w|| >= r_min (an annulus).
//
// Seidel's randomised incremental algorithm, as in the 2D steps of RVO2-3D's linearProgram1/2
// (src/Agent.cc) with a nearest-point objective: with the half-planes in a random order, the
// optimum of the first k either satisfies constraint k + 1 or the new optimum lies on its line,
// where it is w0's projection clamped to the interval the disc and the earlier half-planes
// leave. The annulus: if the disc optimum is inside the inner circle, the annulus optimum lies
// on that circle, at w0's direction if allowed, else at the allowed arc end nearest to it.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace vo3d {

//: Relative tolerance of the feasibility tests: a constraint met within EPS (1 + |h| + r) holds.
constexpr double EXACT2D_EPS = 1e-12;

// The rows G w <= h of one plane QP (row k at G[2k], G[2k + 1]).
struct HalfPlanes {
    const double* G;
    const double* h;
    int64_t m;
};

// A fixed pseudo-random permutation of range(m) (Fisher-Yates with an xorshift): Seidel's random
// order, the same on every call so that answers are reproducible to the last bit.
inline void seidel_order(int64_t m, int64_t* out) {
    for (int64_t k = 0; k < m; ++k) out[k] = k;
    uint64_t state = uint64_t(0x9E3779B97F4A7C15ULL) ^ uint64_t(m);
    for (int64_t k = m - 1; k > 0; --k) {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        int64_t j = int64_t(state % uint64_t(k + 1));
        std::swap(out[k], out[j]);
    }
}

// The point nearest w0 on the line G[i].w = h[i], inside the disc and the half-planes
// order[:upto]; False when that set is empty.
inline bool on_line(const HalfPlanes& hp, const int64_t* order, int64_t upto, int64_t i,
                    const double* w0, double r_max, double tol, double* out) {
    const double *G = hp.G, *h = hp.h;
    double gx = G[2 * i], gy = G[2 * i + 1];
    double norm = std::sqrt(gx * gx + gy * gy);
    double nx = gx / norm, ny = gy / norm, d = h[i] / norm;  // the line n.w = d
    if (std::abs(d) > r_max + tol) return false;             // the disc misses the line
    double half = std::sqrt(std::max(r_max * r_max - d * d, 0.0));
    double px = d * nx, py = d * ny, ux = -ny, uy = nx;  // w = p + t u
    double lo = -half, hi = half;
    for (int64_t k = 0; k < upto; ++k) {
        int64_t j = order[k];
        double denom = G[2 * j] * ux + G[2 * j + 1] * uy;
        double slack = h[j] - (G[2 * j] * px + G[2 * j + 1] * py);
        double scale = std::sqrt(G[2 * j] * G[2 * j] + G[2 * j + 1] * G[2 * j + 1]);
        if (std::abs(denom) <= 1e-12 * scale) {  // parallel: all of the line or none of it
            if (slack < -tol * scale) return false;
            continue;
        }
        double t = slack / denom;
        if (denom > 0) hi = std::min(hi, t);
        else lo = std::max(lo, t);
        if (lo > hi + tol) return false;
    }
    double t = (w0[0] - px) * ux + (w0[1] - py) * uy;
    t = lo <= hi ? std::min(std::max(t, lo), hi) : 0.5 * (lo + hi);
    out[0] = px + t * ux, out[1] = py + t * uy;
    return true;
}

// The point nearest w0 on the circle ||w|| = radius inside every half-plane; False if none.
inline bool on_circle(const HalfPlanes& hp, const double* w0, double radius, double tol,
                      double* out) {
    const double *G = hp.G, *h = hp.h;
    double best = std::numeric_limits<double>::infinity();
    double n0 = std::sqrt(w0[0] * w0[0] + w0[1] * w0[1]);
    double ux = 1.0, uy = 0.0;
    if (n0 > 0) ux = w0[0] / n0, uy = w0[1] / n0;
    for (int64_t c = -1; c < 2 * hp.m; ++c) {  // -1: w0's own direction; then each line's two
        double cx, cy;                          // crossings with the circle
        if (c < 0) {
            cx = radius * ux, cy = radius * uy;
        } else {
            int64_t i = c / 2;
            double norm = std::sqrt(G[2 * i] * G[2 * i] + G[2 * i + 1] * G[2 * i + 1]);
            if (norm == 0.0) continue;
            double nx = G[2 * i] / norm, ny = G[2 * i + 1] / norm, d = h[i] / norm;
            if (std::abs(d) > radius) continue;
            double s = std::sqrt(radius * radius - d * d) * (c % 2 == 0 ? 1.0 : -1.0);
            cx = d * nx - s * ny, cy = d * ny + s * nx;
        }
        bool ok = true;
        for (int64_t k = 0; k < hp.m; ++k) {
            if (G[2 * k] * cx + G[2 * k + 1] * cy > h[k] + tol * (1.0 + std::abs(h[k]))) {
                ok = false;
                break;
            }
        }
        double dist = (cx - w0[0]) * (cx - w0[0]) + (cy - w0[1]) * (cy - w0[1]);
        if (ok && dist < best) best = dist, out[0] = cx, out[1] = cy;
        if (ok && c < 0) break;  // w0's direction is allowed: nothing is nearer
    }
    return best < std::numeric_limits<double>::infinity();
}

// The exact optimum over the m rows of hp into out (2,); False when infeasible. ``order``:
// seidel_order(m, order). r_max may be inf (no disc); r_min <= 0 means no inner bound.
inline bool nearest_in_disc(const HalfPlanes& hp, const double* w0, double r_max, double r_min,
                            const int64_t* order, double* out) {
    const double *G = hp.G, *h = hp.h;
    double tol = EXACT2D_EPS *
                 (std::isfinite(r_max) ? 1.0 + r_max : 1.0 + std::abs(w0[0]) + std::abs(w0[1]));
    for (int64_t k = 0; k < hp.m; ++k)  // empty rows: 0 <= h or nothing
        if (G[2 * k] == 0.0 && G[2 * k + 1] == 0.0 && h[k] < -tol) return false;
    double n0 = std::sqrt(w0[0] * w0[0] + w0[1] * w0[1]);
    double scale = n0 > 0 ? std::min(1.0, r_max / n0) : 1.0;
    out[0] = w0[0] * scale, out[1] = w0[1] * scale;
    for (int64_t k = 0; k < hp.m; ++k) {
        int64_t i = order[k];
        double gx = G[2 * i], gy = G[2 * i + 1];
        if (gx == 0.0 && gy == 0.0) continue;
        if (gx * out[0] + gy * out[1] > h[i] + tol * std::sqrt(gx * gx + gy * gy))
            if (!on_line(hp, order, k, i, w0, r_max, tol, out)) return false;
    }
    if (r_min > 0.0 && out[0] * out[0] + out[1] * out[1] < r_min * r_min)
        return on_circle(hp, w0, r_min, tol, out);
    return true;
}

}  // namespace vo3d
