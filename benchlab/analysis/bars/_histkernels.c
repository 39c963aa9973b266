/* Compiled kernels of the histogram-peak method (benchlab.analysis.histogram, issue 9).
 *
 * Each kernel fuses the per-pixel numpy passes of one stage into plain loops and reproduces
 * numpy's arithmetic step by step - the same products, the same summation order (pairwise
 * sums of contiguous reductions, row-by-row sums across rows, the unrolled two-lane loop of
 * einsum's dot product, reduceat's first element plus a pairwise sum), and numpy's complex
 * product with or without a fused multiply-add (the caller says which numpy uses on this CPU)
 * - so that on a given machine the readings are those of the numpy code, which stays the
 * reference and the fallback (benchlab/analysis/kernels.py).
 *
 * Inputs are 2-D float64 buffers of any strides (read through the buffer protocol, never
 * written); scratch memory is allocated here and freed on every path. Build with
 * -ffp-contract=off: a contracted a * b + c would round differently from numpy.
 *
 * The GIL is released around each kernel's loops on a large input (RELEASE_MIN_PIXELS,
 * RELEASE_MIN_BINS: a 2048 x 2048 ROI held it ~30 ms, stalling the TUI and the acquisition
 * thread), as numpy's own loops do. Safe because:
 * - the loops call no Python API: arguments are parsed, buffers acquired and the result built
 *   with the GIL held; the loops report errors as a status (RUN_*) raised afterwards;
 * - the buffers stay valid: each Py_buffer holds a reference to its exporter until
 *   PyBuffer_Release, after the GIL is taken back, and numpy refuses to resize an array that
 *   is referenced (a bytes object, the phase windows, is immutable);
 * - the loops only read the inputs; the one buffer written, phase_select's ``out``, is the
 *   caller's fresh array; module state (the residual's cache) is taken and given back with the
 *   GIL held. As for numpy's loops, another thread writing into the very array being read
 *   meanwhile is the caller's race: the analysis never writes its input ROI.
 * Small inputs keep the GIL: a call of tens of microseconds stalls nobody, and taking the GIL
 * back from a busy thread can cost a switch interval (5 ms).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const char *data;
    Py_ssize_t rows, cols;
    Py_ssize_t rs, cs; /* strides in bytes */
} Image;

#define PX(im, r, c) (*(const double *)((im)->data + (r) * (im)->rs + (c) * (im)->cs))

static int is_float64_format(const char *fmt)
{
    if (fmt == NULL)
        return 0;
    if (fmt[0] == '@' || fmt[0] == '=' || fmt[0] == '<')
        fmt++;
    return strcmp(fmt, "d") == 0;
}

/* A 2-D float64 buffer of at least one pixel (any strides). On success the caller releases
 * ``view``. */
static int get_image(PyObject *obj, Py_buffer *view, Image *im)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_RECORDS_RO) < 0)
        return -1;
    if (view->ndim != 2 || view->itemsize != 8 || !is_float64_format(view->format)) {
        PyErr_SetString(PyExc_TypeError, "expected a 2-D float64 array");
        PyBuffer_Release(view);
        return -1;
    }
    /* Unaligned doubles are undefined behaviour in C: the callers take the numpy path. */
    if ((uintptr_t)view->buf % sizeof(double) != 0 || view->strides[0] % (Py_ssize_t)sizeof(double) != 0 ||
        view->strides[1] % (Py_ssize_t)sizeof(double) != 0) {
        PyErr_SetString(PyExc_ValueError, "expected an aligned float64 array");
        PyBuffer_Release(view);
        return -1;
    }
    im->data = (const char *)view->buf;
    im->rows = view->shape[0];
    im->cols = view->shape[1];
    im->rs = view->strides[0];
    im->cs = view->strides[1];
    if (im->rows < 1 || im->cols < 1) {
        PyErr_SetString(PyExc_ValueError, "expected at least one pixel");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* The GIL is released for images of at least this many pixels (about 0.25 ms of
 * phase_select or quick_core here) and for histograms of at least this many bins (the merge of
 * many light basins is quadratic in the peaks). */
#define RELEASE_MIN_PIXELS ((Py_ssize_t)1 << 16)
#define RELEASE_MIN_BINS ((Py_ssize_t)1 << 12)

/* PyEval_SaveThread when ``release``, else NULL; undone by reacquire_gil. */
static PyThreadState *release_gil(int release)
{
    return release ? PyEval_SaveThread() : NULL;
}

static void reacquire_gil(PyThreadState *released)
{
    if (released)
        PyEval_RestoreThread(released);
}

/* numpy's pairwise sum (the inner loop of add.reduce over a run of n values). */
static double pairwise_sum(const double *a, Py_ssize_t n, Py_ssize_t stride)
{
    if (n < 8) {
        double res = 0.0;
        for (Py_ssize_t i = 0; i < n; i++)
            res += a[i * stride];
        return res;
    }
    if (n <= 128) {
        double r[8], res;
        Py_ssize_t i;
        for (int k = 0; k < 8; k++)
            r[k] = a[k * stride];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int k = 0; k < 8; k++)
                r[k] += a[(i + k) * stride];
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++)
            res += a[i * stride];
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2, stride) + pairwise_sum(a + n2 * stride, n - n2, stride);
}

/* numpy's pairwise sum of ``count`` complex values (interleaved re, im; ``stride`` in
 * complex elements): its recursion runs on the 2 count doubles, so a block of 8 doubles is
 * 4 complex values, real and imaginary parts summed apart. */
