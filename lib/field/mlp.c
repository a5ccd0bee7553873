/* Small fully connected networks: layout, init, forward and backward (see mlp.h).
 *
 * Where the time goes. Every layer is a GEMM of a tall, thin matrix (B rows, 16..64 columns)
 * by a small weight matrix, 2*fan_in*fan_out FLOP per row. Measured on the 2-core AVX-512
 * EPYC CI machine (Debian 12, OpenBLAS 0.3.21 pthread build, which takes this CPU for a
 * "Haswell" and runs its AVX2 kernels: SGEMM 2048^3 about 210 GFLOP/s on 2 threads), B = 2^16
 * and 2^18, forward GFLOP/s on 2 threads (the machine is shared, figures vary by ~30%):
 *   - one OpenBLAS SGEMM over the whole batch per layer, OpenBLAS threading it, then a ReLU
 *     pass: density net 10-28, colour net 13-30, feature net 42-83. Each call hands small
 *     pieces to OpenBLAS's threads and the ReLU pass walks a 64 MB matrix again. Its results
 *     also change with OpenBLAS's thread count (17% of forward outputs, 30% of a 64x64 weight
 *     gradient differ in their last bits between 1 and 2 threads with the Haswell kernels;
 *     with OPENBLAS_CORETYPE=SkylakeX they happen to agree);
 *   - OpenBLAS set to one thread, the batch cut into chunks of 1024 rows that run through all
 *     layers while in L2, chunks split across OpenMP threads: density 15-67, colour 22-69,
 *     feature 62-190: 1.5-2x faster, and deterministic. Weight gradients (64x64 outputs
 *     summed over all rows) run at 125-140 either way;
 *   - the AVX-512 kernels below, on the same chunked split: density 270-300, colour 280-350,
 *     feature 340-375 GFLOP/s (forward+backward alike), against 120-170 for the chunked
 *     OpenBLAS path (160-300 with OPENBLAS_CORETYPE=SkylakeX). One thread runs a 64->64
 *     layer at ~180 GFLOP/s, near the core's peak.
 * The fast path is therefore the chunked split, with the AVX-512 kernels where the CPU has
 * them and single-threaded OpenBLAS SGEMM per chunk otherwise.
 *
 * Determinism. The cut into chunks, and of chunks into at most GROUPS_MAX groups, depends
 * only on B. Forward rows are independent. For the weight gradient each group sums its
 * chunks in order into its own partial gradient, and the partials are added to dW in group
 * order, so no sum depends on which thread ran what. */
#include "field/mlp.h"

#include "core/blas.h"
#include "core/error.h"
#include "core/rng.h"
#include "core/threads.h"

#include <cblas.h>
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

/* The kernels rely on GCC's target pragma, which clang ignores (it then refuses the
 * intrinsics); a clang build (the libFuzzer one) takes the portable path. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#include <immintrin.h>
#define HAVE_AVX512_KERNELS 1
#else
#define HAVE_AVX512_KERNELS 0
#endif

#define CHUNK_MIN 64    /* rows */
#define CHUNK_MAX 1024  /* rows: a 64-wide chunk is 256 KB, it stays in L2 across layers */
#define GROUPS_MAX 16   /* weight-gradient partials; also the parallelism of the backward */
#define PANEL_MAX_K 256 /* AVX-512 forward: fan_in limit of the W^T panel on the stack (64 KB) */

/* ---- configuration and layout ------------------------------------------------------- */

int fg_mlp_config_check(const fg_mlp_config *cfg) {
  if (!cfg) return fg_fail(FG_EINVAL, "mlp config is NULL");
  if (cfg->n_in < 1 || cfg->n_in > FG_MLP_MAX_WIDTH)
    return fg_fail(FG_EINVAL, "mlp n_in must be 1..%d, got %d", FG_MLP_MAX_WIDTH, cfg->n_in);
  if (cfg->n_hidden < 1 || cfg->n_hidden > FG_MLP_MAX_WIDTH)
    return fg_fail(FG_EINVAL, "mlp n_hidden must be 1..%d, got %d", FG_MLP_MAX_WIDTH,
                   cfg->n_hidden);
  if (cfg->n_hidden_layers < 0 || cfg->n_hidden_layers > FG_MLP_MAX_HIDDEN_LAYERS)
    return fg_fail(FG_EINVAL, "mlp n_hidden_layers must be 0..%d, got %d",
                   FG_MLP_MAX_HIDDEN_LAYERS, cfg->n_hidden_layers);
  if (cfg->n_out < 1 || cfg->n_out > FG_MLP_MAX_WIDTH)
    return fg_fail(FG_EINVAL, "mlp n_out must be 1..%d, got %d", FG_MLP_MAX_WIDTH, cfg->n_out);
  return 0;
}

