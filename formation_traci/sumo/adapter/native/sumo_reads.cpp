// _sumo_reads: the members' and neighbours' subscription rows as numpy tables, and the moves
// of the members, through the libsumo C++ API inside the SWIG module libsumo/_libsumo.so that
// Python has already loaded (the SAME SUMO instance as `import libsumo`).
//
// Built and loaded by formation_traci/sumo/native_reads.py (lazily, cached; the SWIG path is
// the fall-back). attach(path) finds the functions with dlopen(path, RTLD_NOW | RTLD_NOLOAD)
// (never a second copy) + dlsym of their mangled names; the signatures are checked against
// the headers of the eclipse-sumo wheel of the same version (static_assert below).
//
// Rules: every SUMO call is inside try/catch (no C++ exception reaches Python); no RTTI
// (TraCIResult::getType() then static_cast); the GIL is held throughout; nothing of SUMO's
// is released or modified by the reads (the subscription stores are read in place with find,
// never operator[], so a read does not add entries).
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#include <dlfcn.h>

#include <exception>
#include <map>
#include <string>
#include <string_view>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include <libsumo/TraCIDefs.h>
#include <libsumo/Vehicle.h>
#include <libsumo/Simulation.h>

using libsumo::ContextSubscriptionResults;
using libsumo::SubscriptionResults;
using libsumo::TraCIResult;
using libsumo::TraCIResults;

// ---- the functions of _libsumo.so (static member functions: plain functions) -------------
typedef const SubscriptionResults (*GetAllFn)();
typedef const ContextSubscriptionResults (*GetAllCtxFn)();
typedef void (*MoveFn)(const std::string&, const std::string&, const int, const double, const double, double,
                       const int, double);
typedef void (*PrevFn)(const std::string&, double, double);
typedef void (*SpeedFn)(const std::string&, double);
typedef double (*DoubleFn)(const std::string&);
typedef std::string (*StringFn)(const std::string&);
typedef libsumo::TraCIPosition (*PosFn)(const std::string&, const bool);
typedef void (*StepFn)(const double);
static_assert(std::is_same_v<GetAllFn, decltype(&libsumo::Vehicle::getAllSubscriptionResults)>);
static_assert(std::is_same_v<GetAllCtxFn, decltype(&libsumo::Vehicle::getAllContextSubscriptionResults)>);
static_assert(std::is_same_v<MoveFn, decltype(&libsumo::Vehicle::moveToXY)>);
static_assert(std::is_same_v<PrevFn, decltype(&libsumo::Vehicle::setPreviousSpeed)>);
static_assert(std::is_same_v<SpeedFn, decltype(&libsumo::Vehicle::setSpeed)>);
static_assert(std::is_same_v<DoubleFn, decltype(&libsumo::Vehicle::getLength)>);
static_assert(std::is_same_v<DoubleFn, decltype(&libsumo::Vehicle::getWidth)>);
static_assert(std::is_same_v<StringFn, decltype(&libsumo::Vehicle::getTypeID)>);
static_assert(std::is_same_v<PosFn, decltype(&libsumo::Vehicle::getPosition)>);
static_assert(std::is_same_v<DoubleFn, decltype(&libsumo::Vehicle::getAngle)>);
static_assert(std::is_same_v<StepFn, decltype(&libsumo::Simulation::step)>);