static void complex_pairwise_sum(const double *a, Py_ssize_t count, Py_ssize_t stride,
                                 double *rr, double *ri)
{
    const Py_ssize_t step = 2 * stride;
    if (count < 4) {
        double sr = 0.0, si = 0.0;
        for (Py_ssize_t i = 0; i < count; i++) {
            sr += a[i * step];
            si += a[i * step + 1];
        }
        *rr = sr;
        *ri = si;
        return;
    }
    if (count <= 64) {
        double r[8];
        Py_ssize_t i;
        for (int k = 0; k < 4; k++) {
            r[2 * k] = a[k * step];
            r[2 * k + 1] = a[k * step + 1];
        }
        for (i = 4; i < count - (count % 4); i += 4)
            for (int k = 0; k < 4; k++) {
                r[2 * k] += a[(i + k) * step];
                r[2 * k + 1] += a[(i + k) * step + 1];
            }
        double sr = (r[0] + r[2]) + (r[4] + r[6]);
        double si = (r[1] + r[3]) + (r[5] + r[7]);
        for (; i < count; i++) {
            sr += a[i * step];
            si += a[i * step + 1];
        }
        *rr = sr;
        *ri = si;
        return;
    }
    Py_ssize_t half = (count - count % 8) / 2; /* numpy: n2 = n / 2 less n2 % 8, in doubles */
    double ar, ai, br, bi;
    complex_pairwise_sum(a, half, stride, &ar, &ai);
    complex_pairwise_sum(a + half * step, count - half, stride, &br, &bi);
    *rr = ar + br;
    *ri = ai + bi;
}

/* complex_pairwise_sum of the products res[i] * ex[i] (a real times an interleaved complex,
 * numpy's product of the real cast to complex), formed on the fly: no product buffer. */
#define PRE(i) (res[i] * ex[2 * (i)] - 0.0 * ex[2 * (i) + 1])
#define PIM(i) (res[i] * ex[2 * (i) + 1] + 0.0 * ex[2 * (i)])
static void product_pairwise_sum(const double *res, const double *ex, Py_ssize_t count,
                                 double *rr, double *ri)
{
    if (count < 4) {
        double sr = 0.0, si = 0.0;
        for (Py_ssize_t i = 0; i < count; i++) {
            sr += PRE(i);
            si += PIM(i);
        }
        *rr = sr;
        *ri = si;
        return;
    }
    if (count <= 64) {
        double r[8];
        Py_ssize_t i;
        for (int k = 0; k < 4; k++) {
            r[2 * k] = PRE(k);
            r[2 * k + 1] = PIM(k);
        }
        for (i = 4; i < count - (count % 4); i += 4)
            for (int k = 0; k < 4; k++) {
                r[2 * k] += PRE(i + k);
                r[2 * k + 1] += PIM(i + k);
            }
        double sr = (r[0] + r[2]) + (r[4] + r[6]);
        double si = (r[1] + r[3]) + (r[5] + r[7]);
        for (; i < count; i++) {
            sr += PRE(i);
            si += PIM(i);
        }
        *rr = sr;
        *ri = si;
        return;
    }
    Py_ssize_t half = (count - count % 8) / 2;
    double ar, ai, br, bi;
    product_pairwise_sum(res, ex, half, &ar, &ai);
    product_pairwise_sum(res + half, ex + 2 * half, count - half, &br, &bi);
    *rr = ar + br;
    *ri = ai + bi;
}

/* segment_sum (below) of the products res[i] * ex[i], i in [start, end). */
static void product_segment_sum(const double *res, const double *ex, Py_ssize_t start,
                                Py_ssize_t end, double *out)
{
    out[0] = res[start] * ex[2 * start] - 0.0 * ex[2 * start + 1];
    out[1] = res[start] * ex[2 * start + 1] + 0.0 * ex[2 * start];
    if (end - start > 1) {
        double rr, ri;
        product_pairwise_sum(res + start + 1, ex + 2 * (start + 1), end - start - 1, &rr, &ri);
        out[0] += rr;
        out[1] += ri;
    }
}
#undef PRE
#undef PIM

/* np.add.reduceat over one segment of complex values: the first plus the pairwise sum of
 * the rest. ``a`` interleaved, ``stride`` in complex elements. */
static void segment_sum(const double *a, Py_ssize_t start, Py_ssize_t end, Py_ssize_t stride,
                        double *out)
{
    out[0] = a[start * 2 * stride];
    out[1] = a[start * 2 * stride + 1];
    if (end - start > 1) {
        double rr, ri;
        complex_pairwise_sum(a + (start + 1) * 2 * stride, end - start - 1, stride, &rr, &ri);
        out[0] += rr;
        out[1] += ri;
    }
}

/* One buffer of einsum's dot product: two lanes, four pairs per step, the last pair of a
 * step added first; then the lanes. */
static double einsum_chunk(const double *a, const double *b, Py_ssize_t n)
{
    double acc0 = 0.0, acc1 = 0.0;
    Py_ssize_t i = 0;
    for (; n - i >= 8; i += 8) {
        double t0 = acc0, t1 = acc1;
        for (int blk = 3; blk >= 0; blk--) {
            t0 = a[i + 2 * blk] * b[i + 2 * blk] + t0;
            t1 = a[i + 2 * blk + 1] * b[i + 2 * blk + 1] + t1;
        }
        acc0 = t0;
        acc1 = t1;
    }
    for (; i < n; i += 2) {
        acc0 = a[i] * b[i] + acc0;
        if (i + 1 < n)
            acc1 = a[i + 1] * b[i + 1] + acc1;
    }
    return acc0 + acc1;
}

/* np.einsum("i,i->", a, b) on contiguous float64: its iterator hands the loop buffers of
 * 8192 elements, each one's sum added to the output in turn. */
static double einsum_dot(const double *a, const double *b, Py_ssize_t n)
{
    double out = 0.0;
    for (Py_ssize_t i = 0; i < n; i += 8192)
        out = einsum_chunk(a + i, b + i, n - i < 8192 ? n - i : 8192) + out;
    return out;
}