int fg_mlp_layer_fan_in(const fg_mlp_config *cfg, int l) {
  return l == 0 ? cfg->n_in : cfg->n_hidden;
}

int fg_mlp_layer_fan_out(const fg_mlp_config *cfg, int l) {
  return l == cfg->n_hidden_layers ? cfg->n_out : cfg->n_hidden;
}

size_t fg_mlp_layer_offset(const fg_mlp_config *cfg, int l) {
  size_t off = 0;
  for (int i = 0; i < l; i++)
    off += (size_t)fg_mlp_layer_fan_in(cfg, i) * (size_t)fg_mlp_layer_fan_out(cfg, i);
  return off;
}

size_t fg_mlp_n_params(const fg_mlp_config *cfg) {
  return fg_mlp_layer_offset(cfg, cfg->n_hidden_layers + 1);
}

void fg_mlp_init(const fg_mlp_config *cfg, float *W, uint64_t seed) {
  size_t i = 0;
  for (int l = 0; l <= cfg->n_hidden_layers; l++) {
    const int fan_in = fg_mlp_layer_fan_in(cfg, l), fan_out = fg_mlp_layer_fan_out(cfg, l);
    const float scale = sqrtf(6.0f / (float)(fan_in + fan_out));
    for (size_t e = i + (size_t)fan_in * (size_t)fan_out; i < e; i++) {
      /* the (i + 1)-th output of splitmix64 seeded with seed */
      const uint64_t r = fg_mix64(seed + (uint64_t)(i + 1) * 0x9e3779b97f4a7c15ull);
      const float u = (float)(r >> 40) * 0x1p-24f; /* [0, 1), 24 exact bits */
      W[i] = (2.0f * u - 1.0f) * scale;
    }
  }
}

size_t fg_mlp_acts_floats(const fg_mlp_config *cfg, int B) {
  return (size_t)cfg->n_hidden_layers * (size_t)(B > 0 ? B : 0) * (size_t)cfg->n_hidden;
}

/* How a batch is cut: chunks of `chunk` rows (the last one shorter), and the chunks into
 * n_groups contiguous groups, group g holding chunks [g*n_chunks/n_groups, (g+1)*...).
 * Depends only on B. Chunks are multiples of 16 rows, aiming at 16 groups of one chunk for
 * small batches (so that threads have work) and at CHUNK_MAX rows for large ones. */
typedef struct plan {
  int chunk, n_chunks, n_groups;
} plan;

static plan make_plan(int B) {
  plan p = {CHUNK_MIN, 0, 0};
  if (B <= 0) return p;
  int c = (B + GROUPS_MAX - 1) / GROUPS_MAX;
  c = (c + 15) & ~15;
  p.chunk = c < CHUNK_MIN ? CHUNK_MIN : (c > CHUNK_MAX ? CHUNK_MAX : c);
  p.n_chunks = (B + p.chunk - 1) / p.chunk;
  p.n_groups = p.n_chunks < GROUPS_MAX ? p.n_chunks : GROUPS_MAX;
  return p;
}

/* Backward scratch: n_groups partial gradients (n_params each), then per group two delta
 * buffers of chunk x n_hidden (ping-pong between layers). */
size_t fg_mlp_scratch_floats(const fg_mlp_config *cfg, int B) {
  const plan p = make_plan(B);
  const size_t deltas = cfg->n_hidden_layers > 0 ? 2 * (size_t)p.chunk * cfg->n_hidden : 0;
  return (size_t)p.n_groups * (fg_mlp_n_params(cfg) + deltas);
}

/* ---- references ----------------------------------------------------------------------- */

void fg_mlp_forward_ref(const fg_mlp_config *cfg, const float *W, const float *in, int B,
                        float *acts, float *out) {
  const int L = cfg->n_hidden_layers, H = cfg->n_hidden;
  for (int r = 0; r < B; r++) {
    const float *a = in + (size_t)r * cfg->n_in;
    for (int l = 0; l <= L; l++) {
      const int K = fg_mlp_layer_fan_in(cfg, l), N = fg_mlp_layer_fan_out(cfg, l);
      const float *Wl = W + fg_mlp_layer_offset(cfg, l);
      float *o = l < L ? acts + ((size_t)l * B + r) * H : out + (size_t)r * N;
      for (int j = 0; j < N; j++) {
        float s = 0.0f;
        for (int k = 0; k < K; k++) s += a[k] * Wl[(size_t)j * K + k];
        o[j] = l < L ? (s > 0.0f ? s : 0.0f) : s;
      }
      a = o;
    }
  }
}

