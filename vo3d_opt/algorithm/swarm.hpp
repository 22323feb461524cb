// select_many's per-vehicle loop: every deciding vehicle of a swarm decided by decide_one, on
// several threads, and the neighbour lists that say who senses whom.
//
// The Python side (vo3d_opt.swarm) finds who senses whom with a k-d tree and hands the answer
// over as index lists (vehicle d's neighbours are nb_idx[nb_span[d][0]:nb_span[d][1]], the same
// for the static spheres and the obstacles). Each vehicle's nbrs and prisms rows are built from
// those lists as select builds them from Neighbor and obstacle objects, so a vehicle gets
// exactly select's answer. The vehicles are independent: the answers do not depend on the
// number of threads.
#pragma once

#include <atomic>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#ifdef _WIN32
#include <process.h>
#define VO3D_GETPID _getpid
#else
#include <unistd.h>
#define VO3D_GETPID getpid
#endif

#include "decide.hpp"

namespace vo3d {

//: Columns of Swarm.agents: position (3), velocity (3), preferred velocity (3), r_pz,
//: cooperative (1: it decides, 0: it keeps its velocity whatever the others do).
constexpr int64_t AGENT_COLUMNS = 11;
//: decide_many's output row: velocity (3), status, phi, round, solved, then the vehicles and the
//: static zones (spheres and obstacles) the vehicle took into account.
constexpr int64_t MANY_OUT_SIZE = 9;
//: Vehicles a thread claims at a time: small enough that the threads finish together (a
//: crowded vehicle costs many times a lone one), large enough to keep the claims cheap.
constexpr int64_t CHUNK = 16;

// An index list per deciding vehicle: items idx[span[d][0]:span[d][1]].
struct Links {
    const int64_t* span;  // (D, 2)
    const int64_t* idx;
    int64_t lo(int64_t d) const { return span[2 * d]; }
    int64_t hi(int64_t d) const { return span[2 * d + 1]; }
};

// One select_many call. Vehicle rows i < N, deciding vehicles d < D.
struct Swarm {
    Rows agents;          // (N, AGENT_COLUMNS)
    Rows limits;          // (N, 6): each vehicle's Bounds
    const int64_t* who;   // (D,) the vehicle index of each deciding vehicle
    int64_t D;
    Links neighbours;     // vehicle indices
    Rows spheres;         // (S, 4): x, y, z, r_pz of static spheres (zero-velocity neighbours)
    Links sphere_links;
    Rows prisms;          // (M, 4 or 6): the obstacles' prisms
    Links obstacle_links;
};

// Vehicle who[d]'s decision into out (MANY_OUT_SIZE,): its neighbours (r_pz = max(own,
// theirs), cooperative when they decide), then the spheres (zero velocity, their own r_pz, not
// cooperative); its obstacles' prisms.
inline void decide_vehicle(const Swarm& sw, int64_t d, const Config& cfg, double* out) {
    const Rows& a = sw.agents;
    int64_t i = sw.who[d];
    const Links &nb = sw.neighbours, &sp = sw.sphere_links, &ob = sw.obstacle_links;
    int64_t n_nb = nb.hi(d) - nb.lo(d), n_sp = sp.hi(d) - sp.lo(d), n_ob = ob.hi(d) - ob.lo(d);
    int64_t w = sw.prisms.m;
    std::vector<double> nbrs(8 * (n_nb + n_sp)), prisms(w * n_ob);
    for (int64_t e = nb.lo(d); e < nb.hi(d); ++e) {
        int64_t j = nb.idx[e];
        double* row = &nbrs[8 * (e - nb.lo(d))];
        for (int c = 0; c < 6; ++c) row[c] = a(j, c);
        row[6] = std::max(a(i, 9), a(j, 9)), row[7] = a(j, 10);
    }
    for (int64_t e = sp.lo(d); e < sp.hi(d); ++e) {
        int64_t s = sp.idx[e];
        double* row = &nbrs[8 * (n_nb + e - sp.lo(d))];
        for (int c = 0; c < 3; ++c) row[c] = sw.spheres(s, c), row[3 + c] = 0.0;
        row[6] = sw.spheres(s, 3), row[7] = 0.0;
    }
    for (int64_t e = ob.lo(d); e < ob.hi(d); ++e)
        for (int64_t c = 0; c < w; ++c) prisms[w * (e - ob.lo(d)) + c] = sw.prisms(ob.idx[e], c);
    double p[3], v_now[3], v_pref[3];
    for (int c = 0; c < 3; ++c) p[c] = a(i, c), v_now[c] = a(i, 3 + c), v_pref[c] = a(i, 6 + c);
    Bounds b{sw.limits(i, 0), sw.limits(i, 1), sw.limits(i, 2),
             sw.limits(i, 3), sw.limits(i, 4), sw.limits(i, 5)};
    Decision res = decide_one(p, v_now, v_pref, Rows::of(nbrs, 8), Rows::of(prisms, w), b, cfg);
    for (int c = 0; c < 3; ++c) out[c] = res.velocity[c];
    out[3] = double(res.status), out[4] = res.phi, out[5] = double(res.round);
    out[6] = double(res.solved), out[7] = double(n_nb), out[8] = double(n_sp + n_ob);
}

// Helper threads kept from one call to the next: a thread started per call would begin each
// time with a cold memory arena (the decisions allocate their VOs and rows) and cold caches.
// Calls from several Python threads at once take turns. In a child process after a fork the
// helpers are gone: a new pool starts there.
class Helpers {
  public:
    static Helpers& of_this_process() {
        static std::mutex guard;
        static Helpers* pool = nullptr;  // never destroyed: the helpers wait until the exit
        std::lock_guard<std::mutex> hold(guard);
        if (!pool || pool->pid_ != VO3D_GETPID()) pool = new Helpers();
        return *pool;
    }
    // work() on n helper threads and on the calling one; returns when all have finished.
    void run(int64_t n, const std::function<void()>& work) {
        std::lock_guard<std::mutex> turn(call_);
        {
            std::lock_guard<std::mutex> hold(mutex_);
            while (int64_t(started_) < n) std::thread([this, id = started_++] { loop(id); }).detach();
            job_ = &work, wanted_ = n, pending_ = n, ++generation_;
        }
        wake_.notify_all();
        work();
        std::unique_lock<std::mutex> hold(mutex_);
        done_.wait(hold, [this] { return pending_ == 0; });
    }

