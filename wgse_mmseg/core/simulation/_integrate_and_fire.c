/* Integrate-and-fire of a tile of pixels in one pass: the CPU kernel of
 * wgse_mmseg.core.simulation.fixed_point.
 *
 * Charge is int32 in units of 2**-24 thresholds (fixed_point.ONE is one
 * threshold). For each step t and pixel p the kernel adds the step's charge
 * a(t, p) to the pixel's fractional charge x[p], writes the spike
 * (x >> 24 != 0: the pixel crossed at least one threshold; the one-bit
 * readout reads at most one spike per step) and keeps the fraction
 * x & (ONE - 1). That is, step by step, what the torch path computes from
 * the running sums: the same spikes and the same carried charge, bit for bit.
 * x stays below 3 * ONE (a step collects less than two thresholds), far
 * from overflow.
 *
 * The step's charge is either given per step (a (steps, pixels) array with
 * a row stride) or linear in a per-step weight, base[p] + weight[t] *
 * slope[p] (slope may be absent: a constant charge).
 *
 * One call works on one tile (a contiguous pixel range); the Python side
 * runs tiles side by side on threads, so the call releases the GIL.
 * Arguments are addresses of tensors the Python wrapper has checked
 * (dtype, contiguity, sizes): this file trusts them.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

#define FRACTION_BITS 24
#define FRACTION_MASK ((1 << FRACTION_BITS) - 1)

/* The loops vectorise; on x86 with GCC an AVX2 clone runs where the CPU
 * has it, chosen when the module loads. */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define VECTOR_CLONES
#endif

VECTOR_CLONES
static void fire_linear(int32_t *charge, const int32_t *base,
                        const int32_t *slope, const int32_t *weights,
                        Py_ssize_t steps, Py_ssize_t pixels, uint8_t *out,
                        Py_ssize_t out_stride)
{
    for (Py_ssize_t t = 0; t < steps; ++t) {
        uint8_t *row = out + t * out_stride;
        if (slope != NULL && weights[t] != 0) {
            const int32_t weight = weights[t];
            for (Py_ssize_t p = 0; p < pixels; ++p) {
                const int32_t x = charge[p] + base[p] + weight * slope[p];
                row[p] = (uint8_t)((x >> FRACTION_BITS) != 0);
                charge[p] = x & FRACTION_MASK;
            }
        } else {
            for (Py_ssize_t p = 0; p < pixels; ++p) {
                const int32_t x = charge[p] + base[p];
                row[p] = (uint8_t)((x >> FRACTION_BITS) != 0);
                charge[p] = x & FRACTION_MASK;
            }
        }
    }
}

VECTOR_CLONES
static void fire_per_step(int32_t *charge, const int32_t *step_charge,
                          Py_ssize_t step_stride, Py_ssize_t steps,
                          Py_ssize_t pixels, uint8_t *out,
                          Py_ssize_t out_stride)
{
    for (Py_ssize_t t = 0; t < steps; ++t) {
        const int32_t *added = step_charge + t * step_stride;
        uint8_t *row = out + t * out_stride;
        for (Py_ssize_t p = 0; p < pixels; ++p) {
            const int32_t x = charge[p] + added[p];
            row[p] = (uint8_t)((x >> FRACTION_BITS) != 0);
            charge[p] = x & FRACTION_MASK;
        }
    }
}

static void *as_pointer(Py_ssize_t address)
{
    return (void *)(uintptr_t)address;
}

static PyObject *py_fire_linear(PyObject *self, PyObject *args)
{
    Py_ssize_t charge, base, slope, weights, steps, pixels, out, out_stride;
    (void)self;
    if (!PyArg_ParseTuple(args, "nnnnnnnn", &charge, &base, &slope, &weights,
                          &steps, &pixels, &out, &out_stride))
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    fire_linear(as_pointer(charge), as_pointer(base), as_pointer(slope),
                as_pointer(weights), steps, pixels, as_pointer(out),
                out_stride);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

static PyObject *py_fire_per_step(PyObject *self, PyObject *args)
{
    Py_ssize_t charge, step_charge, step_stride, steps, pixels, out,
        out_stride;
    (void)self;
    if (!PyArg_ParseTuple(args, "nnnnnnn", &charge, &step_charge,
                          &step_stride, &steps, &pixels, &out, &out_stride))
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    fire_per_step(as_pointer(charge), as_pointer(step_charge), step_stride,
                  steps, pixels, as_pointer(out), out_stride);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fire_linear", py_fire_linear, METH_VARARGS,
     "fire_linear(charge, base, slope, weights, steps, pixels, out, "
     "out_stride): addresses (slope and weights 0 for a constant charge) "
     "and sizes in elements."},
    {"fire_per_step", py_fire_per_step, METH_VARARGS,
     "fire_per_step(charge, step_charge, step_stride, steps, pixels, out, "
     "out_stride): addresses and sizes in elements."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_integrate_and_fire",
    "One-pass integrate-and-fire of a pixel tile (see fixed_point.py).", -1,
    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__integrate_and_fire(void)
{
    return PyModule_Create(&module);
}