int fg_mlp_backward_ref(const fg_mlp_config *cfg, const float *W, const float *in,
                        const float *acts, const float *dout, int B, float *dW, float *din) {
  const int L = cfg->n_hidden_layers, H = cfg->n_hidden;
  const size_t n_params = fg_mlp_n_params(cfg);
  const int wmax = H > cfg->n_in ? H : cfg->n_in;
  double *dWd = calloc(n_params, sizeof(double));
  float *cur = malloc(sizeof(float) * (size_t)(wmax > cfg->n_out ? wmax : cfg->n_out));
  float *nxt = malloc(sizeof(float) * (size_t)wmax);
  if (!dWd || !cur || !nxt) {
    free(dWd), free(cur), free(nxt);
    return fg_fail(FG_ENOMEM, "fg_mlp_backward_ref: out of memory");
  }
  for (int r = 0; r < B; r++) {
    memcpy(cur, dout + (size_t)r * cfg->n_out, sizeof(float) * (size_t)cfg->n_out);
    for (int l = L; l >= 0; l--) {
      const int K = fg_mlp_layer_fan_in(cfg, l), N = fg_mlp_layer_fan_out(cfg, l);
      const size_t off = fg_mlp_layer_offset(cfg, l);
      const float *a = l > 0 ? acts + ((size_t)(l - 1) * B + r) * H : in + (size_t)r * K;
      for (int j = 0; j < N; j++)
        for (int k = 0; k < K; k++) dWd[off + (size_t)j * K + k] += (double)cur[j] * a[k];
      if (l == 0 && !din) break;
      for (int k = 0; k < K; k++) {
        float s = 0.0f;
        for (int j = 0; j < N; j++) s += cur[j] * W[off + (size_t)j * K + k];
        nxt[k] = (l == 0 || a[k] > 0.0f) ? s : 0.0f;
      }
      if (l == 0)
        memcpy(din + (size_t)r * K, nxt, sizeof(float) * (size_t)K);
      else
        memcpy(cur, nxt, sizeof(float) * (size_t)K);
    }
  }
  for (size_t i = 0; i < n_params; i++) dW[i] += (float)dWd[i];
  free(dWd), free(cur), free(nxt);
  return 0;
}

/* ---- per-chunk layer operations: OpenBLAS ----------------------------------------------
 * Shapes, for a chunk of n rows and a layer W (N, K):
 *   fwd:    C (n,N) = act(A (n,K) @ W^T)           act: ReLU or none
 *   data:   C (n,K) = (D (n,N) @ W) * [M (n,K) > 0]  M: post-ReLU input of the layer, or none
 *   wgrad:  P (N,K) = (accumulate ? P : 0) + D^T @ A */

static void relu_rows(float *C, size_t count) {
  for (size_t i = 0; i < count; i++) C[i] = C[i] > 0.0f ? C[i] : 0.0f;
}

static void blas_fwd(int n, const float *A, int K, const float *W, int N, float *C, int relu) {
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, N, K, 1.0f, A, K, W, K, 0.0f, C, N);
  if (relu) relu_rows(C, (size_t)n * N);
}

static void blas_data(int n, const float *D, int N, const float *W, int K, const float *M,
                      float *C) {
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, K, N, 1.0f, D, N, W, K, 0.0f, C, K);
  if (M)
    for (size_t i = 0; i < (size_t)n * K; i++) C[i] = M[i] > 0.0f ? C[i] : 0.0f;
}

static void blas_wgrad(int n, const float *D, int N, const float *A, int K, float *P,
                       int accumulate) {
  cblas_sgemm(CblasRowMajor, CblasTrans, CblasNoTrans, N, K, n, 1.0f, D, N, A, K,
              accumulate ? 1.0f : 0.0f, P, K);
}