#define STR_ARG "RKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE"
static const char* SYM_GETALL = "_ZN7libsumo7Vehicle25getAllSubscriptionResultsB5cxx11Ev";
static const char* SYM_GETALLCTX = "_ZN7libsumo7Vehicle32getAllContextSubscriptionResultsB5cxx11Ev";
static const char* SYM_STORE = "_ZN7libsumo7Vehicle21mySubscriptionResultsB5cxx11E";         // private static
static const char* SYM_CTXSTORE = "_ZN7libsumo7Vehicle28myContextSubscriptionResultsB5cxx11E";  // private static
static const char* SYM_MOVE = "_ZN7libsumo7Vehicle8moveToXYE" STR_ARG "S8_idddid";
static const char* SYM_PREV = "_ZN7libsumo7Vehicle16setPreviousSpeedE" STR_ARG "dd";
static const char* SYM_SPEED = "_ZN7libsumo7Vehicle8setSpeedE" STR_ARG "d";
static const char* SYM_LENGTH = "_ZN7libsumo7Vehicle9getLengthE" STR_ARG;
static const char* SYM_WIDTH = "_ZN7libsumo7Vehicle8getWidthE" STR_ARG;
static const char* SYM_TYPE = "_ZN7libsumo7Vehicle9getTypeIDE" STR_ARG;
static const char* SYM_POS = "_ZN7libsumo7Vehicle11getPositionE" STR_ARG "b";
static const char* SYM_ANGLE = "_ZN7libsumo7Vehicle8getAngleE" STR_ARG;
static const char* SYM_STEP = "_ZN7libsumo10Simulation4stepEd";

static GetAllFn p_getAll = nullptr;
static GetAllCtxFn p_getAllCtx = nullptr;
static const SubscriptionResults* p_store = nullptr;
static const ContextSubscriptionResults* p_ctxStore = nullptr;
static MoveFn p_move = nullptr;
static PrevFn p_prev = nullptr;
static SpeedFn p_speed = nullptr;
static DoubleFn p_length = nullptr, p_width = nullptr, p_angle = nullptr;
static PosFn p_pos = nullptr;
static StringFn p_type = nullptr;
static StepFn p_step = nullptr;
static bool g_use_store = true;
static PyObject* g_error = nullptr;  // the class raised for SUMO's errors (libsumo.TraCIException)

// ---- small helpers --------------------------------------------------------------------------
struct Ref {  // owns one reference
    PyObject* p = nullptr;
    Ref() = default;
    explicit Ref(PyObject* o) : p(o) {}
    Ref(const Ref&) = delete;
    Ref& operator=(const Ref&) = delete;
    ~Ref() { Py_XDECREF(p); }
    PyObject* release() { PyObject* o = p; p = nullptr; return o; }
};

static void raise_sumo(const char* what) {
    PyErr_SetString(g_error ? g_error : PyExc_RuntimeError, what);
}

static bool to_std(PyObject* o, std::string& out) {
    Py_ssize_t n;
    const char* s = PyUnicode_AsUTF8AndSize(o, &n);
    if (s == nullptr) return false;
    out.assign(s, (size_t)n);
    return true;
}

static PyObject* new_str(std::string_view s) { return PyUnicode_FromStringAndSize(s.data(), (Py_ssize_t)s.size()); }

// lane ids and vType ids repeat: one Python str each (new reference)
static std::unordered_map<std::string, PyObject*> g_strs;
static PyObject* shared_str(const std::string& s) {
    auto it = g_strs.find(s);
    if (it != g_strs.end()) { Py_INCREF(it->second); return it->second; }
    PyObject* o = new_str(s);
    if (o != nullptr && g_strs.size() < 100000) { Py_INCREF(o); g_strs.emplace(s, o); }
    return o;
}

// a vehicle's body, read once: length, width [m], vType (str), id (str)
struct Body { double length, width; PyObject* type; PyObject* id; };
static std::unordered_map<std::string, Body> g_bodies;
static void drop(Body& b) { Py_XDECREF(b.type); Py_XDECREF(b.id); }

