/* WGSE's 1-D band networks on the CPU as one compiled kernel (float32).
 *
 * The network of one band (see wgse.BandNetwork.layers): layer 0 maps the
 * 1-channel coefficients to C = 32 channels, layers 1 .. n-2 map C to C,
 * layer n-1 maps C to 1; every layer is a 'same'-padded convolution of
 * kernel 3 followed by ReLU, and a layer may add an earlier activation
 * before its ReLU (residual: 0 the input, broadcast over channels; m >= 1
 * the output of layer m - 1).
 *
 * Pixels are processed in groups small enough that a group's activations
 * stay in the L2 cache. A group of n pixels of band length L is a
 * (R = n * S, C) row matrix, S = L + 2: each pixel's coefficients between
 * one zero row on each side. Rows r - 1, r, r + 1 of such a matrix are 3 * C
 * contiguous floats, so a wide (C -> C) convolution is a product of those
 * 96 floats with a (96, C) weight matrix per output row: a 6-row x 16-column
 * AVX2 register-blocked microkernel does it (and the input gradient, with
 * the flipped, transposed weights, and the weight gradient, with the rows
 * as the reduction), each with its element-wise epilogue (bias, residual,
 * ReLU, ReLU mask) fused. Rows between pixels are computed and reset to
 * zero, as in the torch kernel (torch_band_networks.py).
 *
 * The backward pass recomputes a group's activations (cheap: they are in
 * cache) and accumulates the parameter gradients of the call in double.
 * There is no input gradient: WGSE's input is spike data.
 *
 * Parameters, packed by the Python side (compiled_band_networks.py) in
 * this layout, per layer l (W is the torch Conv1d weight (C_out, C_in, 3)):
 *   layer 0:      F[j * C + o] = W[o][0][j] (3 * C), bias (C)
 *   wide layers:  F[(j * C + c) * C + o] = W[o][c][j] (96 * C), bias (C),
 *                 B[(j * C + o) * C + c] = W[o][c][2 - j] (96 * C)
 *   last layer:   F[j * C + c] = W[0][c][j] (96), bias (1)
 * Gradients (double) use the same layout without the B blocks.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define C 32
#define KC (3 * C)
#define GROUP_ROWS 1024 /* rows per group: activations stay in L2 */
#define MAX_LAYERS 64

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define HAVE_KERNEL 1
#define AVX2 __attribute__((target("avx2,fma")))
#else
#define HAVE_KERNEL 0
#endif

#if HAVE_KERNEL

typedef struct {
    int layers;
    const int64_t *residual; /* -1: none */
    const float *first_w, *first_b, *last_w, *last_b;
    const float *wide_f[MAX_LAYERS], *wide_b[MAX_LAYERS],
        *wide_back[MAX_LAYERS];
} Net;

typedef struct {
    double *first_w, *first_b, *last_w, *last_b;
    double *wide_f[MAX_LAYERS], *wide_b[MAX_LAYERS];
} Grads;

/* Where layer l (0 .. layers-1) starts in the packed layout of the file
 * comment: 4 * C floats for layer 0, then per wide layer its taps and bias
 * and, for parameters (not gradients), its flipped taps. */
static int64_t layer_offset(int l, int with_back)
{
    return l == 0 ? 0 : 4 * C + (int64_t)(l - 1) *
                                   (KC * C + C + (with_back ? KC * C : 0));
}

static void unpack(Net *net, const float *params, int layers,
                   const int64_t *residual)
{
    net->layers = layers;
    net->residual = residual;
    net->first_w = params;
    net->first_b = params + 3 * C;
    for (int l = 1; l < layers - 1; ++l) {
        const float *layer = params + layer_offset(l, 1);
        net->wide_f[l] = layer;
        net->wide_b[l] = layer + KC * C;
        net->wide_back[l] = layer + KC * C + C;
    }
    net->last_w = params + layer_offset(layers - 1, 1);
    net->last_b = net->last_w + KC;
}

static void unpack_grads(Grads *grads, double *buffer, int layers)
{
    grads->first_w = buffer;
    grads->first_b = buffer + 3 * C;
    for (int l = 1; l < layers - 1; ++l) {
        grads->wide_f[l] = buffer + layer_offset(l, 0);
        grads->wide_b[l] = grads->wide_f[l] + KC * C;
    }
    grads->last_w = buffer + layer_offset(layers - 1, 0);
    grads->last_b = grads->last_w + KC;
}

