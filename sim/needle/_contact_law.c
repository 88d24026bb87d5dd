/* The needle's contact law at its force kernels, compiled: one FEM step of sim.needle.load.kernel_step.
 *
 * In NumPy the law was about forty calls on arrays of 3-12 numbers (einsums, a probe loop for each
 * kernel's normal stiffness, masks for sliding and tearing): 100-175 us a step on this project's
 * 2-core hosts, more than half of a pressing needle's FEM step. Here it is one pass over m kernels:
 *
 *   step(displacements, extra, compliance, soft, stiff, stiff_scale, normals, ratio, friction,
 *        speed, indentation, depth, strain_limit, critical_speed, speed_exponent, limit_floor,
 *        tear_force, forces_out, shifts_out, torn_out) -> (share, indentation, torn count)
 *
 *   displacements (m, 3)  where the needle is against where each kernel holds it (m)
 *   extra (m, 3)          explicit forces on the tissue at the kernels (N; the passage's)
 *   compliance (3m, 3m)   the soft phase's kernel compliance, near field included (m/N)
 *   soft, stiff (3m, 3m)  the phases' kernel stiffnesses (N/m); stiff empty: the stiff phase is
 *                         stiff_scale times the soft one
 *   normals (m, 3)        outward normals of a needle pressing on the surface, or empty (in the wall)
 *   ratio, friction       tangential over normal stiffness (Mindlin), Coulomb coefficient
 *   speed, indentation    the tip's speed (m/s; a negative one counts as 0), the last step's largest
 *                         displacement (m)
 *   depth                 the tissue's depth under the kernels (m)
 *   strain_limit ... limit_floor   the biphase parameters; strain_limit nan: one phase (share 1)
 *   tear_force            the most a kernel carries (N); nan: no tearing
 *   forces_out (m, 3), shifts_out (m, 3), torn_out (m,) int64: what the step returns
 *
 * Every operation is the NumPy reference's (tests/sim/test_contact_law.py keeps it and compares
 * the two under hypothesis); products sum in the same order as a plain loop, so results agree to
 * rounding, not bit for bit. Sizes and types are checked before anything is read.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../_buffer_views.h"

#define MAX_KERNELS 16

/* out = matrix (n x n) . vector (n) */
static void
product(const double *matrix, const double *vector, Py_ssize_t n, double *out)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        double sum = 0.0;
        for (Py_ssize_t j = 0; j < n; j++)
            sum += matrix[i * n + j] * vector[j];
        out[i] = sum;
    }
}

/* n^T K[block m] n: the normal stiffness of kernel m alone in one phase's stiffness */
static double
normal_stiffness(const double *matrix, Py_ssize_t n, Py_ssize_t m, const double *normal)
{
    double sum = 0.0;
    for (int i = 0; i < 3; i++) {
        double row = 0.0;
        for (int j = 0; j < 3; j++)
            row += matrix[(3 * m + i) * n + 3 * m + j] * normal[j];
        sum += row * normal[i];
    }
    return sum;
}