/* numpy's complex product: with a fused multiply-add (its AVX2/AVX-512 loops) or without. */
static inline void cmul(int fused, double ar, double ai, double br, double bi, double *re,
                        double *im)
{
    if (fused) {
        *re = fma(ar, br, -(ai * bi));
        *im = fma(ar, bi, ai * br);
    } else {
        *re = ar * br - ai * bi;
        *im = ar * bi + ai * br;
    }
}

/* Python's complex product (CPython: never fused). */
static inline void pymul(double ar, double ai, double br, double bi, double *re, double *im)
{
    *re = ar * br - ai * bi;
    *im = ar * bi + ai * br;
}

/* The residual's memory, kept between calls: a fresh block per call of a large ROI costs
 * more in page faults than the passes over it. A call takes it (cache_take) and gives it back
 * (cache_give) with the GIL held, and owns it in between, grown as needed: calls running at
 * once in several threads (the GIL released) never share it - a call that finds the cache
 * taken starts from an empty one, and the larger block is kept when both give theirs back. */
static double *resid_cache = NULL;
static size_t resid_cache_len = 0;

typedef struct {
    double *mem;
    size_t len; /* in doubles */
} Block;

static Block cache_take(void)
{
    Block b = {resid_cache, resid_cache_len};
    resid_cache = NULL;
    resid_cache_len = 0;
    return b;
}

static void cache_give(Block b)
{
    if (b.len >= resid_cache_len) {
        free(resid_cache);
        resid_cache = b.mem;
        resid_cache_len = b.len;
    } else {
        free(b.mem);
    }
}

/* At least n doubles of ``b`` (grown; NULL when out of memory, ``b`` then unchanged). */
static double *block_reserve(Block *b, size_t n)
{
    if (n > b->len) {
        double *grown = realloc(b->mem, n * sizeof(double));
        if (!grown)
            return NULL;
        b->mem = grown;
        b->len = n;
    }
    return b->mem;
}

/* Scratch for one quick-geometry call: the residual and the DFT's factors. */
typedef struct {
    Py_ssize_t rows, cols;
    const double *pixels; /* rows x cols, row-major: the input itself or ``img`` */
    double *img;     /* the input made contiguous when it is not (else NULL) */
    double *resid;   /* rows x cols (in the caller's Block) */
    double *x, *y;   /* centred coordinates */
    double *ex, *ey; /* interleaved complex, cols and rows */
    double *blocks;  /* interleaved complex, rows x 4 */
} Scratch;

static void scratch_free(Scratch *s)
{
    free(s->img);
    free(s->x);
    free(s->y);
    free(s->ex);
    free(s->ey);
    free(s->blocks);
}

static int scratch_alloc(Scratch *s, const Image *im, Block *resid)
{
    Py_ssize_t rows = im->rows, cols = im->cols;
    size_t n = (size_t)rows * (size_t)cols;
    int contiguous = im->cs == (Py_ssize_t)sizeof(double) &&
                     (rows == 1 || im->rs == cols * (Py_ssize_t)sizeof(double));
    memset(s, 0, sizeof(*s));
    s->rows = rows;
    s->cols = cols;
    if (contiguous) {
        s->pixels = (const double *)im->data;
    } else {
        s->img = malloc(n * sizeof(double));
        if (s->img) {
            for (Py_ssize_t r = 0; r < rows; r++)
                for (Py_ssize_t c = 0; c < cols; c++)
                    s->img[r * cols + c] = PX(im, r, c);
        }
        s->pixels = s->img;
    }
    s->resid = block_reserve(resid, n);
    s->x = malloc((size_t)cols * sizeof(double));
    s->y = malloc((size_t)rows * sizeof(double));
    s->ex = malloc(2 * (size_t)cols * sizeof(double));
    s->ey = malloc(2 * (size_t)rows * sizeof(double));
    s->blocks = malloc(8 * (size_t)rows * sizeof(double));
    if (!s->pixels || !s->resid || !s->x || !s->y || !s->ex || !s->ey || !s->blocks) {
        scratch_free(s);
        return -1;
    }
    for (Py_ssize_t c = 0; c < cols; c++)
        s->x[c] = (double)c - (double)(cols - 1) / 2.0;
    for (Py_ssize_t r = 0; r < rows; r++)
        s->y[r] = (double)r - (double)(rows - 1) / 2.0;
    return 0;
}

/* bargeometry.detrend of the pixels into s->resid: minus their mean and least-squares
 * plane. */
static int detrend_into(Scratch *s)
{
    Py_ssize_t rows = s->rows, cols = s->cols;
    const double *img = s->pixels;
    double *col_sums = malloc((size_t)cols * sizeof(double));
    double *row_sums = malloc((size_t)rows * sizeof(double));
    double *tmp = malloc((size_t)(rows > cols ? rows : cols) * sizeof(double));
    if (!col_sums || !row_sums || !tmp) {
        free(col_sums);
        free(row_sums);
        free(tmp);
        return -1;
    }
    /* add.reduce(axis=0): rows added one after the other (a single column: pairwise). */
    if (cols == 1) {
        for (Py_ssize_t r = 0; r < rows; r++)
            tmp[r] = img[r];
        col_sums[0] = 0.0 + pairwise_sum(tmp, rows, 1);
    } else {
        for (Py_ssize_t c = 0; c < cols; c++)
            col_sums[c] = 0.0 + img[c];
        for (Py_ssize_t r = 1; r < rows; r++)
            for (Py_ssize_t c = 0; c < cols; c++)
                col_sums[c] += img[r * cols + c];
    }
    /* add.reduce(axis=1): a pairwise sum per row. */
    for (Py_ssize_t r = 0; r < rows; r++)
        row_sums[r] = 0.0 + pairwise_sum(img + r * cols, cols, 1);
    double n = (double)(rows * cols);
    double mean = (0.0 + pairwise_sum(col_sums, cols, 1)) / n;
    double gx = 0.0, gy = 0.0;
    if (cols > 1) {
        for (Py_ssize_t c = 0; c < cols; c++)
            tmp[c] = col_sums[c] * s->x[c];
        gx = (0.0 + pairwise_sum(tmp, cols, 1)) * 12.0 / (double)(rows * cols * (cols * cols - 1));
    }
    if (rows > 1) {
        for (Py_ssize_t r = 0; r < rows; r++)
            tmp[r] = row_sums[r] * s->y[r];
        gy = (0.0 + pairwise_sum(tmp, rows, 1)) * 12.0 / (double)(rows * cols * (rows * rows - 1));
    }
    for (Py_ssize_t r = 0; r < rows; r++) {
        double level = mean + gy * s->y[r];
        double *out = s->resid + r * cols;
        for (Py_ssize_t c = 0; c < cols; c++)
            out[c] = (img[r * cols + c] - level) - gx * s->x[c];
    }
    free(col_sums);
    free(row_sums);
    free(tmp);
    return 0;
}

