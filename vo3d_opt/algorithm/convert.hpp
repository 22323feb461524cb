// The conversions of the nanobind glue (bindings.cpp), not the algorithm: numpy arrays in,
// checked (dtype, dimensions, fixed sizes: anything else raises ValueError naming the argument,
// never a crash; any strides are read as they are), and numpy arrays out; the Python side's
// shapes (VOCones, VOPyramids, AvoidancePlanes, VOs, Bounds) as tuples of arrays in their
// fields' order.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <memory>
#include <string>

#include "swarm.hpp"

namespace nb = nanobind;

namespace vo3d::glue {


template <class T>
using In = nb::ndarray<const T, nb::device::cpu>;
template <class T>
using Out = nb::ndarray<T, nb::device::cpu>;
constexpr int64_t ANY = -1;

const char* dtype_name(const double*) { return "float64"; }
const char* dtype_name(const int64_t*) { return "int64"; }
const char* dtype_name(const bool*) { return "bool"; }

template <class A>
void check_shape(const A& a, const char* name, const char* dtype, std::initializer_list<int64_t> shape) {
    bool ok = a.ndim() == shape.size();
    size_t i = 0;
    for (int64_t s : shape) {
        if (ok && s != ANY && int64_t(a.shape(i)) != s) ok = false;
        ++i;
    }
    if (ok) return;
    std::string want = "(";
    for (int64_t s : shape) want += (want.size() > 1 ? ", " : "") + (s == ANY ? std::string("n") : std::to_string(s));
    want += ")";
    throw nb::value_error((std::string(name) + ": expected a " + dtype + " array of shape " + want)
                              .c_str());
}

// A read-only array of dtype T and the given shape (ANY: any size), or ValueError.
template <class T>
In<T> arr(nb::handle h, const char* name, std::initializer_list<int64_t> shape) {
    In<T> a;
    if (!nb::try_cast(h, a, false))
        throw nb::value_error((std::string(name) + ": expected a " + dtype_name((T*)nullptr) +
                               " numpy array, got " + nb::type_name(h.type()).c_str())
                                  .c_str());
    check_shape(a, name, dtype_name((T*)nullptr), shape);
    return a;
}

// A writable array of dtype T and the given shape, or ValueError.
template <class T>
Out<T> out_arr(nb::handle h, const char* name, std::initializer_list<int64_t> shape) {
    Out<T> a;
    if (!nb::try_cast(h, a, false))
        throw nb::value_error((std::string(name) + ": expected a writable " +
                               dtype_name((T*)nullptr) + " numpy array")
                                  .c_str());
    check_shape(a, name, dtype_name((T*)nullptr), shape);
    return a;
}

// Whether a is C-contiguous (the strides of dimensions of size 1 do not matter, nor those of
// an empty array).
template <class A>
bool c_contig(const A& a) {
    if (a.size() == 0) return true;
    int64_t expect = 1;
    for (size_t i = a.ndim(); i-- > 0;) {
        if (a.shape(i) > 1 && a.stride(i) != expect) return false;
        expect *= int64_t(a.shape(i));
    }
    return true;
}

Rows rows_of(const In<double>& a) {
    return Rows{a.data(), int64_t(a.shape(0)), int64_t(a.shape(1)), int64_t(a.stride(0)),
                int64_t(a.stride(1))};
}

template <class T>
T at(const In<T>& a, int64_t i) { return a.data()[i * a.stride(0)]; }

void vec3(nb::handle h, const char* name, double* out) {
    In<double> a = arr<double>(h, name, {3});
    for (int k = 0; k < 3; ++k) out[k] = at(a, k);
}

std::vector<double> vec(nb::handle h, const char* name) {
    In<double> a = arr<double>(h, name, {ANY});
    std::vector<double> v(a.shape(0));
    for (size_t k = 0; k < v.size(); ++k) v[k] = at(a, int64_t(k));
    return v;
}

nb::tuple fields(nb::handle h, const char* name, size_t n) {
    if (!nb::isinstance<nb::tuple>(h) || nb::len(h) != n)
        throw nb::value_error((std::string(name) + ": expected a tuple of " + std::to_string(n) +
                               " fields")
                                  .c_str());
    return nb::borrow<nb::tuple>(h);
}

Bounds bounds_of(nb::handle h) {
    nb::tuple t = fields(h, "bounds", 6);
    double v[6];
    for (size_t k = 0; k < 6; ++k) {
        if (!nb::try_cast(t[k], v[k]))
            throw nb::value_error("bounds: expected six numbers (v_min, v_max, z_min, z_max, "
                                  "acceleration, dt)");
    }
    return Bounds{v[0], v[1], v[2], v[3], v[4], v[5]};
}

Bounds bounds_of_array(nb::handle h) {
    In<double> a = arr<double>(h, "limits", {6});
    return Bounds{at(a, 0), at(a, 1), at(a, 2), at(a, 3), at(a, 4), at(a, 5)};
}

// Python tuples of numbers (Neighbor.row, an obstacle's prism, a 3-vector): what select() holds
// already, read without building a numpy array for them. A float is read as it is; any other
// number through its __float__.
double number_of(PyObject* x, const char* name) {
    if (PyFloat_Check(x)) return PyFloat_AS_DOUBLE(x);
    if (PyBool_Check(x) || !PyNumber_Check(x))
        throw nb::value_error((std::string(name) + ": expected numbers").c_str());
    double v = PyFloat_AsDouble(x);
    if (v == -1.0 && PyErr_Occurred()) throw nb::python_error();
    return v;
}

void tuple_into(PyObject* row, const char* name, int64_t width, double* out) {
    if (!PyTuple_Check(row) || PyTuple_GET_SIZE(row) != width)
        throw nb::value_error((std::string(name) + ": expected tuples of " + std::to_string(width) +
                               " numbers")
                                  .c_str());
    for (int64_t k = 0; k < width; ++k) out[k] = number_of(PyTuple_GET_ITEM(row, k), name);
}

// A list (or tuple) of tuples of ``width`` numbers as Rows over ``buf``; or a float64 array
// of shape (n, width) as it is.
Rows rows_of_tuples(nb::handle h, const char* name, int64_t width, std::vector<double>& buf) {
    PyObject* seq = h.ptr();
    if (!PyList_Check(seq) && !PyTuple_Check(seq)) return rows_of(arr<double>(h, name, {ANY, width}));
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    PyObject** items = PySequence_Fast_ITEMS(seq);
    buf.resize(size_t(n * width));
    for (Py_ssize_t i = 0; i < n; ++i) tuple_into(items[i], name, width, buf.data() + i * width);
    return Rows::of(buf, width);
}

// Prism rows: a float64 array of shape (m, 4) or (m, 6) (with the obstacles' height and rim,
// PRISM_ROOF_ROW), as it is.
Rows prism_rows_of(nb::handle h) {
    In<double> a;
    if (!nb::try_cast(h, a, false) || a.ndim() != 2 ||
        (a.shape(1) != PRISM_ROW && a.shape(1) != PRISM_ROOF_ROW))
        throw nb::value_error("prisms: expected a float64 array of shape (n, 4) or (n, 6)");
    return rows_of(a);
}

// Prism rows as select() holds them: a list (or tuple) of obstacles' prisms, tuples of 4 or
// 6 numbers, all of one width, over ``buf``; or an array as prism_rows_of.
Rows prism_rows_of_tuples(nb::handle h, std::vector<double>& buf) {
    PyObject* seq = h.ptr();
    if (!PyList_Check(seq) && !PyTuple_Check(seq)) return prism_rows_of(h);
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    PyObject** items = PySequence_Fast_ITEMS(seq);
    Py_ssize_t width = n && PyTuple_Check(items[0]) ? PyTuple_GET_SIZE(items[0]) : PRISM_ROW;
    for (Py_ssize_t i = 0; i < n; ++i)
        if (!PyTuple_Check(items[i]) || PyTuple_GET_SIZE(items[i]) != width ||
            (width != PRISM_ROW && width != PRISM_ROOF_ROW))
            throw nb::value_error(("prisms[" + std::to_string(i) +
                                   "]: expected tuples of 4 or 6 numbers, all of one width")
                                      .c_str());
    return rows_of_tuples(h, "prisms", width, buf);
}

// A 3-vector from a tuple of three numbers or a float64 array of shape (3,).
void vec3_of(nb::handle h, const char* name, double* out) {
    if (PyTuple_Check(h.ptr())) return tuple_into(h.ptr(), name, 3, out);
    vec3(h, name, out);
}

// ------------------------------------------------------------------------------ to numpy

template <class T>
nb::object numpy(std::vector<T> v, std::initializer_list<size_t> shape) {
    if (v.empty()) v.resize(1);  // a valid pointer for an empty array
    auto* buf = new std::vector<T>(std::move(v));
    nb::capsule owner(buf, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::cast(nb::ndarray<nb::numpy, T>(buf->data(), shape, owner));
}

nb::object numpy_bool(const std::vector<uint8_t>& v, std::initializer_list<size_t> shape) {
    std::vector<uint8_t> copy(v);
    if (copy.empty()) copy.resize(1);
    auto* buf = new std::vector<uint8_t>(std::move(copy));
    nb::capsule owner(buf, [](void* p) noexcept { delete static_cast<std::vector<uint8_t>*>(p); });
    return nb::cast(nb::ndarray<nb::numpy, bool>(reinterpret_cast<bool*>(buf->data()), shape, owner));
}

// ------------------------------------------------------------------------------ the shapes

std::vector<Cone> cones_of(nb::handle h) {
    nb::tuple t = fields(h, "cones", 12);
    In<double> rel = arr<double>(t[0], "cones.rel", {ANY, 3});
    int64_t n = rel.shape(0);
    In<double> apex = arr<double>(t[1], "cones.apex", {n, 3}), r_pz = arr<double>(t[2], "cones.r_pz", {n}),
               d_oi = arr<double>(t[3], "cones.d_oi", {n}), th = arr<double>(t[4], "cones.theta_el", {n}),
               ps = arr<double>(t[5], "cones.psi_az", {n}), R = arr<double>(t[6], "cones.R", {n, 3, 3}),
               d_vo = arr<double>(t[7], "cones.d_vo", {n}), r_vo = arr<double>(t[8], "cones.r_vo", {n}),
               tau = arr<double>(t[9], "cones.tau", {n}), sa = arr<double>(t[10], "cones.sin_alpha", {n});
    In<bool> inside = arr<bool>(t[11], "cones.inside", {n});
    std::vector<Cone> out(n);
    for (int64_t i = 0; i < n; ++i) {
        Cone& c = out[i];
        for (int k = 0; k < 3; ++k) {
            c.rel[k] = rel.data()[i * rel.stride(0) + k * rel.stride(1)];
            c.apex[k] = apex.data()[i * apex.stride(0) + k * apex.stride(1)];
            for (int j = 0; j < 3; ++j)
                c.R[k][j] = R.data()[i * R.stride(0) + k * R.stride(1) + j * R.stride(2)];
        }
        c.r_pz = at(r_pz, i), c.d_oi = at(d_oi, i), c.theta_el = at(th, i), c.psi_az = at(ps, i);
        c.d_vo = at(d_vo, i), c.r_vo = at(r_vo, i), c.tau = at(tau, i), c.sin_alpha = at(sa, i);
        c.inside = inside.data()[i * inside.stride(0)];
    }
    return out;
}

nb::tuple cones_to_py(const std::vector<Cone>& cones) {
    size_t n = cones.size();
    std::vector<double> rel(3 * n), apex(3 * n), R(9 * n), r_pz(n), d_oi(n), th(n), ps(n), d_vo(n),
        r_vo(n), tau(n), sa(n);
    std::vector<uint8_t> inside(n);
    for (size_t i = 0; i < n; ++i) {
        const Cone& c = cones[i];
        for (int k = 0; k < 3; ++k) {
            rel[3 * i + k] = c.rel[k], apex[3 * i + k] = c.apex[k];
            for (int j = 0; j < 3; ++j) R[9 * i + 3 * k + j] = c.R[k][j];
        }
        r_pz[i] = c.r_pz, d_oi[i] = c.d_oi, th[i] = c.theta_el, ps[i] = c.psi_az;
        d_vo[i] = c.d_vo, r_vo[i] = c.r_vo, tau[i] = c.tau, sa[i] = c.sin_alpha, inside[i] = c.inside;
    }
    return nb::make_tuple(numpy(rel, {n, 3}), numpy(apex, {n, 3}), numpy(r_pz, {n}),
                          numpy(d_oi, {n}), numpy(th, {n}), numpy(ps, {n}), numpy(R, {n, 3, 3}),
                          numpy(d_vo, {n}), numpy(r_vo, {n}), numpy(tau, {n}), numpy(sa, {n}),
                          numpy_bool(inside, {n}));
}

std::vector<Pyramid> pyramids_of(nb::handle h) {
    nb::tuple t = fields(h, "pyramids", 7);
    In<double> frame = arr<double>(t[0], "pyramids.frame", {ANY, 3, 3});
    int64_t m = frame.shape(0);
    In<double> lo = arr<double>(t[1], "pyramids.lo", {m, 3}), hi = arr<double>(t[2], "pyramids.hi", {m, 3}),
               L = arr<double>(t[3], "pyramids.L_pz", {m}), H = arr<double>(t[4], "pyramids.h_pz", {m});
    In<bool> inside = arr<bool>(t[5], "pyramids.inside", {m}), roof = arr<bool>(t[6], "pyramids.over_roof", {m});
    std::vector<Pyramid> out(m);
    for (int64_t j = 0; j < m; ++j) {
        Pyramid& py = out[j];
        for (int a = 0; a < 3; ++a) {
            py.lo[a] = lo.data()[j * lo.stride(0) + a * lo.stride(1)];
            py.hi[a] = hi.data()[j * hi.stride(0) + a * hi.stride(1)];
            for (int c = 0; c < 3; ++c)
                py.frame[a][c] = frame.data()[j * frame.stride(0) + a * frame.stride(1) + c * frame.stride(2)];
        }
        py.L_pz = at(L, j), py.h_pz = at(H, j), py.inside = inside.data()[j * inside.stride(0)];
        py.over_roof = roof.data()[j * roof.stride(0)];
    }
    return out;
}

nb::tuple pyramids_to_py(const std::vector<Pyramid>& pyramids) {
    size_t m = pyramids.size();
    std::vector<double> frame(9 * m), lo(3 * m), hi(3 * m), L(m), H(m);
    std::vector<uint8_t> inside(m), roof(m);
    for (size_t j = 0; j < m; ++j) {
        const Pyramid& py = pyramids[j];
        for (int a = 0; a < 3; ++a) {
            lo[3 * j + a] = py.lo[a], hi[3 * j + a] = py.hi[a];
            for (int c = 0; c < 3; ++c) frame[9 * j + 3 * a + c] = py.frame[a][c];
        }
        L[j] = py.L_pz, H[j] = py.h_pz, inside[j] = py.inside, roof[j] = py.over_roof;
    }
    return nb::make_tuple(numpy(frame, {m, 3, 3}), numpy(lo, {m, 3}), numpy(hi, {m, 3}),
                          numpy(L, {m}), numpy(H, {m}), numpy_bool(inside, {m}), numpy_bool(roof, {m}));
}

VOs vos_of_py(nb::handle h) {
    nb::tuple t = fields(h, "vos", 3);
    VOs vos;
    vos.cones = cones_of(t[0]);
    vos.pyramids = pyramids_of(t[1]);
    vec3(t[2], "vos.v_pref", vos.v_pref);
    return vos;
}

// The VOs of a decision with options cfg: its pyramids plan with cfg's obstacle horizon.
VOs vos_of_py(nb::handle h, const Config& cfg) {
    VOs vos = vos_of_py(h);
    vos.obstacle_horizon = cfg.obstacle_horizon;
    return vos;
}

nb::tuple vos_to_py(const VOs& vos) {
    return nb::make_tuple(cones_to_py(vos.cones), pyramids_to_py(vos.pyramids),
                          numpy(std::vector<double>(vos.v_pref, vos.v_pref + 3), {3}));
}

Planes planes_of(nb::handle h) {
    nb::tuple t = fields(h, "planes", 3);
    Planes pl;
    pl.phi = vec(t[0], "planes.phi");
    size_t P = pl.phi.size();
    In<double> frame = arr<double>(t[1], "planes.frame", {3, 3});
    In<double> T = arr<double>(t[2], "planes.to_plane", {int64_t(P), 3, 3});
    for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) pl.frame[a][c] = frame.data()[a * frame.stride(0) + c * frame.stride(1)];
    pl.to_plane.resize(P);
    for (size_t p = 0; p < P; ++p)
        for (int a = 0; a < 3; ++a)
            for (int c = 0; c < 3; ++c)
                pl.to_plane[p].m[a][c] = T.data()[p * T.stride(0) + a * T.stride(1) + c * T.stride(2)];
    if (P == 0) throw nb::value_error("planes.phi: expected at least one plane");
    return pl;
}

nb::tuple planes_to_py(const Planes& pl) {
    size_t P = pl.phi.size();
    std::vector<double> frame(9), T(9 * P);
    for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) {
            frame[3 * a + c] = pl.frame[a][c];
            for (size_t p = 0; p < P; ++p) T[9 * p + 3 * a + c] = pl.to_plane[p].m[a][c];
        }
    return nb::make_tuple(numpy(pl.phi, {P}), numpy(frame, {3, 3}), numpy(T, {P, 3, 3}));
}