// a subscribed variable of a row (KeyError/TypeError like the Python extraction otherwise)
static const TraCIResult* var(const TraCIResults& r, int v, std::string_view vid, bool (*ok)(int)) {
    auto it = r.find(v);
    if (it == r.end() || !it->second) {
        PyErr_Format(PyExc_KeyError, "vehicle %s: variable 0x%02x not subscribed", std::string(vid).c_str(), v);
        return nullptr;
    }
    const int t = it->second->getType();
    if (!ok(t)) {
        PyErr_Format(PyExc_TypeError, "vehicle %s: variable 0x%02x has type 0x%02x", std::string(vid).c_str(), v, t);
        return nullptr;
    }
    return it->second.get();
}
static bool is_pos(int t) { return t == libsumo::POSITION_2D || t == libsumo::POSITION_3D; }
static bool is_double(int t) { return t == libsumo::TYPE_DOUBLE; }
static bool is_int(int t) { return t == libsumo::TYPE_INTEGER || t == libsumo::TYPE_BYTE || t == libsumo::TYPE_UBYTE; }
static bool is_string(int t) { return t == libsumo::TYPE_STRING; }

static bool get_xy(const TraCIResults& r, std::string_view vid, double* out) {
    auto p = static_cast<const libsumo::TraCIPosition*>(var(r, libsumo::VAR_POSITION, vid, is_pos));
    if (p == nullptr) return false;
    out[0] = p->x;
    out[1] = p->y;
    return true;
}
static bool get_double(const TraCIResults& r, int v, std::string_view vid, double& out) {
    auto p = static_cast<const libsumo::TraCIDouble*>(var(r, v, vid, is_double));
    if (p != nullptr) out = p->value;
    return p != nullptr;
}
static bool get_int(const TraCIResults& r, int v, std::string_view vid, long& out) {
    auto p = static_cast<const libsumo::TraCIInt*>(var(r, v, vid, is_int));
    if (p != nullptr) out = p->value;
    return p != nullptr;
}
static PyObject* get_lane(const TraCIResults& r, std::string_view vid) {  // new reference
    auto p = static_cast<const libsumo::TraCIString*>(var(r, libsumo::VAR_LANE_ID, vid, is_string));
    return p == nullptr ? nullptr : shared_str(p->value);
}

static PyArrayObject* as_f64(PyObject* o, Py_ssize_t n, const char* name) {
    auto a = (PyArrayObject*)PyArray_FROMANY(o, NPY_FLOAT64, 1, 1, NPY_ARRAY_IN_ARRAY);
    if (a != nullptr && PyArray_DIM(a, 0) != n) {
        PyErr_Format(PyExc_ValueError, "%s has %zd values for %zd vehicles", name, (Py_ssize_t)PyArray_DIM(a, 0), n);
        Py_DECREF(a);
        return nullptr;
    }
    return a;
}

#define GUARD_BEGIN try {
#define GUARD_END                                                                        \
    } catch (const std::exception& e) {                                                  \
        if (!PyErr_Occurred()) raise_sumo(e.what());                                     \
    } catch (...) {                                                                      \
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_RuntimeError, "unknown C++ exception"); \
    }                                                                                    \
    return nullptr;

