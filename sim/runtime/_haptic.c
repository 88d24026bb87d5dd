/* The haptic tick's force path, compiled: from the device's sample to the force command.
 *
 * In the real-time haptic process every tick (1 kHz) does, in this order:
 *   1. publish the holder (time, pose, velocity, grip) to the FEM layer: a seqlock slot;
 *   2. read the FEM layer's force history (a shared ring of (time, force)) at now - delay:
 *      linear between the two outputs around it, held at the ends;
 *   3. scale it (the device's recorded scale factor);
 *   4. the safety filter: a non-finite target becomes zero; a stalled FEM layer ramps the force
 *      to zero (watchdog); the magnitude is clamped to the device's rating; the change from the
 *      last commanded force is limited to the rated force rate;
 *   5. append (time, position, grip, force) to the shared haptic log.
 *
 * The Python versions (sim/runtime/shared.py: SharedHolder, SharedForceHistory,
 * SharedHapticLog; sim/runtime/safety.py: ForceSafety) define the behaviour; this file does the
 * same arithmetic in the same order, so the forces agree bit for bit (tests/sim/test_haptic_kernel.py
 * drives both with the same inputs). Written in Python these steps cost 10-40 us a tick at p99
 * after each wait, with the caches cold; here they are one call.
 *
 * State cells (a float64 array the Python side owns and reads back after the loop):
 *   0-2 last commanded force, 3 last time (NaN: none yet), 4 watchdog since (NaN: not acting),
 *   5 clamping (0/1), 6 non-finite (0/1), 7 the magnitude an event names, 8 the FEM silence an
 *   event names (s).
 * Parameters: stall timeout (s), ramp time (s), max force (N), max force rate (N/s), nominal
 *   tick (s), force delay (s), haptic scale.
 * tick() returns the new events as bits (NONFINITE 1, WATCHDOG 2, RECOVERED 4, CLAMPED 8);
 * the force is written to the output array given at construction.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

enum { LAST_X, LAST_Y, LAST_Z, LAST_TIME, WATCHDOG_SINCE, CLAMPING, NONFINITE, EVENT_MAGNITUDE,
       EVENT_SILENCE, STATE_CELLS };
enum { STALL_TIMEOUT, RAMP_TIME, MAX_FORCE, MAX_FORCE_RATE, TICK, FORCE_DELAY, HAPTIC_SCALE,
       PARAMETERS };
enum { EVENT_NONFINITE = 1, EVENT_WATCHDOG = 2, EVENT_RECOVERED = 4, EVENT_CLAMPED = 8 };
/* The holder slot's fields, in the order ForcePath's holder_layout gives their (start, width): the
 * places come from sim.runtime.snapshots.HOLDER_LAYOUT, the one declaration of the slot. */
enum { H_SEQ, H_TIME, H_POSITION, H_ROTATION, H_VELOCITY, H_GRIP, HOLDER_FIELDS };
static const char *HOLDER_NAMES[] = {"seq", "time", "position", "rotation", "velocity", "grip"};
static const Py_ssize_t HOLDER_WIDTHS[] = {1, 1, 3, 9, 3, 1};
/* A haptic log row's fields, likewise (sim.runtime.snapshots.HAPTIC_LOG_LAYOUT). */
enum { L_TIME, L_POSITION, L_GRIP, L_FORCE, LOG_FIELDS };
static const char *LOG_NAMES[] = {"time", "position", "grip", "force"};
static const Py_ssize_t LOG_WIDTHS[] = {1, 3, 1, 3};

typedef struct {
    PyObject_HEAD
    Py_buffer views[7];  /* holder, ring, counter, log, log count, state, output; held for life */
    int held;
    double *holder, *ring, *counter, *log, *log_count, *state, *out;
    long long capacity, log_capacity;
    double parameters[PARAMETERS];
    Py_ssize_t holder_at[HOLDER_FIELDS];  /* where each holder field starts in the holder slot */
    Py_ssize_t log_at[LOG_FIELDS], log_row;  /* where each log field starts in a row; a row's cells */
} ForcePath;

static const char *VIEW_NAMES[] = {"holder", "ring", "counter", "log", "log_count", "state", "out"};
static const Py_ssize_t MIN_CELLS[] = {1, 4, 1, 1, 1, STATE_CELLS, 3};  /* holder, log: their layouts */

