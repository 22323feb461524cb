// The decision of one vehicle: plane_qp on the exact per-plane solver (formulations/plane_qp.md).
// Read top to bottom, decide_one is the whole algorithm, the way RVO2-3D's Agent.cc reads:
//
// 1. the VOs' inputs: each neighbour's row (cone_rows: the horizon, the buffer, its opening and
//    reciprocity applied), the pyramids of section 4 in reach, and the limits as rows (altitude,
//    acceleration, the closing guard);
// 2. the preferred velocity itself, when within the limits and outside every VO (the exact 3D
//    check), is the optimum of every formulation: returned at once;
// 3. the VO cones of eqs 1-6 with the virtual sphere; the avoidance planes about the preferred
//    direction (eq. 8), at least the default ones with an obstacle in reach or a vehicle that
//    does not avoid (cfg.fine); on each plane and in each linearisation round (near, left,
//    right) one QP: the point nearest the preferred velocity inside the speed disc (or
//    annulus), the limit rows and one half-plane per VO that holds the preferred velocity or
//    that A is inside (the sections of 3.1 / 4.2 linearised: sections.hpp), solved exactly
//    (exact2d.hpp);
// 4. best first: the QP of least deviation is checked with the exact 3D membership; a safe
//    answer is the decision (every other QP's answer is at least as far), an answer that enters
//    VOs not yet constrained on that QP adds their rows and that QP is solved again (constraint
//    generation per QP, so no answer depends on the order the QPs are solved in);
// 5. no QP gives a safe answer: the fallbacks' grid with the exact check and the margin, else
//    the least-bad velocity (latest first intrusion: fallback.hpp);
// 6. the limits, whatever came before: never above v_max, never leaving the altitude band in dt.
//
// A plane QP costs well under a microsecond, so its key in the best-first order is a one-line
// lower bound until it is the least key, and only then its exact optimum: QPs that cannot win
// are never solved, and the rows of a plane are built when one of its QPs first comes up.
#pragma once

#include "exact2d.hpp"
#include "fallback.hpp"
#include "sections.hpp"

namespace vo3d {

//: How a velocity was found (Decision.round): the preferred velocity, a QP round, the sampled
//: grid, the least-bad fallback.
enum Round : int64_t { PREFERRED = 0, SAMPLED = ROUNDS + 1, LEAST_BAD = ROUNDS + 2 };
//: Decision.status: the order of vo3d_opt.status.DECISION_STATUSES.
enum DecisionStatus : int64_t { OPTIMAL = 0, INSIDE_PROTECTED_ZONE = 1, INFEASIBLE_MIN_VIOLATION = 2 };
//: Row counts whose solver order each thread keeps (seidel_order: it depends on the count alone).
constexpr int64_t KEPT_ORDERS = 32;

struct Decision {
    double velocity[3];
    int64_t status;  // DecisionStatus
    double phi;      // the plane the velocity was chosen on (rad), NaN when none
    int64_t round;   // Round, or 1 + a QP round
    int64_t solved;  // plane QPs solved
};

struct SearchResult {
    int64_t r, p;     // the (round, plane) of the answer, -1 when no QP gives a safe one
    int64_t solved;   // the QPs solved
    int64_t n_tried;  // the QP answers written into tried (for the least-bad fallback)
};

// The buffers of a decision's plane QPs (PlaneQPs names each), kept from one decision to the
// next (decide_one keeps one per thread): sized anew per decision, they allocate only while they
// grow, and a decision costs a few microseconds, of which dozens of allocations would be one.
// Each thread keeps its largest decision's size for its lifetime (tried: 72 P (V + 1) bytes).
struct QPBuffers {
    std::vector<RoundRows> vo_rows;
    std::vector<uint8_t> active, computed, based, included, exact, complete, into;
    std::vector<Base> base;
    std::vector<int64_t> starts, plane_r, order;
    std::vector<double> G_lim, key, sol, plane_key, rows, rhs, tried;
    std::vector<std::vector<int64_t>> orders{KEPT_ORDERS + 1};  // seidel_order(m): m's alone
    std::vector<std::pair<int64_t, int64_t>> todo;
    RowWork work{0};
};

// The (round, plane) QPs of one decision and their rows, filled as VOs join. The rows of VO k on
// plane p (every round) once a QP on that plane needs them (computed), from the VO's points in
// the planes' frame (base, once per VO). QP (r, p) constrains the VOs in included(r, p, .) plus
// the limit rows and the speed disc; its exact optimum is sol at deviation key (inf: infeasible
// or done), or key is a lower bound while not exact. Its arrays are those of a QPBuffers.
struct PlaneQPs {
    PlaneQPs(const VOs& vos, const Planes& planes, const LimitRows& limits,
             const std::vector<uint8_t>& initial, const Config& cfg, bool lazy, QPBuffers& buf);
    const VOs& vos;
    const Planes& planes;
    const LimitRows& limits;
    const Config& cfg;
    int64_t V, P, L;
    std::vector<RoundRows>& vo_rows;  // (V, P)
    std::vector<uint8_t>&active, &computed;  // (V, P): the section constrains; rows built
    std::vector<Base>& base;                 // (V,)
    std::vector<uint8_t>& based;             // (V,)
    std::vector<uint8_t>& included;          // (R, P, V)
    std::vector<int64_t>& starts;            // the VOs every QP starts with
    std::vector<double>& G_lim;              // (P, L, 2): the 3D limit rows on each plane
    std::vector<double>&key, &sol;           // (R, P), (R, P, 2)
    std::vector<uint8_t>&exact, &complete;   // (R, P); (P,): rows of every starting VO built
    std::vector<double>& plane_key;          // (P,) each plane's least key ...
    std::vector<int64_t>& plane_r;           // ... and the first round that has it
    double w0[2];  // the preferred velocity in plane coordinates (the same on every plane)
    std::vector<double>&rows, &rhs;          // (V + L, 2), (V + L,): one QP's rows
    std::vector<std::vector<int64_t>>& orders;  // the solver's row order for m rows, kept
    std::vector<int64_t>& order;                // scratch: the order of a QP of many rows
    std::vector<uint8_t>& into;                 // (V,) scratch: the VOs a velocity is in
    std::vector<std::pair<int64_t, int64_t>>& todo;  // the (VO, plane) rows still to build
    RowWork& work;