// ---- member_table(ids) -> (table (n, 5), lanes, lane_index) | None -------------------------
static PyObject* member_table(PyObject*, PyObject* args) {
    PyObject* ids_o;
    if (!PyArg_ParseTuple(args, "O", &ids_o)) return nullptr;
    Ref ids(PySequence_Fast(ids_o, "ids must be a sequence of str"));
    if (!ids.p) return nullptr;
    GUARD_BEGIN
    SubscriptionResults copy;
    const SubscriptionResults& all = (g_use_store && p_store) ? *p_store : (copy = p_getAll(), copy);
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(ids.p);
    std::vector<const TraCIResults*> rows((size_t)n);
    std::string vid;
    for (Py_ssize_t i = 0; i < n; ++i) {
        if (!to_std(PySequence_Fast_GET_ITEM(ids.p, i), vid)) return nullptr;
        auto it = all.find(vid);
        if (it == all.end() || it->second.empty()) Py_RETURN_NONE;  // SUMO no longer has it
        rows[i] = &it->second;
    }
    npy_intp dims[2] = {n, 5};
    Ref table(PyArray_SimpleNew(2, dims, NPY_FLOAT64)), lanes(PyList_New(n)), index(PyList_New(n));
    if (!table.p || !lanes.p || !index.p) return nullptr;
    double* tb = (double*)PyArray_DATA((PyArrayObject*)table.p);
    for (Py_ssize_t i = 0; i < n; ++i) {
        const TraCIResults& r = *rows[i];
        const char* s = PyUnicode_AsUTF8(PySequence_Fast_GET_ITEM(ids.p, i));
        double* row = tb + 5 * i;
        long k;
        if (!get_xy(r, s, row) || !get_double(r, libsumo::VAR_ANGLE, s, row[2])
            || !get_double(r, libsumo::VAR_LANEPOSITION_LAT, s, row[3])
            || !get_double(r, libsumo::VAR_LANEPOSITION, s, row[4]) || !get_int(r, libsumo::VAR_LANE_INDEX, s, k))
            return nullptr;
        PyObject* lane = get_lane(r, s);
        PyObject* ki = lane ? PyLong_FromLong(k) : nullptr;
        if (!ki) { Py_XDECREF(lane); return nullptr; }
        PyList_SET_ITEM(lanes.p, i, lane);
        PyList_SET_ITEM(index.p, i, ki);
    }
    return Py_BuildValue("(NNN)", table.release(), lanes.release(), index.release());
    GUARD_END
}

// the body of a row of neighbour_table (read on first sight), or nullptr with an error set
static Body* body_of(const std::string& vid, Ref& id_str) {
    auto it = g_bodies.find(vid);
    if (it != g_bodies.end()) return &it->second;
    try {
        const double length = p_length(vid), width = p_width(vid);
        PyObject* type = shared_str(p_type(vid));
        if (type == nullptr) return nullptr;
        return &g_bodies.emplace(vid, Body{length, width, type, id_str.release()}).first->second;
    } catch (const std::exception& e) {
        raise_sumo(e.what());
    } catch (...) {
        PyErr_SetString(PyExc_RuntimeError, "unknown C++ exception");
    }
    return nullptr;
}

typedef std::map<std::string_view, const TraCIResults*> Rows;  // in byte order = sorted()

static PyObject* table_of(const Rows& rows, PyObject* exclude);

// ---- neighbour_table(owners, exclude) -> (ids, types, lanes, table (m, 7), lane_index) | None
static PyObject* neighbour_table(PyObject*, PyObject* args) {
    PyObject *owners_o, *exclude;
    if (!PyArg_ParseTuple(args, "OO", &owners_o, &exclude)) return nullptr;
    Ref owners(PySequence_Fast(owners_o, "owners must be a sequence of str"));
    if (!owners.p) return nullptr;
    if (exclude == Py_None) exclude = nullptr;
    GUARD_BEGIN
    ContextSubscriptionResults copy;
    const ContextSubscriptionResults& ctx = (g_use_store && p_ctxStore) ? *p_ctxStore : (copy = p_getAllCtx(), copy);
    Rows rows;  // the union of the owners' contexts
    std::string key;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(owners.p); ++i) {
        if (!to_std(PySequence_Fast_GET_ITEM(owners.p, i), key)) return nullptr;
        auto it = ctx.find(key);
        if (it == ctx.end()) continue;
        for (const auto& kv : it->second) rows[kv.first] = &kv.second;  // the last owner's row
    }
    return table_of(rows, exclude);
    GUARD_END
}

// ---- all_table(exclude) -> neighbour_table's result over every vehicle's variable subscription
// (recording every vehicle: each subscribed with the neighbours' variables; empty rows skipped)
static PyObject* all_table(PyObject*, PyObject* exclude) {
    if (exclude == Py_None) exclude = nullptr;
    GUARD_BEGIN
    SubscriptionResults copy;
    const SubscriptionResults& all = (g_use_store && p_store) ? *p_store : (copy = p_getAll(), copy);
    Rows rows;
    for (const auto& kv : all)
        if (!kv.second.empty()) rows[kv.first] = &kv.second;
    return table_of(rows, exclude);
    GUARD_END
}