static void
release(ForcePath *self)
{
    for (int i = 0; i < self->held; i++)
        PyBuffer_Release(&self->views[i]);
    self->held = 0;
}

/* A layout: a (start, width) pair per field in ``names``' order; each width must be the one this file
 * writes, and each field must lie inside ``cells``. */
static int
read_layout(PyObject *layout, const char **names, const Py_ssize_t *widths, int fields, Py_ssize_t cells,
            Py_ssize_t *at, const char *what)
{
    PyObject *pairs = PySequence_Fast(layout, "ForcePath: a layout must be a sequence");
    if (pairs == NULL)
        return -1;
    if (PySequence_Fast_GET_SIZE(pairs) != fields) {
        PyErr_Format(PyExc_ValueError, "ForcePath: the %s's layout needs %d (start, width) pairs, got %zd",
                     what, fields, PySequence_Fast_GET_SIZE(pairs));
        Py_DECREF(pairs);
        return -1;
    }
    for (int i = 0; i < fields; i++) {
        Py_ssize_t start, width;
        if (!PyArg_ParseTuple(PySequence_Fast_GET_ITEM(pairs, i), "nn;a layout holds (start, width) pairs",
                              &start, &width)) {
            Py_DECREF(pairs);
            return -1;
        }
        if (width != widths[i] || start < 0 || start + width > cells) {
            PyErr_Format(PyExc_ValueError, "ForcePath: the %s's %s must be %zd cells inside its %zd; got %zd at %zd",
                         what, names[i], widths[i], cells, width, start);
            Py_DECREF(pairs);
            return -1;
        }
        at[i] = start;
    }
    Py_DECREF(pairs);
    return 0;
}

