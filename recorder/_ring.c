/* The producer side of the session writer's sample ring, compiled.
 *
 * record() runs on the haptic path, right after the loop's wait. After that wait the
 * caches and predictors are cold, and every distinct piece of interpreter code a call
 * runs costs microseconds on these machines: the same ring push written in Python
 * (attribute loads, a memoryview slice assignment through numpy's buffer export, the
 * head published as a Python float) measured p99 7-13 us paced at 1 kHz, this one
 * 3-5 us with a 1-us empty call as the floor.
 *
 * Layout (recorder/writer.py): one shared float64 mapping holding `capacity` rows of
 * `width` cells, then the counter cells (head, tail, dropped count, first and last
 * dropped time), at the indices given to the constructor. Head and tail count rows
 * ever written and ever consumed; both only grow. Single producer: the head is
 * written here only; the tail is written by the writer thread only.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

typedef struct {
    PyObject_HEAD
    Py_buffer cells;   /* the whole shared mapping, held for this object's lifetime */
    PyObject *ring;    /* the rows as a 2-D numpy array: rows that need converting go through it */
    double *rows;
    double *head, *tail, *dropped, *first_dropped, *last_dropped;
    Py_ssize_t width;
    long long capacity;
    long long limit;   /* tail + capacity as last read: tail only grows, so a stale limit is safe */
} RingProducer;

static int
cell(RingProducer *self, Py_ssize_t index, double **where, const char *name)
{
    Py_ssize_t count = self->cells.len / (Py_ssize_t)sizeof(double);
    if (index < self->width * self->capacity || index >= count) {
        PyErr_Format(PyExc_ValueError,
                     "RingProducer: %s cell %zd is not among the counter cells (%lld..%zd)", name,
                     index, (long long)self->width * self->capacity, count - 1);
        return -1;
    }
    *where = (double *)self->cells.buf + index;
    return 0;
}