static PyObject *
step(PyObject *module, PyObject *args)
{
    enum { DISPLACEMENTS, EXTRA, COMPLIANCE, SOFT, STIFF, NORMALS, FORCES, SHIFTS, TORN, VIEWS };
    PyObject *objects[VIEWS];
    double stiff_scale, ratio, friction, speed, indentation, depth;
    double strain_limit, critical_speed, speed_exponent, limit_floor, tear_force;
    if (!PyArg_ParseTuple(args, "OOOOOdOddddddddddOOO", &objects[DISPLACEMENTS], &objects[EXTRA],
                          &objects[COMPLIANCE], &objects[SOFT], &objects[STIFF], &stiff_scale,
                          &objects[NORMALS], &ratio, &friction, &speed, &indentation, &depth, &strain_limit,
                          &critical_speed, &speed_exponent, &limit_floor, &tear_force, &objects[FORCES],
                          &objects[SHIFTS], &objects[TORN]))
        return NULL;
    static const char *names[VIEWS] = {"displacements", "extra", "compliance", "soft", "stiff",
                                       "normals", "forces_out", "shifts_out", "torn_out"};
    Py_buffer views[VIEWS];
    int held = 0;
    PyObject *result = NULL;
    for (; held < VIEWS; held++) {
        int writable = held >= FORCES;
        if (get_view(objects[held], &views[held], writable, held == TORN ? 'q' : 'd', names[held]) < 0)
            goto done;
    }
    Py_ssize_t n = cells(&views[DISPLACEMENTS]), m = n / 3;
    if (n == 0 || n % 3 != 0 || m > MAX_KERNELS) {
        PyErr_Format(PyExc_ValueError, "displacements must be (m, 3) with 1 <= m <= %d; got %zd values",
                     MAX_KERNELS, n);
        goto done;
    }
    Py_ssize_t square = n * n, stiff_cells = cells(&views[STIFF]), normal_cells = cells(&views[NORMALS]);
    if (cells(&views[EXTRA]) != n || cells(&views[FORCES]) != n || cells(&views[SHIFTS]) != n ||
        cells(&views[TORN]) != m) {
        PyErr_Format(PyExc_ValueError, "extra, forces_out and shifts_out must be (%zd, 3), torn_out (%zd,)", m, m);
        goto done;
    }
    if (cells(&views[COMPLIANCE]) != square || cells(&views[SOFT]) != square ||
        (stiff_cells != 0 && stiff_cells != square)) {
        PyErr_Format(PyExc_ValueError, "compliance, soft and stiff (or an empty stiff) must be (%zd, %zd)", n, n);
        goto done;
    }
    if (normal_cells != 0 && normal_cells != n) {
        PyErr_Format(PyExc_ValueError, "normals must be (%zd, 3) or empty", m);
        goto done;
    }
    const double *given = views[DISPLACEMENTS].buf, *extra = views[EXTRA].buf;
    const double *compliance = views[COMPLIANCE].buf, *soft = views[SOFT].buf;
    const double *stiff = stiff_cells ? views[STIFF].buf : NULL, *normals = normal_cells ? views[NORMALS].buf : NULL;
    double *forces = views[FORCES].buf, *shifts = views[SHIFTS].buf;
    long long *torn = views[TORN].buf;
    double d[3 * MAX_KERNELS], total[3 * MAX_KERNELS], work[3 * MAX_KERNELS];
    memcpy(d, given, n * sizeof(double));
    for (Py_ssize_t i = 0; i < n; i++)
        shifts[i] = 0.0;
    if (normals != NULL) { /* stick-slip on the surface: the Coulomb bound on the tangential part */
        for (Py_ssize_t k = 0; k < m; k++) {
            const double *nk = normals + 3 * k;
            double *dk = d + 3 * k;
            double pressed = -(dk[0] * nk[0] + dk[1] * nk[1] + dk[2] * nk[2]);
            double along[3], size = 0.0;
            for (int i = 0; i < 3; i++) {
                along[i] = dk[i] + pressed * nk[i];
                size += along[i] * along[i];
            }
            size = sqrt(size);
            double bound = friction * (pressed > 0.0 ? pressed : 0.0) / ratio;
            if (size > bound) {
                double keep = bound / size;
                for (int i = 0; i < 3; i++) {
                    double slide = along[i] - along[i] * keep;
                    shifts[3 * k + i] += slide;
                    dk[i] -= slide;
                }
            }
        }
    }
    int any_extra = 0;
    for (Py_ssize_t i = 0; i < n; i++)
        any_extra |= extra[i] != 0.0;
    if (any_extra) { /* the passage's forces add what the soft phase gives them */
        product(compliance, extra, n, work);
        for (Py_ssize_t i = 0; i < n; i++)
            total[i] = d[i] + work[i];
    }
    else
        memcpy(total, d, n * sizeof(double));
    double largest = 0.0;
    int nan_seen = 0;
    for (Py_ssize_t k = 0; k < m; k++) {
        double s = total[3 * k] * total[3 * k] + total[3 * k + 1] * total[3 * k + 1] +
                   total[3 * k + 2] * total[3 * k + 2];
        nan_seen |= isnan(s);
        if (s > largest)
            largest = s;
    }
    double now = nan_seen ? NAN : sqrt(largest);
    double share = 1.0;
    if (!isnan(strain_limit)) { /* the biphase split: the soft phase takes all up to the strain limit */
        double loading_speed = now >= indentation ? speed : 0.0; /* speed stiffens only a loading wall */
        if (!(loading_speed >= 0.0))                              /* Python's max(speed, 0.0) */
            loading_speed = isnan(loading_speed) ? loading_speed : 0.0;
        if (!isfinite(loading_speed)) {
            PyObject *value = PyFloat_FromDouble(loading_speed); /* said as Python says it: nan, inf */
            if (value != NULL) {
                PyErr_Format(PyExc_ValueError, "needle_speed must be a non-negative number of m/s; got %R",
                             value);
                Py_DECREF(value);
            }
            goto done;
        }
        double fraction = loading_speed / critical_speed;
        double limit = strain_limit * (1.0 - (1.0 - limit_floor) * pow(fraction < 1.0 ? fraction : 1.0,
                                                                        speed_exponent));
        double strain = now / depth;
        share = strain <= limit ? 1.0 : limit / strain;
    }
    double mix = share + (1.0 - share) * stiff_scale; /* a stiff phase that is a multiple of the soft */
    if (normals == NULL) {
        product(soft, d, n, forces);
        if (share != 1.0) {
            if (stiff == NULL)
                for (Py_ssize_t i = 0; i < n; i++)
                    forces[i] *= mix;
            else {
                product(stiff, d, n, work);
                for (Py_ssize_t i = 0; i < n; i++)
                    forces[i] = share * forces[i] + (1.0 - share) * work[i];
            }
        }
    }
    else { /* each kernel's own normal stiffness; the tangential one ratio times it */
        for (Py_ssize_t k = 0; k < m; k++) {
            const double *nk = normals + 3 * k;
            double k_soft = normal_stiffness(soft, n, k, nk), k_normal = k_soft;
            if (share != 1.0)
                k_normal = stiff == NULL ? mix * k_soft
                                         : share * k_soft + (1.0 - share) * normal_stiffness(stiff, n, k, nk);
            double *dk = d + 3 * k;
            double along = dk[0] * nk[0] + dk[1] * nk[1] + dk[2] * nk[2];
            for (int i = 0; i < 3; i++) {
                double normal = along * nk[i];
                forces[3 * k + i] = k_normal * (normal + ratio * (dk[i] - normal));
            }
        }
    }
    Py_ssize_t count = 0;
    if (!isnan(tear_force)) { /* a kernel that would carry more gives way at the tear force */
        for (Py_ssize_t k = 0; k < m; k++) {
            double *fk = forces + 3 * k;
            double size = sqrt(fk[0] * fk[0] + fk[1] * fk[1] + fk[2] * fk[2]);
            if (size > tear_force) {
                double scale = tear_force / size;
                for (int i = 0; i < 3; i++) {
                    shifts[3 * k + i] += (1.0 - scale) * d[3 * k + i];
                    fk[i] *= scale;
                }
                torn[count++] = k;
            }
        }
    }
    for (Py_ssize_t i = 0; i < n; i++)
        forces[i] += extra[i];
    result = Py_BuildValue("(ddn)", share, now, count);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"step", step, METH_VARARGS,
     "step(displacements, extra, compliance, soft, stiff, stiff_scale, normals, ratio, friction, speed, "
     "indentation, depth, strain_limit, critical_speed, speed_exponent, limit_floor, tear_force, forces_out, "
     "shifts_out, torn_out): (soft share, largest kernel displacement, kernels torn) of one FEM step of the "
     "needle's contact law."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef contact_law_module = {
    PyModuleDef_HEAD_INIT, "sim.needle._contact_law", "The needle's contact law at its force kernels, compiled.",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__contact_law(void)
{
    return PyModule_Create(&contact_law_module);
}