/* ---- per-chunk layer operations: AVX-512 -----------------------------------------------
 * One register-tiled kernel serves all three operations:
 *   acc[i][v] = sum_t X[i*xs_i + t*xs_t] * Y[t*ys_t + 16v],  i < R, v < NV
 * (the X element broadcast, the Y row loaded as NV vectors, the last one under mask ym).
 *   fwd:   X = A rows (xs_i = K, xs_t = 1), Y = packed W^T panel (ys_t = 64), t over K
 *   data:  X = D rows (xs_i = N, xs_t = 1), Y = W (ys_t = K), t over N
 *   wgrad: X = D columns (xs_i = 1, xs_t = N), Y = A rows (ys_t = K), t over rows
 * R*NV <= 24 accumulators of the 32 zmm registers. R and NV are compile-time constants in
 * every instance (always_inline + switch), so the tile lives in registers. */
#if HAVE_AVX512_KERNELS
#pragma GCC push_options
#pragma GCC target("avx512f,avx2,fma")

#define R_MAX 12

static inline __attribute__((always_inline)) void
avx_tile(const int R, const int NV, int T, const float *X, ptrdiff_t xs_i, ptrdiff_t xs_t,
         const float *Y, ptrdiff_t ys_t, __mmask16 ym, __m512 acc[R_MAX][4]) {
#pragma GCC unroll 12
  for (int i = 0; i < R; i++)
#pragma GCC unroll 4
    for (int v = 0; v < NV; v++) acc[i][v] = _mm512_setzero_ps();
  for (int t = 0; t < T; t++) {
    __m512 y[4];
#pragma GCC unroll 4
    for (int v = 0; v < NV; v++)
      y[v] = v == NV - 1 ? _mm512_maskz_loadu_ps(ym, Y + t * ys_t + 16 * v)
                         : _mm512_loadu_ps(Y + t * ys_t + 16 * v);
#pragma GCC unroll 12
    for (int i = 0; i < R; i++) {
      const __m512 x = _mm512_set1_ps(X[i * xs_i + t * xs_t]);
#pragma GCC unroll 4
      for (int v = 0; v < NV; v++) acc[i][v] = _mm512_fmadd_ps(x, y[v], acc[i][v]);
    }
  }
}

/* Row-block GEMM for fwd and data: C[i][c] (c < ncols <= 64, ldc) = epilogue(acc), where
 * epilogue is ReLU (relu), a mask by M > 0 (M, ldm) or nothing. */
static inline __attribute__((always_inline)) void
avx_rows_fixed(const int R, const int NV, int T, const float *X, ptrdiff_t ldx,
               const float *Y, ptrdiff_t ys_t, __mmask16 ym, float *C, ptrdiff_t ldc,
               int relu, const float *M, ptrdiff_t ldm) {
  __m512 acc[R_MAX][4];
  avx_tile(R, NV, T, X, ldx, 1, Y, ys_t, ym, acc);
  const __m512 zero = _mm512_setzero_ps();
#pragma GCC unroll 12
  for (int i = 0; i < R; i++)
#pragma GCC unroll 4
    for (int v = 0; v < NV; v++) {
      const __mmask16 m = v == NV - 1 ? ym : (__mmask16)0xffff;
      __m512 r = acc[i][v];
      if (relu) r = _mm512_max_ps(r, zero);
      if (M) {
        const __m512 a = _mm512_maskz_loadu_ps(m, M + i * ldm + 16 * v);
        r = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(a, zero, _CMP_GT_OQ), r);
      }
      _mm512_mask_storeu_ps(C + i * ldc + 16 * v, m, r);
    }
}

/* Rows per register tile for NV vectors of columns. */
static inline int rows_per_tile(int NV) { return NV == 1 ? 12 : (NV == 2 ? 12 : (NV == 3 ? 8 : 6)); }

#define AVX_ROWS_CASE(R_, NV_)                                                               \
  case (R_):                                                                                 \
    avx_rows_fixed(R_, NV_, T, X, ldx, Y, ys_t, ym, C, ldc, relu, M, ldm);                   \
    break;
#define AVX_ROWS_NV(NV_)                                                                     \
  static void avx_rows_nv##NV_(int R, int T, const float *X, ptrdiff_t ldx, const float *Y, \
                               ptrdiff_t ys_t, __mmask16 ym, float *C, ptrdiff_t ldc,        \
                               int relu, const float *M, ptrdiff_t ldm) {                    \
    switch (R) {                                                                             \
      AVX_ROWS_CASE(1, NV_) AVX_ROWS_CASE(2, NV_) AVX_ROWS_CASE(3, NV_)                      \
      AVX_ROWS_CASE(4, NV_) AVX_ROWS_CASE(5, NV_) AVX_ROWS_CASE(6, NV_)                      \
      AVX_ROWS_CASE(7, NV_) AVX_ROWS_CASE(8, NV_) AVX_ROWS_CASE(9, NV_)                      \
      AVX_ROWS_CASE(10, NV_) AVX_ROWS_CASE(11, NV_) AVX_ROWS_CASE(12, NV_)                   \
    default:                                                                                 \
      break;                                                                                 \
    }                                                                                        \
  }