/* exp(-2 pi i k t) for the centred coordinates t (numpy: cos and sin of the product). The
 * coordinates are symmetric about 0 (t[n - 1 - i] = -t[i] exactly, so is the argument):
 * the second half from the first, cos being even and sin odd in every libm's arithmetic. */
static void phasors(double k, const double *t, Py_ssize_t n, double *out)
{
    double w = (-2.0 * M_PI) * k;
    Py_ssize_t half = (n + 1) / 2;
    for (Py_ssize_t i = 0; i < half; i++) {
        double arg = w * t[i];
        out[2 * i] = cos(arg);
        out[2 * i + 1] = sin(arg);
    }
    for (Py_ssize_t i = half; i < n; i++) {
        out[2 * i] = out[2 * (n - 1 - i)];
        out[2 * i + 1] = -out[2 * (n - 1 - i) + 1];
    }
}

/* bargeometry._quadrant_sums at (kx, ky): q[0..7] = q00, q01, q10, q11 (re, im). */
static void quadrant_sums(Scratch *s, int fused, double kx, double ky, double *q)
{
    Py_ssize_t rows = s->rows, cols = s->cols;
    Py_ssize_t hc = cols / 2, hr = rows / 2;
    phasors(kx, s->x, cols, s->ex);
    phasors(ky, s->y, rows, s->ey);
    double *h = s->blocks; /* rows x 2 complex */
    for (Py_ssize_t r = 0; r < rows; r++) {
        const double *res = s->resid + r * cols;
        product_segment_sum(res, s->ex, 0, hc, h + 4 * r);
        product_segment_sum(res, s->ex, hc, cols, h + 4 * r + 2);
        for (int j = 0; j < 2; j++) {
            double *v = h + 4 * r + 2 * j;
            cmul(fused, v[0], v[1], s->ey[2 * r], s->ey[2 * r + 1], &v[0], &v[1]);
        }
    }
    for (int j = 0; j < 2; j++) {
        segment_sum(h + 2 * j, 0, hr, 2, q + 2 * j);
        segment_sum(h + 2 * j, hr, rows, 2, q + 4 + 2 * j);
    }
}

/* bargeometry._drift_refine; returns 1 and sets kx, ky, value when settled, else 0. */
static int drift_refine(Scratch *s, int fused, double *kx, double *ky, double settled,
                        int max_passes, double *value)
{
    Py_ssize_t rows = s->rows, cols = s->cols;
    double q[8];
    for (int pass = 0; pass < max_passes; pass++) {
        quadrant_sums(s, fused, *kx, *ky, q);
        double q00r = q[0], q00i = q[1], q01r = q[2], q01i = q[3];
        double q10r = q[4], q10i = q[5], q11r = q[6], q11i = q[7];
        double ar, ai, br, bi;
        pymul(q01r, q01i, q00r, -q00i, &ar, &ai);
        pymul(q11r, q11i, q10r, -q10i, &br, &bi);
        double dkx = atan2(ai + bi, ar + br) / (M_PI * (double)cols);
        pymul(q10r, q10i, q00r, -q00i, &ar, &ai);
        pymul(q11r, q11i, q01r, -q01i, &br, &bi);
        double dky = atan2(ai + bi, ar + br) / (M_PI * (double)rows);
        *kx = *kx + dkx;
        *ky = *ky + dky;
        if (fabs(dkx) * (double)cols / 2.0 + fabs(dky) * (double)rows / 2.0 < settled) {
            value[0] = ((q00r + q01r) + q10r) + q11r;
            value[1] = ((q00i + q01i) + q10i) + q11i;
            return 1;
        }
    }
    return 0;
}