LimitRows limits_of(nb::handle G, nb::handle h) {
    In<double> g = arr<double>(G, "G3", {ANY, 3});
    In<double> hh = arr<double>(h, "h3", {int64_t(g.shape(0))});
    LimitRows L;
    for (size_t j = 0; j < g.shape(0); ++j) {
        for (int c = 0; c < 3; ++c) L.G.push_back(g.data()[j * g.stride(0) + c * g.stride(1)]);
        L.h.push_back(at(hh, int64_t(j)));
    }
    return L;
}

Rows nbrs_of(const In<double>& a) { return rows_of(a); }

// ------------------------------------------------------------------------------ one decision

// decide's output: velocity (3), status, phi, round, solved.
constexpr int64_t OUT_SIZE = 7;

// One decision (decide.hpp), the GIL released, into out (OUT_SIZE,).
void decide_into(const double* p, const double* v_now, const double* v_pref, Rows nbrs, Rows prisms,
                 Bounds b, const Config& cfg, nb::handle out) {
    Out<double> o = out_arr<double>(out, "out", {OUT_SIZE});
    Decision d;
    {
        nb::gil_scoped_release free;
        d = decide_one(p, v_now, v_pref, nbrs, prisms, b, cfg);
    }
    double vals[OUT_SIZE] = {d.velocity[0], d.velocity[1], d.velocity[2], double(d.status),
                             d.phi, double(d.round), double(d.solved)};
    for (int64_t k = 0; k < OUT_SIZE; ++k) o.data()[k * o.stride(0)] = vals[k];
}