AVX_ROWS_NV(1)
AVX_ROWS_NV(2)
AVX_ROWS_NV(3)
AVX_ROWS_NV(4)

/* C (n rows, ncols <= 64 columns) from X (n, T) and Y (T, ncols); see avx_rows_fixed. */
static void avx_rows(int n, int T, const float *X, ptrdiff_t ldx, const float *Y,
                     ptrdiff_t ys_t, int ncols, float *C, ptrdiff_t ldc, int relu,
                     const float *M, ptrdiff_t ldm) {
  const int NV = (ncols + 15) / 16, rt = rows_per_tile(NV);
  const __mmask16 ym = (__mmask16)(0xffffu >> (16 * NV - ncols));
  for (int r = 0; r < n; r += rt) {
    const int R = n - r < rt ? n - r : rt;
    const float *Xr = X + r * ldx, *Mr = M ? M + r * ldm : NULL;
    float *Cr = C + r * ldc;
    switch (NV) {
    case 1: avx_rows_nv1(R, T, Xr, ldx, Y, ys_t, ym, Cr, ldc, relu, Mr, ldm); break;
    case 2: avx_rows_nv2(R, T, Xr, ldx, Y, ys_t, ym, Cr, ldc, relu, Mr, ldm); break;
    case 3: avx_rows_nv3(R, T, Xr, ldx, Y, ys_t, ym, Cr, ldc, relu, Mr, ldm); break;
    default: avx_rows_nv4(R, T, Xr, ldx, Y, ys_t, ym, Cr, ldc, relu, Mr, ldm); break;
    }
  }
}

/* fwd: W^T is packed 64 columns at a time into a (K, 64) panel on the stack (K <= PANEL_MAX_K),
 * so that the kernel streams contiguous rows of it; packing costs 1/n of the GEMM. */
static void avx_fwd(int n, const float *A, int K, const float *W, int N, float *C, int relu) {
  float panel[PANEL_MAX_K * 64] __attribute__((aligned(64)));
  for (int j0 = 0; j0 < N; j0 += 64) {
    const int nc = N - j0 < 64 ? N - j0 : 64;
    for (int j = 0; j < nc; j++)
      for (int k = 0; k < K; k++) panel[k * 64 + j] = W[(size_t)(j0 + j) * K + k];
    avx_rows(n, K, A, K, panel, 64, nc, C + j0, N, relu, NULL, 0);
  }
}

/* Sums of 16 vectors: lane i of the result is the sum of v[i]'s 16 lanes (a fixed tree:
 * pairs within 128-bit lanes, then across them). */
static inline __attribute__((always_inline)) __m512 avx_hsum16(const __m512 v[16]) {
  __m512 t[8], u[4];
#pragma GCC unroll 8
  for (int i = 0; i < 8; i++)
    t[i] = _mm512_add_ps(_mm512_unpacklo_ps(v[2 * i], v[2 * i + 1]),
                         _mm512_unpackhi_ps(v[2 * i], v[2 * i + 1]));
#pragma GCC unroll 4
  for (int i = 0; i < 4; i++)
    u[i] = _mm512_add_ps(_mm512_shuffle_ps(t[2 * i], t[2 * i + 1], _MM_SHUFFLE(1, 0, 1, 0)),
                         _mm512_shuffle_ps(t[2 * i], t[2 * i + 1], _MM_SHUFFLE(3, 2, 3, 2)));
  const __m512 w0 = _mm512_add_ps(_mm512_shuffle_f32x4(u[0], u[1], _MM_SHUFFLE(2, 0, 2, 0)),
                                  _mm512_shuffle_f32x4(u[0], u[1], _MM_SHUFFLE(3, 1, 3, 1)));
  const __m512 w1 = _mm512_add_ps(_mm512_shuffle_f32x4(u[2], u[3], _MM_SHUFFLE(2, 0, 2, 0)),
                                  _mm512_shuffle_f32x4(u[2], u[3], _MM_SHUFFLE(3, 1, 3, 1)));
  return _mm512_add_ps(_mm512_shuffle_f32x4(w0, w1, _MM_SHUFFLE(2, 0, 2, 0)),
                       _mm512_shuffle_f32x4(w0, w1, _MM_SHUFFLE(3, 1, 3, 1)));
}