/* bargeometry._coarse_drift_step: one step between neighbouring quarters. */
static void coarse_drift_step(Scratch *s, int fused, double *kx, double *ky)
{
    Py_ssize_t rows = s->rows, cols = s->cols;
    Py_ssize_t col_edges[5], row_edges[5];
    for (int i = 0; i < 4; i++) {
        col_edges[i] = (Py_ssize_t)nearbyint((double)(i * cols) / 4.0);
        row_edges[i] = (Py_ssize_t)nearbyint((double)(i * rows) / 4.0);
    }
    col_edges[4] = cols;
    row_edges[4] = rows;
    phasors(*kx, s->x, cols, s->ex);
    phasors(*ky, s->y, rows, s->ey);
    double *b = s->blocks; /* rows x 4 complex */
    for (Py_ssize_t r = 0; r < rows; r++) {
        const double *res = s->resid + r * cols;
        for (int k = 0; k < 4; k++) {
            /* reduceat: an index not below the next one gives the single element. */
            Py_ssize_t end = col_edges[k] < col_edges[k + 1] ? col_edges[k + 1] : col_edges[k] + 1;
            double *v = b + 8 * r + 2 * k;
            product_segment_sum(res, s->ex, col_edges[k], end, v);
            cmul(fused, v[0], v[1], s->ey[2 * r], s->ey[2 * r + 1], &v[0], &v[1]);
        }
    }
    double z[32]; /* 4 x 4 complex */
    for (int k = 0; k < 4; k++) {
        Py_ssize_t end = row_edges[k] < row_edges[k + 1] ? row_edges[k + 1] : row_edges[k] + 1;
        for (int j = 0; j < 4; j++)
            segment_sum(b + 2 * j, row_edges[k], end, 4, z + 8 * k + 2 * j);
    }
    double across[24], down[24];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 3; j++) {
            const double *u = z + 8 * i + 2 * (j + 1), *v = z + 8 * i + 2 * j;
            cmul(fused, u[0], u[1], v[0], -v[1], &across[6 * i + 2 * j],
                 &across[6 * i + 2 * j + 1]);
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++) {
            const double *u = z + 8 * (i + 1) + 2 * j, *v = z + 8 * i + 2 * j;
            cmul(fused, u[0], u[1], v[0], -v[1], &down[8 * i + 2 * j], &down[8 * i + 2 * j + 1]);
        }
    double ar, ai, dr, di;
    complex_pairwise_sum(across, 12, 1, &ar, &ai);
    complex_pairwise_sum(down, 12, 1, &dr, &di);
    ar = 0.0 + ar;
    ai = 0.0 + ai;
    dr = 0.0 + dr;
    di = 0.0 + di;
    *kx = *kx + atan2(ai, ar) / (2.0 * M_PI * (double)cols / 4.0);
    *ky = *ky + atan2(di, dr) / (2.0 * M_PI * (double)rows / 4.0);
}

/* bargeometry._cell_gradient_direction */
static double cell_gradient_direction(double theta, double f)
{
    double kx = M_PI * f * cos(theta), ky = M_PI * f * sin(theta);
    return atan2(cos(kx) * sin(ky), sin(kx) * cos(ky));
}

/* structure_tensor_direction's theta; -1 on allocation failure. */
static int structure_theta(Scratch *s, double *theta)
{
    /* The cell differences d1, d2 (row-major over the (rows - 1) x (cols - 1) cells) in
     * einsum("kn,ln->kl")'s order: one unbuffered run of its dot loop per output - blocks of
     * 8 in two lanes, the last pair of a block first, then the tail by pairs - the three
     * outputs' chains interleaved, the differences formed 8 at a time (no buffers). */
    Py_ssize_t rows = s->rows, cols = s->cols;
    double a1[8], a2[8];
    double aa[2] = {0.0, 0.0}, ab[2] = {0.0, 0.0}, bb[2] = {0.0, 0.0};
    int k = 0;
    for (Py_ssize_t r = 0; r + 1 < rows; r++) {
        const double *top = s->resid + r * cols, *bottom = top + cols;
        for (Py_ssize_t c = 0; c + 1 < cols; c++) {
            a1[k] = bottom[c + 1] - top[c];
            a2[k] = bottom[c] - top[c + 1];
            if (++k < 8)
                continue;
            k = 0;
            for (int blk = 3; blk >= 0; blk--)
                for (int l = 0; l < 2; l++) {
                    double u = a1[2 * blk + l], v = a2[2 * blk + l];
                    aa[l] = u * u + aa[l];
                    ab[l] = u * v + ab[l];
                    bb[l] = v * v + bb[l];
                }
        }
    }
    for (int i = 0; i < k; i++) { /* the tail: lane i % 2 */
        double u = a1[i], v = a2[i];
        aa[i % 2] = u * u + aa[i % 2];
        ab[i % 2] = u * v + ab[i % 2];
        bb[i % 2] = v * v + bb[i % 2];
    }
    double s11 = 0.0 + (aa[0] + aa[1]), s12 = 0.0 + (ab[0] + ab[1]);
    double s22 = 0.0 + (bb[0] + bb[1]);
    double a = -s12, b = 0.5 * (s11 - s22);
    double t = 0.5 * atan2(b, a);
    if (t <= -M_PI / 2 + 1e-12)
        t += M_PI;
    *theta = t;
    return 0;
}

PyDoc_STRVAR(quick_core_doc,
"quick_core(img, freq, min_periods, settled_cycles, iterations, coarse_min_px, fused)\n"
"--\n\n"
"bargeometry.quick_fundamental's passes over the pixels of ``img`` (2-D float64, at least\n"
"8 x 8): plane fit, structure tensor, phase-drift refinement. Returns ``(kx, ky, re, im,\n"
"power_sum)`` (the refined frequency vector, the DFT there, the sum of squares about the\n"
"plane), or None when the ROI spans too few periods or the refinement does not settle.");

/* What a kernel's loops report once the GIL is held again (they raise nothing themselves). */
enum { RUN_OK = 0, RUN_NONE = 1, RUN_NO_MEMORY = -1, RUN_NOT_FINITE = -2 };

/* quick_core's passes, no Python API: RUN_OK with ``out`` = (kx, ky, re, im, power),
 * RUN_NONE (too few periods, or not settled) or RUN_NO_MEMORY. */
static int quick_core_run(const Image *im, double f, double min_periods, double settled,
                          int iterations, Py_ssize_t coarse_min_px, int fused, Block *resid,
                          double *out)
{
    Scratch s;
    if (scratch_alloc(&s, im, resid) < 0)
        return RUN_NO_MEMORY;
    int status = RUN_NONE;
    double theta_cells, theta;
    if (detrend_into(&s) < 0 || structure_theta(&s, &theta_cells) < 0) {
        status = RUN_NO_MEMORY;
        goto done;
    }
    Py_ssize_t rows = im->rows, cols = im->cols;
    theta = theta_cells;
    for (int i = 0; i < 3; i++)
        theta += theta_cells - cell_gradient_direction(theta, f);
    if (f * (fabs(cos(theta)) * (double)cols + fabs(sin(theta)) * (double)rows) < min_periods)
        goto done;
    double kx = f * cos(theta), ky = f * sin(theta), value[2];
    int ok = drift_refine(&s, fused, &kx, &ky, settled, iterations, value);
    if (!ok && (rows < cols ? rows : cols) >= coarse_min_px) {
        kx = f * cos(theta);
        ky = f * sin(theta);
        coarse_drift_step(&s, fused, &kx, &ky);
        ok = drift_refine(&s, fused, &kx, &ky, settled, iterations, value);
    }
    if (!ok)
        goto done;
    out[0] = kx;
    out[1] = ky;
    out[2] = value[0];
    out[3] = value[1];
    out[4] = einsum_dot(s.resid, s.resid, rows * cols);
    status = RUN_OK;
done:
    scratch_free(&s);
    return status;
}

