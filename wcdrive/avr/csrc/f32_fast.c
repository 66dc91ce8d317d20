/*
 * f32_fast: the common case of wcdrive.avr.f32's operations as a CPython extension,
 * for speed (the port calls them some 60 times a control tick).
 *
 * Each function computes what its Python twin in f32.py computes when both operands
 * are Python floats and the result is an ordinary one: one IEEE double operation,
 * then rounded once to binary32 (C's double -> float conversion, round to nearest
 * even, overflow to infinity, as struct's "f" packing gives after f32()'s
 * OverflowError). Everything else (an operand that is not exactly a float, a NaN
 * result, a product below 2**-126, a quotient below 2**-125, a division by zero, a NaN
 * to round) is handed back to the Python function, which stays the reference: see
 * _bind(). tests/avr/test_f32_fast.py checks the two agree, and the float sweep
 * (wcdrive verify --fp) checks the result against the AVR.
 *
 * Built at install (setup.py's NATIVE) or else on first use by wcdrive._util.native
 * (gcc -O2 -ffp-contract=off, the Python headers from sysconfig) and imported by
 * f32.py; without a compiler or headers the port keeps the Python functions.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <float.h>

#define MIN_NORMAL FLT_MIN                  /* 2**-126 */
#define TWO_MIN_NORMAL (2.0 * (double)FLT_MIN)

/* The Python reference functions, in the order _bind takes them. */
enum { REF_F32, REF_ADD, REF_SUB, REF_MUL, REF_DIV, REF_FROM_INT, N_REF };
static PyObject *reference[N_REF];

static PyObject *rounded(double r) {
    return PyFloat_FromDouble((double)(float)r);
}

static PyObject *defer(int which, PyObject *const *args, Py_ssize_t nargs) {
    if (reference[which] == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "f32_fast: _bind() was not called");
        return NULL;
    }
    return PyObject_Vectorcall(reference[which], args, (size_t)nargs, NULL);
}

static int two_floats(PyObject *const *args, Py_ssize_t nargs, double *a, double *b) {
    if (nargs != 2 || !PyFloat_CheckExact(args[0]) || !PyFloat_CheckExact(args[1]))
        return 0;
    *a = PyFloat_AS_DOUBLE(args[0]);
    *b = PyFloat_AS_DOUBLE(args[1]);
    return 1;
}

static PyObject *f32_f32(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 1 || !PyFloat_CheckExact(args[0]) || isnan(PyFloat_AS_DOUBLE(args[0])))
        return defer(REF_F32, args, nargs);
    return rounded(PyFloat_AS_DOUBLE(args[0]));
}

static PyObject *f32_add(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double a, b;
    (void)self;
    if (!two_floats(args, nargs, &a, &b))
        return defer(REF_ADD, args, nargs);
    double r = a + b;
    if (isnan(r))
        return defer(REF_ADD, args, nargs);
    return rounded(r);
}

static PyObject *f32_sub(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double a, b;
    (void)self;
    if (!two_floats(args, nargs, &a, &b))
        return defer(REF_SUB, args, nargs);
    double r = a - b;
    if (isnan(r))
        return defer(REF_SUB, args, nargs);
    return rounded(r);
}

static PyObject *f32_mul(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double a, b;
    (void)self;
    if (!two_floats(args, nargs, &a, &b))
        return defer(REF_MUL, args, nargs);
    double p = a * b;
    if (isnan(p) || (p != 0.0 && fabs(p) < MIN_NORMAL))
        return defer(REF_MUL, args, nargs);
    return rounded(p);
}

static PyObject *f32_div(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    double a, b;
    (void)self;
    if (!two_floats(args, nargs, &a, &b) || b == 0.0)
        return defer(REF_DIV, args, nargs);
    double q = a / b;
    if (isnan(q) || (q != 0.0 && fabs(q) < TWO_MIN_NORMAL))
        return defer(REF_DIV, args, nargs);
    return rounded(q);
}

static PyObject *f32_from_int(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    if (nargs != 1 || !PyLong_CheckExact(args[0]))
        return defer(REF_FROM_INT, args, nargs);
    int overflow = 0;
    long long n = PyLong_AsLongLongAndOverflow(args[0], &overflow);
    if (overflow || n > (1LL << 53) || n < -(1LL << 53))
        return defer(REF_FROM_INT, args, nargs);
    if (n == -1 && PyErr_Occurred())
        return NULL;
    return rounded((double)n);         /* exact in a double, then rounded once */
}

static PyObject *f32_bind(PyObject *self, PyObject *args) {
    (void)self;
    PyObject *refs[N_REF];
    if (!PyArg_ParseTuple(args, "OOOOOO:_bind", &refs[0], &refs[1], &refs[2], &refs[3], &refs[4],
                          &refs[5]))
        return NULL;
    for (int i = 0; i < N_REF; i++) {
        if (!PyCallable_Check(refs[i])) {
            PyErr_SetString(PyExc_TypeError, "_bind: the reference functions must be callable");
            return NULL;
        }
    }
    for (int i = 0; i < N_REF; i++) {
        Py_INCREF(refs[i]);
        Py_XSETREF(reference[i], refs[i]);
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"f32", (PyCFunction)(void (*)(void))f32_f32, METH_FASTCALL, "f32(x): x rounded to binary32."},
    {"add", (PyCFunction)(void (*)(void))f32_add, METH_FASTCALL, "add(a, b) as __addsf3."},
    {"sub", (PyCFunction)(void (*)(void))f32_sub, METH_FASTCALL, "sub(a, b) as __subsf3."},
    {"mul", (PyCFunction)(void (*)(void))f32_mul, METH_FASTCALL, "mul(a, b) as __mulsf3."},
    {"div", (PyCFunction)(void (*)(void))f32_div, METH_FASTCALL, "div(a, b) as __divsf3."},
    {"from_int", (PyCFunction)(void (*)(void))f32_from_int, METH_FASTCALL, "from_int(n): (float)n."},
    {"_bind", f32_bind, METH_VARARGS,
     "_bind(f32, add, sub, mul, div, from_int): the Python functions the uncommon cases go to."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_f32_fast",
    "The common case of wcdrive.avr.f32 in C (see f32_fast.c).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__f32_fast(void) {
    return PyModule_Create(&module);
}