/* Epilogue of a wide product, applied to an accumulator of 8 channels
 * before it is stored: + bias, + a row of add (R x C), + a broadcast
 * scalar per row, ReLU, x (mask > 0). Any may be absent (NULL / 0). */
typedef struct {
    const float *bias, *add, *scalar, *mask;
    int relu;
} Epilogue;

AVX2 static inline __m256 finish(__m256 v, const Epilogue *e, int64_t row,
                                 int col)
{
    if (e->bias)
        v = _mm256_add_ps(v, _mm256_loadu_ps(e->bias + col));
    if (e->add)
        v = _mm256_add_ps(v, _mm256_loadu_ps(e->add + row * C + col));
    if (e->scalar)
        v = _mm256_add_ps(v, _mm256_set1_ps(e->scalar[row]));
    if (e->relu)
        v = _mm256_max_ps(v, _mm256_setzero_ps());
    if (e->mask) {
        __m256 m = _mm256_cmp_ps(_mm256_loadu_ps(e->mask + row * C + col),
                                 _mm256_setzero_ps(), _CMP_GT_OQ);
        v = _mm256_and_ps(v, m);
    }
    return v;
}

/* Six rows of accumulators, two vectors (16 channels) each, as named
 * variables: an array would be written back to the stack every step. */
#define ACC6(X) X(0) X(1) X(2) X(3) X(4) X(5)
#define DECLARE(i) __m256 c##i##0 = _mm256_setzero_ps(), \
                          c##i##1 = _mm256_setzero_ps();

/* out[r][col..col+16) for 6 rows r = row .. row+5:
 * sum_k in[(r - 1) * C + k] * w[k * C + col ..] over k < 96, then the
 * epilogue. */