static PyObject *quick_core(PyObject *self, PyObject *args)
{
    PyObject *obj;
    double f, min_periods, settled;
    int iterations, fused;
    Py_ssize_t coarse_min_px;
    (void)self;
    if (!PyArg_ParseTuple(args, "Odddinp", &obj, &f, &min_periods, &settled, &iterations,
                          &coarse_min_px, &fused))
        return NULL;
    Py_buffer view;
    Image im;
    if (get_image(obj, &view, &im) < 0)
        return NULL;
    if (im.rows < 8 || im.cols < 8) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "quick_core needs at least 8 x 8 pixels");
        return NULL;
    }
    /* The plane fit's denominators (rows * cols * (cols^2 - 1)) must fit a Py_ssize_t. */
    if (im.rows > 4096 || im.cols > 4096) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "quick_core takes at most 4096 x 4096 pixels");
        return NULL;
    }
    double out[5];
    Block resid = cache_take();
    PyThreadState *released = release_gil(im.rows * im.cols >= RELEASE_MIN_PIXELS);
    int status = quick_core_run(&im, f, min_periods, settled, iterations, coarse_min_px, fused,
                                &resid, out);
    reacquire_gil(released);
    cache_give(resid);
    PyBuffer_Release(&view);
    if (status == RUN_NO_MEMORY)
        return PyErr_NoMemory();
    if (status == RUN_NONE)
        Py_RETURN_NONE;
    return Py_BuildValue("(ddddd)", out[0], out[1], out[2], out[3], out[4]);
}

PyDoc_STRVAR(phase_select_doc,
"phase_select(img, kx_bins, ky_bins, centre, inner_limit, near, wide, min_pixels, out)\n"
"--\n\n"
"histogram._phases_at and the bar-centre selection in one pass: each pixel's scaled phase\n"
"``ky_bins y + centre + kx_bins x`` (32 bins a cycle), its bin (the low 5 bits), whether it\n"
"lies on the inner bars (``|scaled - centre| <= inner_limit``; a negative limit: all do);\n"
"the pooled scatter about the bins' means; and the pixels of the inner bars in the bins\n"
"``near`` (32 bytes, nonzero = in), else ``wide`` when fewer than ``min_pixels``, else all\n"
"bins, written in row-major order to ``out`` (float64, at least the pixel count). Returns\n"
"``(scatter, n_selected, vmin, vmax)``.");

#define N_PHASE_BINS 32

/* phase_select's pass, no Python API: RUN_OK with ``res`` = (scatter, vmin, vmax) and
 * ``*selected`` values written to ``dst``, or RUN_NO_MEMORY. */
static int phase_select_run(const Image *im, double kx32, double ky32, double centre,
                            double inner_limit, const unsigned char *near,
                            const unsigned char *wide, Py_ssize_t min_pixels, double *dst,
                            double *res, Py_ssize_t *selected)
{
    Py_ssize_t rows = im->rows, cols = im->cols, n = rows * cols;
    /* The pixels row-major: the input itself when contiguous, else a copy. */
    const double *flat = (const double *)im->data;
    double *copy = NULL;
    if (im->cs != (Py_ssize_t)sizeof(double) ||
        (rows > 1 && im->rs != cols * (Py_ssize_t)sizeof(double))) {
        copy = malloc((size_t)n * sizeof(double));
        if (!copy)
            return RUN_NO_MEMORY;
        for (Py_ssize_t r = 0; r < rows; r++)
            for (Py_ssize_t c = 0; c < cols; c++)
                copy[r * cols + c] = PX(im, r, c);
        flat = copy;
    }
    unsigned char *tags = malloc((size_t)n);
    if (!tags) {
        free(copy);
        return RUN_NO_MEMORY;
    }
    long long count[N_PHASE_BINS] = {0};
    double sums[N_PHASE_BINS] = {0.0};
    Py_ssize_t n_near = 0, n_wide = 0;
    Py_ssize_t k = 0;
    for (Py_ssize_t r = 0; r < rows; r++) {
        double yr = (double)r - (double)(rows - 1) / 2.0;
        double a = ky32 * yr + centre;
        for (Py_ssize_t c = 0; c < cols; c++, k++) {
            double xc = (double)c - (double)(cols - 1) / 2.0;
            double scaled = a + kx32 * xc;
            /* numpy's astype(intp) truncates; beyond int64 (or NaN) x86 gives INT64_MIN,
             * bin 0 - converting such a double in C would be undefined. */
            int bin = fabs(scaled) < 9.2e18 ? (int)((int64_t)scaled & (N_PHASE_BINS - 1)) : 0;
            int inner = inner_limit < 0 || fabs(scaled - centre) <= inner_limit;
            double v = flat[k];
            count[bin]++;
            sums[bin] += v;
            tags[k] = (unsigned char)(bin | (inner ? 0x80 : 0));
            if (inner) {
                n_near += near[bin] != 0;
                n_wide += wide[bin] != 0;
            }
        }
    }
    /* histogram._scatter_about_bins */
    double squares = einsum_dot(flat, flat, n);
    double means[N_PHASE_BINS];
    Py_ssize_t occupied = 0;
    for (int b = 0; b < N_PHASE_BINS; b++) {
        means[b] = sums[b] / (double)(count[b] > 1 ? count[b] : 1);
        occupied += count[b] != 0;
    }
    double within = squares - einsum_dot(sums, means, N_PHASE_BINS);
    if (0.0 > within)
        within = 0.0;
    Py_ssize_t dof = n - occupied > 1 ? n - occupied : 1;
    double scatter = sqrt(within / (double)dof);
    /* The selection: near, else wide, else every bin of the inner bars. */
    const unsigned char *table = n_near >= min_pixels ? near : n_wide >= min_pixels ? wide : NULL;
    double vmin = 0.0, vmax = 0.0;
    Py_ssize_t m = 0;
    for (k = 0; k < n; k++) {
        if (!(tags[k] & 0x80) || (table && !table[tags[k] & 0x7f]))
            continue;
        double v = flat[k];
        if (m == 0 || v < vmin)
            vmin = v;
        if (m == 0 || v > vmax)
            vmax = v;
        dst[m++] = v;
    }
    free(tags);
    free(copy);
    res[0] = scatter;
    res[1] = vmin;
    res[2] = vmax;
    *selected = m;
    return RUN_OK;
}

