// select() and select_arrays() on the default path in one call (nanobind glue, not the
// algorithm): the user's own objects or arrays read where they lie (AgentState's arrays, each
// Neighbor's fields, each obstacle's cached prism, numpy arrays through numpy's array struct),
// one decide_one, and the Decision built here. A decision takes about as long as the Python
// that would check and convert its inputs, so that Python is left out whenever the inputs are
// of the plain kind; anything else (a subclass, a generator, an int dt or int array, a
// non-finite number, an obstacle whose prism is not cached yet, a sensing range) makes
// ``decide`` return None and select() takes its Python path, which gives the same answer or
// words the error. Nothing here runs Python code while it holds a borrowed reference.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstring>

#include "convert.hpp"

#ifndef NPY_NO_DEPRECATED_API
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#endif
#include <numpy/ndarraytypes.h>  // the array struct alone: its fields are read, no API called

namespace vo3d::glue {

// The Python objects select() is given and builds: the exact types read here (a subclass may
// override what is read), the default limits, Decision and its fields' values.
struct ObjectTypes {
    nb::object agent, neighbor, cylinder, box, limits, decision, ndarray, empty;
    nb::object default_limits, statuses, rounds, formulation, solver, clock, bounds_and_config;
    double max_magnitude;  // vo3d_opt.types.MAX_MAGNITUDE
};

// A numpy array read where it lies: numpy's array struct (ndarraytypes.h), its fields alone,
// no call into numpy. The buffer protocol would do the same at several times the cost per
// array, most of a fresh neighbour's reading.
struct Array {
    PyArrayObject* a = nullptr;
    // ``h`` if it is a numpy array (exactly) of ``ndim`` dimensions and items of ``type`` in
    // the machine's byte order; else none (ok() false).
    Array(nb::handle h, const nb::object& ndarray, int ndim, int type) {
        auto* x = reinterpret_cast<PyArrayObject*>(h.ptr());
        if (h.type().is(ndarray) && PyArray_NDIM(x) == ndim && PyArray_TYPE(x) == type &&
            PyArray_ISNOTSWAPPED(x))
            a = x;
    }
    bool ok() const { return a != nullptr; }
    int64_t shape(int d) const { return int64_t(PyArray_DIMS(a)[d]); }
    char* at(int64_t i, int64_t j = 0) const {
        return PyArray_BYTES(a) + i * PyArray_STRIDES(a)[0] + (j ? j * PyArray_STRIDES(a)[1] : 0);
    }
    double number(int64_t i, int64_t j = 0) const {
        double x;
        std::memcpy(&x, at(i, j), sizeof x);
        return x;
    }
};

class ObjectPath {
  public:
    explicit ObjectPath(ObjectTypes t) : t_(std::move(t)) {}

    // Every object held, for Python's cycle collector: the selector holds this path, which
    // holds the selector's bound method (traverse_objects, clear_objects below).
    template <class F>
    void each_object(F f) {
        for (nb::object* o : {&t_.agent, &t_.neighbor, &t_.cylinder, &t_.box, &t_.limits,
                              &t_.decision, &t_.ndarray, &t_.empty, &t_.default_limits,
                              &t_.statuses, &t_.rounds, &t_.formulation, &t_.solver, &t_.clock,
                              &t_.bounds_and_config, &last_limits_, &config_obj_})
            f(*o);
    }

    // The Decision of one select(), or None when an input is not of the plain kind.
    nb::object decide(nb::handle own, nb::handle v_pref, nb::handle neighbors, nb::handle obstacles,
                      nb::handle limits, nb::handle dt, double t0) {
        double p[3], v_now[3], w[3];
        if (!t_.bounds_and_config.is_valid()) return nb::none();  // cleared by the collector
        if (!own.type().is(t_.agent) || !array3(own.attr("position"), p) ||
            !array3(own.attr("velocity"), v_now) || !vector3(v_pref, w))
            return nb::none();
        std::vector<double> nbrs, prisms;  // per call: another thread may decide meanwhile
        auto fields = [this](nb::handle item, double* row) { return neighbour_row(item, row); };
        auto prism = [this](nb::handle item, double* row) { return prism_row(item, row); };
        if (!rows(neighbors, t_.neighbor, t_.neighbor, fields, 8, nbrs) ||
            !rows(obstacles, t_.cylinder, t_.box, prism, PRISM_ROOF_ROW, prisms))
            return nb::none();
        return decided(p, v_now, w, Rows::of(nbrs, 8), Rows::of(prisms, PRISM_ROOF_ROW), limits,
                       dt, t0);
    }