static int
ForcePath_init(ForcePath *self, PyObject *args, PyObject *kwargs)
{
    static char *names[] = {"holder", "ring", "counter", "log", "log_count", "state", "out",
                            "parameters", "holder_layout", "log_layout", NULL};
    PyObject *objects[7], *parameters, *layout, *log_layout;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOOOOO(nO)", names, &objects[0], &objects[1],
                                     &objects[2], &objects[3], &objects[4], &objects[5],
                                     &objects[6], &parameters, &layout, &self->log_row, &log_layout))
        return -1;
    if (self->held) {
        PyErr_SetString(PyExc_TypeError, "ForcePath: already initialised");
        return -1;
    }
    double *cells[7];
    for (int i = 0; i < 7; i++) {
        Py_buffer *view = &self->views[i];
        if (PyObject_GetBuffer(objects[i], view, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
            goto fail;
        self->held = i + 1;
        if (view->itemsize != sizeof(double) || view->format == NULL
            || (strcmp(view->format, "d") != 0 && strcmp(view->format, "<d") != 0
                && strcmp(view->format, "=d") != 0)) {
            PyErr_Format(PyExc_TypeError, "ForcePath: %s must be float64, not '%s'", VIEW_NAMES[i],
                         view->format ? view->format : "B");
            goto fail;
        }
        if (view->len / (Py_ssize_t)sizeof(double) < MIN_CELLS[i]) {
            PyErr_Format(PyExc_ValueError, "ForcePath: %s has %zd cells, needs at least %zd",
                         VIEW_NAMES[i], view->len / (Py_ssize_t)sizeof(double), MIN_CELLS[i]);
            goto fail;
        }
        cells[i] = (double *)view->buf;
    }
    self->holder = cells[0];
    self->ring = cells[1];
    self->counter = cells[2];
    self->log = cells[3];
    self->log_count = cells[4];
    self->state = cells[5];
    self->out = cells[6];
    self->capacity = (long long)(self->views[1].len / (Py_ssize_t)(4 * sizeof(double)));
    if (self->log_row < 1) {
        PyErr_SetString(PyExc_ValueError, "ForcePath: a log row needs at least one cell");
        goto fail;
    }
    self->log_capacity = (long long)(self->views[3].len / (self->log_row * (Py_ssize_t)sizeof(double)));
    if (self->capacity < 2) {
        PyErr_SetString(PyExc_ValueError, "ForcePath: the force ring needs at least 2 rows");
        goto fail;
    }
    if (read_layout(layout, HOLDER_NAMES, HOLDER_WIDTHS, HOLDER_FIELDS,
                    self->views[0].len / (Py_ssize_t)sizeof(double), self->holder_at, "holder") < 0
        || read_layout(log_layout, LOG_NAMES, LOG_WIDTHS, LOG_FIELDS, self->log_row, self->log_at, "log row") < 0)
        goto fail;
    PyObject *values = PySequence_Fast(parameters, "ForcePath: parameters must be a sequence");
    if (values == NULL)
        goto fail;
    if (PySequence_Fast_GET_SIZE(values) != PARAMETERS) {
        PyErr_Format(PyExc_ValueError, "ForcePath: %d parameters needed, got %zd", PARAMETERS,
                     PySequence_Fast_GET_SIZE(values));
        Py_DECREF(values);
        goto fail;
    }
    for (int i = 0; i < PARAMETERS; i++) {
        self->parameters[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(values, i));
        if (PyErr_Occurred()) {
            Py_DECREF(values);
            goto fail;
        }
    }
    Py_DECREF(values);
    return 0;
fail:
    release(self);
    return -1;
}

static void
ForcePath_dealloc(ForcePath *self)
{
    release(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* SharedHolder.put, at the places the holder's layout gives */
static void
publish_holder(const ForcePath *self, double now, const double *position, const double *rotation,
               const double *velocity, double grip)
{
    double *slot = self->holder;
    const Py_ssize_t *at = self->holder_at;
    slot[at[H_SEQ]] += 1.0;  /* odd: writing */
    __atomic_thread_fence(__ATOMIC_RELEASE);
    slot[at[H_TIME]] = now;
    memcpy(slot + at[H_POSITION], position, 3 * sizeof(double));
    memcpy(slot + at[H_ROTATION], rotation, 9 * sizeof(double));
    memcpy(slot + at[H_VELOCITY], velocity, 3 * sizeof(double));
    slot[at[H_GRIP]] = grip;
    __atomic_thread_fence(__ATOMIC_RELEASE);
    slot[at[H_SEQ]] += 1.0;  /* even: consistent */
}

/* SharedForceHistory.at (and interpolate_force's arithmetic); *latest: the newest output's time,
 * NaN when there is none. */
static void
force_at(const ForcePath *self, double time, double force[3], double *latest)
{
    double counted;
    __atomic_load(self->counter, &counted, __ATOMIC_ACQUIRE);  /* entries before it are complete */
    long long count = (long long)counted, capacity = self->capacity;
    const double *ring = self->ring;
    if (count == 0) {
        force[0] = force[1] = force[2] = 0.0;
        *latest = NAN;
        return;
    }
    long long low = count - (capacity - 1) > 0 ? count - (capacity - 1) : 0, high = count - 1;
    const double *newest = ring + 4 * (high % capacity), *oldest = ring + 4 * (low % capacity);
    *latest = newest[0];
    if (time >= newest[0]) {
        memcpy(force, newest + 1, 3 * sizeof(double));
        return;
    }
    if (time < oldest[0]) {
        memcpy(force, oldest + 1, 3 * sizeof(double));
        return;
    }
    while (high - low > 1) {  /* times[low] <= time < times[high] */
        long long middle = (low + high) / 2;
        if (ring[4 * (middle % capacity)] <= time)
            low = middle;
        else
            high = middle;
    }
    const double *a = ring + 4 * (low % capacity), *b = ring + 4 * (high % capacity);
    double w = (time - a[0]) / (b[0] - a[0]);
    for (int i = 0; i < 3; i++)
        force[i] = a[i + 1] + w * (b[i + 1] - a[i + 1]);
}

/* ForceSafety.filter; returns the event bits. */
static int
safety_filter(const ForcePath *self, double *state, double now, double f[3], double fem_time)
{
    const double *p = self->parameters;
    int events = 0;
    if (!(isfinite(f[0]) && isfinite(f[1]) && isfinite(f[2]))) {
        if (state[NONFINITE] == 0.0)
            events |= EVENT_NONFINITE;
        state[NONFINITE] = 1.0;
        f[0] = f[1] = f[2] = 0.0;
    } else {
        state[NONFINITE] = 0.0;
    }
    /* the watchdog */
    int stalled = !isnan(fem_time) && now - fem_time > p[STALL_TIMEOUT];
    if (stalled && isnan(state[WATCHDOG_SINCE])) {
        state[WATCHDOG_SINCE] = now;
        state[EVENT_SILENCE] = now - fem_time;
        events |= EVENT_WATCHDOG;
    } else if (!stalled && !isnan(state[WATCHDOG_SINCE])) {
        events |= EVENT_RECOVERED;
        state[WATCHDOG_SINCE] = NAN;
    }
    double gain = 1.0;
    if (!isnan(state[WATCHDOG_SINCE])) {
        gain = 1.0 - (now - state[WATCHDOG_SINCE]) / p[RAMP_TIME];
        gain = gain > 0.0 ? gain : 0.0;  /* max(0.0, ...) */
    }
    double fx = f[0] * gain, fy = f[1] * gain, fz = f[2] * gain;
    /* the clamp */
    double magnitude = sqrt(fx * fx + fy * fy + fz * fz), limit = p[MAX_FORCE];
    if (magnitude > limit) {
        if (state[CLAMPING] == 0.0) {
            events |= EVENT_CLAMPED;
            state[EVENT_MAGNITUDE] = magnitude;
        }
        state[CLAMPING] = 1.0;
        double scale = limit / magnitude;
        fx *= scale;
        fy *= scale;
        fz *= scale;
    } else {
        state[CLAMPING] = 0.0;
    }
    /* the rate limit: a clock that jumps forward licenses at most one nominal tick */
    double dt = 0.0;
    if (!isnan(state[LAST_TIME])) {
        dt = now - state[LAST_TIME];
        dt = dt > 0.0 ? dt : 0.0;
        dt = dt < p[TICK] ? dt : p[TICK];
    }
    state[LAST_TIME] = now;
    double lx = state[LAST_X], ly = state[LAST_Y], lz = state[LAST_Z];
    double dx = fx - lx, dy = fy - ly, dz = fz - lz;
    double allowed = p[MAX_FORCE_RATE] * dt;
    double size = sqrt(dx * dx + dy * dy + dz * dz);
    if (size > allowed) {
        double scale = allowed / size;
        dx *= scale;
        dy *= scale;
        dz *= scale;
        state[LAST_X] = lx + dx;
        state[LAST_Y] = ly + dy;
        state[LAST_Z] = lz + dz;
    } else {
        state[LAST_X] = fx;  /* exactly the target, so ramps end at exact zero */
        state[LAST_Y] = fy;
        state[LAST_Z] = fz;
    }
    f[0] = state[LAST_X];
    f[1] = state[LAST_Y];
    f[2] = state[LAST_Z];
    return events;
}

/* SharedHapticLog.append */
static void
log_tick(ForcePath *self, double now, const double *position, double grip, const double f[3])
{
    long long index = (long long)*self->log_count;
    if (index >= self->log_capacity)
        return;  /* full: the run outlived its planned duration */
    double *row = self->log + self->log_row * index;
    const Py_ssize_t *at = self->log_at;
    row[at[L_TIME]] = now;
    memcpy(row + at[L_POSITION], position, 3 * sizeof(double));
    row[at[L_GRIP]] = grip;
    memcpy(row + at[L_FORCE], f, 3 * sizeof(double));
    *self->log_count = (double)(index + 1);
}

/* ``cells`` float64 values from a buffer of that many (1-D or 2-D, contiguous or strided: a device
 * may hand over a transposed rotation), in C order. */
static int
read_vector(PyObject *object, double *into, Py_ssize_t cells, const char *name)
{
    Py_buffer view;
    if (PyObject_GetBuffer(object, &view, PyBUF_STRIDES | PyBUF_FORMAT) < 0)
        return -1;
    int good = view.itemsize == sizeof(double) && view.len == cells * (Py_ssize_t)sizeof(double)
               && view.format != NULL
               && (strcmp(view.format, "d") == 0 || strcmp(view.format, "<d") == 0
                   || strcmp(view.format, "=d") == 0)
               && view.ndim >= 1 && view.ndim <= 2;
    if (good && PyBuffer_IsContiguous(&view, 'C')) {
        memcpy(into, view.buf, (size_t)view.len);
    } else if (good) {
        Py_ssize_t rows = view.ndim == 2 ? view.shape[0] : 1, columns = view.shape[view.ndim - 1];
        Py_ssize_t row_stride = view.ndim == 2 ? view.strides[0] : 0, stride = view.strides[view.ndim - 1];
        for (Py_ssize_t i = 0; i < rows; i++)
            for (Py_ssize_t j = 0; j < columns; j++)
                memcpy(into + i * columns + j, (char *)view.buf + i * row_stride + j * stride, sizeof(double));
    }
    PyBuffer_Release(&view);
    if (!good) {
        PyErr_Format(PyExc_ValueError, "ForcePath.tick: %s must be %zd float64 values", name, cells);
        return -1;
    }
    return 0;
}

static PyObject *
ForcePath_tick(ForcePath *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_Format(PyExc_TypeError, "ForcePath.tick takes 5 arguments (now, position, rotation, "
                                      "velocity, grip), %zd given", nargs);
        return NULL;
    }
    double now = PyFloat_AsDouble(args[0]);
    if (now == -1.0 && PyErr_Occurred())
        return NULL;
    double position[3], rotation[9], velocity[3];
    if (read_vector(args[1], position, 3, "position") < 0 || read_vector(args[2], rotation, 9, "rotation") < 0
        || read_vector(args[3], velocity, 3, "velocity") < 0)
        return NULL;
    int truth = PyObject_IsTrue(args[4]);
    if (truth < 0)
        return NULL;
    double grip = truth ? 1.0 : 0.0;
    const double *p = self->parameters;
    publish_holder(self, now, position, rotation, velocity, grip);
    double force[3], latest;
    force_at(self, now - p[FORCE_DELAY], force, &latest);
    if (p[HAPTIC_SCALE] != 1.0) {
        for (int i = 0; i < 3; i++)
            force[i] = p[HAPTIC_SCALE] * force[i];
    }
    int events = safety_filter(self, self->state, now, force, latest);
    memcpy(self->out, force, 3 * sizeof(double));
    log_tick(self, now, position, grip, force);
    return PyLong_FromLong(events);
}

/* The tick's reads and arithmetic on scratch copies, nothing written: run in the wait before a
 * deadline, it brings the code and the cells the next tick uses into the caches (after a sleep they
 * are cold, and a cold tick took up to 20 us at p99 where a warm one takes under 1). */
static PyObject *
ForcePath_warm(ForcePath *self, PyObject *argument)
{
    double now = PyFloat_AsDouble(argument);
    if (now == -1.0 && PyErr_Occurred())
        return NULL;
    double force[3], latest, state[STATE_CELLS];
    memcpy(state, self->state, sizeof(state));
    force_at(self, now - self->parameters[FORCE_DELAY], force, &latest);
    safety_filter(self, state, now, force, latest);
    volatile double sink = self->holder[self->holder_at[H_SEQ]] + self->holder[self->holder_at[H_GRIP]]
                           + *self->log_count + self->out[0];
    long long index = (long long)*self->log_count;
    if (index < self->log_capacity)
        sink += self->log[self->log_row * index] + self->log[self->log_row * (index + 1) - 1];
    (void)sink;
    Py_RETURN_NONE;
}

static PyMethodDef ForcePath_methods[] = {
    {"warm", (PyCFunction)ForcePath_warm, METH_O,
     "warm(now) -> None\n--\n\nThe tick's reads and arithmetic, nothing written: warms the caches."},
    {"tick", (PyCFunction)(void (*)(void))ForcePath_tick, METH_FASTCALL,
     "tick(now, position, rotation, velocity, grip) -> int\n--\n\n"
     "One haptic tick's force path; the force is in the output array, the new events' bits returned."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject ForcePathType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "sim.runtime._haptic.ForcePath",
    .tp_basicsize = sizeof(ForcePath),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "ForcePath(holder, ring, counter, log, log_count, state, out, parameters, holder_layout, log_layout)\n--\n\n"
              "The haptic tick's force path over shared float64 arrays (see sim/runtime/_haptic.c).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)ForcePath_init,
    .tp_dealloc = (destructor)ForcePath_dealloc,
    .tp_methods = ForcePath_methods,
};

static struct PyModuleDef haptic_module = {
    PyModuleDef_HEAD_INIT, "sim.runtime._haptic", "The haptic tick's force path, compiled.", -1, NULL,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__haptic(void)
{
    if (PyType_Ready(&ForcePathType) < 0)
        return NULL;
    PyObject *module = PyModule_Create(&haptic_module);
    if (module == NULL)
        return NULL;
    Py_INCREF(&ForcePathType);
    if (PyModule_AddObject(module, "ForcePath", (PyObject *)&ForcePathType) < 0) {
        Py_DECREF(&ForcePathType);
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
