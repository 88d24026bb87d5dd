/* Reading NumPy arrays in this project's C extensions through the buffer protocol: one C-contiguous
 * view of float64 ('d') or int64 ('q'/'l') items, refused with a TypeError naming the argument
 * otherwise. Included by sim/fem/_local_stress.c and sim/needle/_contact_law.c (after Python.h). */
#ifndef VASCSIM_BUFFER_VIEWS_H
#define VASCSIM_BUFFER_VIEWS_H

#include <string.h>

static int
get_view(PyObject *object, Py_buffer *view, int writable, char kind, const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(object, view, flags) < 0) {
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous%s array", name,
                     writable ? " writable" : "");
        return -1;
    }
    const char *format = view->format ? view->format : "B";
    if (*format == '<' || *format == '=' || *format == '@')
        format++;
    int ok = kind == 'd' ? (strcmp(format, "d") == 0 && view->itemsize == 8)
                         : ((strcmp(format, "q") == 0 || strcmp(format, "l") == 0) && view->itemsize == 8);
    if (!ok) {
        PyErr_Format(PyExc_TypeError, "%s must be %s", name, kind == 'd' ? "float64" : "int64");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* How many 8-byte items a view holds. */
static Py_ssize_t
cells(Py_buffer *view)
{
    return view->len / 8;
}

#endif