    // The Decision of one select_arrays(), or None when an input is not of the plain kind:
    // float64 numpy arrays (3,), (N, 7) neighbours, cooperative None or (N,) booleans, obstacles
    // None, (M, 6) or (M, 4) rows or a list of Cylinder and Box objects.
    nb::object decide_arrays(nb::handle position, nb::handle velocity, nb::handle v_pref,
                             nb::handle neighbors, nb::handle cooperative, nb::handle obstacles,
                             nb::handle limits, nb::handle dt, double t0) {
        double p[3], v_now[3], w[3];
        if (!t_.bounds_and_config.is_valid()) return nb::none();  // cleared by the collector
        if (!array3(position, p) || !array3(velocity, v_now) || !array3(v_pref, w))
            return nb::none();
        std::vector<double> table, nbrs, prisms;
        if (!neighbors.is_none() && !floats_table(neighbors, 7, 6, table)) return nb::none();
        int64_t n = int64_t(table.size()) / 7;
        nbrs.resize(size_t(8 * n));
        for (int64_t i = 0; i < n; ++i) {
            std::copy_n(&table[size_t(7 * i)], 7, &nbrs[size_t(8 * i)]);
            nbrs[size_t(8 * i + 7)] = 1.0;
        }
        if (!cooperative.is_none() && !flags(cooperative, n, nbrs)) return nb::none();
        int64_t width = PRISM_ROOF_ROW;
        if (PyList_CheckExact(obstacles.ptr()) || PyTuple_CheckExact(obstacles.ptr())) {
            auto prism = [this](nb::handle item, double* row) { return prism_row(item, row); };
            if (!rows(obstacles, t_.cylinder, t_.box, prism, PRISM_ROOF_ROW, prisms))
                return nb::none();
        } else if (!obstacles.is_none()) {
            width = obstacle_width(obstacles);
            if (!width || !floats_table(obstacles, width, 2, prisms)) return nb::none();
        }
        return decided(p, v_now, w, Rows::of(nbrs, 8), Rows::of(prisms, width), limits, dt, t0);
    }

  private:
    ObjectTypes t_;
    // Names looked up in an object's __dict__, made once (their hashes kept)
    nb::str row_key_{"row"}, prism_key_{"prism"}, position_key_{"position"},
        velocity_key_{"velocity"}, r_pz_key_{"r_pz"}, cooperative_key_{"cooperative"};
    nb::object last_limits_, config_obj_;  // the last limits asked with, and their Config
    double last_dt_ = kNaN;
    Bounds bounds_{};

    bool plain(double x) const { return std::fabs(x) <= t_.max_magnitude; }  // NaN fails

    // The limits and the period checked, one decide_one without the interpreter lock, the
    // Decision; None for limits of another kind or a period that is not a positive float.
    nb::object decided(const double* p, const double* v_now, const double* w, Rows nbrs,
                       Rows prisms, nb::handle limits, nb::handle dt, double t0) {
        nb::handle lim = limits.is_none() ? t_.default_limits : limits;
        if (!lim.type().is(t_.limits) || !PyFloat_CheckExact(dt.ptr())) return nb::none();
        double period = PyFloat_AS_DOUBLE(dt.ptr());
        if (!(period > 0.0 && period <= t_.max_magnitude)) return nb::none();
        if (!last_limits_.is(lim) || period != last_dt_) remember(lim, dt, period);
        nb::object held = config_obj_;  // kept alive, whatever another thread remembers
        // checked at every call, as decide_rows does: a Config's fields can be set from Python
        const Config& cfg = checked(nb::cast<const Config&>(held));
        Bounds b = bounds_;
        Decision d;
        {
            nb::gil_scoped_release free;
            d = decide_one(p, v_now, w, nbrs, prisms, b, cfg);
        }
        return answer(d, t0);
    }