static int
RingProducer_init(RingProducer *self, PyObject *args, PyObject *kwargs)
{
    static char *names[] = {"cells", "ring", "width", "capacity", "head", "tail",
                            "dropped", "first_dropped", "last_dropped", NULL};
    PyObject *cells, *ring;
    Py_ssize_t width, capacity, head, tail, dropped, first_dropped, last_dropped;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOnnnnnnn", names, &cells, &ring, &width,
                                     &capacity, &head, &tail, &dropped, &first_dropped,
                                     &last_dropped))
        return -1;
    if (self->cells.obj != NULL) {
        PyErr_SetString(PyExc_TypeError, "RingProducer: already initialised");
        return -1;
    }
    if (width < 1 || capacity < 1) {
        PyErr_Format(PyExc_ValueError, "RingProducer: width %zd and capacity %zd must be positive",
                     width, capacity);
        return -1;
    }
    if (PyObject_GetBuffer(cells, &self->cells, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    if (self->cells.itemsize != sizeof(double) || self->cells.format == NULL
        || strcmp(self->cells.format, "d") != 0) {
        PyErr_Format(PyExc_TypeError, "RingProducer: cells must be float64 (format 'd'), not '%s'",
                     self->cells.format ? self->cells.format : "B");
        goto fail;
    }
    self->width = width;
    self->capacity = capacity;
    if (cell(self, head, &self->head, "head") < 0 || cell(self, tail, &self->tail, "tail") < 0
        || cell(self, dropped, &self->dropped, "dropped") < 0
        || cell(self, first_dropped, &self->first_dropped, "first_dropped") < 0
        || cell(self, last_dropped, &self->last_dropped, "last_dropped") < 0)
        goto fail;
    self->rows = (double *)self->cells.buf;
    Py_INCREF(ring);
    self->ring = ring;
    self->limit = (long long)*self->tail + capacity;
    return 0;
fail:
    PyBuffer_Release(&self->cells);
    self->cells.obj = NULL;
    return -1;
}

static void
RingProducer_dealloc(RingProducer *self)
{
    if (self->cells.obj != NULL)
        PyBuffer_Release(&self->cells);
    Py_XDECREF(self->ring);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* The row's first cell (its time), for the dropped-samples record; NaN if it has none. */
static double
time_of(PyObject *row)
{
    PyObject *first = PySequence_GetItem(row, 0);
    double value = first != NULL ? PyFloat_AsDouble(first) : -1.0;
    Py_XDECREF(first);
    if (PyErr_Occurred()) {
        PyErr_Clear();
        return Py_NAN;
    }
    return value;
}

/* memcpy the row if it is a 1-D contiguous float64 buffer of the ring's width: 1 done, 0 not
 * such a row (nothing raised), -1 error. */
static int
copy_plain_row(RingProducer *self, PyObject *row, double *slot)
{
    Py_buffer own, *view;
    int done = 0;
    if (PyMemoryView_Check(row)) {
        view = PyMemoryView_GET_BUFFER(row);
    } else if (PyObject_CheckBuffer(row)) {
        if (PyObject_GetBuffer(row, &own, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
            PyErr_Clear();  /* a strided view, say: numpy's assignment takes it */
            return 0;
        }
        view = &own;
    } else {
        return 0;
    }
    if (view->ndim == 1 && view->itemsize == sizeof(double) && view->len == self->width * (Py_ssize_t)sizeof(double)
        && view->format != NULL && (strcmp(view->format, "d") == 0 || strcmp(view->format, "<d") == 0
                                    || strcmp(view->format, "=d") == 0)
        && PyBuffer_IsContiguous(view, 'C')) {
        memcpy(slot, view->buf, (size_t)view->len);
        done = 1;
    }
    if (view == &own)
        PyBuffer_Release(&own);
    return done;
}

static PyObject *
RingProducer_record(RingProducer *self, PyObject *row)
{
    double head_value, tail_value;
    __atomic_load(self->head, &head_value, __ATOMIC_RELAXED);
    long long head = (long long)head_value;
    if (head >= self->limit) {
        __atomic_load(self->tail, &tail_value, __ATOMIC_ACQUIRE);
        self->limit = (long long)tail_value + self->capacity;
        if (head >= self->limit) {  /* full: count it, never block */
            double when = time_of(row);
            if (*self->dropped == 0.0)
                *self->first_dropped = when;
            *self->dropped += 1.0;
            *self->last_dropped = when;
            Py_RETURN_FALSE;
        }
    }
    long long slot = head % self->capacity;
    int copied = copy_plain_row(self, row, self->rows + slot * self->width);
    if (copied < 0)
        return NULL;
    if (!copied) {  /* lists, other dtypes, strided rows: numpy converts, or names a wrong length */
        PyObject *index = PyLong_FromLongLong(slot);
        if (index == NULL)
            return NULL;
        int failed = PyObject_SetItem(self->ring, index, row);
        Py_DECREF(index);
        if (failed < 0)
            return NULL;
    }
    head_value = (double)(head + 1);
    __atomic_store(self->head, &head_value, __ATOMIC_RELEASE);  /* publish after the row is complete */
    Py_RETURN_TRUE;
}

static PyMethodDef RingProducer_methods[] = {
    {"record", (PyCFunction)RingProducer_record, METH_O,
     "record(row) -> bool\n--\n\nQueue one sample row; False if the ring was full (the drop is counted)."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject RingProducerType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "recorder._ring.RingProducer",
    .tp_basicsize = sizeof(RingProducer),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "RingProducer(cells, ring, width, capacity, head, tail, dropped, first_dropped, last_dropped)\n"
              "--\n\n"
              "Pushes sample rows into a shared float64 ring (see recorder/_ring.c).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)RingProducer_init,
    .tp_dealloc = (destructor)RingProducer_dealloc,
    .tp_methods = RingProducer_methods,
};

static struct PyModuleDef ring_module = {
    PyModuleDef_HEAD_INIT, "recorder._ring", "The session writer's ring producer, compiled.", -1, NULL,
};

PyMODINIT_FUNC
PyInit__ring(void)
{
    if (PyType_Ready(&RingProducerType) < 0)
        return NULL;
    PyObject *module = PyModule_Create(&ring_module);
    if (module == NULL)
        return NULL;
    Py_INCREF(&RingProducerType);
    if (PyModule_AddObject(module, "RingProducer", (PyObject *)&RingProducerType) < 0) {
        Py_DECREF(&RingProducerType);
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