static PyObject *phase_select(PyObject *self, PyObject *args)
{
    PyObject *obj, *out_obj;
    double kx32, ky32, centre, inner_limit;
    Py_buffer near_view, wide_view;
    Py_ssize_t min_pixels;
    (void)self;
    if (!PyArg_ParseTuple(args, "Oddddy*y*nO", &obj, &kx32, &ky32, &centre, &inner_limit,
                          &near_view, &wide_view, &min_pixels, &out_obj))
        return NULL;
    PyObject *result = NULL;
    Py_buffer view, out_view;
    Image im;
    int have_img = 0, have_out = 0;
    if (near_view.len != N_PHASE_BINS || wide_view.len != N_PHASE_BINS) {
        PyErr_SetString(PyExc_ValueError, "near and wide must be 32 bytes");
        goto done;
    }
    if (get_image(obj, &view, &im) < 0)
        goto done;
    have_img = 1;
    if (PyObject_GetBuffer(out_obj, &out_view,
                           PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto done;
    have_out = 1;
    Py_ssize_t n = im.rows * im.cols;
    if (!is_float64_format(out_view.format) || out_view.len < n * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "out must hold a float64 per pixel");
        goto done;
    }
    double res[3];
    Py_ssize_t m = 0;
    PyThreadState *released = release_gil(n >= RELEASE_MIN_PIXELS);
    int status = phase_select_run(&im, kx32, ky32, centre, inner_limit, near_view.buf,
                                  wide_view.buf, min_pixels, out_view.buf, res, &m);
    reacquire_gil(released);
    if (status == RUN_NO_MEMORY) {
        PyErr_NoMemory();
        goto done;
    }
    result = Py_BuildValue("(dndd)", res[0], m, res[1], res[2]);
done:
    if (have_out)
        PyBuffer_Release(&out_view);
    if (have_img)
        PyBuffer_Release(&view);
    PyBuffer_Release(&near_view);
    PyBuffer_Release(&wide_view);
    return result;
}

PyDoc_STRVAR(modes_doc,
"modes(smooth, min_fraction)\n"
"--\n\n"
"histogram._find_peaks(smooth, 0.0) then histogram._massive_modes on its peaks, for a\n"
"smoothed histogram (1-D float64): returns ``(modes, valley, many)`` - the massive modes'\n"
"bins (a list), the valley's bin when two clear modes took the short path (else None), and\n"
"whether there were at least two local maxima.");

/* np.argmin of y[p..q]: the first minimum. */
static Py_ssize_t first_min(const double *y, Py_ssize_t p, Py_ssize_t q)
{
    Py_ssize_t best = p;
    for (Py_ssize_t i = p + 1; i <= q; i++)
        if (y[i] < y[best])
            best = i;
    return best;
}

/* modes' loops, no Python API, over the n values y: the massive modes' bins in ``peaks``
 * (room for n), their count, the valley (-1: none) and ``many``; RUN_OK, RUN_NOT_FINITE or
 * RUN_NO_MEMORY. */
static int modes_run(const double *y, Py_ssize_t n, double min_fraction, Py_ssize_t *peaks,
                     Py_ssize_t *n_out, Py_ssize_t *valley_out, int *many_out)
{
    Py_ssize_t n_peaks = 0;
    /* A smoothed histogram is finite; -inf valleys would index before the mode arrays. */
    for (Py_ssize_t i = 0; i < n; i++)
        if (!isfinite(y[i]))
            return RUN_NOT_FINITE;
    /* _rises and _find_peaks: where a rise ends (y[i-1] < y[i] >= y[i+1]); a single-bin
     * top is a peak, a flat top one when the first different bin after it is lower (its
     * middle bin). Heights below 0 (the minimum height) are skipped. */
    for (Py_ssize_t i = 1; i + 1 < n; i++) {
        if (!(y[i] > y[i - 1]) || y[i + 1] > y[i])
            continue;
        double h = y[i];
        if (h < 0.0)
            continue;
        if (y[i + 1] < h) {
            peaks[n_peaks++] = i;
            continue;
        }
        Py_ssize_t j = i + 1;
        while (j < n && y[j] == h)
            j++;
        if (j < n && y[j] < h)
            peaks[n_peaks++] = (i + j - 1) / 2;
    }
    *many_out = n_peaks >= 2;
    *valley_out = -1;
    *n_out = n_peaks;
    if (n_peaks < 2)
        return RUN_OK;
    /* _massive_modes */
    double total = 0.0 + pairwise_sum(y, n, 1);
    double *cs = malloc((size_t)n * sizeof(double));
    Py_ssize_t *cuts = malloc((size_t)n_peaks * sizeof(Py_ssize_t));
    double *mass = malloc((size_t)n_peaks * sizeof(double));
    double *valleys = malloc((size_t)n_peaks * sizeof(double));
    int status = RUN_OK;
    if (!cs || !cuts || !mass || !valleys) {
        status = RUN_NO_MEMORY;
        goto done;
    }
    double run = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        run = i ? run + y[i] : y[i];
        cs[i] = run;
    }
    double need = min_fraction * total;
    if (n_peaks == 2) {
        Py_ssize_t cut = first_min(y, peaks[0], peaks[1]);
        double low = cs[cut], high = cs[n - 1] - low;
        if ((high < low ? high : low) >= need) {
            *valley_out = cut;
            goto done;
        }
    }
    for (Py_ssize_t k = 0; k + 1 < n_peaks; k++) {
        cuts[k] = first_min(y, peaks[k], peaks[k + 1]);
        valleys[k] = y[cuts[k]];
    }
    for (Py_ssize_t k = 0; k < n_peaks; k++) {
        Py_ssize_t lo = k ? cuts[k - 1] + 1 : 0, hi = k + 1 < n_peaks ? cuts[k] + 1 : n;
        mass[k] = cs[hi - 1] - (lo ? cs[lo - 1] : 0.0);
    }
    /* Merge the lightest basin into the neighbour across its shallower valley. */
    Py_ssize_t n_modes = n_peaks;
    while (n_modes > 1) {
        Py_ssize_t light = 0;
        for (Py_ssize_t k = 1; k < n_modes; k++)
            if (mass[k] < mass[light])
                light = k;
        if (mass[light] >= need)
            break;
        double left = light > 0 ? valleys[light - 1] : -INFINITY;
        double right = light < n_modes - 1 ? valleys[light] : -INFINITY;
        Py_ssize_t j = left >= right ? light - 1 : light + 1;
        Py_ssize_t keep = y[peaks[j]] >= y[peaks[light]] ? j : light;
        double merged = mass[light] + mass[j];
        Py_ssize_t peak = peaks[keep], lo = light < j ? light : j;
        peaks[lo] = peak;
        mass[lo] = merged;
        for (Py_ssize_t k = lo + 1; k + 1 < n_modes; k++) {
            peaks[k] = peaks[k + 1];
            mass[k] = mass[k + 1];
        }
        for (Py_ssize_t k = lo; k + 2 < n_modes; k++)
            valleys[k] = valleys[k + 1];
        n_modes--;
    }
    Py_ssize_t kept = 0;
    for (Py_ssize_t k = 0; k < n_modes; k++)
        if (mass[k] >= need)
            peaks[kept++] = peaks[k];
    *n_out = kept;
done:
    free(cs);
    free(cuts);
    free(mass);
    free(valleys);
    return status;
}

