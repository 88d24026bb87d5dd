/* The continuous collision test's segment-triangle crossings among the triangles within reach, compiled.
 *
 *   crossings(start, end, corners, triangles, bound, relative_accuracy[, lower, upper])
 *       -> (segment, triangle, t, barycentric, entering, place, unsure_segment, unsure_place)
 *
 * start, end (S, 3) float64: the segments; corners (T, 3, 3) float64: every triangle's corners;
 * triangles (n,) int64: the ids to test; lower, upper (n, 3) float64, optional: those triangles'
 * bounding boxes, where the caller keeps them (the global test's x-sorted window: read in order, not
 * gathered from the corners). The hits are sim.collision.segments' NumPy path's (candidate_pairs,
 * then intersect_pairs), bit for bit and in its order: the pairs whose closed bounding boxes overlap,
 * segment by segment and in the listed triangles' order; for each, the five floating-point orient3d
 * determinants of predicates.orient3d_fast (the same operations in the same order, so this file is
 * compiled without fused multiply-adds) with their error bounds (``bound`` times the permanent). A
 * pair crosses where the segment's ends are not on one side of the plane and the three volumes
 * around the line share a sign; its t and barycentrics are those of intersect_pairs. ``place`` is
 * each hit's position in ``triangles``.
 *
 * A pair some determinant of which is not sure to ``relative_accuracy`` of its magnitude
 * (|det| * relative_accuracy <= bound, a NaN included), or whose crossing's volumes sum to nothing
 * usable, is not decided here: it comes back as (unsure_segment, unsure_place) for the exact path.
 * A NaN in any segment makes no pair (NumPy's boxes of every segment then compare false); a triangle
 * with a NaN corner meets nothing. Sizes, types and triangle ids are checked before anything is read.
 * Every column is a bytearray (int64, int64, float64, float64 x 3, bool, int64, int64, int64) for
 * numpy.frombuffer.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "../_buffer_views.h"

typedef struct {
    double det, bound;
} Orient;

/* predicates.orient3d_fast for one quadruple: the determinant and its error bound. */
static Orient
orient3d_fast(const double *a, const double *b, const double *c, const double *d, double bound)
{
    double adx = a[0] - d[0], ady = a[1] - d[1], adz = a[2] - d[2];
    double bdx = b[0] - d[0], bdy = b[1] - d[1], bdz = b[2] - d[2];
    double cdx = c[0] - d[0], cdy = c[1] - d[1], cdz = c[2] - d[2];
    double b_c = bdy * cdz, c_b = bdz * cdy;
    double c_a = cdy * adz, a_c = cdz * ady;
    double a_b = ady * bdz, b_a = adz * bdy;
    Orient o;
    o.det = adx * (b_c - c_b) + bdx * (c_a - a_c) + cdx * (a_b - b_a);
    double permanent = fabs(adx) * (fabs(b_c) + fabs(c_b)) + fabs(bdx) * (fabs(c_a) + fabs(a_c)) +
                       fabs(cdx) * (fabs(a_b) + fabs(b_a));
    o.bound = bound * permanent;
    return o;
}

static int
sure(Orient o, double relative_accuracy)
{
    return fabs(o.det) * relative_accuracy > o.bound; /* false for a NaN, as NumPy's test */
}

static int
sign_of(double x)
{
    return (x > 0) - (x < 0);
}

/* A triangle kept by the first filter: its place in the list and its box (lower x, y, z, upper x, y, z). */
typedef struct {
    Py_ssize_t index;
    double box[6];
} Near;

#define COLUMNS 8

/* A growing array of fixed-size items in a bytearray. */
typedef struct {
    PyObject *bytes;
    Py_ssize_t used, item;
} Column;

static int
push(Column *column, const void *item)
{
    Py_ssize_t size = PyByteArray_GET_SIZE(column->bytes);
    if (column->used + column->item > size &&
        PyByteArray_Resize(column->bytes, size ? 2 * size : 16 * column->item) < 0)
        return -1;
    memcpy(PyByteArray_AS_STRING(column->bytes) + column->used, item, (size_t)column->item);
    column->used += column->item;
    return 0;
}