/* fwd for narrow layers (N <= NARROW_MAX, the colour net's 3 outputs): the broadcast kernel
 * would spend one FMA on 16 lanes for N useful ones, so here lanes run along K instead: per
 * block of 16 rows and per output j, 16 row-by-W_j products of K/16 vectors each, reduced
 * across lanes by avx_hsum16. No ReLU (narrow layers are output layers here; the caller
 * passes relu only for hidden layers, which are never this narrow in practice). */
#define NARROW_MAX 8
static void avx_fwd_narrow(int n, const float *A, int K, const float *W, int N, float *C,
                           int relu) {
  const int KV = (K + 15) / 16;
  const __mmask16 km = (__mmask16)(0xffffu >> (16 * KV - K));
  float tmp[NARROW_MAX][16] __attribute__((aligned(64)));
  for (int r0 = 0; r0 < n; r0 += 16) {
    const int R = n - r0 < 16 ? n - r0 : 16;
    const float *Ar = A + (size_t)r0 * K;
    for (int j = 0; j < N; j++) {
      const float *Wj = W + (size_t)j * K;
      __m512 acc[16];
#pragma GCC unroll 16
      for (int r = 0; r < 16; r++) acc[r] = _mm512_setzero_ps();
      for (int v = 0; v < KV; v++) {
        const __mmask16 m = v == KV - 1 ? km : (__mmask16)0xffff;
        const __m512 w = _mm512_maskz_loadu_ps(m, Wj + 16 * v);
#pragma GCC unroll 16
        for (int r = 0; r < 16; r++)
          if (r < R)
            acc[r] = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(m, Ar + r * K + 16 * v), w, acc[r]);
      }
      __m512 s = avx_hsum16(acc);
      if (relu) s = _mm512_max_ps(s, _mm512_setzero_ps());
      _mm512_store_ps(tmp[j], s);
    }
    for (int r = 0; r < R; r++)
      for (int j = 0; j < N; j++) C[(size_t)(r0 + r) * N + j] = tmp[j][r];
  }
}

static void avx_data(int n, const float *D, int N, const float *W, int K, const float *M,
                     float *C) {
  for (int k0 = 0; k0 < K; k0 += 64) {
    const int nc = K - k0 < 64 ? K - k0 : 64;
    avx_rows(n, N, D, N, W + k0, K, nc, C + k0, K, 0, M ? M + k0 : NULL, K);
  }
}

/* wgrad tile: P[i][c] (ld K) = (accumulate ? P : 0) + acc, i < R, c < 16*NV under ym. */
static inline __attribute__((always_inline)) void
avx_wgrad_fixed(const int R, const int NV, int n, const float *D, ptrdiff_t N, const float *A,
                ptrdiff_t K, __mmask16 ym, float *P, int accumulate) {
  __m512 acc[R_MAX][4];
  avx_tile(R, NV, n, D, 1, N, A, K, ym, acc);
#pragma GCC unroll 12
  for (int i = 0; i < R; i++)
#pragma GCC unroll 4
    for (int v = 0; v < NV; v++) {
      const __mmask16 m = v == NV - 1 ? ym : (__mmask16)0xffff;
      __m512 r = acc[i][v];
      if (accumulate) r = _mm512_add_ps(_mm512_maskz_loadu_ps(m, P + i * K + 16 * v), r);
      _mm512_mask_storeu_ps(P + i * K + 16 * v, m, r);
    }
}

#define AVX_WGRAD_CASE(R_, NV_)                                                              \
  case (R_):                                                                                 \
    avx_wgrad_fixed(R_, NV_, n, D, N, A, K, ym, P, accumulate);                              \
    break;
#define AVX_WGRAD_NV(NV_)                                                                    \
  static void avx_wgrad_nv##NV_(int R, int n, const float *D, ptrdiff_t N, const float *A,   \
                                ptrdiff_t K, __mmask16 ym, float *P, int accumulate) {       \
    switch (R) {                                                                             \
      AVX_WGRAD_CASE(1, NV_) AVX_WGRAD_CASE(2, NV_) AVX_WGRAD_CASE(3, NV_)                   \
      AVX_WGRAD_CASE(4, NV_) AVX_WGRAD_CASE(5, NV_) AVX_WGRAD_CASE(6, NV_)                   \
      AVX_WGRAD_CASE(7, NV_) AVX_WGRAD_CASE(8, NV_) AVX_WGRAD_CASE(9, NV_)                   \
      AVX_WGRAD_CASE(10, NV_) AVX_WGRAD_CASE(11, NV_) AVX_WGRAD_CASE(12, NV_)                \
    default:                                                                                 \
      break;                                                                                 \
    }                                                                                        \
  }