// the table of neighbour_table and all_table: the rows not in ``exclude``
static PyObject* table_of(const Rows& rows, PyObject* exclude) {
    std::string key;
    std::vector<std::pair<const Body*, const TraCIResults*>> keep;
    keep.reserve(rows.size());
    for (const auto& kv : rows) {
        key.assign(kv.first);
        auto it = g_bodies.find(key);
        Ref id_str(it != g_bodies.end() ? (Py_INCREF(it->second.id), it->second.id) : new_str(key));
        if (!id_str.p) return nullptr;
        const int out = exclude ? PySequence_Contains(exclude, id_str.p) : 0;
        if (out < 0) return nullptr;
        if (out) continue;
        const Body* b = it != g_bodies.end() ? &it->second : body_of(key, id_str);
        if (b == nullptr) return nullptr;
        keep.emplace_back(b, kv.second);
    }
    const Py_ssize_t m = (Py_ssize_t)keep.size();
    if (m == 0) Py_RETURN_NONE;
    npy_intp dims[2] = {m, 7}, dim1[1] = {m};
    Ref ids(PyList_New(m)), types(PyList_New(m)), lanes(PyList_New(m));
    Ref table(PyArray_SimpleNew(2, dims, NPY_FLOAT64)), index(PyArray_SimpleNew(1, dim1, NPY_INT64));
    if (!ids.p || !types.p || !lanes.p || !table.p || !index.p) return nullptr;
    double* tb = (double*)PyArray_DATA((PyArrayObject*)table.p);
    npy_int64* ix = (npy_int64*)PyArray_DATA((PyArrayObject*)index.p);
    for (Py_ssize_t i = 0; i < m; ++i) {
        const Body& b = *keep[i].first;
        const TraCIResults& r = *keep[i].second;
        const char* s = PyUnicode_AsUTF8(b.id);
        double* row = tb + 7 * i;
        long k;
        if (!get_xy(r, s, row) || !get_double(r, libsumo::VAR_ANGLE, s, row[2])
            || !get_double(r, libsumo::VAR_SPEED, s, row[3]) || !get_double(r, libsumo::VAR_ACCELERATION, s, row[4])
            || !get_int(r, libsumo::VAR_LANE_INDEX, s, k))
            return nullptr;
        row[5] = b.length;
        row[6] = b.width;
        ix[i] = k;
        PyObject* lane = get_lane(r, s);
        if (!lane) return nullptr;
        PyList_SET_ITEM(lanes.p, i, lane);
        Py_INCREF(b.id);
        PyList_SET_ITEM(ids.p, i, b.id);
        Py_INCREF(b.type);
        PyList_SET_ITEM(types.p, i, b.type);
    }
    return Py_BuildValue("(NNNNN)", ids.release(), types.release(), lanes.release(), table.release(),
                         index.release());
}

// ---- body(id) -> (length, width, vType): the cached body (read on first sight by either path) -
static PyObject* body(PyObject*, PyObject* id_o) {
    std::string vid;
    if (!to_std(id_o, vid)) return nullptr;
    Py_INCREF(id_o);
    Ref id_str(id_o);
    const Body* b = body_of(vid, id_str);
    if (b == nullptr) return nullptr;
    return Py_BuildValue("(ddO)", b->length, b->width, b->type);
}