// ------------------------------------------------------------------------------ the options

// A Config is built field by field from Python (def_rw): before the core reads one, its
// arrays must agree and its grid be a grid, or the core would read past an array's end.
const Config& checked(const Config& c) {
    if (c.phi.empty() || c.cos_phi.size() != c.phi.size() || c.sin_phi.size() != c.phi.size())
        throw nb::value_error("cfg.phi, cfg.cos_phi, cfg.sin_phi: expected arrays of one length, at least 1");
    if (c.t.empty() || c.cos_t.size() != c.t.size() || c.sin_t.size() != c.t.size())
        throw nb::value_error("cfg.t, cfg.cos_t, cfg.sin_t: expected arrays of one length, at least 1");
    if (c.speed_levels < 2) throw nb::value_error("cfg.speed_levels: expected at least 2");
    if (!(c.heading_step > 0.0)) throw nb::value_error("cfg.heading_step: expected a positive angle");
    if (c.fallback_speed_levels < 2)
        throw nb::value_error("cfg.fallback_speed_levels: expected at least 2");
    if (!(c.fallback_heading_step > 0.0))
        throw nb::value_error("cfg.fallback_heading_step: expected a positive angle");
    if (c.fine && c.fine->fine)
        throw nb::value_error("cfg.fine.fine: expected none (the fine planes are one level)");
    if (c.fine) checked(*c.fine);
    return c;
}