static PyObject *
crossings(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[6] = {NULL, NULL, NULL, NULL, Py_None, Py_None};
    double bound, relative_accuracy;
    if (!PyArg_ParseTuple(args, "OOOOdd|OO", &objects[0], &objects[1], &objects[2], &objects[3], &bound,
                          &relative_accuracy, &objects[4], &objects[5]))
        return NULL;
    static const char *names[6] = {"start", "end", "corners", "triangles", "lower", "upper"};
    int given_boxes = objects[4] != Py_None && objects[5] != Py_None, wanted = given_boxes ? 6 : 4;
    Py_buffer views[6];
    int held = 0;
    PyObject *result = NULL;
    /* the hits' segment, triangle, t, barycentrics, entering and place in the list; the unsure pairs'
     * segment and place in the list */
    Column columns[COLUMNS] = {{NULL, 0, 8}, {NULL, 0, 8}, {NULL, 0, 8}, {NULL, 0, 24},
                               {NULL, 0, 1},    {NULL, 0, 8}, {NULL, 0, 8}, {NULL, 0, 8}};
    Near *near = NULL;
    for (; held < wanted; held++)
        if (get_view(objects[held], &views[held], 0, held == 3 ? 'q' : 'd', names[held]) < 0)
            goto done;
    Py_ssize_t n = cells(&views[0]), count = cells(&views[2]) / 9, listed = cells(&views[3]);
    if (n % 3 != 0 || cells(&views[1]) != n || cells(&views[2]) % 9 != 0) {
        PyErr_SetString(PyExc_ValueError, "start and end must be (S, 3) alike and corners (T, 3, 3)");
        goto done;
    }
    if (given_boxes && (cells(&views[4]) != 3 * listed || cells(&views[5]) != 3 * listed)) {
        PyErr_SetString(PyExc_ValueError, "lower and upper must be (n, 3), one box per listed triangle");
        goto done;
    }
    const double *given_lower = given_boxes ? views[4].buf : NULL, *given_upper = given_boxes ? views[5].buf : NULL;
    const double *start = views[0].buf, *end = views[1].buf, *corners = views[2].buf;
    const long long *triangles = views[3].buf;
    for (Py_ssize_t j = 0; j < listed; j++)
        if (triangles[j] < 0 || triangles[j] >= count) {
            PyErr_Format(PyExc_ValueError, "triangle id %lld is not one of the %zd triangles", triangles[j],
                         count);
            goto done;
        }
    for (int k = 0; k < COLUMNS; k++)
        if ((columns[k].bytes = PyByteArray_FromStringAndSize(NULL, 0)) == NULL)
            goto done;
    Py_ssize_t segments = n / 3;
    int finite = 1;
    double reach_low[3] = {INFINITY, INFINITY, INFINITY}, reach_high[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (Py_ssize_t i = 0; i < n && finite; i++) {
        finite = !isnan(start[i]) && !isnan(end[i]);
        reach_low[i % 3] = fmin(reach_low[i % 3], fmin(start[i], end[i]));
        reach_high[i % 3] = fmax(reach_high[i % 3], fmax(start[i], end[i]));
    }
    /* the triangles whose boxes meet the box of every segment (NumPy's first filter), with their boxes,
     * in a buffer that grows as they are found (a global test's window lists thousands, keeps few) */
    Py_ssize_t kept = 0, capacity = 0;
    int ascending = 1;    /* the kept boxes' lower x never decreases (an x-sorted window) */
    double widest = 0.0;  /* the widest kept box along x */
    for (Py_ssize_t j = 0; j < listed && finite; j++) {
        double box[6];
        int overlap = 1;
        if (given_boxes) { /* the caller's boxes of these triangles (NaN where a corner is) */
            for (int i = 0; i < 3 && overlap; i++) {
                box[i] = given_lower[3 * j + i];
                box[3 + i] = given_upper[3 * j + i];
                overlap = box[3 + i] >= reach_low[i] && box[i] <= reach_high[i];
            }
        }
        else {
            const double *a = corners + 9 * triangles[j], *b = a + 3, *c = a + 6;
            for (int i = 0; i < 3 && overlap; i++) {
                if (isnan(a[i]) || isnan(b[i]) || isnan(c[i])) {
                    overlap = 0;
                    break;
                }
                box[i] = fmin(fmin(a[i], b[i]), c[i]);
                box[3 + i] = fmax(fmax(a[i], b[i]), c[i]);
                overlap = box[3 + i] >= reach_low[i] && box[i] <= reach_high[i];
            }
        }
        if (!overlap)
            continue;
        if (kept == capacity) {
            capacity = capacity ? 2 * capacity : 64;
            Near *grown = PyMem_Realloc(near, (size_t)capacity * sizeof(Near));
            if (grown == NULL) {
                PyErr_NoMemory();
                goto done;
            }
            near = grown;
        }
        near[kept].index = j;
        memcpy(near[kept].box, box, sizeof(box));
        if (kept > 0 && box[0] < near[kept - 1].box[0])
            ascending = 0;
        widest = fmax(widest, box[3] - box[0]);
        kept++;
    }
    for (Py_ssize_t s = 0; s < segments && finite; s++) {
        const double *p = start + 3 * s, *q = end + 3 * s;
        double low[3], high[3];
        for (int i = 0; i < 3; i++) {
            low[i] = p[i] < q[i] ? p[i] : q[i];
            high[i] = p[i] < q[i] ? q[i] : p[i];
        }
        /* in an x-sorted list only the boxes whose lower x lies in [low x - widest, high x] can meet
         * the segment's: from the first of them (binary search) to the first beyond */
        Py_ssize_t from = 0;
        if (ascending) { /* a margin for the subtraction's rounding: the pair test below decides */
            double threshold = low[0] - widest - 1e-12 * (fabs(low[0]) + widest);
            Py_ssize_t below = 0, above = kept;
            while (below < above) {
                Py_ssize_t middle = below + (above - below) / 2;
                if (near[middle].box[0] < threshold)
                    below = middle + 1;
                else
                    above = middle;
            }
            from = below;
        }
        for (Py_ssize_t k = from; k < kept; k++) {
            const double *box = near[k].box;
            if (ascending && box[0] > high[0])
                break;
            if (!(box[3] >= low[0] && box[0] <= high[0] && box[4] >= low[1] && box[1] <= high[1] &&
                  box[5] >= low[2] && box[2] <= high[2]))
                continue;
            Py_ssize_t j = near[k].index;
            const double *a = corners + 9 * triangles[j], *b = a + 3, *c = a + 6;
            Orient side_p = orient3d_fast(a, b, c, p, bound), side_q = orient3d_fast(a, b, c, q, bound);
            Orient volumes[3] = {orient3d_fast(q, c, b, p, bound), orient3d_fast(q, a, c, p, bound),
                                 orient3d_fast(q, b, a, p, bound)};
            long long segment = s, place = j;
            if (!sure(side_p, relative_accuracy) || !sure(side_q, relative_accuracy) ||
                !sure(volumes[0], relative_accuracy) || !sure(volumes[1], relative_accuracy) ||
                !sure(volumes[2], relative_accuracy)) {
                if (push(&columns[6], &segment) < 0 || push(&columns[7], &place) < 0)
                    goto done; /* the exact path decides this pair */
                continue;
            }
            int sp = sign_of(side_p.det), sq = sign_of(side_q.det);
            int v0 = sign_of(volumes[0].det), v1 = sign_of(volumes[1].det), v2 = sign_of(volumes[2].det);
            int lowest = v0 < v1 ? (v0 < v2 ? v0 : v2) : (v1 < v2 ? v1 : v2);
            int highest = v0 > v1 ? (v0 > v2 ? v0 : v2) : (v1 > v2 ? v1 : v2);
            int crossing = sp * sq <= 0 && !(sp == 0 && sq == 0);
            if (!crossing || !(lowest >= 0 || highest <= 0))
                continue;
            double weights[3] = {fabs(volumes[0].det), fabs(volumes[1].det), fabs(volumes[2].det)};
            double total = weights[0] + weights[1] + weights[2];
            if (!(total > 0) || !isfinite(total) || side_p.det == side_q.det) {
                if (push(&columns[6], &segment) < 0 || push(&columns[7], &place) < 0)
                    goto done; /* volumes under- or overflowed: exactly, as NumPy's path does */
                continue;
            }
            double t = side_p.det / (side_p.det - side_q.det);
            t = t >= 0.0 ? t : 0.0; /* np.maximum(t, 0.0), then np.minimum(t, 1.0) */
            t = t <= 1.0 ? t : 1.0;
            double barycentric[3] = {weights[0] / total, weights[1] / total, weights[2] / total};
            long long triangle = triangles[j];
            char entering = sp < 0 || (sp == 0 && sq > 0);
            if (push(&columns[0], &segment) < 0 || push(&columns[1], &triangle) < 0 ||
                push(&columns[2], &t) < 0 || push(&columns[3], barycentric) < 0 ||
                push(&columns[4], &entering) < 0 || push(&columns[5], &place) < 0)
                goto done;
        }
    }
    result = PyTuple_New(COLUMNS);
    if (result == NULL)
        goto done;
    for (int k = 0; k < COLUMNS; k++) {
        if (PyByteArray_Resize(columns[k].bytes, columns[k].used) < 0) {
            Py_CLEAR(result);
            goto done;
        }
        Py_INCREF(columns[k].bytes);
        PyTuple_SET_ITEM(result, k, columns[k].bytes);
    }
done:
    PyMem_Free(near);
    for (int k = 0; k < COLUMNS; k++)
        Py_XDECREF(columns[k].bytes);
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

/* -1, 0, 1 or nan, as numpy.sign. */
static double
numpy_sign(double x)
{
    return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : (x == 0.0 ? 0.0 : NAN));
}

/* plane_crossing(vertices, normal, point): where the needle's polyline (V, 3) crosses the plane
 * through ``point`` with ``normal``, the crossing nearest the point (the first of equals), as an
 * (x, y, z) tuple, or None where it does not cross. The NumPy it replaces
 * (NeedleInteraction._needle_point_at_plane: signed distances, np.sign, the pairs whose signs
 * differ, a / (a - b) along each, np.argmin of the squared distances, a nan first) is read twice
 * each FEM step a needle is through the wall; its answer here is the same to rounding (the signed
 * distances are summed without the fused multiply-adds a BLAS may use). */
static PyObject *
plane_crossing(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[3];
    if (!PyArg_ParseTuple(args, "OOO", &objects[0], &objects[1], &objects[2]))
        return NULL;
    static const char *names[] = {"vertices", "normal", "point"};
    Py_buffer views[3];
    int held = 0;
    PyObject *result = NULL;
    for (; held < 3; held++)
        if (get_view(objects[held], &views[held], 0, 'd', names[held]) < 0)
            goto done;
    if (cells(&views[0]) % 3 != 0 || cells(&views[1]) != 3 || cells(&views[2]) != 3) {
        PyErr_Format(PyExc_ValueError, "vertices must be (V, 3) and normal and point (3,); got %zd, %zd and %zd values",
                     cells(&views[0]), cells(&views[1]), cells(&views[2]));
        goto done;
    }
    const double *v = (const double *)views[0].buf, *n = (const double *)views[1].buf;
    const double *p = (const double *)views[2].buf;
    Py_ssize_t count = cells(&views[0]) / 3;
    double level = p[0] * n[0] + p[1] * n[1] + p[2] * n[2];
    double best[3] = {0.0, 0.0, 0.0}, nearest = INFINITY;
    int found = 0, nearest_nan = 0;
    double previous = 0.0;
    for (Py_ssize_t k = 0; k < count; k++) {
        const double *x = v + 3 * k;
        double side = x[0] * n[0] + x[1] * n[1] + x[2] * n[2] - level;
        if (k > 0) {
            double before = numpy_sign(previous), after = numpy_sign(side);
            if (before != after) { /* nan != nan: a nan pair counts, as in NumPy */
                const double *w = x - 3;
                double t = previous / (previous - side), point[3], square = 0.0;
                for (int i = 0; i < 3; i++) {
                    point[i] = w[i] + t * (x[i] - w[i]);
                    double offset = point[i] - p[i];
                    square += offset * offset;
                }
                /* np.argmin: the first nan wins; otherwise the first of the smallest */
                int better = !found || (!nearest_nan && (isnan(square) || square < nearest));
                if (better) {
                    memcpy(best, point, sizeof best);
                    nearest = square, nearest_nan = isnan(square), found = 1;
                }
            }
        }
        previous = side;
    }
    result = found ? Py_BuildValue("(ddd)", best[0], best[1], best[2]) : Py_NewRef(Py_None);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"crossings", crossings, METH_VARARGS,
     "crossings(start, end, corners, triangles, bound, relative_accuracy[, lower, upper]): the "
     "segment-triangle crossings among the listed triangles as bytearrays (segment, triangle, t, "
     "barycentric, entering, place) and the pairs floating point is not sure of (segment, place)."},
    {"plane_crossing", plane_crossing, METH_VARARGS,
     "plane_crossing(vertices, normal, point): where the polyline crosses the plane through point with "
     "normal, the crossing nearest the point, as (x, y, z), or None."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef crossings_module = {
    PyModuleDef_HEAD_INIT, "sim.collision._crossings",
    "The continuous collision test's segment-triangle crossings, compiled.", -1, methods,
};

PyMODINIT_FUNC
PyInit__crossings(void)
{
    return PyModule_Create(&crossings_module);
}