// ---- poses(ids) -> table (n, 5): front bumper x, y [m], SUMO angle [deg], length, width [m] --
// the direct getters (getPosition, getAngle, getLength, getWidth) of each vehicle, in one call
static PyObject* poses(PyObject*, PyObject* ids_o) {
    Ref ids(PySequence_Fast(ids_o, "ids must be a sequence of str"));
    if (!ids.p) return nullptr;
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(ids.p);
    npy_intp dims[2] = {n, 5};
    Ref table(PyArray_SimpleNew(2, dims, NPY_FLOAT64));
    if (!table.p) return nullptr;
    double* tb = (double*)PyArray_DATA((PyArrayObject*)table.p);
    GUARD_BEGIN
    std::string vid;
    for (Py_ssize_t i = 0; i < n; ++i) {
        if (!to_std(PySequence_Fast_GET_ITEM(ids.p, i), vid)) return nullptr;
        const libsumo::TraCIPosition p = p_pos(vid, false);
        double* row = tb + 5 * i;
        row[0] = p.x;
        row[1] = p.y;
        row[2] = p_angle(vid);
        row[3] = p_length(vid);
        row[4] = p_width(vid);
    }
    return table.release();
    GUARD_END
}

// ---- move_all(ids, x, y, angle, keep_route, threshold, v=None) -> [(id, message)] of refused moves
// v: each member's speed at the end of the coming step [m/s], commanded with setSpeed after its
// move (SUMO's speed of the member during the step is then ours, not one inferred from the move)
static PyObject* move_all(PyObject*, PyObject* args) {
    PyObject *ids_o, *xo, *yo, *ao, *vo = Py_None;
    int keep;
    double threshold;
    if (!PyArg_ParseTuple(args, "OOOOid|O", &ids_o, &xo, &yo, &ao, &keep, &threshold, &vo)) return nullptr;
    Ref ids(PySequence_Fast(ids_o, "ids must be a sequence of str"));
    if (!ids.p) return nullptr;
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(ids.p);
    Ref x((PyObject*)as_f64(xo, n, "x")), y((PyObject*)as_f64(yo, n, "y")), a((PyObject*)as_f64(ao, n, "angle"));
    Ref v(vo == Py_None ? nullptr : (PyObject*)as_f64(vo, n, "v"));
    Ref refused(PyList_New(0));
    if (!x.p || !y.p || !a.p || !refused.p || (vo != Py_None && !v.p)) return nullptr;
    const double* xp = (const double*)PyArray_DATA((PyArrayObject*)x.p);
    const double* yp = (const double*)PyArray_DATA((PyArrayObject*)y.p);
    const double* ap = (const double*)PyArray_DATA((PyArrayObject*)a.p);
    const double* vp = v.p ? (const double*)PyArray_DATA((PyArrayObject*)v.p) : nullptr;
    GUARD_BEGIN
    static const std::string no_edge;
    std::string vid, msg;
    for (Py_ssize_t i = 0; i < n; ++i) {
        PyObject* id = PySequence_Fast_GET_ITEM(ids.p, i);
        if (!to_std(id, vid)) return nullptr;
        try {
            p_move(vid, no_edge, -1, xp[i], yp[i], ap[i], keep, threshold);
            if (vp != nullptr) p_speed(vid, vp[i] > 0.0 ? vp[i] : 0.0);
            continue;
        } catch (const std::exception& e) {
            msg = e.what();
        } catch (...) {
            msg = "unknown C++ exception";
        }
        Ref item(Py_BuildValue("(Os#)", id, msg.data(), (Py_ssize_t)msg.size()));
        if (!item.p || PyList_Append(refused.p, item.p) < 0) return nullptr;
    }
    return refused.release();
    GUARD_END
}

