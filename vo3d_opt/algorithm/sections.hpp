// The VOs' sections on the avoidance planes (section 3.1 for cones, 4.2 for pyramids) and their
// linearised rows, one half-plane G.w <= h per VO, plane and round (formulations/plane_qp.md).
//
// Every section is described the paper's way, in plane coordinates (x^phi, y^phi): the curve of
// eq. (12) (generators meeting the plane), the two points of eq. (17) where the base circle B_vo
// meets it (the chord), the projected apex A^phi (eq. 7), the symmetry-line point H (eq. 13),
// and, inside a protected zone, the escape half-plane. The corrections of section 3.1 can be
// switched off one by one (Corrections).
//
// A row of a conic section is the cone's tangent plane along the generator through a boundary
// point (round "near": the one nearest the preferred velocity; "left" / "right": the nearest in
// the upper / lower half of the section), restricted to the plane; a triangle's row is one of
// its sides through the apex; inside the zone, the escape half-plane. Every row is pushed out
// by the margin, so answers are strictly outside the VO.
#pragma once

#include "vo.hpp"

namespace vo3d {

enum Kind : int64_t {
    BLANK, POINT, LINE, TRIANGLE, CIRCLE, ELLIPSE, PARABOLA, HYPERBOLA, INSIDE_CODE
};
constexpr double ANGLE_TOL = 1e-7;
//: Linearisation rounds: the nearest boundary point, then the section passed on its left, right.
constexpr int ROUNDS = 3;

// One VO shape on one plane, in plane coordinates (NaN where there is none).
struct Section {
    std::vector<double> curve_x, curve_y;  // (K,) eq. (12): where generator k meets the plane
    double chord[2][2];                    // eq. (17): the base circle meets the plane here
    double chord_cs[2][2];                 // cos and sin of the chord points' generator angles
    double apex[2];                        // A^phi of eq. (7)
    double symmetry[2];                    // H of eq. (13)
    double halfplane[3];                   // A inside the zone: the VO is a x + b y > c
    explicit Section(int64_t K = 0) : curve_x(K), curve_y(K) {}
};

// A VO's points in the planes' (e_x, e_y0, e_z0) frame, one row per axis, computed once per VO:
// each plane only turns them about e_x (eq. 8). Cones: B_vo(t_k) of eq. (4), then the apex, C_vo
// (eq. 5) and rel (columns K, K+1, K+2); pyramids: C_pz's eight corners, then h.
struct Base {
    std::vector<double> xyz;  // (3, cols)
    int64_t cols = 0;
    void resize(int64_t c) { cols = c, xyz.assign(3 * c, 0.0); }
    double& operator()(int r, int64_t k) { return xyz[r * cols + k]; }
    double operator()(int r, int64_t k) const { return xyz[r * cols + k]; }
};

// A world vector in the planes' frame.
inline void framed(double x, double y, double z, const double (&f)[3][3], double* out) {
    out[0] = f[0][0] * x + f[0][1] * y + f[0][2] * z;
    out[1] = f[1][0] * x + f[1][1] * y + f[1][2] * z;
    out[2] = f[2][0] * x + f[2][1] * y + f[2][2] * z;
}

inline void put(Base& base, int64_t k, const double* xyz) {
    base(0, k) = xyz[0], base(1, k) = xyz[1], base(2, k) = xyz[2];
}

// B_vo(t_k) of eq. (4) for every generator angle, the apex, C_vo and rel, into base (3, K + 3).
inline void cone_base_points(const Cone& c, const double (&frame)[3][3],
                             const std::vector<double>& cos_t, const std::vector<double>& sin_t,
                             Base& base) {
    const double* a = c.apex;
    const auto& R = c.R;
    double dv = c.d_vo, rv = c.r_vo, xyz[3];
    int64_t K = int64_t(cos_t.size());
    for (int64_t k = 0; k < K; ++k) {
        double ct = rv * cos_t[k], st = rv * sin_t[k];
        framed(a[0] + R[0][0] * dv + R[0][1] * ct + R[0][2] * st,
               a[1] + R[1][0] * dv + R[1][1] * ct + R[1][2] * st,
               a[2] + R[2][0] * dv + R[2][1] * ct + R[2][2] * st, frame, xyz);
        put(base, k, xyz);
    }
    framed(a[0], a[1], a[2], frame, xyz);
    put(base, K, xyz);
    framed(a[0] + dv * R[0][0], a[1] + dv * R[1][0], a[2] + dv * R[2][0], frame, xyz);
    put(base, K + 1, xyz);
    framed(c.rel[0], c.rel[1], c.rel[2], frame, xyz);
    put(base, K + 2, xyz);
}

// C_pz's eight corners (bits far, left, top of k pick hi over lo), then h, into base (3, >= 9).
inline void pyramid_base_points(const Pyramid& py, const double (&frame)[3][3], Base& base) {
    const auto& F = py.frame;
    double xyz[3];
    for (int k = 0; k < 8; ++k) {
        double a0 = (k & 1) ? py.hi[0] : py.lo[0];
        double a1 = ((k >> 1) & 1) ? py.hi[1] : py.lo[1];
        double a2 = ((k >> 2) & 1) ? py.hi[2] : py.lo[2];
        framed(a0 * F[0][0] + a1 * F[1][0] + a2 * F[2][0], a0 * F[0][1] + a1 * F[1][1] + a2 * F[2][1],
               a0 * F[0][2] + a1 * F[1][2] + a2 * F[2][2], frame, xyz);
        put(base, k, xyz);
    }
    framed(F[0][0], F[0][1], F[0][2], frame, xyz);
    put(base, 8, xyz);
}

// Eqs (14)-(16): the base circle B_vo(t) meets the plane of normal n where A + B cos t +
// C sin t = 0; both roots' (cos t, sin t) into cs, without trigonometry. False: it misses.
inline bool crossings(const Cone& c, double nx, double ny, double nz, double (&cs)[2][2]) {
    const auto& R = c.R;
    const double* apex = c.apex;
    double A_ = c.d_vo * (R[0][0] * nx + R[1][0] * ny + R[2][0] * nz) + apex[0] * nx +
                apex[1] * ny + apex[2] * nz;
    double B_ = c.r_vo * (R[0][1] * nx + R[1][1] * ny + R[2][1] * nz);
    double C_ = c.r_vo * (R[0][2] * nx + R[1][2] * ny + R[2][2] * nz);
    double rho2 = B_ * B_ + C_ * C_;
    if (!(rho2 > 0 && A_ * A_ <= rho2)) return false;
    double root = std::sqrt(rho2 - A_ * A_);
    for (int j = 0; j < 2; ++j) {  // t = atan2(C, B) -/+ acos(-A/rho)
        double sign = j == 0 ? -1.0 : 1.0;
        cs[j][0] = (-A_ * B_ - sign * root * C_) / rho2;
        cs[j][1] = (-A_ * C_ + sign * root * B_) / rho2;
    }
    return true;
}

// Section 3.1 for a cone on the plane with cos/sin phi = c, s: writes sec, returns the kind.
inline int64_t cone_section(const Cone& cone, const Base& base, const double (&frame)[3][3],
                            double c, double s, const Corrections& corr, Section& sec) {
    int64_t K = base.cols - 3;
    const double* apex = cone.apex;
    const auto& R = cone.R;
    double d_vo = cone.d_vo, r_vo = cone.r_vo;
    // eq. (7)
    double xA = base(0, K), yA = c * base(1, K) + s * base(2, K), zA = c * base(2, K) - s * base(1, K);
    sec.apex[0] = xA, sec.apex[1] = yA;
    double scale = 1.0 + std::sqrt(sq(apex[0]) + sq(apex[1]) + sq(apex[2])) + d_vo;
    bool on_apex = std::abs(zA) <= 1e-9 * scale;  // 3.1.3: A_vo lies on the plane
    // Eqs (11)-(12): generator k meets the plane at parameter t_g. (GCC does not vectorise
    // this loop: its comparisons may trap; a vectorised loop of the arithmetic alone, followed
    // by the comparisons, measured no faster.)
    const double* __restrict bx = &base.xyz[0];
    const double* __restrict by = bx + base.cols;
    const double* __restrict bz = by + base.cols;
    double* __restrict cx = sec.curve_x.data();
    double* __restrict cy = sec.curve_y.data();
    bool tg_range = corr.tg_range;
    int any_valid = 0;
    for (int64_t k = 0; k < K; ++k) {
        double yB = c * by[k] + s * bz[k], zB = c * bz[k] - s * by[k];
        double dz = zB - zA;
        double t_g = -zA / dz;
        int valid = tg_range ? (t_g >= 0.0) & (t_g <= 1.0)  // 3.1.1
                             // the original condition z_Bvo != z_A: both nappes, any length
                             : (std::abs(t_g) <= std::numeric_limits<double>::max()) &
                                   (std::abs(dz) > 1e-12);
        any_valid |= valid;
        int keep = valid & !on_apex;
        cx[k] = keep ? (bx[k] - xA) * t_g + xA : kNaN;
        cy[k] = keep ? (yB - yA) * t_g + yA : kNaN;
    }
    // Eqs (14)-(17): where the base circle meets the plane.
    double nx = c * frame[2][0] - s * frame[1][0], ny = c * frame[2][1] - s * frame[1][1],
           nz = c * frame[2][2] - s * frame[1][2];
    bool chord_ok = crossings(cone, nx, ny, nz, sec.chord_cs);
    for (int j = 0; j < 2; ++j) {
        if (chord_ok) {
            double ct = r_vo * sec.chord_cs[j][0], st = r_vo * sec.chord_cs[j][1], b[3];
            framed(apex[0] + R[0][0] * d_vo + R[0][1] * ct + R[0][2] * st,
                   apex[1] + R[1][0] * d_vo + R[1][1] * ct + R[1][2] * st,
                   apex[2] + R[2][0] * d_vo + R[2][1] * ct + R[2][2] * st, frame, b);
            sec.chord[j][0] = b[0], sec.chord[j][1] = c * b[1] + s * b[2];
        } else {
            sec.chord[j][0] = sec.chord[j][1] = kNaN;
            sec.chord_cs[j][0] = sec.chord_cs[j][1] = kNaN;
        }
    }
    // Classification by the angle between the plane and the axis (|n.a| against sin alpha).
    double sa = cone.sin_alpha;
    double na = std::abs(R[0][0] * nx + R[1][0] * ny + R[2][0] * nz);
    int64_t kind = BLANK;
    if (any_valid || chord_ok) {
        if (na > sa + ANGLE_TOL) kind = na > 1 - ANGLE_TOL ? CIRCLE : ELLIPSE;
        else if (std::abs(na - sa) <= ANGLE_TOL) kind = PARABOLA;
        else kind = HYPERBOLA;
    }
    if (on_apex) {
        kind = na > sa + ANGLE_TOL ? POINT : (na >= sa - ANGLE_TOL ? LINE : TRIANGLE);
        if (kind == TRIANGLE && !corr.triangle) kind = POINT;  // the original: A^phi alone
    }
    // Eq. (13): the symmetry-line point H, where the axis line meets the plane.
    double xC = base(0, K + 1), yC = c * base(1, K + 1) + s * base(2, K + 1),
           zC = c * base(2, K + 1) - s * base(1, K + 1);
    double dzc = zC - zA;
    if (std::abs(dzc) <= 1e-12 * scale) {  // the axis is parallel to the plane
        sec.symmetry[0] = xC, sec.symmetry[1] = yC;
    } else {
        double t_h = -zA / dzc;
        if (corr.symmetry_abs) t_h = std::abs(t_h);  // 3.1.2
        sec.symmetry[0] = (xC - xA) * t_h + xA, sec.symmetry[1] = (yC - yA) * t_h + yA;
    }
    // Inside the protected zone: the VO is the closing half-space (v - apex).rel > 0.
    double xr = base(0, K + 2), yr = c * base(1, K + 2) + s * base(2, K + 2),
           zr = c * base(2, K + 2) - s * base(1, K + 2);
    sec.halfplane[0] = xr, sec.halfplane[1] = yr, sec.halfplane[2] = xA * xr + yA * yr + zA * zr;
    return cone.inside ? int64_t(INSIDE_CODE) : kind;
}

// A number in [-2, 2] that grows with atan2(y, x) (no trigonometry); NaN for NaN input.
inline double pseudo_angle(double y, double x) {
    double frac = (x != 0.0 || y != 0.0) ? y / (std::abs(x) + std::abs(y)) : 0.0;
    if (x >= 0.0 || x != x) return frac;
    return y >= 0.0 ? (2.0 - std::abs(frac)) : -(2.0 - std::abs(frac));
}

//: The 12 edges of a box as pairs of corner indices (corners differing in one bit).
constexpr int BOX_EDGES[12][2] = {{0, 1}, {0, 2}, {0, 4}, {1, 3}, {1, 5}, {2, 3},
                                  {2, 6}, {3, 7}, {4, 5}, {4, 6}, {5, 7}, {6, 7}};

// C_pz's corners turned onto the plane (c, s): in-plane y and height z above it, per corner.
struct Corners {
    double y[8], z[8];
};

inline Corners turned(const Base& base, double c, double s) {
    Corners out;
    for (int k = 0; k < 8; ++k)
        out.y[k] = c * base(1, k) + s * base(2, k), out.z[k] = c * base(2, k) - s * base(1, k);
    return out;
}

// Where box edge e crosses the plane, if it does.
inline bool edge_crossing(const Base& base, const Corners& at, int e, double& x, double& y) {
    int ka = BOX_EDGES[e][0], kb = BOX_EDGES[e][1];
    double za = at.z[ka], zb = at.z[kb];
    if (!(za * zb <= 0 && za != zb)) return false;
    double f = za / (za - zb);
    x = base(0, ka) + f * (base(0, kb) - base(0, ka));
    y = at.y[ka] + f * (at.y[kb] - at.y[ka]);
    return true;
}

// Section 4.2 for a pyramid on the plane (c, s): every plane contains the pyramid's apex, the
// velocity origin (eq. 19), so a triangle (the chord: the two extreme points where C_pz's edges
// cross the plane), a line or a point.
inline int64_t pyramid_section(const Pyramid& py, const Base& base, double c, double s,
                               Section& sec) {
    for (int a = 0; a < 2; ++a) {
        sec.apex[a] = 0.0, sec.symmetry[a] = kNaN;
        sec.chord[a][0] = sec.chord[a][1] = sec.chord_cs[a][0] = sec.chord_cs[a][1] = kNaN;
    }
    sec.halfplane[0] = base(0, 8), sec.halfplane[1] = c * base(1, 8) + s * base(2, 8);
    sec.halfplane[2] = 0.0;
    // C_pz meets the plane in the convex hull of its edges' crossings; the extreme ones seen
    // from the apex bound the section. First pass: the mean direction of the crossings.
    Corners at = turned(base, c, s);
    int n_cross = 0;
    bool at_apex = false;
    double sx = 0.0, sy = 0.0, mx = 0.0, my = 0.0, xs[12], ys[12];
    for (int e = 0; e < 12; ++e) {
        double& x = xs[n_cross];
        double& y = ys[n_cross];
        if (!edge_crossing(base, at, e, x, y)) continue;
        double norm = std::sqrt(x * x + y * y);
        n_cross += 1, sx = sx + x, sy = sy + y;
        if (norm > 0) mx = mx + x / norm, my = my + y / norm;
        else at_apex = true;  // A on the surface of C_pz: no wedge to speak of
    }
    if (n_cross == 0) return py.inside ? int64_t(INSIDE_CODE) : int64_t(POINT);
    sec.symmetry[0] = sx / double(n_cross), sec.symmetry[1] = sy / double(n_cross);
    double a_lo = kInf, a_hi = -kInf;
    for (int q = 0; q < n_cross; ++q) {  // second pass: the extreme angles about that direction
        double x = xs[q], y = ys[q];
        double ang = pseudo_angle(mx * y - my * x, mx * x + my * y);
        if (ang < a_lo) a_lo = ang, sec.chord[0][0] = x, sec.chord[0][1] = y;
        if (ang > a_hi) a_hi = ang, sec.chord[1][0] = x, sec.chord[1][1] = y;
    }
    int64_t kind = TRIANGLE;
    if (at_apex || !(a_hi - a_lo > 1e-9)) {
        kind = LINE;
        for (int a = 0; a < 2; ++a) sec.chord[a][0] = sec.chord[a][1] = kNaN;
    }
    return py.inside ? int64_t(INSIDE_CODE) : kind;
}

// ------------------------------------------------------------------------------ rows

// One row per round, G[r].w <= h[r].
struct RoundRows {
    double G[ROUNDS][2];
    double h[ROUNDS];
};

// The boundary point each round linearises at, among the curve points of eq. (12) (0..K-1) and
// the chord points of eq. (17) (K, K+1): "near" the nearest, "left" / "right" the nearest in
// the upper / lower half of the section (by y about the candidates' mean), or the nearest when
// that half is empty. A candidate exists if its x is not NaN. ``dist``, ``side_y``: scratch.
struct Picks {
    int64_t round[ROUNDS];
};

inline Picks pick(const Section& sec, int64_t K, const double* w0, std::vector<double>& dist,
                  std::vector<double>& side_y) {
    int64_t count = 0, near = 0;
    double total = 0.0, d_near = kInf;
    for (int64_t k = 0; k < K + 2; ++k) {
        double qx = k < K ? sec.curve_x[k] : sec.chord[k - K][0];
        double qy = k < K ? sec.curve_y[k] : sec.chord[k - K][1];
        side_y[k] = qy;
        // squared: only compared; inf (never picked) for a candidate that does not exist
        dist[k] = qx == qx ? sq(qx - w0[0]) + sq(qy - w0[1]) : kInf;
        if (qx == qx) count += 1, total = total + qy;
        if (dist[k] < d_near) near = k, d_near = dist[k];
    }
    double centre = total / double(std::max(count, int64_t(1)));
    // The nearest is also the nearest of its own half: only the other half needs a search
    // (above: y >= centre, below: y <= centre; on the centre line it is in both).
    bool above = side_y[near] >= centre;
    int64_t other = -1;
    double d_other = kInf;
    for (int64_t k = 0; k < K + 2; ++k) {
        if ((above ? side_y[k] <= centre : side_y[k] >= centre) && dist[k] < d_other)
            other = k, d_other = dist[k];
    }
    if (other < 0) other = near;
    return above ? Picks{{near, near, other}} : Picks{{near, other, near}};
}

// Each round's side of a triangle (the generators through its apex), normal away from the other
// chord point; False when degenerate. "near" the nearer side, "left" / "right" the upper /
// lower one (as pick does).
inline bool triangle_rows(const double* apex, const double (&chord)[2][2], const double* w0,
                          RoundRows& out) {
    double d0x = chord[0][0] - apex[0], d0y = chord[0][1] - apex[1];
    double d1x = chord[1][0] - apex[0], d1y = chord[1][1] - apex[1];
    if (d0x * d0x + d0y * d0y == 0.0 || d1x * d1x + d1y * d1y == 0.0)
        return false;  // a side of length zero: the section is a segment (measure zero)
    double wx = w0[0] - apex[0], wy = w0[1] - apex[1];
    double s0 = std::max((wx * d0x + wy * d0y) / (d0x * d0x + d0y * d0y), 0.0);
    double s1 = std::max((wx * d1x + wy * d1y) / (d1x * d1x + d1y * d1y), 0.0);
    // the squared distances decide as their roots do (sqrt is monotonic; the roots are taken
    // only where two squares round to one root), without waiting on a root in most sections
    double sq0 = sq(wx - s0 * d0x) + sq(wy - s0 * d0y), sq1 = sq(wx - s1 * d1x) + sq(wy - s1 * d1y);
    if (!(std::isfinite(sq0) && std::isfinite(sq1))) return false;
    double centre = 0.5 * (chord[0][1] + chord[1][1]);
    int near = sq0 <= sq1 || std::sqrt(sq0) == std::sqrt(sq1) ? 0 : 1;
    for (int r = 0; r < ROUNDS; ++r) {
        int i = near;
        if (r > 0) {  // the nearest candidate on the round's side, if there is one
            bool on0 = r == 1 ? chord[0][1] >= centre : chord[0][1] <= centre;
            bool on1 = r == 1 ? chord[1][1] >= centre : chord[1][1] <= centre;
            if (on0 && on1) i = near;
            else if (on0 || on1) i = on0 ? 0 : 1;
        }
        double dx = i == 0 ? d0x : d1x, dy = i == 0 ? d0y : d1y;
        double ox = i == 0 ? d1x : d0x, oy = i == 0 ? d1y : d0y;
        double length = std::sqrt(dx * dx + dy * dy);  // a unit normal: the margin is in m/s
        double nx = dy / length, ny = -dx / length;      // G.w <= G.apex, away from the other
        if (nx * ox + ny * oy < 0) nx = -nx, ny = -ny;
        out.G[r][0] = nx, out.G[r][1] = ny, out.h[r] = nx * apex[0] + ny * apex[1];
    }
    return true;
}

// Each round's tangent-plane row of a cone's conic section: N.v >= N.apex on P_phi, N the
// outward normal along the generator through the round's boundary point.
inline void curve_rows(const Cone& cone, const Section& sec, const Config& cfg, const double* w0,
                       const Mat3& to_plane, RoundRows& out, std::vector<double>& dist,
                       std::vector<double>& side_y) {
    int64_t K = cfg.samples();
    Picks picks = pick(sec, K, w0, dist, side_y);
    const double *e1 = to_plane.m[0], *e2 = to_plane.m[1];
    for (int r = 0; r < ROUNDS; ++r) {
        int64_t k = picks.round[r];
        double ct = k < K ? cfg.cos_t[k] : sec.chord_cs[k - K][0];
        double st = k < K ? cfg.sin_t[k] : sec.chord_cs[k - K][1];
        double N[3];
        outward_normal(cone.R, cone.sin_alpha, ct, st, N);
        out.G[r][0] = -(N[0] * e1[0] + N[1] * e1[1] + N[2] * e1[2]);
        out.G[r][1] = -(N[0] * e2[0] + N[1] * e2[1] + N[2] * e2[2]);
        out.h[r] = -(N[0] * cone.apex[0] + N[1] * cone.apex[1] + N[2] * cone.apex[2]);
    }
}

// Scratch of plane_rows (a decision's QPBuffers hold one).
struct RowWork {
    Section sec;
    std::vector<double> dist, side_y;  // (K + 2,) the boundary candidates' distances and sides
    explicit RowWork(int64_t K) : sec(K), dist(K + 2), side_y(K + 2) {}
    void resize(int64_t K) {
        sec.curve_x.resize(K), sec.curve_y.resize(K), dist.resize(K + 2), side_y.resize(K + 2);
    }
};

// VO k's points in the planes' frame (cones first, then pyramids), into base (3, K + 3).
inline void vo_base(const VOs& vos, int64_t k, const double (&frame)[3][3], const Config& cfg,
                    Base& base) {
    base.resize(cfg.samples() + 3);
    if (k < vos.n()) cone_base_points(vos.cones[k], frame, cfg.cos_t, cfg.sin_t, base);
    else pyramid_base_points(vos.pyramids[k - vos.n()], frame, base);
}

// Every round's row of VO k on plane p; False when its section constrains nothing (blank,
// point and line sections). ``base``: vo_base.
inline bool plane_rows(const VOs& vos, int64_t k, int64_t p, const Base& base, const Planes& planes,
                       const Config& cfg, const double* w0, RoundRows& out, RowWork& work) {
    Section& sec = work.sec;
    double c = cfg.cos_phi[p], s = cfg.sin_phi[p];
    bool cone = k < vos.n();
    int64_t kind = cone ? cone_section(vos.cones[k], base, planes.frame, c, s, cfg.corrections, sec)
                        : pyramid_section(vos.pyramids[k - vos.n()], base, c, s, sec);
    bool active = false;
    // Escape, every round: not closing in (for a prism horizontally; under its top the QPs'
    // climb row holds the descent, qp_limit_rows).
    if (kind == INSIDE_CODE) {
        for (int r = 0; r < ROUNDS; ++r) {
            out.G[r][0] = sec.halfplane[0], out.G[r][1] = sec.halfplane[1];
            out.h[r] = sec.halfplane[2];
        }
        active = true;
    } else if (kind == TRIANGLE) {
        active = triangle_rows(sec.apex, sec.chord, w0, out);
    } else if (cone && (kind == CIRCLE || kind == ELLIPSE || kind == PARABOLA || kind == HYPERBOLA)) {
        curve_rows(vos.cones[k], sec, cfg, w0, planes.to_plane[p], out, work.dist, work.side_y);
        active = true;
    }
    for (int r = 0; r < ROUNDS; ++r) out.h[r] -= cfg.margin;  // strictly outside, by the margin
    return active;
}

}  // namespace vo3d