AVX_WGRAD_NV(1)
AVX_WGRAD_NV(2)
AVX_WGRAD_NV(3)
AVX_WGRAD_NV(4)

/* P (N,K) = (accumulate ? P : 0) + D^T @ A: tiles of R rows of P (columns of D) by up to 64
 * columns of P, each summed over the chunk's n rows in row order. */
static void avx_wgrad_block(int n, const float *D, int N, const float *A, int K, float *P,
                            int accumulate) {
  for (int k0 = 0; k0 < K; k0 += 64) {
    const int nc = K - k0 < 64 ? K - k0 : 64;
    const int NV = (nc + 15) / 16, rt = rows_per_tile(NV);
    const __mmask16 ym = (__mmask16)(0xffffu >> (16 * NV - nc));
    for (int i0 = 0; i0 < N; i0 += rt) {
      const int R = N - i0 < rt ? N - i0 : rt;
      const float *Di = D + i0, *Ak = A + k0;
      float *Pi = P + (size_t)i0 * K + k0;
      switch (NV) {
      case 1: avx_wgrad_nv1(R, n, Di, N, Ak, K, ym, Pi, accumulate); break;
      case 2: avx_wgrad_nv2(R, n, Di, N, Ak, K, ym, Pi, accumulate); break;
      case 3: avx_wgrad_nv3(R, n, Di, N, Ak, K, ym, Pi, accumulate); break;
      default: avx_wgrad_nv4(R, n, Di, N, Ak, K, ym, Pi, accumulate); break;
      }
    }
  }
}

/* Rows in blocks of WGRAD_ROWS, so that a wide D block (the feature net's 512 columns) stays
 * in L2 while every tile of P walks it; blocks are added to P in row order. */
#define WGRAD_ROWS 128
static void avx_wgrad(int n, const float *D, int N, const float *A, int K, float *P,
                      int accumulate) {
  const int rows = N > 128 ? WGRAD_ROWS : n;
  for (int r0 = 0; r0 < n; r0 += rows) {
    const int nr = n - r0 < rows ? n - r0 : rows;
    avx_wgrad_block(nr, D + (size_t)r0 * N, N, A + (size_t)r0 * K, K, P, accumulate || r0 > 0);
  }
}

#pragma GCC pop_options
#endif /* HAVE_AVX512_KERNELS */

/* ---- dispatch --------------------------------------------------------------------------- */

static int g_kernel_force; /* 0 auto, 1 OpenBLAS, 2 AVX-512 */

void fg_mlp_set_kernel(int which) { g_kernel_force = which; }

static int use_avx512(void) {
#if HAVE_AVX512_KERNELS
  if (g_kernel_force == 1) return 0;
  return __builtin_cpu_supports("avx512f");
#else
  return 0;
#endif
}

const char *fg_mlp_kernel_name(void) { return use_avx512() ? "avx512" : "openblas"; }

static void layer_fwd(int avx, int n, const float *A, int K, const float *W, int N, float *C,
                      int relu) {
#if HAVE_AVX512_KERNELS
  if (avx && N <= NARROW_MAX) {
    avx_fwd_narrow(n, A, K, W, N, C, relu);
    return;
  }
  if (avx && K <= PANEL_MAX_K) {
    avx_fwd(n, A, K, W, N, C, relu);
    return;
  }
#endif
  blas_fwd(n, A, K, W, N, C, relu);
}

static void layer_data(int avx, int n, const float *D, int N, const float *W, int K,
                       const float *M, float *C) {
#if HAVE_AVX512_KERNELS
  if (avx) {
    avx_data(n, D, N, W, K, M, C);
    return;
  }
#endif
  blas_data(n, D, N, W, K, M, C);
}

static void layer_wgrad(int avx, int n, const float *D, int N, const float *A, int K,
                        float *P, int accumulate) {
#if HAVE_AVX512_KERNELS
  if (avx) {
    avx_wgrad(n, D, N, A, K, P, accumulate);
    return;
  }
#endif
  blas_wgrad(n, D, N, A, K, P, accumulate);
}