// ---- set_previous_speeds(ids, v, a): a vehicle SUMO does not have is skipped ----------------
static PyObject* set_previous_speeds(PyObject*, PyObject* args) {
    PyObject *ids_o, *vo, *ao;
    if (!PyArg_ParseTuple(args, "OOO", &ids_o, &vo, &ao)) return nullptr;
    Ref ids(PySequence_Fast(ids_o, "ids must be a sequence of str"));
    if (!ids.p) return nullptr;
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(ids.p);
    Ref v((PyObject*)as_f64(vo, n, "v")), a((PyObject*)as_f64(ao, n, "a"));
    if (!v.p || !a.p) return nullptr;
    const double* vp = (const double*)PyArray_DATA((PyArrayObject*)v.p);
    const double* ap = (const double*)PyArray_DATA((PyArrayObject*)a.p);
    GUARD_BEGIN
    std::string vid;
    for (Py_ssize_t i = 0; i < n; ++i) {
        if (!to_std(PySequence_Fast_GET_ITEM(ids.p, i), vid)) return nullptr;
        try {
            p_prev(vid, vp[i], ap[i]);
        } catch (const libsumo::TraCIException&) {  // not known (any more): skipped
        }
    }
    Py_RETURN_NONE;
    GUARD_END
}

// ---- step(): libsumo::Simulation::step(0.0) (no step listeners) ----------------------------
static PyObject* step(PyObject*, PyObject*) {
    if (p_step == nullptr) {
        PyErr_SetString(PyExc_NotImplementedError, "libsumo::Simulation::step not found");
        return nullptr;
    }
    GUARD_BEGIN
    p_step(0.0);
    Py_RETURN_NONE;
    GUARD_END
}

// ---- the body cache ---------------------------------------------------------------------------
static PyObject* forget(PyObject*, PyObject* ids_o) {
    Ref ids(PySequence_Fast(ids_o, "ids must be a sequence of str"));
    if (!ids.p) return nullptr;
    GUARD_BEGIN
    std::string vid;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(ids.p); ++i) {
        if (!to_std(PySequence_Fast_GET_ITEM(ids.p, i), vid)) return nullptr;
        auto it = g_bodies.find(vid);
        if (it != g_bodies.end()) { drop(it->second); g_bodies.erase(it); }
    }
    Py_RETURN_NONE;
    GUARD_END
}

static PyObject* clear(PyObject*, PyObject*) {
    for (auto& kv : g_bodies) drop(kv.second);
    g_bodies.clear();
    for (auto& kv : g_strs) Py_DECREF(kv.second);
    g_strs.clear();
    Py_RETURN_NONE;
}

static PyObject* bodies(PyObject*, PyObject*) {  // {id: (length, width, vType)} of the cache
    Ref d(PyDict_New());
    if (!d.p) return nullptr;
    for (const auto& kv : g_bodies) {
        Ref v(Py_BuildValue("(ddO)", kv.second.length, kv.second.width, kv.second.type));
        if (!v.p || PyDict_SetItem(d.p, kv.second.id, v.p) < 0) return nullptr;
    }
    return d.release();
}

// ---- attach(path, error=None): find the functions in the loaded _libsumo.so ----------------
static PyObject* attach(PyObject*, PyObject* args) {
    const char* path;
    PyObject* error = Py_None;
    if (!PyArg_ParseTuple(args, "s|O", &path, &error)) return nullptr;
    void* h = dlopen(path, RTLD_NOW | RTLD_NOLOAD);  // only the copy Python loaded, never a second
    if (h == nullptr) {
        const char* why = dlerror();
        PyErr_Format(PyExc_ImportError, "%s is not loaded: %s", path, why ? why : "?");
        return nullptr;
    }
    std::string missing;
    auto need = [&](const char* sym) {
        void* p = dlsym(h, sym);
        if (p == nullptr) missing += std::string(missing.empty() ? "" : ", ") + sym;
        return p;
    };
    p_getAll = (GetAllFn)need(SYM_GETALL);
    p_getAllCtx = (GetAllCtxFn)need(SYM_GETALLCTX);
    p_move = (MoveFn)need(SYM_MOVE);
    p_prev = (PrevFn)need(SYM_PREV);
    p_speed = (SpeedFn)need(SYM_SPEED);
    p_length = (DoubleFn)need(SYM_LENGTH);
    p_width = (DoubleFn)need(SYM_WIDTH);
    p_type = (StringFn)need(SYM_TYPE);
    p_pos = (PosFn)need(SYM_POS);
    p_angle = (DoubleFn)need(SYM_ANGLE);
    p_store = (const SubscriptionResults*)dlsym(h, SYM_STORE);  // optional: else the getAll copies
    p_ctxStore = (const ContextSubscriptionResults*)dlsym(h, SYM_CTXSTORE);
    p_step = (StepFn)dlsym(h, SYM_STEP);  // optional
    if (!missing.empty()) {
        PyErr_Format(PyExc_ImportError, "symbols missing in %s: %s", path, missing.c_str());
        return nullptr;
    }
    Py_XDECREF(g_error);
    g_error = nullptr;
    if (error != Py_None) {
        Py_INCREF(error);
        g_error = error;
    }
    Py_RETURN_NONE;
}