// ------------------------------------------------------------------------------ plane QPs

// PlaneQPs with the decision it belongs to, for the Python search on outside backends
// (formulations/plane_qp.py): its arrays are numpy views of the C++ state.
struct PyPlaneQPs {
    VOs vos;
    Planes planes;
    LimitRows limits;
    Config cfg;
    QPBuffers buffers;
    std::unique_ptr<PlaneQPs> qps;
};

template <class T>
nb::object view(PyPlaneQPs& self, T* data, std::initializer_list<size_t> shape) {
    return nb::cast(nb::ndarray<nb::numpy, T>(data, shape, nb::find(&self)));
}

nb::object bool_view(PyPlaneQPs& self, uint8_t* data, std::initializer_list<size_t> shape) {
    return nb::cast(nb::ndarray<nb::numpy, bool>(reinterpret_cast<bool*>(data), shape, nb::find(&self)));
}

void check_qp(const PyPlaneQPs& self, int64_t r, int64_t p) {
    if (r < 0 || r >= ROUNDS || p < 0 || p >= self.qps->P)
        throw nb::value_error("(r, p): not a QP of this decision");
}

// ------------------------------------------------------------------------------ QP checks

// solvers/base.py's screen of a standard-form QP (min ½xᵀPx + qᵀx, l <= C x <= u, the first
// m_ineq rows inequalities, the next m_eq equalities): a dozen numpy reductions on arrays of a
// few tens of entries, in one pass. Finite data: every entry finite and their sum too (as numpy
// judges it from the sum, which also overflows on huge data).
int qp_screen(const In<double>& P, const In<double>& q, const In<double>& C, const In<double>& l,
              const In<double>& u, double r, bool has_r, int64_t m_ineq, int64_t m_eq) {
    double sum = 0.0;
    bool finite = !has_r || std::isfinite(r);
    auto add = [&](const In<double>& a) {
        int64_t rows = a.shape(0), cols = a.ndim() > 1 ? a.shape(1) : 1;
        for (int64_t i = 0; i < rows; ++i)
            for (int64_t j = 0; j < cols; ++j) {
                double x = a.data()[i * a.stride(0) + (a.ndim() > 1 ? j * a.stride(1) : 0)];
                finite = finite && std::isfinite(x), sum += x;
            }
    };
    add(P), add(q), add(C);
    int64_t m = l.shape(0);
    if (int64_t(u.shape(0)) != m) throw nb::value_error("l, u: expected one length");
    bool nan = false, bad = false;
    for (int64_t i = 0; i < m; ++i) {
        double lo = at(l, i), hi = at(u, i);
        nan = nan || std::isnan(lo) || std::isnan(hi);
        bad = bad || !(lo <= hi && lo < kInf && hi > -kInf);
    }
    if (!finite || !std::isfinite(sum) || nan) return 1;
    if (!bad && (!has_r || r >= 0)) return 0;
    for (int64_t i = m_ineq; i < m_ineq + m_eq && i < m; ++i)
        if (std::isinf(at(l, i))) return 2;
    return 3;
}

