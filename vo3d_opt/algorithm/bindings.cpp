// vo3d_opt._core: the algorithm of this folder for Python (nanobind glue, not the algorithm).
//
// Every array argument is checked (convert.hpp): its dtype (float64, int64 or bool as the name
// says), its number of dimensions and its fixed sizes; anything else raises ValueError naming
// the argument, never a crash. The shapes of the Python side travel as tuples of arrays in
// their fields' order; the Python NamedTuples are built from them.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/shared_ptr.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include "convert.hpp"
#include "bind_geometry.hpp"
#include "objects.hpp"

namespace nb = nanobind;
using namespace nb::literals;
using namespace vo3d;
using namespace vo3d::glue;

NB_MODULE(_core, m) {
    m.doc() = "vo3d-opt's compiled core: the decision of vo3d_opt/algorithm/decide.hpp and its parts";
    m.attr("OUT_SIZE") = OUT_SIZE;
    m.attr("MANY_OUT_SIZE") = MANY_OUT_SIZE;
    m.attr("AGENT_COLUMNS") = AGENT_COLUMNS;
    m.attr("FINE_SPEED_LEVELS") = FINE_SPEED_LEVELS;
    m.attr("FINE_HEADING_STEP") = FINE_HEADING_STEP;
    m.attr("LIMIT_TOL") = LIMIT_TOL;
    m.attr("NEVER") = NEVER;

    // The options field by field, named as the Python options they come from where the meaning
    // is the same (Options.config sets them by name); the core checks them when it reads them.
    nb::class_<Corrections>(m, "Corrections", "The corrections of the paper's section 3.1 that apply.")
        .def(nb::init<>())
        .def_rw("tg_range", &Corrections::tg_range)
        .def_rw("symmetry_abs", &Corrections::symmetry_abs)
        .def_rw("triangle", &Corrections::triangle)
        .def_rw("base_chord", &Corrections::base_chord)
        .def_rw("vo_lines", &Corrections::vo_lines)
        .def_rw("virtual_sphere", &Corrections::virtual_sphere);
    nb::class_<Config>(m, "Config", "The formulation options as the core reads them (Options.config).")
        .def(nb::init<>())
        .def_rw("reciprocal", &Config::reciprocal)
        .def_rw("horizon", &Config::horizon)
        .def_rw("obstacle_horizon", &Config::obstacle_horizon)
        .def_rw("pz_buffer", &Config::pz_buffer)
        .def_rw("margin", &Config::margin)
        .def_rw("corrections", &Config::corrections)
        .def_rw("phi", &Config::phi)
        .def_rw("cos_phi", &Config::cos_phi)
        .def_rw("sin_phi", &Config::sin_phi)
        .def_rw("t", &Config::t)
        .def_rw("cos_t", &Config::cos_t)
        .def_rw("sin_t", &Config::sin_t)
        .def_rw("speed_levels", &Config::speed_levels)
        .def_rw("heading_step", &Config::heading_step)
        .def_rw("fallback_speed_levels", &Config::fallback_speed_levels)
        .def_rw("fallback_heading_step", &Config::fallback_heading_step)
        .def_rw("fine", &Config::fine)
        .def_rw("closing_guard", &Config::closing_guard)
        .def_rw("least_bad_escape", &Config::least_bad_escape)
        .def_rw("fine_fallback", &Config::fine_fallback);

    // ------------------------------------------------------------------ the decision
    m.def("decide",
          [](nb::handle p, nb::handle v_now, nb::handle v_pref, nb::handle nbrs, nb::handle prisms,
             nb::handle limits, const Config& cfg_in, nb::handle out) {
              const Config& cfg = checked(cfg_in);
              double P_[3], V[3], W[3];
              vec3(p, "p", P_), vec3(v_now, "v_now", V), vec3(v_pref, "v_pref", W);
              In<double> nb_ = arr<double>(nbrs, "nbrs", {ANY, 8});
              decide_into(P_, V, W, rows_of(nb_), prism_rows_of(prisms), bounds_of_array(limits), cfg, out);
          },
          "p"_a, "v_now"_a, "v_pref"_a, "nbrs"_a, "prisms"_a, "limits"_a, "cfg"_a, "out"_a,
          "One decision (decide.hpp) into out (7,): velocity, status, phi, round, solved.");

    m.def("decide_rows",
          [](nb::handle p, nb::handle v_now, nb::handle v_pref, nb::handle nbrs, nb::handle prisms,
             nb::handle limits, const Config& cfg_in, nb::handle out) {
              const Config& cfg = checked(cfg_in);
              double P_[3], V[3], W[3];
              vec3(p, "p", P_), vec3(v_now, "v_now", V), vec3_of(v_pref, "v_pref", W);
              std::vector<double> nb_buf, pr_buf;
              Rows nb_ = rows_of_tuples(nbrs, "nbrs", 8, nb_buf), pr = prism_rows_of_tuples(prisms, pr_buf);
              decide_into(P_, V, W, nb_, pr, bounds_of(limits), cfg, out);
          },
          "p"_a, "v_now"_a, "v_pref"_a, "nbrs"_a, "prisms"_a, "limits"_a, "cfg"_a, "out"_a,
          "decide with the rows as select holds them: v_pref a tuple of 3 numbers (or an array),\n"
          "nbrs a list of 8-tuples (Neighbor.row) or an (n, 8) array, prisms a list of 6- or 4-tuples\n"
          "(an obstacle's prism) or an (m, 6) or (m, 4) array, limits a tuple of 6 (Bounds).");

    nb::class_<ObjectPath>(m, "ObjectPath", "select() on the default path in one call (objects.hpp).",
                           nb::type_slots(object_path_slots))
        .def("__init__",
             [](ObjectPath* self, nb::dict t) {
                 new (self) ObjectPath(ObjectTypes{
                     t["agent"], t["neighbor"], t["cylinder"], t["box"], t["limits"], t["decision"],
                     t["ndarray"], t["empty"], t["default_limits"], t["statuses"], t["rounds"],
                     t["formulation"], t["solver"], t["clock"], t["bounds_and_config"],
                     nb::cast<double>(t["max_magnitude"])});
             },
             "types"_a)
        // every argument may be None: None is not of the plain kind, and select() words the error
        .def("decide", &ObjectPath::decide, "own"_a.none(), "v_pref"_a.none(), "neighbors"_a.none(),
             "obstacles"_a.none(), "limits"_a.none(), "dt"_a.none(), "t0"_a,
             "The Decision of select(), or None when an input is not of the plain kind.")
        .def("decide_arrays", &ObjectPath::decide_arrays, "position"_a.none(), "velocity"_a.none(),
             "v_pref"_a.none(), "neighbors"_a.none(), "cooperative"_a.none(), "obstacles"_a.none(),
             "limits"_a.none(), "dt"_a.none(), "t0"_a,
             "The Decision of select_arrays(), or None (decide's rule).");

    m.def("decide_many",
          [](nb::handle swarm, const Config& cfg_in, int64_t threads, nb::handle out, int64_t lo,
             int64_t hi) {
              const Config& cfg = checked(cfg_in);
              nb::tuple t = fields(swarm, "swarm", 11);
              In<double> agents = arr<double>(t[0], "agents", {ANY, AGENT_COLUMNS});
              int64_t N = agents.shape(0);
              In<double> limits = arr<double>(t[1], "limits", {N, 6});
              In<int64_t> who = arr<int64_t>(t[2], "who", {ANY});
              int64_t D = who.shape(0);
              In<int64_t> nb_span = arr<int64_t>(t[3], "nb_span", {D, 2}), nb_idx = arr<int64_t>(t[4], "nb_idx", {ANY});
              In<double> spheres = arr<double>(t[5], "spheres", {ANY, 4});
              In<int64_t> sp_span = arr<int64_t>(t[6], "sp_span", {D, 2}), sp_idx = arr<int64_t>(t[7], "sp_idx", {ANY});
              Rows prisms = prism_rows_of(t[8]);
              In<int64_t> ob_span = arr<int64_t>(t[9], "ob_span", {D, 2}), ob_idx = arr<int64_t>(t[10], "ob_idx", {ANY});
              Out<double> o = out_arr<double>(out, "out", {D, MANY_OUT_SIZE});
              if (!c_contig(o) || !c_contig(who))
                  throw nb::value_error("out, who: expected C-contiguous arrays");
              for (int64_t d = 0; d < D; ++d)
                  if (who.data()[d] < 0 || who.data()[d] >= N) throw nb::value_error("who: index out of range");
              Swarm sw{rows_of(agents), rows_of(limits), who.data(), D,
                       links_of(nb_span, nb_idx, D, "nb_span"), rows_of(spheres),
                       links_of(sp_span, sp_idx, D, "sp_span"), prisms,
                       links_of(ob_span, ob_idx, D, "ob_span")};
              check_indices(nb_span, nb_idx, N, "nb_idx");
              check_indices(sp_span, sp_idx, int64_t(spheres.shape(0)), "sp_idx");
              check_indices(ob_span, ob_idx, prisms.n, "ob_idx");
              if (hi < 0) hi = D;
              if (lo < 0 || lo > hi || hi > D) throw nb::value_error("lo, hi: not a range of the deciding vehicles");
              if (threads < 1) throw nb::value_error("threads: expected at least 1");
              nb::gil_scoped_release free;
              decide_many(sw, cfg, lo, hi, threads, o.data());
          },
          "swarm"_a, "cfg"_a, "threads"_a, "out"_a, "lo"_a = 0, "hi"_a = -1,
          "Deciding vehicles lo <= d < hi of a Swarm (swarm.hpp) into out (D, 9), on threads.");

    m.def("neighbor_lists",
          [](nb::handle a, nb::handle b, nb::handle dist, double sensing_range, nb::handle place,
             int64_t k, nb::handle span) {
              In<int64_t> A = arr<int64_t>(a, "a", {ANY});
              int64_t E = A.shape(0);
              In<int64_t> B = arr<int64_t>(b, "b", {E}), pl = arr<int64_t>(place, "place", {ANY});
              In<double> dd = arr<double>(dist, "dist", {E});
              Out<int64_t> sp = out_arr<int64_t>(span, "span", {ANY, 2});
              if (!c_contig(A) || !c_contig(B) || !c_contig(dd) || !c_contig(pl) || !c_contig(sp))
                  throw nb::value_error("neighbor_lists: expected C-contiguous arrays");
              int64_t n = pl.shape(0), D = sp.shape(0);
              for (int64_t e = 0; e < E; ++e)
                  if (A.data()[e] < 0 || A.data()[e] >= n || B.data()[e] < 0 || B.data()[e] >= n)
                      throw nb::value_error("a, b: index out of range");
              for (int64_t i = 0; i < n; ++i)
                  if (pl.data()[i] >= D) throw nb::value_error("place: row out of range");
              std::vector<int64_t> idx = neighbor_lists(A.data(), B.data(), dd.data(), E, sensing_range,
                                                        pl.data(), k, D, sp.data());
              size_t size = idx.size();
              return numpy(std::move(idx), {size});
          },
          "a"_a, "b"_a, "dist"_a, "sensing_range"_a, "place"_a, "k"_a, "span"_a);

    m.def("nearest_lists",
          [](nb::handle P, nb::handle who, nb::handle near, nb::handle far, double sensing_range,
             nb::handle chosen) {
              In<double> pos = arr<double>(P, "P", {ANY, 3});
              In<int64_t> w = arr<int64_t>(who, "who", {ANY});
              int64_t D = w.shape(0);
              In<int64_t> nr = arr<int64_t>(near, "near", {D, ANY});
              int64_t K = nr.shape(1);
              In<double> fr = arr<double>(far, "far", {D, K});
              Out<int64_t> ch = out_arr<int64_t>(chosen, "chosen", {D, ANY});
              int64_t k = ch.shape(1);
              if (!c_contig(w) || !c_contig(nr) || !c_contig(fr) || !c_contig(ch)) throw nb::value_error("nearest_lists: expected C-contiguous arrays");
              if (k < 1 || k > K) throw nb::value_error("chosen: expected 1 <= k <= the proposals");
              for (int64_t r = 0; r < D; ++r)
                  if (w.data()[r] < 0 || w.data()[r] >= int64_t(pos.shape(0))) throw nb::value_error("who: index out of range");
              std::vector<uint8_t> settled(D);
              {
                  nb::gil_scoped_release free;
                  nearest_lists(rows_of(pos), w.data(), D, nr.data(), fr.data(), K, sensing_range, k,
                                ch.data(), settled.data());
              }
              return numpy_bool(settled, {size_t(D)});
          },
          "P"_a, "who"_a, "near"_a, "far"_a, "sensing_range"_a, "chosen"_a);

    bind_geometry(m);  // the VOs and their sections, one by one (bind_geometry.hpp)

    // ------------------------------------------------------------------ build_vos and limits
    m.def("build_vos", [](nb::handle p, nb::handle v_now, nb::handle v_pref, nb::handle nbrs,
                          nb::handle prisms, nb::handle bounds, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        double P_[3], V[3], W[3];
        vec3(p, "p", P_), vec3(v_now, "v_now", V), vec3(v_pref, "v_pref", W);
        Rows nb_ = rows_of(arr<double>(nbrs, "nbrs", {ANY, 8})), pr = prism_rows_of(prisms);
        return vos_to_py(build_vos(P_, V, W, nb_, pr, bounds_of(bounds), cfg));
    });
    m.def("pref_clear", [](nb::handle p, nb::handle v_now, nb::handle v_pref, nb::handle nbrs,
                           nb::handle prisms, nb::handle bounds, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        double P_[3], V[3], W[3], pref[3];
        vec3(p, "p", P_), vec3(v_now, "v_now", V), vec3(v_pref, "v_pref", W);
        Rows nb_ = rows_of(arr<double>(nbrs, "nbrs", {ANY, 8})), pr = prism_rows_of(prisms);
        Bounds b = bounds_of(bounds);
        aimed(W, b, pref);
        return pref_clear(P_, cone_rows(P_, V, nb_, b, cfg), pyramids_in_reach(P_, pr, b, cfg), pref, cfg.horizon,
                          cfg.obstacle_horizon);
    });
    m.def("decision_planes", [](nb::handle vos, nb::handle v_now, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        double V[3];
        vec3(v_now, "v_now", V);
        return planes_to_py(decision_planes(vos_of_py(vos, cfg), V, cfg));
    });
    m.def("limit_rows", [](nb::handle p, nb::handle v_now, nb::handle nbrs, nb::handle bounds, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        double P_[3], V[3];
        vec3(p, "p", P_), vec3(v_now, "v_now", V);
        LimitRows L = limit_rows(P_, V, rows_of(arr<double>(nbrs, "nbrs", {ANY, 8})), bounds_of(bounds), cfg);
        size_t n = L.h.size();
        return nb::make_tuple(numpy(L.G, {n, 3}), numpy(L.h, {n}));
    });
    m.def("escape_rows", [](nb::handle vos, double margin) {
        LimitRows L = qp_limit_rows(LimitRows{}, vos_of_py(vos), margin);
        size_t n = L.h.size();
        return nb::make_tuple(numpy(L.G, {n, 3}), numpy(L.h, {n}));
    });
    m.def("vz_range", [](double z, nb::handle bounds) {
        VzRange r = vz_range(z, bounds_of(bounds));
        return std::make_pair(r.lo, r.hi);
    });
    m.def("enforce_limits", [](nb::handle v, nb::handle p, nb::handle bounds) {
        double x[3], P_[3];
        vec3(v, "v", x), vec3(p, "p", P_);
        std::vector<double> out(3);
        enforce_limits(x, P_, bounds_of(bounds), out.data());
        return numpy(std::move(out), {3});
    });
    auto per_velocity = [](nb::handle v, auto&& fn) {
        Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
        std::vector<double> out;
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            out.push_back(fn(x));
        }
        return numpy(std::move(out), {size_t(vel.n)});
    };
    m.def("closing_rates", [per_velocity](nb::handle vos, nb::handle v) {
        VOs V = vos_of_py(vos);
        return per_velocity(v, [&](const double* x) { return closing_rate(V, x); });
    });
    m.def("times_to_intrusion", [per_velocity](nb::handle vos, nb::handle v) {
        VOs V = vos_of_py(vos);
        int64_t hint = 0;
        return per_velocity(v, [&](const double* x) { return time_to_intrusion(V, x, -1.0, hint); });
    });
    m.def("zone_times", [per_velocity](nb::handle vos, int64_t k, nb::handle v) {
        VOs V = vos_of_py(vos);
        if (k < 0 || k >= V.count()) throw nb::value_error("k: not a zone");
        return per_velocity(v, [&](const double* x) { return zone_time(V, k, x); });
    });
    m.def("zone_time_bound", [](nb::handle vos, int64_t k, nb::handle c, double rho) {
        VOs V = vos_of_py(vos);
        if (k < 0 || k >= V.n()) throw nb::value_error("k: not a cone");
        double x[3];
        vec3(c, "c", x);
        return zone_time_bound(V, k, x, rho);
    });
    m.def("all_within", [](nb::handle v, nb::handle G, nb::handle h, nb::handle bounds) {
        LimitRows L = limits_of(G, h);
        Bounds b = bounds_of(bounds);
        Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
        std::vector<uint8_t> out;
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            out.push_back(within_limits(x, L, b));
        }
        return numpy_bool(out, {size_t(vel.n)});
    });

    // ------------------------------------------------------------------ fallbacks (fallback.hpp)
    m.def("polar_grid", [](nb::handle bounds, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        Grid g = polar(bounds_of(bounds), cfg.speed_levels, cfg.heading_step);
        size_t M = g.points.size() / 2;
        return numpy(g.points, {M, 2});
    });
    m.def("grid_of", [](nb::handle bounds, const Config& cfg_in, bool hazard) {
        const Config& cfg = checked(cfg_in);
        Grid g = grid_of(bounds_of(bounds), cfg, hazard);
        size_t M = size_t(g.size()), B = size_t(g.blocks());
        return nb::make_tuple(numpy(g.points, {M, 2}), numpy(g.block, {M}), numpy(g.discs, {B, 3}));
    });
    m.def("has_hazard", [](nb::handle vos, nb::handle nbrs) {
        return has_hazard(vos_of_py(vos), rows_of(arr<double>(nbrs, "nbrs", {ANY, 8})));
    });
    m.def("fallback", [](nb::handle vos, nb::handle planes, nb::handle tried, nb::handle p, nb::handle v_now,
                         nb::handle G3, nb::handle h3, nb::handle bounds, const Config& cfg_in, bool hazard) {
        const Config& cfg = checked(cfg_in);
        VOs V = vos_of_py(vos, cfg);
        Planes pl = planes_of(planes);
        if (pl.count() != cfg.planes()) throw nb::value_error("planes: expected cfg's planes");
        Rows tr = rows_of(arr<double>(tried, "tried", {ANY, 3}));
        double P_[3], W[3], v[3];
        vec3(p, "p", P_), vec3(v_now, "v_now", W);
        LimitRows L = limits_of(G3, h3);
        Bounds b = bounds_of(bounds);
        Grid g = grid_of(b, cfg, hazard);
        Cover cover;
        Found f = grid_search(V, pl, g, L, b, cfg, cover);
        if (f.found) return std::make_tuple(true, numpy(std::vector<double>(f.v, f.v + 3), {3}), f.plane);
        least_bad(V, pl, g, cover, tr, P_, W, L, b, cfg, v);
        return std::make_tuple(false, numpy(std::vector<double>(v, v + 3), {3}), int64_t(-1));
    });
    m.def("least_bad", [](nb::handle vos, nb::handle planes, nb::handle tried, nb::handle p, nb::handle v_now,
                          nb::handle G3, nb::handle h3, nb::handle bounds, const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        VOs V = vos_of_py(vos, cfg);
        Planes pl = planes_of(planes);
        Rows tr = rows_of(arr<double>(tried, "tried", {ANY, 3}));
        double P_[3], W[3], v[3];
        vec3(p, "p", P_), vec3(v_now, "v_now", W);
        LimitRows L = limits_of(G3, h3);
        Bounds b = bounds_of(bounds);
        Grid g = sampled_grid(b, cfg);
        Cover cover;  // no block known to lie in a cone
        cover.B = g.blocks();
        cover.cone.assign(pl.count() * cover.B, -2);
        least_bad(V, pl, g, cover, tr, P_, W, L, b, cfg, v);
        return numpy(std::vector<double>(v, v + 3), {3});
    });
    m.def("first_safe", [](nb::handle vos, nb::handle v, nb::handle G3, nb::handle h3, nb::handle bounds,
                           const Config& cfg_in) {
        const Config& cfg = checked(cfg_in);
        VOs V = vos_of_py(vos, cfg);
        Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
        LimitRows L = limits_of(G3, h3);
        Bounds b = bounds_of(bounds);
        int64_t hint = 0;
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            if (safe_by_margin(V, x, L, b, cfg, hint)) return k;
        }
        return int64_t(-1);
    });

    // ------------------------------------------------------------------ exact2d, plane QPs
    m.def("nearest_in_disc", [](nb::handle G, nb::handle h, int64_t m_, nb::handle w0, double r_max,
                                double r_min, nb::handle order, nb::handle out) {
        In<double> g = arr<double>(G, "G", {ANY, 2});
        In<double> hh = arr<double>(h, "h", {ANY});
        Out<int64_t> ord = out_arr<int64_t>(order, "order", {ANY});
        Out<double> o = out_arr<double>(out, "out", {2});
        In<double> w = arr<double>(w0, "w0", {2});
        if (m_ < 0 || m_ > int64_t(g.shape(0)) || m_ > int64_t(hh.shape(0)) || m_ > int64_t(ord.shape(0)))
            throw nb::value_error("m: more rows than G, h or order hold");
        std::vector<double> rows(2 * m_), rhs(m_);
        for (int64_t k = 0; k < m_; ++k)
            rows[2 * k] = g.data()[k * g.stride(0)], rows[2 * k + 1] = g.data()[k * g.stride(0) + g.stride(1)],
            rhs[k] = at(hh, k);
        std::vector<int64_t> ordv(m_);
        seidel_order(m_, ordv.data());
        double ww[2] = {at(w, 0), at(w, 1)}, res[2] = {o.data()[0], o.data()[o.stride(0)]};
        bool ok = nearest_in_disc({rows.data(), rhs.data(), m_}, ww, r_max, r_min, ordv.data(), res);
        for (int64_t k = 0; k < m_; ++k) ord.data()[k * ord.stride(0)] = ordv[k];
        o.data()[0] = res[0], o.data()[o.stride(0)] = res[1];
        return ok;
    });
    m.def("lift", [](nb::handle planes, nb::handle w, int64_t p, nb::handle out) {
        Planes pl = planes_of(planes);
        In<double> ww = arr<double>(w, "w", {2});
        Out<double> o = out_arr<double>(out, "out", {3});
        if (p < 0 || p >= pl.count()) throw nb::value_error("p: not a plane");
        double x[2] = {at(ww, 0), at(ww, 1)}, v[3];
        lift(pl, x, p, v);
        for (int c = 0; c < 3; ++c) o.data()[c * o.stride(0)] = v[c];
    });

    nb::class_<PyPlaneQPs>(m, "PlaneQPs",
                           "The (round, plane) QPs of one decision (decide.hpp), for the Python "
                           "search on outside backends; its arrays are views of the C++ state.")
        .def("__init__",
             [](PyPlaneQPs* self, nb::handle vos, nb::handle planes, nb::handle G3, nb::handle h3,
                nb::handle initial, const Config& cfg_in, bool lazy) {
                 const Config& cfg = checked(cfg_in);
                 new (self) PyPlaneQPs();
                 self->vos = vos_of_py(vos, cfg);
                 self->planes = planes_of(planes);
                 self->limits = limits_of(G3, h3);
                 self->cfg = cfg;
                 if (self->planes.count() != cfg.planes()) throw nb::value_error("planes: expected cfg's planes");
                 In<bool> ini = arr<bool>(initial, "initial", {self->vos.count()});
                 std::vector<uint8_t> init(self->vos.count());
                 for (size_t k = 0; k < init.size(); ++k) init[k] = ini.data()[k * ini.stride(0)];
                 self->qps = std::make_unique<PlaneQPs>(self->vos, self->planes, self->limits, init, self->cfg, lazy,
                                                        self->buffers);
             },
             "vos"_a, "planes"_a, "G3"_a, "h3"_a, "initial"_a, "cfg"_a, "lazy"_a)
        .def_prop_ro("key", [](PyPlaneQPs& s) { return view(s, s.qps->key.data(), {ROUNDS, size_t(s.qps->P)}); })
        .def_prop_ro("sol", [](PyPlaneQPs& s) { return view(s, s.qps->sol.data(), {ROUNDS, size_t(s.qps->P), 2}); })
        .def_prop_ro("included", [](PyPlaneQPs& s) {
            return bool_view(s, s.qps->included.data(), {ROUNDS, size_t(s.qps->P), size_t(s.qps->V)});
        })
        .def_prop_ro("w0", [](PyPlaneQPs& s) { return view(s, s.qps->w0, {2}); })
        .def_prop_ro("rows", [](PyPlaneQPs& s) { return view(s, s.qps->rows.data(), {size_t(s.qps->V + s.qps->L), 2}); })
        .def_prop_ro("rhs", [](PyPlaneQPs& s) { return view(s, s.qps->rhs.data(), {size_t(s.qps->V + s.qps->L)}); })
        .def("add_rows",
             [](PyPlaneQPs& s, int64_t k, int64_t p) {
                 check_qp(s, 0, p);
                 if (k < 0 || k >= s.qps->V) throw nb::value_error("k: not a VO of this decision");
                 s.qps->todo.emplace_back(k, p);
                 s.qps->add_rows();
             },
             "k"_a, "p"_a, "Build VO k's rows on plane p (every round), once.")
        .def("gather",
             [](PyPlaneQPs& s, int64_t r, int64_t p) {
                 check_qp(s, r, p);
                 return s.qps->gather(r, p);
             },
             "r"_a, "p"_a, "QP (r, p)'s rows into rows / rhs: how many.")
        .def("solve",
             [](PyPlaneQPs& s, int64_t r, int64_t p, nb::handle bounds) {
                 check_qp(s, r, p);
                 s.qps->solve(r, p, bounds_of(bounds));
             },
             "r"_a, "p"_a, "bounds"_a, "QP (r, p) solved exactly: its optimum into sol, its deviation into key.")
        .def("solve_all",
             [](PyPlaneQPs& s, nb::handle bounds) {
                 Bounds b = bounds_of(bounds);
                 for (int64_t r = 0; r < ROUNDS; ++r)
                     for (int64_t p = 0; p < s.qps->P; ++p) s.qps->solve(r, p, b);
             },
             "bounds"_a, "Every QP solved exactly, as solve(r, p) for each in turn.")
        .def("search",
             [](PyPlaneQPs& s, nb::handle bounds, nb::handle tried) {
                 Out<double> t = out_arr<double>(tried, "tried", {ANY, 3});
                 int64_t need = ROUNDS * s.qps->P * (s.qps->V + 1);
                 if (int64_t(t.shape(0)) < need || !c_contig(t))
                     throw nb::value_error("tried: expected a C-contiguous (3 P (V + 1), 3) array at least");
                 SearchResult r = s.qps->search(bounds_of(bounds), t.data());
                 return std::make_tuple(r.r, r.p, r.solved, r.n_tried);
             },
             "bounds"_a, "tried"_a, "The best-first search of decide.hpp: (r, p, solved, n_tried).")
        // The Python search's checks of an answer, on the VOs, planes and limits held here
        .def("lift",
             [](PyPlaneQPs& s, nb::handle w, int64_t p, nb::handle out) {
                 In<double> ww = arr<double>(w, "w", {2});
                 Out<double> o = out_arr<double>(out, "out", {3});
                 check_qp(s, 0, p);
                 double x[2] = {at(ww, 0), at(ww, 1)}, v[3];
                 lift(s.planes, x, p, v);
                 for (int c = 0; c < 3; ++c) o.data()[c * o.stride(0)] = v[c];
             },
             "w"_a, "p"_a, "out"_a, "Plane p's coordinates w as the world velocity out (3,).")
        .def("entered",
             [](PyPlaneQPs& s, nb::handle v, nb::handle out) {
                 double x[3];
                 vec3(v, "v", x);
                 Out<bool> o = out_arr<bool>(out, "out", {s.vos.count()});
                 std::vector<uint8_t> in(s.vos.count());
                 bool any = containing(s.vos, x, s.cfg.horizon, in.data());
                 for (size_t k = 0; k < in.size(); ++k) o.data()[k * o.stride(0)] = in[k];
                 return any;
             },
             "v"_a, "out"_a, "Which VOs contain v (the exact 3D membership), into out: whether any.")
        .def("within",
             [](PyPlaneQPs& s, nb::handle v, nb::handle bounds) {
                 double x[3];
                 vec3(v, "v", x);
                 return within_limits(x, s.limits, bounds_of(bounds));
             },
             "v"_a, "bounds"_a, "Whether v keeps the speed and the limit rows (within tolerance).");

    // ------------------------------------------------------------------ select_arrays' checks
    m.def("first_bad",
          [](nb::handle values, double max_magnitude, int64_t positive_from) {
              In<double> a = arr<double>(values, "values", {ANY, ANY});
              return first_bad(a, max_magnitude, positive_from);
          },
          "values"_a, "max_magnitude"_a, "positive_from"_a,
          "The flat index of the first entry of values (n, k) that is not finite, beyond\n"
          "max_magnitude, or (in a column from positive_from on) not positive; -1 for none.");

    // ------------------------------------------------------------------ solvers/base.py's checks
    m.def("qp_screen",
          [](nb::handle P, nb::handle q, nb::handle C, nb::handle l, nb::handle u, double r, bool has_r,
             int64_t m_ineq, int64_t m_eq) {
              return qp_screen(arr<double>(P, "P", {ANY, ANY}), arr<double>(q, "q", {ANY}),
                               arr<double>(C, "C", {ANY, ANY}), arr<double>(l, "l", {ANY}),
                               arr<double>(u, "u", {ANY}), r, has_r, m_ineq, m_eq);
          },
          "P"_a, "q"_a, "C"_a, "l"_a, "u"_a, "r"_a, "has_r"_a, "m_ineq"_a, "m_eq"_a,
          "0: fine; 1: NaN or a misplaced infinity; 2: an infinite b; 3: infeasible bounds.");
    m.def("qp_violation",
          [](nb::handle C, nb::handle l, nb::handle u, nb::handle x, double r) {
              In<double> c = arr<double>(C, "C", {ANY, ANY});
              int64_t m_ = c.shape(0), n = c.shape(1);
              In<double> xx = arr<double>(x, "x", {n});
              if (r >= 0.0 && n > 8) throw nb::value_error("x: at most 8 entries with a radius");
              return qp_violation(c, arr<double>(l, "l", {m_}), arr<double>(u, "u", {m_}), xx, r);
          },
          "C"_a, "l"_a, "u"_a, "x"_a, "r"_a,
          "The largest of l - C x, C x - u and (r >= 0) |x| - r; a NaN never wins; -inf for none.");
    m.def("qp_rows_form", &qp_rows_form, "P"_a.none(), "q"_a.none(), "G"_a.none(), "h"_a.none(),
          "0: P, q, G, h fit a solver as they are (float64, C-contiguous, finite, P symmetric);\n"
          "2: the same but some array read-only; 1: anything else.");
    m.def("qp_rows_gap",
          [](nb::handle G, nb::handle h, nb::handle x) {
              In<double> g = arr<double>(G, "G", {ANY, ANY});
              return qp_rows_gap(g, arr<double>(h, "h", {int64_t(g.shape(0))}), x);
          },
          "G"_a, "h"_a, "x"_a, "max(G x - h); +inf when x is not a finite array of G's width.");
}