    void add_rows();                        // builds the rows listed in todo, each once
    int64_t gather(int64_t r, int64_t p);   // QP (r, p)'s rows into rows / rhs: how many
    void solve(int64_t r, int64_t p, const Bounds& b);  // its optimum into sol, key
    SearchResult search(const Bounds& b, double* tried);
    double& key_at(int64_t r, int64_t p) { return key[r * P + p]; }
    uint8_t& included_at(int64_t r, int64_t p, int64_t k) { return included[(r * P + p) * V + k]; }
    const double* sol_at(int64_t r, int64_t p) const { return &sol[2 * (r * P + p)]; }

  private:
    double beyond(int64_t k, int64_t r, int64_t p) const;
    double bound(int64_t r, int64_t p) const;
    void least_round(int64_t p);
    std::pair<int64_t, int64_t> least_key() const;
};

// One decision (the steps of the header). ``nbrs`` (n, 8): position, velocity, r_pz,
// cooperative (1/0); ``prisms`` (m, 4 or 6): x, y, L_pz, h_pz (and the obstacle's height and rim).
inline Decision decide_one(const double* p, const double* v_now, const double* v_pref,
                           const Rows& nbrs, const Rows& prisms, const Bounds& b,
                           const Config& cfg) {
    Decision out{{0.0, 0.0, 0.0}, OPTIMAL, kNaN, PREFERRED, 0};
    double pref[3];
    aimed(v_pref, b, pref);  // 1
    std::vector<NeighbourRow> rows = cone_rows(p, v_now, nbrs, b, cfg);
    std::vector<Pyramid> pyramids = pyramids_in_reach(p, prisms, b, cfg);
    LimitRows limits = limit_rows(p, v_now, nbrs, b, cfg);
    if (pref_clear(p, rows, pyramids, pref, cfg.horizon, cfg.obstacle_horizon) && within_limits(pref, limits, b)) {
        enforce_limits(pref, p, b, out.velocity);  // 2
        return out;
    }
    VOs vos = vos_of(p, pref, rows, std::move(pyramids), b, cfg);  // 3
    int64_t n = vos.n(), V = vos.count();
    std::vector<uint8_t> initial(V);
    bool pref_in = containing(vos, vos.v_pref, cfg.horizon, initial.data());
    for (int64_t k = 0; k < V; ++k) {  // the zones A is inside constrain every QP
        if (k < n ? vos.cones[k].inside : vos.pyramids[k - n].inside)
            initial[k] = 1, out.status = INSIDE_PROTECTED_ZONE;
    }
    // 2 on the cones kept, as the Python formulations check it: pref_clear's answer but for a
    // rounding at min_speed's margin
    if (out.status == OPTIMAL && !pref_in && within_limits(vos.v_pref, limits, b)) {
        enforce_limits(vos.v_pref, p, b, out.velocity);
        return out;
    }
    // an obstacle does not take its share of the avoidance, nor does a vehicle that does not
    // avoid, and a velocity between coarse planes may be the one that clears it under a lag
    bool hazard = has_hazard(vos, nbrs);
    const Config& pc = hazard && cfg.fine ? *cfg.fine : cfg;
    Planes planes = decision_planes(vos, v_now, pc);
    thread_local QPBuffers buffers;
    // the QPs' limits with the climb row (a copy, made only under a prism's top)
    bool climb = under_a_top(vos);
    LimitRows climbing = climb ? qp_limit_rows(limits, vos, pc.margin) : LimitRows{};
    PlaneQPs qps(vos, planes, climb ? climbing : limits, initial, pc, true, buffers);
    // at most every QP once, then once per VO it gains; only the answers written are read
    buffers.tried.resize(3 * ROUNDS * planes.count() * (V + 1));
    double* tried = buffers.tried.data();
    SearchResult s = qps.search(b, tried);  // 4
    out.solved = s.solved;
    double v[3];
    if (s.r >= 0) {
        lift(planes, qps.sol_at(s.r, s.p), s.p, v);
        enforce_limits(v, p, b, out.velocity);
        out.phi = pc.phi[s.p], out.round = 1 + s.r;
        return out;
    }
    Grid grid = grid_of(b, pc, hazard);  // 5
    Cover cover;
    Found f = grid_search(vos, planes, grid, limits, b, pc, cover);
    if (f.found) {
        enforce_limits(f.v, p, b, out.velocity);
        out.phi = pc.phi[f.plane], out.round = SAMPLED;
        return out;
    }
    Rows answers{tried, s.n_tried, 3, 3, 1};
    least_bad(vos, planes, grid, cover, answers, p, v_now, limits, b, pc, v);
    enforce_limits(v, p, b, out.velocity);  // 6
    out.status = INFEASIBLE_MIN_VIOLATION, out.phi = kNaN, out.round = LEAST_BAD;
    return out;
}

// ------------------------------------------------------------------------------ the plane QPs

// The QPs of one decision, each starting with the rows of the ``initial`` VOs (those holding the
// preferred velocity, and the zones A is inside) on every plane. ``lazy``: built on plane 0
// only, and elsewhere only the probe's (the initial VO farthest from w0 on plane 0): search
// completes a plane when one of its QPs first comes up (a lower bound from the probe alone is
// still a lower bound, so no answer changes; planes that never come up are never built).
inline PlaneQPs::PlaneQPs(const VOs& vos_, const Planes& planes_, const LimitRows& limits_,
                          const std::vector<uint8_t>& initial, const Config& cfg_, bool lazy,
                          QPBuffers& buf)
    : vos(vos_), planes(planes_), limits(limits_), cfg(cfg_), V(vos_.count()),
      P(planes_.count()), L(limits_.count()), vo_rows(buf.vo_rows), active(buf.active),
      computed(buf.computed), base(buf.base), based(buf.based), included(buf.included),
      starts(buf.starts), G_lim(buf.G_lim), key(buf.key), sol(buf.sol), exact(buf.exact),
      complete(buf.complete), plane_key(buf.plane_key), plane_r(buf.plane_r), rows(buf.rows),
      rhs(buf.rhs), orders(buf.orders), order(buf.order), into(buf.into), todo(buf.todo),
      work(buf.work) {
    // each read only once written (vo_rows once computed, sol once solved...) but for these
    vo_rows.resize(V * P), active.assign(V * P, 0), computed.assign(V * P, 0);
    if (int64_t(base.size()) < V) base.resize(V);  // never shrunk: each keeps its capacity
    based.assign(V, 0), included.assign(ROUNDS * P * V, 0), G_lim.resize(P * L * 2);
    key.assign(ROUNDS * P, kInf), sol.resize(ROUNDS * P * 2), exact.assign(ROUNDS * P, 0);
    complete.assign(P, 1), plane_key.resize(P), plane_r.resize(P), rows.resize((V + L) * 2);
    rhs.resize(V + L), order.resize(V + L), into.resize(V), starts.clear(), todo.clear();
    work.resize(cfg_.samples());
    for (int64_t p = 0; p < P; ++p) {  // the 3D limit rows G3 v <= h3 on P_phi: G3 [e1, e2(phi)]
        for (int64_t j = 0; j < L; ++j) {
            const double* g = &limits.G[3 * j];
            for (int c = 0; c < 2; ++c) {
                const double* T = planes.to_plane[p].m[c];
                G_lim[(p * L + j) * 2 + c] = g[0] * T[0] + g[1] * T[1] + g[2] * T[2];
            }
        }
    }
    const double* e1 = planes.to_plane[0].m[0];  // v_pref lies in every plane
    w0[0] = e1[0] * vos.v_pref[0] + e1[1] * vos.v_pref[1] + e1[2] * vos.v_pref[2], w0[1] = 0.0;
    for (int64_t k = 0; k < V; ++k)
        if (initial[k]) starts.push_back(k);
    for (int64_t r = 0; r < ROUNDS; ++r)
        for (int64_t p = 0; p < P; ++p)
            for (int64_t k : starts) included_at(r, p, k) = 1;
    for (int64_t k = 0; k < V; ++k)  // the rows every QP starts with (lazy: on plane 0)
        for (int64_t p = 0; p < (lazy ? 1 : P) * initial[k]; ++p) todo.emplace_back(k, p);
    size_t first = todo.size();
    int64_t probe = first ? todo[0].first : 0;
    add_rows();
    if (lazy && first > 1) {
        double far = -kInf;
        for (int64_t k : starts) {
            double d = active[k * P] ? beyond(k, 0, 0) : -kInf;
            if (d > far) probe = k, far = d;
        }
        for (int64_t p = 1; p < P; ++p) complete[p] = 0;
    }
    if (lazy && first >= 1) {  // one initial VO: every plane is complete once it is built
        for (int64_t p = 1; p < P; ++p) todo.emplace_back(probe, p);
        add_rows();
    }
}

// Build the rows of the (VO, plane) pairs in todo (every round), each once.
inline void PlaneQPs::add_rows() {
    for (auto [k, p] : todo) {
        if (computed[k * P + p]) continue;
        if (!based[k]) {
            vo_base(vos, k, planes.frame, cfg, base[k]);
            based[k] = 1;
        }
        active[k * P + p] = plane_rows(vos, k, p, base[k], planes, cfg, w0, vo_rows[k * P + p], work);
        computed[k * P + p] = 1;
    }
    todo.clear();
}

// QP (r, p)'s rows (its VOs', then the limits') into rows / rhs: how many.
inline int64_t PlaneQPs::gather(int64_t r, int64_t p) {
    int64_t m = 0;
    for (int64_t k = 0; k < V; ++k) {
        if (included_at(r, p, k) && active[k * P + p]) {
            const RoundRows& rr = vo_rows[k * P + p];
            rows[2 * m] = rr.G[r][0], rows[2 * m + 1] = rr.G[r][1], rhs[m] = rr.h[r];
            m += 1;
        }
    }
    for (int64_t j = 0; j < L; ++j) {
        rows[2 * m] = G_lim[(p * L + j) * 2], rows[2 * m + 1] = G_lim[(p * L + j) * 2 + 1];
        rhs[m] = limits.h[j];
        m += 1;
    }
    return m;
}

// QP (r, p) solved exactly: its optimum into sol, its deviation into key (inf: infeasible).
inline void PlaneQPs::solve(int64_t r, int64_t p, const Bounds& b) {
    int64_t m = gather(r, p);
    const int64_t* ord = order.data();
    if (m >= int64_t(orders.size())) {  // many rows: the order computed each time
        seidel_order(m, order.data());
    } else {  // the order depends on m alone: computed once per thread
        if (orders[m].empty() && m > 0) {
            orders[m].resize(m);
            seidel_order(m, orders[m].data());
        }
        ord = orders[m].data();
    }
    double* out = &sol[2 * (r * P + p)];
    if (nearest_in_disc({rows.data(), rhs.data(), m}, w0, b.v_max, b.v_min, ord, out))
        key_at(r, p) = std::sqrt(sq(out[0] - w0[0]) + sq(out[1] - w0[1]));
    else
        key_at(r, p) = kInf;
}

// How far w0 lies beyond VO k's half-plane of QP (r, p) (negative: inside it).
inline double PlaneQPs::beyond(int64_t k, int64_t r, int64_t p) const {
    const RoundRows& rr = vo_rows[k * P + p];
    double gx = rr.G[r][0], gy = rr.G[r][1];
    return (gx * w0[0] + gy * w0[1] - rr.h[r]) / std::sqrt(gx * gx + gy * gy);
}

// A lower bound on QP (r, p)'s deviation before it is solved (it then constrains the VOs it
// starts with): its feasible set lies inside each of its half-planes built so far.
inline double PlaneQPs::bound(int64_t r, int64_t p) const {
    double lb = 0.0;
    for (int64_t k : starts) {
        if (active[k * P + p]) {
            double over = beyond(k, r, p);
            if (over > 0.0) lb = std::max(lb, over);
        }
    }
    return lb;
}

// Plane p's least key and the first round that has it.
inline void PlaneQPs::least_round(int64_t p) {
    int64_t br = 0;
    for (int64_t r = 1; r < ROUNDS; ++r)
        if (key[r * P + p] < key[br * P + p]) br = r;
    plane_key[p] = key[br * P + p], plane_r[p] = br;
}

// The first (r, p) of the least key: the least key, then the first round, then the first plane.
inline std::pair<int64_t, int64_t> PlaneQPs::least_key() const {
    const double* pk = plane_key.data();
    const int64_t* pr = plane_r.data();
    double bk = pk[0];
    int64_t br = pr[0], bp = 0;
    for (int64_t p = 1; p < P; ++p)
        if (pk[p] < bk || (pk[p] == bk && pr[p] < br)) bk = pk[p], br = pr[p], bp = p;
    return {br, bp};
}

// Best first over the QPs (step 4): each iteration takes the least key; a plane not yet
// complete gets the rest of its starting rows and new bounds; a bound is replaced by the QP's
// exact optimum; an optimum is checked in 3D: safe (and within the limits) it is the answer,
// else the VOs it entered join that QP, which is solved again. ``tried``: each QP answer in
// solve order, for the least-bad fallback.
inline SearchResult PlaneQPs::search(const Bounds& b, double* tried) {
    SearchResult res{-1, -1, 0, 0};
    double v[3];
    int64_t p = 0;
    for (int64_t it = 0; it < 1 + ROUNDS * P * (2 + 2 * V); ++it) {  // per QP: a solve, each VO
        add_rows();
        if (it == 0) {
            for (int64_t r = 0; r < ROUNDS; ++r)
                for (int64_t q = 0; q < P; ++q) key_at(r, q) = bound(r, q), exact[r * P + q] = 0;
            for (int64_t q = 0; q < P; ++q) least_round(q);
        } else {
            least_round(p);  // only the last plane's keys changed
        }
        auto [r, bp] = least_key();
        p = bp;
        if (key_at(r, p) == kInf) break;
        if (!complete[p]) {  // its bound is the probe's alone: build the rest, bound again
            for (int64_t k = 0; k < V; ++k)
                if (included_at(r, p, k) && !computed[k * P + p]) todo.emplace_back(k, p);
            add_rows();
            for (int64_t rr = 0; rr < ROUNDS; ++rr) key_at(rr, p) = bound(rr, p);
            complete[p] = 1;
            continue;
        }
        if (!exact[r * P + p]) {
            solve(r, p, b);
            exact[r * P + p] = 1;
            res.solved += 1;
            if (key_at(r, p) < kInf) lift(planes, sol_at(r, p), p, &tried[3 * res.n_tried++]);
            continue;
        }
        lift(planes, sol_at(r, p), p, v);
        if (!containing(vos, v, cfg.horizon, into.data())) {
            if (within_limits(v, limits, b)) {
                res.r = r, res.p = p;
                return res;
            }
            key_at(r, p) = kInf;  // outside the limits within tolerance: it gives nothing
            continue;
        }
        bool added = false;
        for (int64_t k = 0; k < V; ++k) {  // constrain the VOs it entered and solve again
            if (into[k] && !included_at(r, p, k)) {
                included_at(r, p, k) = 1, added = true;
                if (!computed[k * P + p]) todo.emplace_back(k, p);
            }
        }
        // Solve it again (its new rows first): 0 is a valid lower bound until then.
        key_at(r, p) = added ? 0.0 : kInf, exact[r * P + p] = !added;
    }
    return res;
}

}  // namespace vo3d