// Row i of C x, summed column by column as the rows are written (as numpy's column-wise sums
// do).
double row_times(const In<double>& C, const In<double>& x, int64_t i) {
    double cx = 0.0;
    for (int64_t j = 0; j < int64_t(C.shape(1)); ++j)
        cx = cx + C.data()[i * C.stride(0) + j * C.stride(1)] * at(x, j);
    return cx;
}

// The largest of l - C x and C x - u over the rows, each C x summed column by column as the
// rows are written (as numpy's column-wise sums do), and, for r >= 0, of |x| - r (|x|² summed
// left to right, as numpy sums up to 8 entries); a NaN never wins; -inf for nothing.
double qp_violation(const In<double>& C, const In<double>& l, const In<double>& u,
                    const In<double>& x, double r) {
    double worst = -kInf;
    if (r >= 0.0) {
        double sq = 0.0;
        for (int64_t j = 0; j < int64_t(x.shape(0)); ++j) sq = sq + at(x, j) * at(x, j);
        worst = std::sqrt(sq) - r;
        if (std::isnan(worst)) worst = -kInf;
    }
    for (int64_t i = 0; i < int64_t(C.shape(0)); ++i) {
        double cx = row_times(C, x, i);
        double lo = at(l, i) - cx, hi = cx - at(u, i);
        if (lo > worst) worst = lo;
        if (hi > worst) worst = hi;
    }
    return worst;
}