static PyObject *modes(PyObject *self, PyObject *args)
{
    PyObject *obj;
    double min_fraction;
    (void)self;
    if (!PyArg_ParseTuple(args, "Od", &obj, &min_fraction))
        return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(obj, &view, PyBUF_ND | PyBUF_FORMAT | PyBUF_C_CONTIGUOUS) < 0)
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t *peaks = NULL;
    if (view.ndim != 1 || view.itemsize != 8 || !is_float64_format(view.format)) {
        PyErr_SetString(PyExc_TypeError, "expected a 1-D float64 array");
        goto done;
    }
    const double *y = view.buf;
    Py_ssize_t n = view.shape[0], n_modes = 0, valley = -1;
    int many = 0;
    peaks = malloc((size_t)(n > 0 ? n : 1) * sizeof(Py_ssize_t));
    if (!peaks) {
        PyErr_NoMemory();
        goto done;
    }
    PyThreadState *released = release_gil(n >= RELEASE_MIN_BINS);
    int status = modes_run(y, n, min_fraction, peaks, &n_modes, &valley, &many);
    reacquire_gil(released);
    if (status == RUN_NOT_FINITE) {
        PyErr_SetString(PyExc_ValueError, "modes needs finite values");
        goto done;
    }
    if (status == RUN_NO_MEMORY) {
        PyErr_NoMemory();
        goto done;
    }
    PyObject *list = PyList_New(n_modes);
    if (!list)
        goto done;
    for (Py_ssize_t k = 0; k < n_modes; k++) {
        PyObject *item = PyLong_FromSsize_t(peaks[k]);
        if (!item) {
            Py_DECREF(list);
            goto done;
        }
        PyList_SET_ITEM(list, k, item);
    }
    if (valley >= 0)
        result = Py_BuildValue("(NnO)", list, valley, many ? Py_True : Py_False);
    else
        result = Py_BuildValue("(NOO)", list, Py_None, many ? Py_True : Py_False);
done:
    free(peaks);
    PyBuffer_Release(&view);
    return result;
}

static PyMethodDef methods[] = {
    {"quick_core", quick_core, METH_VARARGS, quick_core_doc},
    {"phase_select", phase_select, METH_VARARGS, phase_select_doc},
    {"modes", modes, METH_VARARGS, modes_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_histkernels",
    "Compiled kernels of the histogram-peak method (see benchlab.analysis.kernels).", -1,
    methods, NULL, NULL, NULL, NULL,
};

/* Bumped with any change of the functions' signatures or meaning: kernels.py runs the numpy
 * path rather than a stale build. */
#define KERNELS_VERSION 1

PyMODINIT_FUNC PyInit__histkernels(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m && (PyModule_AddIntConstant(m, "VERSION", KERNELS_VERSION) < 0 ||
              PyModule_AddIntConstant(m, "RELEASE_MIN_PIXELS", RELEASE_MIN_PIXELS) < 0 ||
              PyModule_AddIntConstant(m, "RELEASE_MIN_BINS", RELEASE_MIN_BINS) < 0)) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