  private:
    void loop(int64_t id) {
        uint64_t seen = 0;
        std::unique_lock<std::mutex> hold(mutex_);
        for (;;) {
            wake_.wait(hold, [&] { return generation_ != seen; });
            seen = generation_;
            if (id >= wanted_) continue;
            const std::function<void()>* job = job_;
            hold.unlock();
            (*job)();
            hold.lock();
            if (--pending_ == 0) done_.notify_all();
        }
    }
    long pid_ = long(VO3D_GETPID());
    std::mutex call_, mutex_;
    std::condition_variable wake_, done_;
    const std::function<void()>* job_ = nullptr;
    int64_t started_ = 0, wanted_ = 0, pending_ = 0;
    uint64_t generation_ = 0;
};

// Deciding vehicles lo <= d < hi, row d of out (D, MANY_OUT_SIZE) for each, on ``threads``
// threads (the caller's among them): each claims the next CHUNK vehicles until none are left.
inline void decide_many(const Swarm& sw, const Config& cfg, int64_t lo, int64_t hi,
                        int64_t threads, double* out) {
    std::atomic<int64_t> next{lo};
    std::exception_ptr failed;
    std::mutex failed_lock;
    std::function<void()> work = [&]() {
        try {
            for (int64_t start; (start = next.fetch_add(CHUNK)) < hi;)
                for (int64_t d = start; d < std::min(hi, start + CHUNK); ++d)
                    decide_vehicle(sw, d, cfg, &out[MANY_OUT_SIZE * d]);
        } catch (...) {
            std::lock_guard<std::mutex> hold(failed_lock);
            failed = std::current_exception();
        }
    };
    int64_t helpers = std::min(threads, (hi - lo + CHUNK - 1) / CHUNK) - 1;
    if (helpers > 0) Helpers::of_this_process().run(helpers, work);
    else work();
    if (failed) std::rethrow_exception(failed);
}

// ------------------------------------------------------------------------------ neighbour lists

// The pairs (a[e], b[e]) at distance dist[e] as each deciding vehicle's neighbour list (place:
// a vehicle's row, -1 when it does not decide): those within sensing_range, the k nearest of
// them when k >= 0 (ties: the lower index), in increasing index order, into span (D, 2); returns
// the concatenated lists. A counting sort by row: O(pairs).
inline std::vector<int64_t> neighbor_lists(const int64_t* a, const int64_t* b, const double* dist,
                                           int64_t E, double sensing_range, const int64_t* place,
                                           int64_t k, int64_t D, int64_t* span) {
    std::vector<int64_t> start(D + 1, 0);
    for (int64_t e = 0; e < E; ++e) {
        if (dist[e] <= sensing_range) {
            if (place[a[e]] >= 0) start[place[a[e]] + 1] += 1;
            if (place[b[e]] >= 0) start[place[b[e]] + 1] += 1;
        }
    }
    for (int64_t r = 0; r < D; ++r) start[r + 1] += start[r];
    std::vector<int64_t> fill(start.begin(), start.end() - 1), idx(start[D]);
    std::vector<double> near(start[D]);
    for (int64_t e = 0; e < E; ++e) {
        if (!(dist[e] <= sensing_range)) continue;
        for (auto [x, y] : {std::pair{a[e], b[e]}, std::pair{b[e], a[e]}}) {
            int64_t r = place[x];
            if (r >= 0) idx[fill[r]] = y, near[fill[r]] = dist[e], fill[r] += 1;
        }
    }
    std::vector<int64_t> out;
    out.reserve(start[D]);
    std::vector<std::pair<int64_t, double>> row;
    for (int64_t r = 0; r < D; ++r) {
        row.clear();
        for (int64_t q = start[r]; q < start[r + 1]; ++q) row.emplace_back(idx[q], near[q]);
        auto by_index = [](const auto& x, const auto& y) { return x.first < y.first; };
        std::stable_sort(row.begin(), row.end(), by_index);
        int64_t c = int64_t(row.size());
        if (0 <= k && k < c) {  // by distance, stable: ties keep the lower index
            std::stable_sort(row.begin(), row.end(),
                             [](const auto& x, const auto& y) { return x.second < y.second; });
            row.resize(k);
            std::stable_sort(row.begin(), row.end(), by_index);
        }
        span[2 * r] = int64_t(out.size());
        for (const auto& [j, d] : row) out.push_back(j);
        span[2 * r + 1] = int64_t(out.size());
    }
    return out;
}

// numpy's np.linalg.norm(P[i] - P[j]): its squares summed left to right (vo3d_opt.swarm checks
// at import that numpy's reduction over a row of three does so).
inline double pair_distance(const Rows& P, int64_t i, int64_t j) {
    double d0 = P(i, 0) - P(j, 0), d1 = P(i, 1) - P(j, 1), d2 = P(i, 2) - P(j, 2);
    return std::sqrt((d0 * d0 + d1 * d1) + d2 * d2);
}

// Each deciding vehicle's k nearest within sensing_range (ties: the lower index) from the k-d
// tree's proposals (its K nearest: near (D, K) indices, n for none; far (D, K) the tree's
// distances), ranked by numpy's distance, into chosen (D, k) in increasing index order (n for
// none). settled[r]: whether every vehicle the tree did not propose lies clearly beyond the
// k-th nearest (or the range), so that no tie hides beyond the proposals.
inline void nearest_lists(const Rows& P, const int64_t* who, int64_t D, const int64_t* near,
                          const double* far, int64_t K, double sensing_range, int64_t k,
                          int64_t* chosen, uint8_t* settled) {
    int64_t n = P.n;
    std::vector<std::pair<int64_t, double>> keys(K);
    auto by_index = [](const auto& x, const auto& y) { return x.first < y.first; };
    for (int64_t r = 0; r < D; ++r) {
        int64_t i = who[r];
        for (int64_t q = 0; q < K; ++q) {  // out of range or none: (n, inf), after every real one
            int64_t j = near[r * K + q];
            keys[q] = {n, kInf};
            if (j < n && j != i) {
                double d = pair_distance(P, i, j);
                if (d <= sensing_range) keys[q] = {j, d};
            }
        }
        std::stable_sort(keys.begin(), keys.end(), by_index);  // by index, then by distance
        std::stable_sort(keys.begin(), keys.end(),
                         [](const auto& x, const auto& y) { return x.second < y.second; });
        double edge = std::min(keys[k - 1].second, sensing_range);
        double last = far[r * K + K - 1];
        settled[r] = std::isinf(last) || last > edge * (1.0 + 1e-9) + 1e-12;
        std::stable_sort(keys.begin(), keys.begin() + k, by_index);  // in index order, none last
        for (int64_t q = 0; q < k; ++q) chosen[r * k + q] = keys[q].first;
    }
}

}  // namespace vo3d