// Whether a QP min ½xᵀPx + qᵀx, G x <= h can go to a solver as it is, without the standard
// form (daqp_backend's short path): 0 when P (n, n), q (n,), G (m, n), h (m,) are C-contiguous
// float64 arrays, every entry finite (their sum too, as qp_screen judges it) and P exactly
// symmetric (so that ½(P + Pᵀ) is P itself); 2 the same but some array read-only (the solver
// wants writable buffers: copies); 1 anything else (the standard form decides what it is).
int qp_rows_form(nb::handle P_, nb::handle q_, nb::handle G_, nb::handle h_) {
    In<double> P, q, G, h;
    bool read_only = false;
    auto take = [&](nb::handle a, In<double>& into) {  // writable first: the usual case, one cast
        Out<double> w;
        if (nb::try_cast(a, w, false)) return into = In<double>(w), true;
        read_only = true;
        return nb::try_cast(a, into, false);
    };
    if (!take(P_, P) || !take(q_, q) || !take(G_, G) || !take(h_, h)) return 1;
    if (q.ndim() != 1 || P.ndim() != 2 || G.ndim() != 2 || h.ndim() != 1) return 1;
    int64_t n = q.shape(0), m = h.shape(0);
    if (n < 1 || int64_t(P.shape(0)) != n || int64_t(P.shape(1)) != n || int64_t(G.shape(0)) != m ||
        int64_t(G.shape(1)) != n || !c_contig(P) || !c_contig(q) || !c_contig(G) || !c_contig(h))
        return 1;
    double sum = 0.0;
    bool finite = true;
    for (const In<double>* a : {&P, &q, &G, &h})
        for (size_t i = 0; i < a->size(); ++i) finite = finite && std::isfinite(a->data()[i]), sum += a->data()[i];
    if (!finite || !std::isfinite(sum)) return 1;
    for (int64_t i = 0; i < n; ++i)
        for (int64_t j = 0; j < i; ++j)
            if (P.data()[i * n + j] != P.data()[j * n + i]) return 1;
    return read_only ? 2 : 0;
}

