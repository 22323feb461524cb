// The geometry's parts for Python one by one (nanobind glue, not the algorithm): the VO cones
// and pyramids (vo.hpp) and their sections on the avoidance planes (sections.hpp), which the
// tests hold against brute force and the Python formulations build on. bindings.cpp calls
// bind_geometry; the conversions are convert.hpp's.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include "convert.hpp"

namespace vo3d::glue {

using namespace nb::literals;

// f(item, velocity) for every item (cone, pyramid) and every row of v (M, 3): an (items, M)
// float64 array.
template <class T, class F>
nb::object per_velocity(const std::vector<T>& items, nb::handle v, F f) {
    Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
    std::vector<double> out;
    out.reserve(items.size() * size_t(vel.n));
    for (const T& item : items)
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            out.push_back(f(item, x));
        }
    return numpy(std::move(out), {items.size(), size_t(vel.n)});
}

inline void bind_geometry(nb::module_& m) {
    // ------------------------------------------------------------------ the VOs (vo.hpp)
    m.def("build_cones", [](nb::handle p_A, nb::handle p_B, nb::handle apex, nb::handle r_pz,
                            double reach, double tau_min) {
        double pa[3];
        vec3(p_A, "p_A", pa);
        In<double> pb = arr<double>(p_B, "p_B", {ANY, 3});
        int64_t n = pb.shape(0);
        In<double> ap = arr<double>(apex, "apex", {n, 3}), r = arr<double>(r_pz, "r_pz", {n});
        std::vector<Cone> cones;
        for (int64_t i = 0; i < n; ++i) {
            double b[3], a[3];
            for (int k = 0; k < 3; ++k)
                b[k] = pb.data()[i * pb.stride(0) + k * pb.stride(1)],
                a[k] = ap.data()[i * ap.stride(0) + k * ap.stride(1)];
            cones.push_back(build_cone(pa, b, a, at(r, i), reach, tau_min));
        }
        return cones_to_py(cones);
    });
    m.def("min_speeds", [](nb::handle cones) {
        std::vector<Cone> c = cones_of(cones);
        std::vector<double> out;
        for (const Cone& cone : c) out.push_back(min_speed(cone));
        size_t n = c.size();
        return numpy(std::move(out), {n});
    });
    m.def("outward_normals", [](nb::handle R, nb::handle sin_alpha, nb::handle t) {
        In<double> r = arr<double>(R, "R", {ANY, 3, 3});
        int64_t n = r.shape(0);
        In<double> sa = arr<double>(sin_alpha, "sin_alpha", {n});
        std::vector<double> ts = vec(t, "t"), out;
        for (int64_t i = 0; i < n; ++i) {
            double M[3][3];
            for (int a = 0; a < 3; ++a)
                for (int c = 0; c < 3; ++c) M[a][c] = r.data()[i * r.stride(0) + a * r.stride(1) + c * r.stride(2)];
            for (double tk : ts) {
                double N[3];
                outward_normal(M, at(sa, i), std::cos(tk), std::sin(tk), N);
                out.insert(out.end(), N, N + 3);
            }
        }
        return numpy(std::move(out), {size_t(n), ts.size(), 3});
    });
    m.def("build_pyramids", [](nb::handle p_A, nb::handle prisms) {
        double pa[3];
        vec3(p_A, "p_A", pa);
        Rows pr = prism_rows_of(prisms);
        std::vector<Pyramid> out;
        for (int64_t j = 0; j < pr.n; ++j) out.push_back(pyramid_of_row(pa, pr, j, pr(j, 3)));
        return pyramids_to_py(out);
    });
    m.def("prism_corners", [](nb::handle frame, nb::handle lo, nb::handle hi) {
        In<double> f = arr<double>(frame, "frame", {ANY, 3, 3});
        int64_t m = f.shape(0);
        In<double> l = arr<double>(lo, "lo", {m, 3}), h = arr<double>(hi, "hi", {m, 3});
        std::vector<double> out(m * 24, 0.0);
        for (int64_t j = 0; j < m; ++j)
            for (int k = 0; k < 8; ++k)
                for (int a = 0; a < 3; ++a) {
                    const In<double>& src = (k >> a) & 1 ? h : l;
                    double local = src.data()[j * src.stride(0) + a * src.stride(1)];
                    for (int c = 0; c < 3; ++c)
                        out[24 * j + 3 * k + c] += local * f.data()[j * f.stride(0) + a * f.stride(1) + c * f.stride(2)];
                }
        return numpy(std::move(out), {size_t(m), 8, 3});
    });
    m.def("avoidance_frame", [](nb::handle direction) {
        double d[3], f[3][3];
        vec3(direction, "direction", d);
        avoidance_frame(d, f);
        return numpy(std::vector<double>(&f[0][0], &f[0][0] + 9), {3, 3});
    });
    m.def("build_planes", [](nb::handle direction, nb::handle phi) {
        double d[3];
        vec3(direction, "direction", d);
        std::vector<double> ph = vec(phi, "phi"), c, s;
        for (double x : ph) c.push_back(std::cos(x)), s.push_back(std::sin(x));
        return planes_to_py(build_planes(d, ph, c, s));
    });
    m.def("in_vos", [](nb::handle cones, nb::handle pyramids, nb::handle v, double horizon, double tol,
                       double obstacle_horizon) {
        VOs vos;
        vos.cones = cones_of(cones), vos.pyramids = pyramids_of(pyramids);
        vos.obstacle_horizon = obstacle_horizon;
        double reach = pyramid_horizon(vos, horizon);
        Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
        int64_t n = vos.n(), count = vos.count();
        std::vector<uint8_t> out(count * vel.n);
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            for (int64_t i = 0; i < n; ++i) out[i * vel.n + k] = in_cone(vos.cones[i], x, horizon, tol);
            for (int64_t j = n; j < count; ++j) out[j * vel.n + k] = in_pyramid(vos.pyramids[j - n], x, reach);
        }
        return numpy_bool(out, {size_t(count), size_t(vel.n)});
    }, "cones"_a, "pyramids"_a, "v"_a, "horizon"_a, "tol"_a, "obstacle_horizon"_a = SAME_HORIZON);
    m.def("cone_penetration", [](nb::handle cones, nb::handle v) {
        return per_velocity(cones_of(cones), v, [](const Cone& c, const double* x) {
            return c.r_pz - approach(c.apex, c.rel, x, NO_HORIZON).closest;
        });
    });
    m.def("entry_times", [](nb::handle pyramids, nb::handle v) {
        return per_velocity(pyramids_of(pyramids), v,
                            [](const Pyramid& py, const double* x) { return entry_time(py, x); });
    });
    m.def("clearances", [](nb::handle cones, nb::handle pyramids, nb::handle v, double horizon,
                           double obstacle_horizon) {
        VOs vos;
        vos.cones = cones_of(cones), vos.pyramids = pyramids_of(pyramids);
        vos.obstacle_horizon = obstacle_horizon;
        Rows vel = rows_of(arr<double>(v, "v", {ANY, 3}));
        std::vector<double> out;
        for (int64_t k = 0; k < vel.n; ++k) {
            double x[3] = {vel(k, 0), vel(k, 1), vel(k, 2)};
            out.push_back(clearance(vos, x, horizon));
        }
        return numpy(std::move(out), {size_t(vel.n)});
    }, "cones"_a, "pyramids"_a, "v"_a, "horizon"_a, "obstacle_horizon"_a = SAME_HORIZON);
    m.def("clearance_floors", [](nb::handle cones, nb::handle v) {
        return per_velocity(cones_of(cones), v, cone_clearance_floor);
    }, "cones"_a, "v"_a);
    m.def("ball_in_cone", [](nb::handle cones, int64_t k, nb::handle c, double rho) {
        std::vector<Cone> cs = cones_of(cones);
        if (k < 0 || k >= int64_t(cs.size())) throw nb::value_error("k: not a cone");
        double x[3];
        vec3(c, "c", x);
        return ball_in_cone(cs[k], x, rho);
    });

    // ------------------------------------------------------------------ sections (sections.hpp)
    m.def("cone_sections", [](nb::handle cones, nb::handle planes, nb::handle t, std::vector<bool> corr) {
        std::vector<Cone> cs = cones_of(cones);
        Planes pl = planes_of(planes);
        std::vector<double> ts = vec(t, "t"), cos_t, sin_t;
        for (double x : ts) cos_t.push_back(std::cos(x)), sin_t.push_back(std::sin(x));
        if (corr.size() != 6) throw nb::value_error("corrections: expected six flags");
        Corrections c{corr[0], corr[1], corr[2], corr[3], corr[4], corr[5]};
        size_t n = cs.size(), P = pl.phi.size(), K = ts.size();
        std::vector<int64_t> kind(n * P);
        std::vector<double> curve(n * P * K * 2), chord(n * P * 4), chord_cs(n * P * 4), apex(n * P * 2),
            sym(n * P * 2), half(n * P * 3);
        Base base;
        Section sec{int64_t(K)};
        for (size_t i = 0; i < n; ++i) {
            base.resize(int64_t(K) + 3);
            cone_base_points(cs[i], pl.frame, cos_t, sin_t, base);
            for (size_t p = 0; p < P; ++p) {
                size_t ip = i * P + p;
                kind[ip] = cone_section(cs[i], base, pl.frame, std::cos(pl.phi[p]), std::sin(pl.phi[p]), c, sec);
                for (size_t k = 0; k < K; ++k) curve[(ip * K + k) * 2] = sec.curve_x[k], curve[(ip * K + k) * 2 + 1] = sec.curve_y[k];
                for (int a = 0; a < 2; ++a) {
                    for (int b = 0; b < 2; ++b) chord[ip * 4 + 2 * a + b] = sec.chord[a][b], chord_cs[ip * 4 + 2 * a + b] = sec.chord_cs[a][b];
                    apex[ip * 2 + a] = sec.apex[a], sym[ip * 2 + a] = sec.symmetry[a];
                }
                for (int a = 0; a < 3; ++a) half[ip * 3 + a] = sec.halfplane[a];
            }
        }
        return nb::make_tuple(numpy(kind, {n, P}), numpy(curve, {n, P, K, 2}), numpy(chord, {n, P, 2, 2}),
                              numpy(chord_cs, {n, P, 2, 2}), numpy(apex, {n, P, 2}), numpy(sym, {n, P, 2}),
                              numpy(half, {n, P, 3}));
    });
    m.def("pyramid_sections", [](nb::handle pyramids, nb::handle planes) {
        std::vector<Pyramid> py = pyramids_of(pyramids);
        Planes pl = planes_of(planes);
        size_t m = py.size(), P = pl.phi.size();
        std::vector<int64_t> kind(m * P);
        std::vector<double> chord(m * P * 4, kNaN), chord_cs(m * P * 4, kNaN), apex(m * P * 2, 0.0),
            sym(m * P * 2, kNaN), half(m * P * 3, 0.0);
        Base base;
        base.resize(9);
        Section sec(0);
        for (size_t j = 0; j < m; ++j) {
            pyramid_base_points(py[j], pl.frame, base);
            for (size_t p = 0; p < P; ++p) {
                size_t jp = j * P + p;
                kind[jp] = pyramid_section(py[j], base, std::cos(pl.phi[p]), std::sin(pl.phi[p]), sec);
                for (int a = 0; a < 2; ++a) {
                    for (int b = 0; b < 2; ++b) chord[jp * 4 + 2 * a + b] = sec.chord[a][b], chord_cs[jp * 4 + 2 * a + b] = sec.chord_cs[a][b];
                    apex[jp * 2 + a] = sec.apex[a], sym[jp * 2 + a] = sec.symmetry[a];
                }
                for (int a = 0; a < 3; ++a) half[jp * 3 + a] = sec.halfplane[a];
            }
        }
        return nb::make_tuple(numpy(kind, {m, P}), numpy(std::vector<double>(), {m, P, 0, 2}),
                              numpy(chord, {m, P, 2, 2}), numpy(chord_cs, {m, P, 2, 2}), numpy(apex, {m, P, 2}),
                              numpy(sym, {m, P, 2}), numpy(half, {m, P, 3}));
    });
    m.def("pick", [](nb::handle curve, nb::handle chord, nb::handle w0) {
        In<double> cu = arr<double>(curve, "curve", {2, ANY});
        In<double> ch = arr<double>(chord, "chord", {2, 2});
        In<double> w = arr<double>(w0, "w0", {2});
        int64_t K = cu.shape(1);
        Section sec(K);
        for (int64_t k = 0; k < K; ++k)
            sec.curve_x[k] = cu.data()[k * cu.stride(1)], sec.curve_y[k] = cu.data()[cu.stride(0) + k * cu.stride(1)];
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b) sec.chord[a][b] = ch.data()[a * ch.stride(0) + b * ch.stride(1)];
        double ww[2] = {at(w, 0), at(w, 1)};
        std::vector<double> dist(K + 2), side(K + 2);
        Picks pk = pick(sec, K, ww, dist, side);
        return std::make_tuple(pk.round[0], pk.round[1], pk.round[2]);
    });
}

}  // namespace vo3d::glue