AVX2 static inline void wide6(const float *in, const float *w, int col,
                              float *out, int64_t row, const Epilogue *e)
{
    ACC6(DECLARE)
    const float *a = in + (row - 1) * C;
    for (int k = 0; k < KC; ++k) {
        const __m256 w0 = _mm256_loadu_ps(w + k * C + col);
        const __m256 w1 = _mm256_loadu_ps(w + k * C + col + 8);
#define STEP(i)                                                    \
        {                                                          \
            const __m256 x = _mm256_broadcast_ss(a + (i) * C + k); \
            c##i##0 = _mm256_fmadd_ps(x, w0, c##i##0);             \
            c##i##1 = _mm256_fmadd_ps(x, w1, c##i##1);             \
        }
        ACC6(STEP)
#undef STEP
    }
#define STORE(i)                                                        \
    _mm256_storeu_ps(out + (row + (i)) * C + col,                       \
                     finish(c##i##0, e, row + (i), col));               \
    _mm256_storeu_ps(out + (row + (i)) * C + col + 8,                   \
                     finish(c##i##1, e, row + (i), col + 8));
    ACC6(STORE)
#undef STORE
}

AVX2 static inline void wide1(const float *in, const float *w, float *out,
                              int64_t row, const Epilogue *e)
{
    __m256 c[4];
    for (int q = 0; q < 4; ++q)
        c[q] = _mm256_setzero_ps();
    const float *a = in + (row - 1) * C;
    for (int k = 0; k < KC; ++k) {
        const __m256 x = _mm256_broadcast_ss(a + k);
        for (int q = 0; q < 4; ++q)
            c[q] = _mm256_fmadd_ps(x, _mm256_loadu_ps(w + k * C + 8 * q),
                                   c[q]);
    }
    for (int q = 0; q < 4; ++q)
        _mm256_storeu_ps(out + row * C + 8 * q, finish(c[q], e, row, 8 * q));
}

/* Rows 1 .. rows-2 of out (rows x C) from in (rows x C) and w (96 x C). */
AVX2 static void wide_rows(const float *in, const float *w, float *out,
                           int64_t rows, const Epilogue *e)
{
    int64_t row = 1;
    for (; row + 6 <= rows - 1; row += 6) {
        wide6(in, w, 0, out, row, e);
        wide6(in, w, 16, out, row, e);
    }
    for (; row < rows - 1; ++row)
        wide1(in, w, out, row, e);
}

static inline void add16(double *dst, __m256 low, __m256 high)
    __attribute__((target("avx2,fma")));
static inline void add16(double *dst, __m256 low, __m256 high)
{
    float v[16];
    _mm256_storeu_ps(v, low);
    _mm256_storeu_ps(v + 8, high);
    for (int q = 0; q < 16; ++q)
        dst[q] += v[q];
}

/* dw[k * C + o] += sum_r in[(r - 1) * C + k] * g[r * C + o], r in 1 ..
 * rows-2, and db[o] += sum_r g[r * C + o]. */
AVX2 static void wide_weight_grad(const float *in, const float *g,
                                  int64_t rows, double *dw, double *db)
{
    for (int k0 = 0; k0 < KC; k0 += 6) {
        for (int col = 0; col < C; col += 16) {
            ACC6(DECLARE)
            for (int64_t r = 1; r < rows - 1; ++r) {
                const __m256 g0 = _mm256_loadu_ps(g + r * C + col);
                const __m256 g1 = _mm256_loadu_ps(g + r * C + col + 8);
                const float *a = in + (r - 1) * C + k0;
#define STEP(i)                                                \
                {                                              \
                    const __m256 x = _mm256_broadcast_ss(a + (i)); \
                    c##i##0 = _mm256_fmadd_ps(x, g0, c##i##0);  \
                    c##i##1 = _mm256_fmadd_ps(x, g1, c##i##1);  \
                }
                ACC6(STEP)
#undef STEP
            }
#define ADD(i) add16(dw + (k0 + (i)) * C + col, c##i##0, c##i##1);
            ACC6(ADD)
#undef ADD
        }
    }
    __m256 s[4];
    for (int q = 0; q < 4; ++q)
        s[q] = _mm256_setzero_ps();
    for (int64_t r = 1; r < rows - 1; ++r)
        for (int q = 0; q < 4; ++q)
            s[q] = _mm256_add_ps(s[q], _mm256_loadu_ps(g + r * C + 8 * q));
    float v[C];
    for (int q = 0; q < 4; ++q)
        _mm256_storeu_ps(v + 8 * q, s[q]);
    for (int o = 0; o < C; ++o)
        db[o] += v[o];
}

/* Zero the rows between pixels (width floats per row). */
static void zero_padding(float *rows, int64_t pixels, int64_t seg,
                         int width)
{
    for (int64_t p = 0; p < pixels; ++p) {
        memset(rows + p * seg * width, 0, sizeof(float) * width);
        memset(rows + ((p + 1) * seg - 1) * width, 0, sizeof(float) * width);
    }
}

/* Layer 0: act[r][o] = relu(b[o] + sum_j x[r - 1 + j] w[j * C + o]). */
AVX2 static void first_forward(const float *x, const Net *net, float *act,
                               int64_t rows)
{
    __m256 w[3][4], b[4];
    for (int q = 0; q < 4; ++q) {
        b[q] = _mm256_loadu_ps(net->first_b + 8 * q);
        for (int j = 0; j < 3; ++j)
            w[j][q] = _mm256_loadu_ps(net->first_w + j * C + 8 * q);
    }
    for (int64_t r = 1; r < rows - 1; ++r) {
        const __m256 x0 = _mm256_set1_ps(x[r - 1]),
                     x1 = _mm256_set1_ps(x[r]), x2 = _mm256_set1_ps(x[r + 1]);
        for (int q = 0; q < 4; ++q) {
            __m256 v = _mm256_fmadd_ps(x0, w[0][q], b[q]);
            v = _mm256_fmadd_ps(x1, w[1][q], v);
            v = _mm256_fmadd_ps(x2, w[2][q], v);
            _mm256_storeu_ps(act + r * C + 8 * q,
                             _mm256_max_ps(v, _mm256_setzero_ps()));
        }
    }
}

AVX2 static void first_weight_grad(const float *x, const float *g,
                                   int64_t rows, Grads *grads)
{
    __m256 c[3][4], s[4];
    for (int q = 0; q < 4; ++q) {
        s[q] = _mm256_setzero_ps();
        for (int j = 0; j < 3; ++j)
            c[j][q] = _mm256_setzero_ps();
    }
    for (int64_t r = 1; r < rows - 1; ++r) {
        for (int q = 0; q < 4; ++q) {
            const __m256 gv = _mm256_loadu_ps(g + r * C + 8 * q);
            s[q] = _mm256_add_ps(s[q], gv);
            for (int j = 0; j < 3; ++j)
                c[j][q] = _mm256_fmadd_ps(_mm256_set1_ps(x[r - 1 + j]), gv,
                                          c[j][q]);
        }
    }
    float v[8];
    for (int q = 0; q < 4; ++q) {
        for (int j = 0; j < 3; ++j) {
            _mm256_storeu_ps(v, c[j][q]);
            for (int i = 0; i < 8; ++i)
                grads->first_w[j * C + 8 * q + i] += v[i];
        }
        _mm256_storeu_ps(v, s[q]);
        for (int i = 0; i < 8; ++i)
            grads->first_b[8 * q + i] += v[i];
    }
}

AVX2 static inline float sum8(__m256 v)
{
    __m128 s = _mm_add_ps(_mm256_castps256_ps128(v),
                          _mm256_extractf128_ps(v, 1));
    s = _mm_add_ps(s, _mm_movehl_ps(s, s));
    s = _mm_add_ss(s, _mm_movehdup_ps(s));
    return _mm_cvtss_f32(s);
}

/* Last layer: out[r] = relu(b + sum_k act[(r - 1) * C + k] w[k]). */
AVX2 static void last_forward(const float *act, const Net *net, float *out,
                              int64_t rows)
{
    for (int64_t r = 1; r < rows - 1; ++r) {
        const float *a = act + (r - 1) * C;
        __m256 s = _mm256_mul_ps(_mm256_loadu_ps(a), _mm256_loadu_ps(
            net->last_w));
        for (int k = 8; k < KC; k += 8)
            s = _mm256_fmadd_ps(_mm256_loadu_ps(a + k),
                                _mm256_loadu_ps(net->last_w + k), s);
        const float v = sum8(s) + net->last_b[0];
        out[r] = v > 0 ? v : 0;
    }
}

/* The last layer's weight gradient and the gradient reaching its input,
 * g[r][c] = sum_j gl[r + 1 - j] w[j * C + c], plus add, masked by
 * (mask > 0); rows 0 and rows-1 zero. */
AVX2 static void last_backward(const float *act, const float *gl,
                               const Net *net, int64_t rows,
                               const float *add, const float *mask, float *g,
                               Grads *grads)
{
    __m256 c[12];
    for (int q = 0; q < 12; ++q)
        c[q] = _mm256_setzero_ps();
    double bias_grad = 0;
    for (int64_t r = 1; r < rows - 1; ++r) {
        const __m256 gv = _mm256_set1_ps(gl[r]);
        const float *a = act + (r - 1) * C;
        for (int q = 0; q < 12; ++q)
            c[q] = _mm256_fmadd_ps(_mm256_loadu_ps(a + 8 * q), gv, c[q]);
        bias_grad += gl[r];
    }
    float v[8];
    for (int q = 0; q < 12; ++q) {
        _mm256_storeu_ps(v, c[q]);
        for (int i = 0; i < 8; ++i)
            grads->last_w[8 * q + i] += v[i];
    }
    grads->last_b[0] += bias_grad;
    memset(g, 0, sizeof(float) * C);
    memset(g + (rows - 1) * C, 0, sizeof(float) * C);
    for (int64_t r = 1; r < rows - 1; ++r) {
        const __m256 g0 = _mm256_set1_ps(gl[r + 1]), g1 = _mm256_set1_ps(
            gl[r]), g2 = _mm256_set1_ps(gl[r - 1]);
        for (int q = 0; q < 4; ++q) {
            __m256 s = _mm256_mul_ps(g0, _mm256_loadu_ps(net->last_w + 8 * q));
            s = _mm256_fmadd_ps(g1, _mm256_loadu_ps(net->last_w + C + 8 * q),
                                s);
            s = _mm256_fmadd_ps(g2, _mm256_loadu_ps(
                net->last_w + 2 * C + 8 * q), s);
            if (add)
                s = _mm256_add_ps(s, _mm256_loadu_ps(add + r * C + 8 * q));
            const __m256 m = _mm256_cmp_ps(
                _mm256_loadu_ps(mask + r * C + 8 * q), _mm256_setzero_ps(),
                _CMP_GT_OQ);
            _mm256_storeu_ps(g + r * C + 8 * q, _mm256_and_ps(s, m));
        }
    }
}

/* Work space of one group: the padded input, every activation, two
 * gradient buffers and one pending (residual) gradient per activation. */
typedef struct {
    float *x, *out, *gl, *g[2];
    float *act[MAX_LAYERS + 1];
    float *pending[MAX_LAYERS + 1];
    int has_pending[MAX_LAYERS + 1];
    float *memory;
} Work;

static int work_alloc(Work *work, const Net *net, int64_t rows)
{
    const int layers = net->layers;
    memset(work, 0, sizeof(*work));
    for (int l = 1; l < layers - 1; ++l)
        if (net->residual[l] >= 1)
            work->has_pending[net->residual[l]] = 1;
    int64_t wide = layers - 1 + 2; /* act[1 .. layers-1], g[2] */
    for (int m = 1; m < layers; ++m)
        wide += work->has_pending[m];
    const int64_t floats = wide * rows * C + 3 * rows;
    work->memory = aligned_alloc(64, ((floats * sizeof(float) + 63) / 64)
                                     * 64);
    if (!work->memory)
        return -1;
    float *p = work->memory;
    work->x = p, p += rows;
    work->out = p, p += rows;
    work->gl = p, p += rows;
    for (int l = 1; l < layers; ++l)
        work->act[l] = p, p += rows * C;
    work->g[0] = p, p += rows * C;
    work->g[1] = p, p += rows * C;
    for (int m = 1; m < layers; ++m)
        if (work->has_pending[m])
            work->pending[m] = p, p += rows * C;
    return 0;
}

/* Load pixels' coefficients (x[p * stride + i], i < length) between zero
 * rows. */
static void load_rows(const float *src, int64_t stride, int64_t pixels,
                      int64_t length, float *rows)
{
    const int64_t seg = length + 2;
    for (int64_t p = 0; p < pixels; ++p) {
        float *dst = rows + p * seg;
        dst[0] = dst[seg - 1] = 0;
        memcpy(dst + 1, src + p * stride, sizeof(float) * length);
    }
}

/* All activations of a group (act[1 .. layers-1], out) from work->x. */
AVX2 static void group_forward(const Net *net, Work *work, int64_t pixels,
                               int64_t seg)
{
    const int64_t rows = pixels * seg;
    const int layers = net->layers;
    work->act[0] = work->x;
    first_forward(work->x, net, work->act[1], rows);
    zero_padding(work->act[1], pixels, seg, C);
    for (int l = 1; l < layers - 1; ++l) {
        const int64_t res = net->residual[l];
        Epilogue e = {net->wide_b[l], res >= 1 ? work->act[res] : NULL,
                      res == 0 ? work->x : NULL, NULL, 1};
        wide_rows(work->act[l], net->wide_f[l], work->act[l + 1], rows, &e);
        zero_padding(work->act[l + 1], pixels, seg, C);
    }
    last_forward(work->act[layers - 1], net, work->out, rows);
    zero_padding(work->out, pixels, seg, 1);
}

AVX2 static void group_backward(const Net *net, Work *work, int64_t pixels,
                                int64_t seg, Grads *grads)
{
    const int64_t rows = pixels * seg;
    const int layers = net->layers;
    for (int64_t r = 0; r < rows; ++r)
        work->gl[r] = work->out[r] > 0 ? work->gl[r] : 0;
    for (int m = 1; m < layers; ++m)
        if (work->has_pending[m])
            memset(work->pending[m], 0, sizeof(float) * rows * C);
    float *g = work->g[0], *spare = work->g[1];
    last_backward(work->act[layers - 1], work->gl, net, rows,
                  work->has_pending[layers - 1] ? work->pending[layers - 1]
                                                : NULL,
                  work->act[layers - 1], g, grads);
    for (int l = layers - 2; l >= 1; --l) {
        const int64_t res = net->residual[l];
        if (res >= 1) {
            float *pending = work->pending[res];
            for (int64_t i = 0; i < rows * C; ++i)
                pending[i] += g[i];
        }
        wide_weight_grad(work->act[l], g, rows, grads->wide_f[l],
                         grads->wide_b[l]);
        Epilogue e = {NULL, work->has_pending[l] ? work->pending[l] : NULL,
                      NULL, work->act[l], 0};
        memset(spare, 0, sizeof(float) * C);
        memset(spare + (rows - 1) * C, 0, sizeof(float) * C);
        wide_rows(g, net->wide_back[l], spare, rows, &e);
        float *t = g;
        g = spare, spare = t;
    }
    first_weight_grad(work->x, g, rows, grads);
}

/* Run groups of pixels: forward (out != NULL) or backward (grads). */
static int run(const float *x, int64_t x_stride, const float *grad_out,
               int64_t grad_stride, float *out, int64_t out_stride,
               int64_t pixels, int64_t length, const Net *net, Grads *grads)
{
    const int64_t seg = length + 2;
    int64_t group = GROUP_ROWS / seg;
    if (group < 1)
        group = 1;
    if (group > pixels)
        group = pixels;
    Work work;
    if (work_alloc(&work, net, group * seg) != 0)
        return -1;
    for (int64_t p = 0; p < pixels; p += group) {
        const int64_t n = pixels - p < group ? pixels - p : group;
        load_rows(x + p * x_stride, x_stride, n, length, work.x);
        group_forward(net, &work, n, seg);
        if (out) {
            for (int64_t i = 0; i < n; ++i)
                memcpy(out + (p + i) * out_stride, work.out + i * seg + 1,
                       sizeof(float) * length);
        } else {
            load_rows(grad_out + p * grad_stride, grad_stride, n, length,
                      work.gl);
            group_backward(net, &work, n, seg, grads);
        }
    }
    free(work.memory);
    return 0;
}

#endif /* HAVE_KERNEL */

static int supported(void)
{
#if HAVE_KERNEL
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

static void *address(Py_ssize_t value)
{
    return (void *)(uintptr_t)value;
}

/* run(x, x_stride, grad_out, grad_stride, out, out_stride, pixels, length,
 *     layers, residual, params, grads): addresses (0 for absent) and sizes
 * in elements. */
static PyObject *py_run(PyObject *self, PyObject *args)
{
    Py_ssize_t x, x_stride, grad_out, grad_stride, out, out_stride, pixels,
        length, residual, params, grads;
    int layers;
    (void)self;
    if (!PyArg_ParseTuple(args, "nnnnnnnninnn", &x, &x_stride, &grad_out,
                          &grad_stride, &out, &out_stride, &pixels, &length,
                          &layers, &residual, &params, &grads))
        return NULL;
    if (!supported() || layers < 2 || layers > MAX_LAYERS) {
        PyErr_SetString(PyExc_ValueError,
                        "band network kernel: unsupported CPU or layers");
        return NULL;
    }
#if HAVE_KERNEL
    Net net;
    Grads g;
    int status = 0;
    unpack(&net, address(params), layers, address(residual));
    if (grads)
        unpack_grads(&g, address(grads), layers);
    Py_BEGIN_ALLOW_THREADS
    status = run(address(x), x_stride, address(grad_out), grad_stride,
                 address(out), out_stride, pixels, length, &net,
                 grads ? &g : NULL);
    Py_END_ALLOW_THREADS
    if (status != 0)
        return PyErr_NoMemory();
#endif
    Py_RETURN_NONE;
}

static PyObject *py_supported(PyObject *self, PyObject *args)
{
    (void)self;
    (void)args;
    return PyBool_FromLong(supported());
}

static PyMethodDef methods[] = {
    {"run", py_run, METH_VARARGS,
     "run(x, x_stride, grad_out, grad_stride, out, out_stride, pixels, "
     "length, layers, residual, params, grads): one band's networks over "
     "pixels; forward when out is given, else backward into grads."},
    {"supported", py_supported, METH_NOARGS,
     "Whether this CPU runs the kernel (x86-64 with AVX2 and FMA)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_band_networks",
    "WGSE's 1-D band networks as one compiled CPU kernel (float32).", -1,
    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__band_networks(void)
{
    return PyModule_Create(&module);
}