// max(G x - h) over the rows (row_times, as qp_violation); +inf when x is not a
// finite array of G's width (the caller then takes the standard form's longer check).
double qp_rows_gap(const In<double>& G, const In<double>& h, nb::handle x_) {
    In<double> x;
    int64_t n = G.shape(1);
    if (!nb::try_cast(x_, x, false) || x.ndim() != 1 || int64_t(x.shape(0)) != n) return kInf;
    for (int64_t j = 0; j < n; ++j)
        if (!std::isfinite(at(x, j))) return kInf;
    double worst = -kInf;
    for (int64_t i = 0; i < int64_t(G.shape(0)); ++i) worst = std::max(worst, row_times(G, x, i) - at(h, i));
    return worst;
}

// ------------------------------------------------------------------------------ array checks

// select_arrays' check of a table of numbers in one pass (formulations/inputs.py words the
// error): the flat index of the first entry that is not finite or beyond max_magnitude, or, in
// a column from positive_from on, not positive; -1 for none.
int64_t first_bad(const In<double>& a, double max_magnitude, int64_t positive_from) {
    int64_t rows = a.shape(0), cols = a.shape(1);
    for (int64_t i = 0; i < rows; ++i)
        for (int64_t j = 0; j < cols; ++j) {
            double x = a.data()[i * a.stride(0) + j * a.stride(1)];
            if (!(std::fabs(x) <= max_magnitude) || (j >= positive_from && !(x > 0.0))) return i * cols + j;
        }
    return -1;
}

// ------------------------------------------------------------------------------ swarms

Links links_of(const In<int64_t>& span, const In<int64_t>& idx, int64_t D, const char* name) {
    if (!c_contig(span) || !c_contig(idx))
        throw nb::value_error((std::string(name) + ": expected C-contiguous arrays").c_str());
    int64_t E = idx.shape(0), bound = 0;
    for (int64_t d = 0; d < D; ++d) {
        int64_t lo = span.data()[2 * d], hi = span.data()[2 * d + 1];
        if (lo < 0 || hi < lo || hi > E) throw nb::value_error((std::string(name) + ": span out of range").c_str());
        bound = std::max(bound, hi);
    }
    return Links{span.data(), idx.data()};
}

void check_indices(const In<int64_t>& span, const In<int64_t>& idx, int64_t n, const char* name) {
    for (int64_t d = 0; d < int64_t(span.shape(0)); ++d)
        for (int64_t e = span.data()[2 * d]; e < span.data()[2 * d + 1]; ++e)
            if (idx.data()[e] < 0 || idx.data()[e] >= n)
                throw nb::value_error((std::string(name) + ": index out of range").c_str());
}

}  // namespace vo3d::glue