static PyObject* info(PyObject*, PyObject*) {
    Dl_info di;
    const char* where = (p_move && dladdr((void*)p_move, &di) && di.dli_fname) ? di.dli_fname : "";
    return Py_BuildValue("{s:s,s:O,s:O,s:O,s:n,s:n}", "object", where, "store",
                         (p_store && p_ctxStore) ? Py_True : Py_False, "use_store", g_use_store ? Py_True : Py_False,
                         "step", p_step ? Py_True : Py_False, "bodies", (Py_ssize_t)g_bodies.size(), "strings",
                         (Py_ssize_t)g_strs.size());
}

static PyObject* use_store(PyObject*, PyObject* flag) {  // tests: False reads the getAll* copies
    const int on = PyObject_IsTrue(flag);
    if (on < 0) return nullptr;
    const bool before = g_use_store;
    g_use_store = on != 0;
    return PyBool_FromLong(before);
}

static PyMethodDef methods[] = {
    {"attach", attach, METH_VARARGS, "attach(libsumo_so_path, error=None): resolve the libsumo functions"},
    {"member_table", member_table, METH_VARARGS, "member_table(ids) -> (table (n,5), lanes, lane_index) | None"},
    {"neighbour_table", neighbour_table, METH_VARARGS,
     "neighbour_table(owners, exclude) -> (ids, types, lanes, table (m,7), lane_index) | None"},
    {"move_all", move_all, METH_VARARGS, "move_all(ids, x, y, angle, keep_route, threshold, v=None) -> [(id, message)]"},
    {"all_table", all_table, METH_O,
     "all_table(exclude) -> neighbour_table's result over every vehicle's variable subscription"},
    {"body", body, METH_O, "body(id) -> (length, width, vType), read once and cached (as neighbour_table's)"},
    {"poses", poses, METH_O, "poses(ids) -> table (n, 5): front bumper x, y, angle [deg], length, width"},
    {"set_previous_speeds", set_previous_speeds, METH_VARARGS, "set_previous_speeds(ids, v, a)"},
    {"step", step, METH_NOARGS, "libsumo::Simulation::step(0.0)"},
    {"forget", forget, METH_O, "forget(ids): drop the cached bodies of these vehicles"},
    {"clear", clear, METH_NOARGS, "drop every cached body and str"},
    {"bodies", bodies, METH_NOARGS, "the cached bodies {id: (length, width, vType)}"},
    {"info", info, METH_NOARGS, "where the functions were found, and the caches' sizes"},
    {"use_store", use_store, METH_O, "use_store(flag) -> previous flag (read the stores in place or copies)"},
    {nullptr, nullptr, 0, nullptr}};

static struct PyModuleDef moddef = {PyModuleDef_HEAD_INIT, "_sumo_reads", nullptr, -1, methods,
                                    nullptr, nullptr, nullptr, nullptr};

PyMODINIT_FUNC PyInit__sumo_reads(void) {
    import_array();
    return PyModule_Create(&moddef);
}