/* Whether some call of this pass will go to OpenBLAS (the AVX-512 path calls it only for a
 * forward layer wider than PANEL_MAX_K). */
static int needs_blas(const fg_mlp_config *cfg, int avx, int forward) {
  if (!avx) return 1;
  return forward && (cfg->n_in > PANEL_MAX_K ||
                     (cfg->n_hidden_layers > 0 && cfg->n_hidden > PANEL_MAX_K));
}

/* ---- forward and backward ------------------------------------------------------------- */

void fg_mlp_forward(const fg_mlp_config *cfg, const float *W, const float *in, int B,
                    float *acts, float *out, int n_threads) {
  if (B <= 0) return;
  const plan p = make_plan(B);
  const int L = cfg->n_hidden_layers, H = cfg->n_hidden, avx = use_avx512();
  const int nt = fg_threads(n_threads);
  const int blas = needs_blas(cfg, avx, 1) ? fg_blas_single_begin() : 1;
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && p.n_chunks > 1)
  for (int c = 0; c < p.n_chunks; c++) {
    const int r0 = c * p.chunk, n = B - r0 < p.chunk ? B - r0 : p.chunk;
    const float *a = in + (size_t)r0 * cfg->n_in;
    for (int l = 0; l <= L; l++) {
      const int K = fg_mlp_layer_fan_in(cfg, l), N = fg_mlp_layer_fan_out(cfg, l);
      float *o = l < L ? acts + ((size_t)l * B + r0) * H : out + (size_t)r0 * N;
      layer_fwd(avx, n, a, K, W + fg_mlp_layer_offset(cfg, l), N, o, l < L);
      a = o;
    }
  }
  fg_blas_single_end(blas);
}

void fg_mlp_backward(const fg_mlp_config *cfg, const float *W, const float *in,
                     const float *acts, const float *dout, int B, float *dW, float *din,
                     float *scratch, int n_threads) {
  if (B <= 0) return;
  const plan p = make_plan(B);
  const int L = cfg->n_hidden_layers, H = cfg->n_hidden, avx = use_avx512();
  const int nt = fg_threads(n_threads);
  const size_t n_params = fg_mlp_n_params(cfg);
  const size_t delta_floats = L > 0 ? (size_t)p.chunk * H : 0;
  float *parts = scratch, *deltas = scratch + (size_t)p.n_groups * n_params;
  const int blas = needs_blas(cfg, avx, 0) ? fg_blas_single_begin() : 1;

#pragma omp parallel num_threads(nt) if (nt > 1 && p.n_groups > 1)
  {
#pragma omp for schedule(static)
    for (int g = 0; g < p.n_groups; g++) {
      float *part = parts + (size_t)g * n_params;
      float *dbuf[2] = {deltas + 2 * (size_t)g * delta_floats,
                        deltas + (2 * (size_t)g + 1) * delta_floats};
      const int c0 = (int)((long long)g * p.n_chunks / p.n_groups);
      const int c1 = (int)((long long)(g + 1) * p.n_chunks / p.n_groups);
      for (int c = c0; c < c1; c++) {
        const int r0 = c * p.chunk, n = B - r0 < p.chunk ? B - r0 : p.chunk;
        const float *delta = dout + (size_t)r0 * cfg->n_out;
        for (int l = L; l >= 0; l--) {
          const int K = fg_mlp_layer_fan_in(cfg, l), N = fg_mlp_layer_fan_out(cfg, l);
          const size_t off = fg_mlp_layer_offset(cfg, l);
          const float *a = l > 0 ? acts + ((size_t)(l - 1) * B + r0) * H
                                 : in + (size_t)r0 * cfg->n_in;
          layer_wgrad(avx, n, delta, N, a, K, part + off, c > c0);
          if (l > 0) {
            float *next = dbuf[l & 1];
            layer_data(avx, n, delta, N, W + off, K, a, next);
            delta = next;
          } else if (din) {
            layer_data(avx, n, delta, N, W + off, K, NULL, din + (size_t)r0 * cfg->n_in);
          }
        }
      }
    }
    /* dW += partials in group order; elements split across threads. */
#pragma omp for schedule(static)
    for (size_t i = 0; i < n_params; i++) {
      float s = dW[i];
      for (int g = 0; g < p.n_groups; g++) s += parts[(size_t)g * n_params + i];
      dW[i] = s;
    }
  }
  fg_blas_single_end(blas);
}
