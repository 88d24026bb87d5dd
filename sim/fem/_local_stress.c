/* The local-stress operator of a contact, compiled: what a contact start pays for its live stress.
 *
 * When a needle touches the wall, sim.fem.fields.LocalStress builds the linear map from the
 * contact's q generalised forces (a force kernel's three components, or plain nodal forces) to
 * the von Mises stress of the elements within 1 mm of it. Two steps, each a loop here:
 *
 *   response(columns, loads, nodes, out)
 *       The displacement (m) of the local nodes' dofs per unit generalised force:
 *           out[3l + i, j] = sum_n sum_c K0^-1[3 nodes[l] + i, 3 n + c] loads[3 n + c, j]
 *       from each load node's three cached whole columns of K0^-1 (one (3N, 3) C-ordered array per
 *       load node: row 3a + i holds dof i of node a, so a node's nine values are contiguous).
 *       In NumPy this was a fancy-index gather per load node, a stack and a product: about 1 ms for
 *       50 load nodes and 200 local nodes, most of it allocation and Python overhead around reads
 *       that miss the cache; here it is one pass, the output (3L x q) staying in L1.
 *
 *   von_mises_rows(response, tets, gradients, mu, out)
 *       Per element m (four local node indices, the shape functions' gradients g_a (4 x 3), the
 *       shear modulus mu) and per generalised force j: grad u = sum_a u_a (x) g_a,
 *       eps = sym(grad u), and the deviatoric stress s = 2 mu dev(eps) (the Lame lambda multiplies
 *       the trace, which the deviator removes, so it never enters: exact, and free of the round-off
 *       lambda tr(eps) would add on a nearly incompressible wall). The six rows of element m are
 *           sqrt(3/2) (s00, s11, s22, sqrt2 s01, sqrt2 s02, sqrt2 s12)
 *       so that the von Mises stress of a load f is the norm of those six rows times f.
 *
 *   measures(operator, split, deformation, rest, rest_length, forces, scale)
 *       What each FEM step reads of the contact's field for its generalised forces f (q,): the
 *       largest von Mises stress of the first ``split`` elements' rows of ``operator`` (6E, q) and of
 *       the rest (the watched wound edge), and the largest stretch of the local edges, the edge
 *       vectors rest (n, 3) plus scale x (deformation (3n, q) f) against their squared rest lengths.
 *       In NumPy these were two products and a dozen small calls (about 100 us a step on the
 *       interrupted stitch's wall, more than the products' arithmetic); here one pass each.
 *       Given bounds per element and edge, in decreasing order (the stress and the stretch fall off
 *       away from the load), the pass stops where no element or edge left can beat the largest
 *       found and skips those that cannot (|rows_m f| <= |rows_m|_F |f| and the column norms'
 *       sum; the stretch expanded to first and second order in the load). The answer is the whole
 *       pass's to the last bit; through the wall on the interrupted stitch it reads about a sixth
 *       of the elements' and edges' 0.5 MB (the whole pass was 28 us a step, more with cold caches).
 *
 *   measure_bounds(operator, q, deformation, rest, rest_length, elements, edges)
 *       Those bounds, unsorted, once per contact set (sim.fem.fields sorts them).
 *
 * Arrays arrive through the buffer protocol (C-contiguous float64 'd' / int64 'q' or 'l'); every
 * size and index is checked before anything is read, and an error names the argument. The NumPy
 * reference these must agree with is in tests/sim/test_local_stress.py.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../_buffer_views.h"

static PyObject *
response(PyObject *module, PyObject *args)
{
    PyObject *columns, *loads_object, *nodes_object, *out_object;
    if (!PyArg_ParseTuple(args, "OOOO", &columns, &loads_object, &nodes_object, &out_object))
        return NULL;
    PyObject *sequence = PySequence_Fast(columns, "columns must be a sequence of arrays");
    if (sequence == NULL)
        return NULL;
    Py_ssize_t k = PySequence_Fast_GET_SIZE(sequence);
    Py_buffer loads, nodes, out;
    Py_buffer *views = PyMem_Calloc(k > 0 ? k : 1, sizeof(Py_buffer));
    Py_ssize_t held = 0;
    int have_loads = 0, have_nodes = 0, have_out = 0;
    PyObject *result = NULL;
    if (views == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    if (get_view(loads_object, &loads, 0, 'd', "loads") < 0)
        goto done;
    have_loads = 1;
    if (get_view(nodes_object, &nodes, 0, 'q', "nodes") < 0)
        goto done;
    have_nodes = 1;
    if (get_view(out_object, &out, 1, 'd', "out") < 0)
        goto done;
    have_out = 1;
    if (k == 0 || cells(&loads) % (3 * k) != 0) {
        PyErr_Format(PyExc_ValueError, "loads must hold 3 rows per load node (%zd nodes); got %zd values",
                     k, cells(&loads));
        goto done;
    }
    Py_ssize_t q = cells(&loads) / (3 * k), n_local = cells(&nodes), whole = -1;
    if (q == 0 || cells(&out) != 3 * n_local * q) {
        PyErr_Format(PyExc_ValueError, "out must hold %zd values (3 per local node x %zd loads); got %zd",
                     3 * n_local * q, q, cells(&out));
        goto done;
    }
    for (; held < k; held++) {
        if (get_view(PySequence_Fast_GET_ITEM(sequence, held), &views[held], 0, 'd', "each column block") < 0)
            goto done;
        Py_ssize_t size = cells(&views[held]);
        if (size % 9 != 0 || (whole >= 0 && size != whole)) {
            PyErr_Format(PyExc_ValueError, "column block %zd must be (3N, 3) like the first; got %zd values",
                         held, size);
            held++;
            goto done;
        }
        whole = size;
    }
    Py_ssize_t n_nodes = whole / 9;
    const long long *ids = (const long long *)nodes.buf;
    for (Py_ssize_t l = 0; l < n_local; l++) {
        if (ids[l] < 0 || ids[l] >= n_nodes) {
            PyErr_Format(PyExc_IndexError, "local node %lld is not a node of a %zd-node mesh", ids[l], n_nodes);
            goto done;
        }
    }
    double *o = (double *)out.buf;
    const double *w_all = (const double *)loads.buf;
    Py_BEGIN_ALLOW_THREADS /* the buffers are held: a prefetching thread may run meanwhile */
    memset(o, 0, (size_t)out.len);
    for (Py_ssize_t n = 0; n < k; n++) {
        const double *column = (const double *)views[n].buf;
        const double *w = w_all + 3 * n * q; /* this node's three rows of the load map */
        int used = 0;
        for (Py_ssize_t c = 0; c < 3 * q; c++)
            used |= w[c] != 0.0;
        if (!used)
            continue;
        for (Py_ssize_t l = 0; l < n_local; l++) {
            const double *row = column + 9 * ids[l];
            double *target = o + 3 * l * q;
            for (int i = 0; i < 3; i++) {
                double a = row[3 * i], b = row[3 * i + 1], c = row[3 * i + 2];
                for (Py_ssize_t j = 0; j < q; j++)
                    target[i * q + j] += a * w[j] + b * w[q + j] + c * w[2 * q + j];
            }
        }
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (Py_ssize_t i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    PyMem_Free(views);
    if (have_loads)
        PyBuffer_Release(&loads);
    if (have_nodes)
        PyBuffer_Release(&nodes);
    if (have_out)
        PyBuffer_Release(&out);
    Py_DECREF(sequence);
    return result;
}

static PyObject *
von_mises_rows(PyObject *module, PyObject *args)
{
    PyObject *objects[5];
    if (!PyArg_ParseTuple(args, "OOOOO", &objects[0], &objects[1], &objects[2], &objects[3], &objects[4]))
        return NULL;
    static const char *names[] = {"response", "tets", "gradients", "mu", "out"};
    static const char kinds[] = {'d', 'q', 'd', 'd', 'd'};
    Py_buffer views[5];
    int held = 0;
    PyObject *result = NULL;
    for (; held < 5; held++)
        if (get_view(objects[held], &views[held], held == 4, kinds[held], names[held]) < 0)
            goto done;
    Py_ssize_t n_elements = cells(&views[3]);
    if (cells(&views[1]) != 4 * n_elements || cells(&views[2]) != 12 * n_elements) {
        PyErr_Format(PyExc_ValueError, "tets (E, 4) and gradients (E, 4, 3) must match mu's %zd elements",
                     n_elements);
        goto done;
    }
    if (n_elements == 0 || cells(&views[4]) % (6 * n_elements) != 0 || cells(&views[4]) == 0) {
        PyErr_Format(PyExc_ValueError, "out must hold 6 rows per element (%zd elements); got %zd values",
                     n_elements, cells(&views[4]));
        goto done;
    }
    Py_ssize_t q = cells(&views[4]) / (6 * n_elements);
    if (cells(&views[0]) % (3 * q) != 0) {
        PyErr_Format(PyExc_ValueError, "response must be (3L, %zd); got %zd values", q, cells(&views[0]));
        goto done;
    }
    Py_ssize_t n_local = cells(&views[0]) / (3 * q);
    const long long *tets = (const long long *)views[1].buf;
    for (Py_ssize_t i = 0; i < 4 * n_elements; i++) {
        if (tets[i] < 0 || tets[i] >= n_local) {
            PyErr_Format(PyExc_IndexError, "tets name local node %lld of %zd", tets[i], n_local);
            goto done;
        }
    }
    const double *u = (const double *)views[0].buf, *gradients = (const double *)views[2].buf;
    const double *mu = (const double *)views[3].buf;
    double *o = (double *)views[4].buf;
    const double root2 = sqrt(2.0), root_three_halves = sqrt(1.5);
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t m = 0; m < n_elements; m++) {
        const long long *tet = tets + 4 * m;
        const double *g = gradients + 12 * m;
        double two_mu = 2.0 * mu[m];
        double *rows = o + 6 * m * q;
        for (Py_ssize_t j = 0; j < q; j++) {
            double grad[3][3] = {{0.0}};
            for (int a = 0; a < 4; a++) {
                const double *node = u + 3 * tet[a] * q + j; /* dof i of node a at row 3 tet[a] + i */
                for (int i = 0; i < 3; i++)
                    for (int k = 0; k < 3; k++)
                        grad[i][k] += node[i * q] * g[3 * a + k];
            }
            double trace = (grad[0][0] + grad[1][1] + grad[2][2]) / 3.0;
            double s00 = two_mu * (grad[0][0] - trace), s11 = two_mu * (grad[1][1] - trace);
            double s22 = two_mu * (grad[2][2] - trace);
            double s01 = mu[m] * (grad[0][1] + grad[1][0]), s02 = mu[m] * (grad[0][2] + grad[2][0]);
            double s12 = mu[m] * (grad[1][2] + grad[2][1]);
            rows[0 * q + j] = root_three_halves * s00;
            rows[1 * q + j] = root_three_halves * s11;
            rows[2 * q + j] = root_three_halves * s22;
            rows[3 * q + j] = root_three_halves * root2 * s01;
            rows[4 * q + j] = root_three_halves * root2 * s02;
            rows[5 * q + j] = root_three_halves * root2 * s12;
        }
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

/* row . f over q entries, summed in order from the first (the loop's sum, to the last bit); the
 * contact's usual sizes spelled out (one force kernel: q = 3, a needle through the wall: 6) so the
 * forces stay in registers: the FEM step's largest single cost was this loop (61 us a step through
 * the wall on the interrupted stitch's patch). */
static inline double
dot(const double *row, const double *f, Py_ssize_t q)
{
    switch (q) {
    case 3:
        return row[0] * f[0] + row[1] * f[1] + row[2] * f[2];
    case 6:
        return row[0] * f[0] + row[1] * f[1] + row[2] * f[2] + row[3] * f[3] + row[4] * f[4] + row[5] * f[5];
    default: {
        double value = 0.0;
        for (Py_ssize_t j = 0; j < q; j++)
            value += row[j] * f[j];
        return value;
    }
    }
}

/* How far a rounded product may exceed the bound it is checked against (relative): the dot products
 * and the squared norms are each within (q + 10) machine epsilons of exact, far below this. */
#define BOUND_MARGIN 1e-10

static int
out_of_group(const char *name, Py_ssize_t position, long long entry, Py_ssize_t low, Py_ssize_t high)
{
    PyErr_Format(PyExc_IndexError, "%s order entry %zd (%lld) is outside its group [%zd, %zd)", name, position,
                 entry, low, high);
    return -1;
}

/* The largest ||rows_m f||^2 (six rows of q per element) over positions [begin, end) of ``order``
 * (the elements themselves without it), into *largest from its value on entry; *is_nan when one is
 * nan. With ``bound`` ((E, 1 + q) in the order's positions: each element's squared Frobenius norm,
 * decreasing, then its q column norms), the pass stops at the first element whose Frobenius bound
 * |rows_m f| <= |rows_m|_F |f| cannot beat the largest so far (nor can any after it), and skips an
 * element whose column bound |rows_m f| <= sum_j |f_j| |column j of rows_m| cannot: the answer is
 * the whole pass's to the last bit. */
static int
largest_square(const double *op, Py_ssize_t q, const double *f, Py_ssize_t begin, Py_ssize_t end,
               const long long *order, const double *bound, double reach, double *largest, int *is_nan)
{
    for (Py_ssize_t i = begin; i < end; i++) {
        if (bound != NULL) {
            const double *own = bound + i * (q + 1);
            if (own[0] * reach <= *largest)
                return 0; /* a nan bound or reach compares false: that element is read */
            double columns = 0.0;
            for (Py_ssize_t j = 0; j < q; j++)
                columns += fabs(f[j]) * own[1 + j];
            if (columns * columns * (1.0 + BOUND_MARGIN) <= *largest)
                continue;
        }
        Py_ssize_t m = order != NULL ? (Py_ssize_t)order[i] : i;
        if (m < begin || m >= end) /* checked as read: a local element is never read as a watched one */
            return out_of_group("element", i, order[i], begin, end);
        double square = 0.0;
        for (int r = 0; r < 6; r++) {
            double value = dot(op + (6 * m + r) * q, f, q);
            square += value * value;
        }
        *is_nan |= isnan(square);
        if (square > *largest)
            *largest = square;
    }
    return 0;
}

/* The largest squared stretch |r_e + s D_e f|^2 / L_e (rest vector r_e, squared rest length L_e,
 * deformation rows D_e (3, q), scale s) over the edges (in ``order`` when given). Expanded, it is at
 * most base + 2 a_e F + c_e F^2 with F = |s| |f|, base the largest |r|^2 / L, a_e = |D_e^T r_e| / L_e
 * and c_e = |D_e|_F^2 / L_e. With ``bound`` ((n, 3) in the order's positions: a_e decreasing, the
 * largest c from there on, c_e) the pass stops once no edge left can beat the largest so far, and
 * skips an edge that cannot. */
static int
largest_stretch(const double *deformation, const double *rest, const double *rest_length, Py_ssize_t q,
                const double *f, double scale, Py_ssize_t n_edges, const long long *order, const double *bound,
                double base, double f_norm, double *largest, int *is_nan)
{
    double stretch = 0.0, reach = fabs(scale) * f_norm;
    for (Py_ssize_t i = 0; i < n_edges; i++) {
        if (bound != NULL && i > 0) {
            const double *own = bound + 3 * i;
            double along = base + 2.0 * own[0] * reach;
            if ((along + own[1] * reach * reach) * (1.0 + BOUND_MARGIN) <= stretch)
                break;
            if ((along + own[2] * reach * reach) * (1.0 + BOUND_MARGIN) <= stretch)
                continue;
        }
        Py_ssize_t e = order != NULL ? (Py_ssize_t)order[i] : i;
        if (e < 0 || e >= n_edges)
            return out_of_group("edge", i, order[i], 0, n_edges);
        double length = 0.0;
        for (int k = 0; k < 3; k++) {
            double value = dot(deformation + (3 * e + k) * q, f, q);
            double component = rest[3 * e + k] + scale * value;
            length += component * component;
        }
        double ratio = length / rest_length[e];
        *is_nan |= isnan(ratio);
        if (ratio > stretch || i == 0)
            stretch = ratio;
    }
    *largest = stretch;
    return 0;
}

/* An order given to measures must hold ``count`` entries and ``width`` bounds per entry; its entries
 * are checked as they are read (most never are). */
static int
check_sizes(Py_buffer *order, Py_buffer *bound, Py_ssize_t count, Py_ssize_t width, const char *name)
{
    if (cells(order) != count || cells(bound) != count * width) {
        PyErr_Format(PyExc_ValueError, "%s order and bounds must hold %zd and %zd entries; got %zd and %zd", name,
                     count, count * width, cells(order), cells(bound));
        return -1;
    }
    return 0;
}

static PyObject *
measures(PyObject *module, PyObject *args)
{
    PyObject *objects[9] = {NULL};
    Py_ssize_t split;
    double scale, base = 1.0; /* the largest |r|^2 / L of the edges */
    if (!PyArg_ParseTuple(args, "OnOOOOd|OOOOd", &objects[0], &split, &objects[1], &objects[2], &objects[3],
                          &objects[4], &scale, &objects[5], &objects[6], &objects[7], &objects[8], &base))
        return NULL;
    static const char *names[] = {"operator",     "deformation",   "rest",       "rest_length", "forces",
                                  "element_order", "element_bound", "edge_order", "edge_bound"};
    static const char kinds[] = {'d', 'd', 'd', 'd', 'd', 'q', 'd', 'q', 'd'};
    int given = objects[5] != NULL ? 9 : 5;
    if (given == 9 && (objects[6] == NULL || objects[7] == NULL || objects[8] == NULL)) {
        PyErr_SetString(PyExc_TypeError, "measures takes the element order and bounds with the edge order and bounds");
        return NULL;
    }
    Py_buffer views[9];
    int held = 0;
    PyObject *result = NULL;
    for (; held < given; held++)
        if (get_view(objects[held], &views[held], 0, kinds[held], names[held]) < 0)
            goto done;
    Py_ssize_t q = cells(&views[4]), n_edges = cells(&views[3]);
    if (q == 0 || cells(&views[0]) % (6 * q) != 0) {
        PyErr_Format(PyExc_ValueError, "operator must be (6E, %zd) for %zd forces; got %zd values", q, q,
                     cells(&views[0]));
        goto done;
    }
    Py_ssize_t n_elements = cells(&views[0]) / (6 * q);
    if (split < 0 || split > n_elements) {
        PyErr_Format(PyExc_ValueError, "split must be within the operator's %zd elements; got %zd", n_elements,
                     split);
        goto done;
    }
    if (cells(&views[2]) != 3 * n_edges || cells(&views[1]) != 3 * n_edges * q) {
        PyErr_Format(PyExc_ValueError,
                     "rest (n, 3) and deformation (3n, %zd) must match rest_length's %zd edges", q, n_edges);
        goto done;
    }
    const long long *element_order = NULL, *edge_order = NULL;
    const double *element_bound = NULL, *edge_bound = NULL;
    if (given == 9) {
        if (check_sizes(&views[5], &views[6], n_elements, q + 1, "element") < 0 ||
            check_sizes(&views[7], &views[8], n_edges, 3, "edge") < 0)
            goto done;
        element_order = (const long long *)views[5].buf, element_bound = (const double *)views[6].buf;
        edge_order = (const long long *)views[7].buf, edge_bound = (const double *)views[8].buf;
    }
    const double *op = (const double *)views[0].buf, *deformation = (const double *)views[1].buf;
    const double *rest = (const double *)views[2].buf, *rest_length = (const double *)views[3].buf;
    const double *f = (const double *)views[4].buf;
    double f_square = 0.0;
    for (Py_ssize_t j = 0; j < q; j++)
        f_square += f[j] * f[j];
    double reach = f_square * (1.0 + BOUND_MARGIN);
    double local = 0.0, watched = -1.0, stretch = 0.0;
    int local_nan = 0, watched_nan = 0, stretch_nan = 0; /* NumPy's max: a nan anywhere is the answer */
    if (largest_square(op, q, f, 0, split, element_order, element_bound, reach, &local, &local_nan) < 0 ||
        largest_square(op, q, f, split, n_elements, element_order, element_bound, reach, &watched,
                       &watched_nan) < 0 ||
        largest_stretch(deformation, rest, rest_length, q, f, scale, n_edges, edge_order, edge_bound, base,
                        sqrt(f_square), &stretch, &stretch_nan) < 0)
        goto done;
    result = Py_BuildValue("(ddd)", local_nan ? NAN : sqrt(local),
                           watched_nan || watched < 0.0 ? NAN : sqrt(watched),
                           stretch_nan ? NAN : (n_edges ? sqrt(stretch) : 1.0));
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

/* measure_bounds(operator, q, deformation, rest, rest_length, elements, edges) -> base
 * What measures' bounds are made of, in one pass over a contact's operator (NumPy's reductions over
 * the same small arrays took ~0.2 ms a contact set): per element m of operator (6E, q),
 * elements[m] = (the squared Frobenius norm of its six rows, then its q column norms); per edge e of
 * deformation (3n, q), edges[e] = (a_e = |D_e^T r_e| / L_e, c_e = |D_e|_F^2 / L_e). Returns the largest
 * |r_e|^2 / L_e (1.0 without edges). */
static PyObject *
measure_bounds(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *objects[6];
    Py_ssize_t q;
    if (!PyArg_ParseTuple(args, "OnOOOOO", &objects[0], &q, &objects[1], &objects[2], &objects[3], &objects[4],
                          &objects[5]))
        return NULL;
    static const char *names[] = {"operator", "deformation", "rest", "rest_length", "elements", "edges"};
    Py_buffer views[6];
    int held = 0;
    PyObject *result = NULL;
    for (; held < 6; held++)
        if (get_view(objects[held], &views[held], held >= 4, 'd', names[held]) < 0)
            goto done;
    Py_ssize_t n_elements = q > 0 ? cells(&views[0]) / (6 * q) : 0, n_edges = cells(&views[3]);
    if (q <= 0 || cells(&views[0]) != 6 * q * n_elements || cells(&views[4]) != (1 + q) * n_elements) {
        PyErr_Format(PyExc_ValueError, "operator (6E, %zd) and elements (E, %zd) do not fit: %zd and %zd values", q,
                     1 + q, cells(&views[0]), cells(&views[4]));
        goto done;
    }
    if (cells(&views[1]) != 3 * q * n_edges || cells(&views[2]) != 3 * n_edges || cells(&views[5]) != 2 * n_edges) {
        PyErr_Format(PyExc_ValueError, "deformation (3n, %zd), rest (n, 3) and edges (n, 2) must match "
                     "rest_length's %zd edges", q, n_edges);
        goto done;
    }
    const double *op = (const double *)views[0].buf, *deformation = (const double *)views[1].buf;
    const double *rest = (const double *)views[2].buf, *rest_length = (const double *)views[3].buf;
    double *elements = (double *)views[4].buf, *edges = (double *)views[5].buf;
    for (Py_ssize_t m = 0; m < n_elements; m++) {
        double *own = elements + m * (1 + q), total = 0.0;
        for (Py_ssize_t j = 0; j < q; j++) {
            double square = 0.0;
            for (int r = 0; r < 6; r++) {
                double value = op[(6 * m + r) * q + j];
                square += value * value;
            }
            own[1 + j] = sqrt(square);
            total += square;
        }
        own[0] = total;
    }
    double base = n_edges ? -INFINITY : 1.0;
    int base_nan = 0;
    for (Py_ssize_t e = 0; e < n_edges; e++) {
        const double *rows = deformation + 3 * e * q, *r = rest + 3 * e;
        double along = 0.0, spread = 0.0;
        for (Py_ssize_t j = 0; j < q; j++) {
            double projected = r[0] * rows[j] + r[1] * rows[q + j] + r[2] * rows[2 * q + j];
            along += projected * projected;
            spread += rows[j] * rows[j] + rows[q + j] * rows[q + j] + rows[2 * q + j] * rows[2 * q + j];
        }
        edges[2 * e] = sqrt(along) / rest_length[e];
        edges[2 * e + 1] = spread / rest_length[e];
        double own = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) / rest_length[e];
        base_nan |= isnan(own);
        if (own > base)
            base = own;
    }
    result = PyFloat_FromDouble(base_nan ? NAN : base);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"response", response, METH_VARARGS,
     "response(columns, loads, nodes, out): the local nodes' displacement per unit generalised force, "
     "from the load nodes' cached K0^-1 columns, written into out (3L, q)."},
    {"von_mises_rows", von_mises_rows, METH_VARARGS,
     "von_mises_rows(response, tets, gradients, mu, out): the six weighted deviatoric stress rows per "
     "element and generalised force, written into out (6E, q)."},
    {"measure_bounds", measure_bounds, METH_VARARGS,
     "measure_bounds(operator, q, deformation, rest, rest_length, elements, edges): each element's squared "
     "Frobenius norm and column norms into elements (E, 1 + q), each edge's first- and second-order "
     "stretch gains into edges (n, 2); returns the largest squared rest ratio."},
    {"measures", measures, METH_VARARGS,
     "measures(operator, split, deformation, rest, rest_length, forces, scale[, element_order, element_bound, "
     "edge_order, edge_bound, base]): (largest local von Mises stress, largest watched one (nan without any), "
     "largest edge stretch (1.0 without edges)) for the generalised forces; with the orders and bounds, the "
     "elements and edges that cannot hold the largest are not read (the same answer)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef local_stress_module = {
    PyModuleDef_HEAD_INIT, "sim.fem._local_stress", "The local-stress operator of a contact, compiled.", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__local_stress(void)
{
    return PyModule_Create(&local_stress_module);
}