    // A float64 numpy array (N, width) into buf row by row: every entry finite and within
    // MAX_MAGNITUDE, positive in the columns from positive_from on (inputs._table's rules).
    bool floats_table(nb::handle h, int64_t width, int64_t positive_from,
                      std::vector<double>& buf) const {
        Array a(h, t_.ndarray, 2, NPY_DOUBLE);
        if (!a.ok() || a.shape(1) != width) return false;
        int64_t n = a.shape(0);
        buf.resize(size_t(n * width));
        for (int64_t i = 0; i < n; ++i)
            for (int64_t j = 0; j < width; ++j) {
                double x = a.number(i, j);
                if (!plain(x) || (j >= positive_from && !(x > 0.0))) return false;
                buf[size_t(i * width + j)] = x;
            }
        return true;
    }

    // The width of a numpy array of obstacle rows, 6 or 4 (no roof); 0 for anything else.
    int64_t obstacle_width(nb::handle h) const {
        Array a(h, t_.ndarray, 2, NPY_DOUBLE);
        int64_t width = a.ok() ? a.shape(1) : 0;
        return width == PRISM_ROOF_ROW || width == PRISM_ROW ? width : 0;
    }

    // A numpy bool array (n,) as the neighbours' cooperative column (8th of each row).
    bool flags(nb::handle h, int64_t n, std::vector<double>& nbrs) const {
        Array a(h, t_.ndarray, 1, NPY_BOOL);
        if (!a.ok() || a.shape(0) != n) return false;
        for (int64_t i = 0; i < n; ++i) nbrs[size_t(8 * i + 7)] = *a.at(i) ? 1.0 : 0.0;
        return true;
    }

    // A float64 numpy array of shape (3,), finite and within MAX_MAGNITUDE (AgentState's
    // fields, a Neighbor's, select_arrays' vectors).
    bool array3(nb::handle h, double* out) const {
        Array a(h, t_.ndarray, 1, NPY_DOUBLE);
        if (!a.ok() || a.shape(0) != 3) return false;
        for (int k = 0; k < 3; ++k) out[k] = a.number(k);
        return plain(out[0]) && plain(out[1]) && plain(out[2]);
    }

    // As inputs.vector3 takes it at once: a tuple or list of three floats or ints (not bools)
    // within MAX_MAGNITUDE, or a float64 array of shape (3,).
    bool vector3(nb::handle h, double* out) const {
        PyObject* x = h.ptr();
        if (!PyTuple_CheckExact(x) && !PyList_CheckExact(x)) return array3(h, out);
        if (PySequence_Fast_GET_SIZE(x) != 3) return false;
        PyObject** items = PySequence_Fast_ITEMS(x);
        for (int k = 0; k < 3; ++k) {
            PyObject* item = items[k];
            if (PyFloat_CheckExact(item)) {
                out[k] = PyFloat_AS_DOUBLE(item);
            } else if (PyLong_CheckExact(item)) {
                out[k] = PyLong_AsDouble(item);
                if (out[k] == -1.0 && PyErr_Occurred()) return PyErr_Clear(), false;
            } else {
                return false;
            }
            if (!plain(out[k])) return false;
        }
        return true;
    }

    // A tuple of ``width`` floats into out.
    static bool floats(PyObject* row, int64_t width, double* out) {
        if (!row || !PyTuple_CheckExact(row) || PyTuple_GET_SIZE(row) != width) return false;
        for (int64_t k = 0; k < width; ++k) {
            PyObject* x = PyTuple_GET_ITEM(row, k);
            if (!PyFloat_CheckExact(x)) return false;
            out[k] = PyFloat_AS_DOUBLE(x);
        }
        return true;
    }

    // An object's __dict__ (a new reference), or an invalid object when it has none.
    static nb::object dict_of(nb::handle item) {
        nb::object dict = nb::steal(PyObject_GenericGetDict(item.ptr(), nullptr));
        if (!dict.is_valid()) PyErr_Clear();
        return dict;
    }

    // An obstacle's prism as cached on it (Cylinder.prism, Box.prism: six floats), read from
    // its __dict__ without running Python; not cached yet: the Python path computes it.
    bool prism_row(nb::handle item, double* out) const {
        nb::object dict = dict_of(item);
        return dict.is_valid() && floats(PyDict_GetItem(dict.ptr(), prism_key_.ptr()), PRISM_ROOF_ROW, out);
    }

