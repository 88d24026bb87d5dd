/* The points of a uniform grid within any of a few balls, compiled: the continuous collision test's
 * "which triangles and edges may reach the needle's swept boxes" (sim.collision.grid.PointGrid).
 *
 *   within(centres, radii, points, ids, starts, origin, cell, dims) -> bytearray of int64
 *
 * centres (B, 3) and radii (B,) float64: the balls; points (N, 3) float64 sorted by grid cell, ids
 * (N,) int64 the original index of each (a permutation of 0..N-1); starts (C + 1,) int64 where each
 * cell's points begin (C = dims[0] * dims[1] * dims[2], row-major); origin (3,) float64 the grid's
 * lower corner and cell its side (m); dims (3,) int64. Returns the original indices of the points
 * within distance <= radius of some centre, ascending, each once: what scipy's cKDTree
 * query_ball_point then numpy.unique gave (the same set up to rounding at the balls' surfaces), in
 * a few microseconds instead of a hundred of Python calls. A ball with a NaN or a negative radius
 * holds nothing. Sizes, types and the grid's tables are checked before anything is read.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../_buffer_views.h"

/* The cells [first, last] along one axis that a span [low, high] overlaps; 0 when it misses the grid. */
static int
cell_span(double low, double high, double origin, double cell, long long count, long long *first,
          long long *last)
{
    double a = (low - origin) / cell, b = (high - origin) / cell;
    if (!(b >= 0.0) || !(a < (double)count)) /* NaN compares false: no cells */
        return 0;
    *first = a <= 0.0 ? 0 : (long long)a;
    *last = b >= (double)(count - 1) ? count - 1 : (long long)b;
    return *first <= *last;
}

static PyObject *
within(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[7];
    double cell;
    if (!PyArg_ParseTuple(args, "OOOOOOdO", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4],
                          &objects[5], &cell, &objects[6]))
        return NULL;
    static const char *names[7] = {"centres", "radii", "points", "ids", "starts", "origin", "dims"};
    static const char kinds[7] = {'d', 'd', 'd', 'q', 'q', 'd', 'q'};
    Py_buffer views[7];
    int held = 0;
    PyObject *result = NULL;
    unsigned char *marked = NULL;
    for (; held < 7; held++)
        if (get_view(objects[held], &views[held], 0, kinds[held], names[held]) < 0)
            goto done;
    Py_ssize_t balls = cells(&views[1]), count = cells(&views[3]);
    const long long *dims = views[6].buf;
    if (cells(&views[0]) != 3 * balls || cells(&views[2]) != 3 * count || cells(&views[5]) != 3 ||
        cells(&views[6]) != 3) {
        PyErr_SetString(PyExc_ValueError,
                        "centres must be (B, 3), radii (B,), points (N, 3), ids (N,), origin and dims (3,)");
        goto done;
    }
    if (!(cell > 0.0) || dims[0] < 1 || dims[1] < 1 || dims[2] < 1 ||
        cells(&views[4]) != dims[0] * dims[1] * dims[2] + 1) {
        PyErr_SetString(PyExc_ValueError, "the grid needs a positive cell, dims >= 1 and one start per cell + 1");
        goto done;
    }
    const double *centres = views[0].buf, *radii = views[1].buf, *points = views[2].buf, *origin = views[5].buf;
    const long long *ids = views[3].buf, *starts = views[4].buf;
    Py_ssize_t total_cells = cells(&views[4]) - 1;
    if (starts[0] != 0 || starts[total_cells] != count) {
        PyErr_SetString(PyExc_ValueError, "the grid's starts must run from 0 to the number of points");
        goto done;
    }
    for (Py_ssize_t c = 0; c < total_cells; c++)
        if (starts[c + 1] < starts[c]) {
            PyErr_SetString(PyExc_ValueError, "the grid's starts must not decrease");
            goto done;
        }
    for (Py_ssize_t k = 0; k < count; k++)
        if (ids[k] < 0 || ids[k] >= count) {
            PyErr_Format(PyExc_ValueError, "id %lld is not one of the %zd points", ids[k], count);
            goto done;
        }
    marked = PyMem_Calloc((size_t)(count ? count : 1), 1);
    if (marked == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_ssize_t found = 0;
    for (Py_ssize_t b = 0; b < balls; b++) {
        const double *centre = centres + 3 * b;
        double radius = radii[b];
        if (!(radius >= 0.0))
            continue;
        long long first[3], last[3];
        int inside = 1;
        for (int i = 0; i < 3 && inside; i++)
            inside = cell_span(centre[i] - radius, centre[i] + radius, origin[i], cell, dims[i], &first[i],
                               &last[i]);
        if (!inside)
            continue;
        double limit = radius * radius;
        for (long long x = first[0]; x <= last[0]; x++)
            for (long long y = first[1]; y <= last[1]; y++) {
                long long row = (x * dims[1] + y) * dims[2];
                for (long long k = starts[row + first[2]]; k < starts[row + last[2] + 1]; k++) {
                    const double *p = points + 3 * k;
                    double dx = p[0] - centre[0], dy = p[1] - centre[1], dz = p[2] - centre[2];
                    if (dx * dx + dy * dy + dz * dz <= limit && !marked[ids[k]]) {
                        marked[ids[k]] = 1;
                        found++;
                    }
                }
            }
    }
    result = PyByteArray_FromStringAndSize(NULL, found * 8);
    if (result == NULL)
        goto done;
    long long *out = (long long *)PyByteArray_AS_STRING(result);
    for (Py_ssize_t k = 0, n = 0; k < count && n < found; k++)
        if (marked[k])
            out[n++] = k;
done:
    PyMem_Free(marked);
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"within", within, METH_VARARGS,
     "within(centres, radii, points, ids, starts, origin, cell, dims): the original indices of the grid's "
     "points within any of the balls, ascending, each once (int64 in a bytearray)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef grid_module = {
    PyModuleDef_HEAD_INIT, "sim.collision._grid", "Points of a uniform grid within balls, compiled.", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__grid(void)
{
    return PyModule_Create(&grid_module);
}
