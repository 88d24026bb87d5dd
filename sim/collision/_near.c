/* Two questions the needle's continuous collision test asks every FEM step, compiled.
 *
 * A needle pressing on the wall or held in it moves a few micrometres a step; most steps the answer
 * is "nothing new", found by two tests that were each a dozen NumPy calls on a few numbers (about
 * 35 us apiece on this project's 2-core hosts):
 *
 *   swept_inside(before, after, moved, centres, radii) -> bool
 *       Whether every segment's swept box (segment k from vertex k+1 to vertex k, before and after
 *       the step) lies inside the padded ball of the collision mesh's last near-box query:
 *       |centre_k - centres[k]| + half-diagonal_k + moved <= radii[k]. Then the last query's answer
 *       (the triangles and edges within reach) still holds (sim.collision.mesh.CollisionMesh).
 *
 *   all_within(corners, triangles, centres, radii2) -> bool
 *       Whether every corner of the listed triangles (corners (T, 3, 3), triangles (n,) ids) lies
 *       within one of the balls (centres (c, 3), squared radii (c,)): every surface point the needle
 *       could newly meet is one it already accounts for (a current contact, a hole it made).
 *
 * A NaN anywhere answers false (the NumPy path then runs and says what it says). Sizes, types and
 * triangle ids are checked before anything is read.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../_buffer_views.h"

static PyObject *
swept_inside(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[4];
    double moved;
    if (!PyArg_ParseTuple(args, "OOdOO", &objects[0], &objects[1], &moved, &objects[2], &objects[3]))
        return NULL;
    static const char *names[4] = {"before", "after", "centres", "radii"};
    Py_buffer views[4];
    int held = 0;
    PyObject *result = NULL;
    for (; held < 4; held++)
        if (get_view(objects[held], &views[held], 0, 'd', names[held]) < 0)
            goto done;
    Py_ssize_t n = cells(&views[0]), boxes = n / 3 - 1;
    if (n % 3 != 0 || boxes < 1 || cells(&views[1]) != n || cells(&views[2]) != 3 * boxes ||
        cells(&views[3]) != boxes) {
        PyErr_SetString(PyExc_ValueError,
                        "before and after must be (V, 3) alike, centres (V - 1, 3) and radii (V - 1,)");
        goto done;
    }
    const double *before = views[0].buf, *after = views[1].buf, *centres = views[2].buf, *radii = views[3].buf;
    int inside = 1;
    for (Py_ssize_t k = 0; k < boxes && inside; k++) {
        double diagonal = 0.0, shift = 0.0;
        for (int i = 0; i < 3; i++) {
            double a = before[3 * (k + 1) + i], b = before[3 * k + i];
            double c = after[3 * (k + 1) + i], d = after[3 * k + i];
            double low = fmin(fmin(a, b), fmin(c, d)), high = fmax(fmax(a, b), fmax(c, d));
            if (isnan(a) || isnan(b) || isnan(c) || isnan(d))
                low = high = NAN;
            double centre = 0.5 * (low + high) - centres[3 * k + i];
            diagonal += (high - low) * (high - low);
            shift += centre * centre;
        }
        inside = sqrt(shift) + (0.5 * sqrt(diagonal) + moved) <= radii[k];
    }
    result = PyBool_FromLong(inside);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyObject *
all_within(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[4];
    if (!PyArg_ParseTuple(args, "OOOO", &objects[0], &objects[1], &objects[2], &objects[3]))
        return NULL;
    static const char *names[4] = {"corners", "triangles", "centres", "radii2"};
    Py_buffer views[4];
    int held = 0;
    PyObject *result = NULL;
    for (; held < 4; held++)
        if (get_view(objects[held], &views[held], 0, held == 1 ? 'q' : 'd', names[held]) < 0)
            goto done;
    Py_ssize_t count = cells(&views[0]) / 9, balls = cells(&views[3]), listed = cells(&views[1]);
    if (cells(&views[0]) % 9 != 0 || cells(&views[2]) != 3 * balls) {
        PyErr_SetString(PyExc_ValueError, "corners must be (T, 3, 3), centres (c, 3) and radii2 (c,)");
        goto done;
    }
    const double *corners = views[0].buf, *centres = views[2].buf, *radii2 = views[3].buf;
    const long long *triangles = views[1].buf;
    for (Py_ssize_t t = 0; t < listed; t++)
        if (triangles[t] < 0 || triangles[t] >= count) {
            PyErr_Format(PyExc_ValueError, "triangle id %lld is not one of the %zd triangles", triangles[t],
                         count);
            goto done;
        }
    int every = 1;
    for (Py_ssize_t t = 0; t < listed && every; t++) {
        for (int corner = 0; corner < 3 && every; corner++) {
            const double *p = corners + 9 * triangles[t] + 3 * corner;
            int near = 0;
            for (Py_ssize_t b = 0; b < balls && !near; b++) {
                double dx = p[0] - centres[3 * b], dy = p[1] - centres[3 * b + 1], dz = p[2] - centres[3 * b + 2];
                near = dx * dx + dy * dy + dz * dz <= radii2[b];
            }
            every = near;
        }
    }
    result = PyBool_FromLong(every);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"swept_inside", swept_inside, METH_VARARGS,
     "swept_inside(before, after, moved, centres, radii): whether every segment's swept box lies inside "
     "the padded ball of the last near-box query."},
    {"all_within", all_within, METH_VARARGS,
     "all_within(corners, triangles, centres, radii2): whether every corner of the listed triangles lies "
     "within one of the balls."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef near_module = {
    PyModuleDef_HEAD_INIT, "sim.collision._near", "The continuous collision test's two quick answers, compiled.",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__near(void)
{
    return PyModule_Create(&near_module);
}