    // Neighbor.row without building it: its cached row when it has one, else its fields as
    // they lie in its __dict__ (a neighbour is usually made anew each step, and its row costs
    // the interpreter a microsecond); the same numbers either way.
    bool neighbour_row(nb::handle item, double* out) const {
        nb::object dict = dict_of(item);
        if (!dict.is_valid()) return false;
        PyObject* d = dict.ptr();
        if (PyObject* row = PyDict_GetItem(d, row_key_.ptr())) return floats(row, 8, out);
        PyObject* position = PyDict_GetItem(d, position_key_.ptr());
        PyObject* velocity = PyDict_GetItem(d, velocity_key_.ptr());
        PyObject* r_pz = PyDict_GetItem(d, r_pz_key_.ptr());
        PyObject* cooperative = PyDict_GetItem(d, cooperative_key_.ptr());
        if (!position || !velocity || !r_pz || !PyFloat_CheckExact(r_pz) || !cooperative ||
            !PyBool_Check(cooperative))
            return false;
        out[6] = PyFloat_AS_DOUBLE(r_pz), out[7] = cooperative == Py_True ? 1.0 : 0.0;
        return array3(position, out) && array3(velocity, out + 3);
    }

    // Each item's row (``read``: ``width`` numbers) into buf; the items a list or tuple of
    // objects of type a or b exactly.
    template <class Read>
    static bool rows(nb::handle seq, const nb::object& a, const nb::object& b, Read read,
                     int64_t width, std::vector<double>& buf) {
        PyObject* s = seq.ptr();
        if (!PyList_CheckExact(s) && !PyTuple_CheckExact(s)) return false;
        Py_ssize_t n = PySequence_Fast_GET_SIZE(s);
        buf.resize(size_t(n * width));
        for (Py_ssize_t i = 0; i < n; ++i) {
            nb::handle item = PySequence_Fast_ITEMS(s)[i];
            if (!item.type().is(a) && !item.type().is(b)) return false;
            if (!read(item, buf.data() + i * width)) return false;
        }
        return true;
    }

    // The bounds and the Config of these limits and this period (the selector's own).
    void remember(nb::handle lim, nb::handle dt, double period) {
        nb::tuple got = nb::borrow<nb::tuple>(t_.bounds_and_config(lim, dt, nb::none()));
        bounds_ = bounds_of(got[0]), config_obj_ = got[1];
        last_limits_ = nb::borrow(lim), last_dt_ = period;
    }

    nb::object answer(const Decision& d, double t0) {
        nb::object velocity = t_.empty(3);  // numpy.empty(3), written where it lies
        Array v(velocity, t_.ndarray, 1, NPY_DOUBLE);
        if (!v.ok() || v.shape(0) != 3 || !PyArray_ISWRITEABLE(v.a))
            throw nb::type_error("numpy.empty(3): expected a writable float64 array");
        for (int k = 0; k < 3; ++k) std::memcpy(v.at(k), d.velocity + k, 8);
        nb::dict info;
        info["round"] = t_.rounds[d.round];
        info["solved"] = d.solved;
        double elapsed = nb::cast<double>(t_.clock()) - t0;
        nb::object phi = std::isnan(d.phi) ? nb::none() : nb::cast(d.phi);
        return t_.decision(velocity, t_.statuses[d.status], elapsed, t_.formulation, t_.solver,
                           phi, info);
    }
};

int traverse_objects(PyObject* self, visitproc visit, void* arg) {
    int failed = 0;
    if (nb::inst_ready(self))  // the collector may look before __init__ has run
        nb::inst_ptr<ObjectPath>(self)->each_object([&](nb::object& o) {
            if (!failed && o.ptr()) failed = visit(o.ptr(), arg);
        });
    return failed ? failed : visit(reinterpret_cast<PyObject*>(Py_TYPE(self)), arg);
}

int clear_objects(PyObject* self) {
    if (nb::inst_ready(self))
        nb::inst_ptr<ObjectPath>(self)->each_object([](nb::object& o) { o.reset(); });
    return 0;
}

PyType_Slot object_path_slots[] = {{Py_tp_traverse, (void*)traverse_objects},
                                   {Py_tp_clear, (void*)clear_objects},
                                   {0, nullptr}};

}  // namespace vo3d::glue
