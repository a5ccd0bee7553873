/* Occupancy grid and ray marching (see occupancy.h).
 *
 * Why the DDA reproduces the brute-force marcher to the bit
 * ---------------------------------------------------------
 * Both marchers evaluate, for lattice index k, exactly the same float expressions:
 *   t_k = t_start + (float)k * dt,  p_i = o_i + t_k * d_i,  c_i = clamp(trunc(p_i * N), 0, N-1).
 * Rounding is monotone, so t_k is non-decreasing in k and each c_i is a monotone function of
 * t_k (non-decreasing for d_i > 0, non-increasing for d_i < 0, constant for d_i = 0): once an
 * axis index has left a value it never returns to it. Hence the lattice points whose computed
 * cell is a given cell form one contiguous run of k. When the point at k lies in an empty cell
 * the DDA jumps to the end of that run: it estimates the run's end from the exact (double)
 * exit distance of the ray from the cell, then corrects the estimate by evaluating the same
 * float expressions at its neighbours (0 to 2 evaluations in practice) until k* is the first
 * index whose computed cell differs. Every skipped point is thus one the brute-force marcher
 * also finds in the same empty cell, and the estimate's accuracy affects speed, never output.
 * The same holds for blocks of 2^m cells per axis (the indices shifted right by m are monotone
 * too): the DDA skips the coarsest empty block of the mip levels around the point (up to 16^3
 * cells), which is what makes it faster than stepping: at dt = sqrt(3)/1024 a 128^3 cell holds
 * only 3 to 5 lattice points, so skipping single cells barely beats evaluating them.
 * (Built with c_std=c11, GCC does not contract a*b+c into an FMA, so the expressions are
 * evaluated the same way at every call site.) */
#include "field/occupancy.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/rng.h"
#include "core/threads.h"

#ifdef _OPENMP
#include <omp.h>
#endif

/* Coarse occupancy levels for skipping: level m groups 2^m x 2^m x 2^m fine cells; up to 4
 * (16^3 fine cells for N = 128, an 8^3 top level). */
enum { MAX_MIPS = 4 };

struct fg_occgrid {
  int N;
  int owned;          /* 1 when fg_occgrid_free releases the block */
  int32_t n_cells;    /* N^3 */
  int32_t n_words;    /* N^3 / 64 */
  float *density;     /* (n_cells) */
  uint64_t *bits;     /* (n_words) */
  uint32_t *rank;     /* (n_words + 1): set bits before word w; rank[n_words] = total */
  int n_mips;         /* coarse levels 1..n_mips: level m has (N >> m)^3 cells */
  uint64_t *mip[MAX_MIPS + 1]; /* mip[m]: bit set iff one of the level-m cell's fine cells is */
  int64_t n_occupied;
  float threshold, mean;
};

/* ---- helpers -------------------------------------------------------------------------- */

enum { RAYS_PER_CHUNK = 64, MEAN_BLOCKS = 64 };

/* Random streams, so that update points and ray jitter never share numbers. */
enum { STREAM_UPDATE = 1, STREAM_MARCH = 2 };


/* Counter-based: a pure function of its arguments. */
static inline uint64_t hash4(uint64_t seed, int32_t step, uint64_t index, uint64_t stream) {
  uint64_t h = fg_mix64(seed + 0x9e3779b97f4a7c15ull);
  h = fg_mix64(h ^ ((uint64_t)(uint32_t)step * 0xd1b54a32d192ed03ull + stream));
  return fg_mix64(h ^ (index * 0xaef17502108ef2d9ull));
}

/* 24 bits of h starting at bit `shift`, as a float in [0,1). */
static inline float unit24(uint64_t h, int shift) {
  return (float)((h >> shift) & 0xffffffu) * (1.0f / 16777216.0f);
}

/* floor(u * n / 2^32) for a 32-bit u: uniform in [0, n). */
static inline uint32_t below(uint32_t u, uint32_t n) {
  return (uint32_t)(((uint64_t)u * (uint64_t)n) >> 32);
}

static inline size_t round_up64(size_t n) { return (n + 63) & ~(size_t)63; }

static int mips_for(int N) {
  int m = 0;
  while (m < MAX_MIPS && N % (2 << m) == 0 && (N >> (m + 1)) >= 2) m++;
  return m;
}

static size_t mip_words(int N, int m) {
  const size_t n = (size_t)(N >> m);
  return (n * n * n + 63) / 64;
}

static inline int bit_of(const uint64_t *bits, int32_t c) {
  return (int)((bits[c >> 6] >> (c & 63)) & 1u);
}

static inline int occupied(const fg_occgrid *g, int32_t c) {
  return (int)((g->bits[c >> 6] >> (c & 63)) & 1u);
}

/* ---- state ---------------------------------------------------------------------------- */

size_t fg_occgrid_size(int N) {
  if (N < 4 || N > 1024 || N % 4 != 0) return 0;
  const size_t cells = (size_t)N * (size_t)N * (size_t)N, words = cells / 64;
  size_t size = round_up64(sizeof(fg_occgrid)) + round_up64(cells * sizeof(float)) +
                round_up64(words * sizeof(uint64_t)) + round_up64((words + 1) * sizeof(uint32_t));
  for (int m = 1; m <= mips_for(N); m++) size += round_up64(mip_words(N, m) * sizeof(uint64_t));
  return size;
}

int fg_occgrid_init(fg_occgrid **out, int N, void *mem, size_t size) {
  const size_t need = fg_occgrid_size(N);
  if (!out || !mem) return fg_fail(FG_EINVAL, "occgrid: out and mem must not be NULL");
  if (!need) return fg_fail(FG_EINVAL, "occgrid: N must be a multiple of 4 in [4, 1024], got %d", N);
  if ((uintptr_t)mem % 16 != 0) return fg_fail(FG_EINVAL, "occgrid: mem must be 16-byte aligned");
  if (size < need)
    return fg_fail(FG_ERANGE, "occgrid: N = %d needs %zu bytes, got %zu", N, need, size);
  unsigned char *p = mem;
  fg_occgrid *g = (fg_occgrid *)p;
  memset(g, 0, sizeof *g);
  g->N = N;
  g->n_cells = N * N * N;
  g->n_words = g->n_cells / 64;
  p += round_up64(sizeof(fg_occgrid));
  g->density = (float *)p;
  p += round_up64((size_t)g->n_cells * sizeof(float));
  g->bits = (uint64_t *)p;
  p += round_up64((size_t)g->n_words * sizeof(uint64_t));
  g->rank = (uint32_t *)p;
  p += round_up64(((size_t)g->n_words + 1) * sizeof(uint32_t));
  g->n_mips = mips_for(N);
  g->mip[0] = g->bits;
  for (int m = 1; m <= g->n_mips; m++) {
    g->mip[m] = (uint64_t *)p;
    memset(g->mip[m], 0xff, mip_words(N, m) * sizeof(uint64_t));
    p += round_up64(mip_words(N, m) * sizeof(uint64_t));
  }
  memset(g->density, 0, (size_t)g->n_cells * sizeof(float));
  memset(g->bits, 0xff, (size_t)g->n_words * sizeof(uint64_t)); /* march everything at first */
  for (int32_t w = 0; w <= g->n_words; w++) g->rank[w] = (uint32_t)w * 64u;
  g->n_occupied = g->n_cells;
  *out = g;
  return 0;
}

int fg_occgrid_new(fg_occgrid **out, int N) {
  const size_t need = fg_occgrid_size(N);
  if (!out) return fg_fail(FG_EINVAL, "occgrid: out must not be NULL");
  if (!need) return fg_fail(FG_EINVAL, "occgrid: N must be a multiple of 4 in [4, 1024], got %d", N);
  void *mem = aligned_alloc(64, round_up64(need));
  if (!mem) return fg_fail(FG_ENOMEM, "occgrid: cannot allocate %zu bytes for N = %d", need, N);
  int rc = fg_occgrid_init(out, N, mem, need);
  if (rc < 0) {
    free(mem);
    return rc;
  }
  (*out)->owned = 1;
  return 0;
}

void fg_occgrid_free(fg_occgrid *g) {
  if (g && g->owned) free(g);
}

int fg_occgrid_resolution(const fg_occgrid *g) { return g->N; }
float *fg_occgrid_density(fg_occgrid *g) { return g->density; }
const uint64_t *fg_occgrid_bits(const fg_occgrid *g) { return g->bits; }
int fg_occgrid_occupied(const fg_occgrid *g, int32_t cell) { return occupied(g, cell); }
int64_t fg_occgrid_n_occupied(const fg_occgrid *g) { return g->n_occupied; }
float fg_occgrid_threshold(const fg_occgrid *g) { return g->threshold; }
float fg_occgrid_mean_density(const fg_occgrid *g) { return g->mean; }
float fg_occgrid_density_threshold(float dt_min) {
  return FG_OCCGRID_MIN_OPTICAL_THICKNESS / dt_min;
}

/* Everything derived from the bits: the rank table, n_occupied and the coarse levels. */
static void rebuild_from_bits(fg_occgrid *g) {
  uint32_t acc = 0;
  for (int32_t w = 0; w < g->n_words; w++) {
    g->rank[w] = acc;
    acc += (uint32_t)__builtin_popcountll(g->bits[w]);
  }
  g->rank[g->n_words] = acc;
  g->n_occupied = acc;
  /* the coarse levels: a cell is occupied when one of its 8 children is */
  for (int m = 1; m <= g->n_mips; m++) {
    const int32_t n = g->N >> m, nf = n * 2;
    const uint64_t *restrict fine = g->mip[m - 1];
    uint64_t *restrict coarse = g->mip[m];
    memset(coarse, 0, mip_words(g->N, m) * sizeof(uint64_t));
    /* one z slab per iteration writes whole words only when n^2 is a multiple of 64; the
     * levels are small, so build them serially */
    for (int32_t z = 0; z < n; z++)
      for (int32_t y = 0; y < n; y++)
        for (int32_t x = 0; x < n; x++) {
          int any = 0;
          for (int j = 0; j < 8 && !any; j++)
            any = bit_of(fine, (2 * x + (j & 1)) + nf * ((2 * y + ((j >> 1) & 1)) +
                                                         nf * (2 * z + (j >> 2))));
          const int32_t c = x + n * (y + n * z);
          coarse[c >> 6] |= (uint64_t)any << (c & 63);
        }
  }
}

void fg_occgrid_update_bits(fg_occgrid *g, float density_threshold, int n_threads) {
  const int nt = fg_threads(n_threads);
  const float *restrict dens = g->density;
  /* mean: MEAN_BLOCKS fixed blocks summed in double, combined in block order */
  double part[MEAN_BLOCKS];
  const int32_t per_block = g->n_cells / MEAN_BLOCKS; /* n_cells is a multiple of 64 */
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1)
  for (int b = 0; b < MEAN_BLOCKS; b++) {
    double s = 0.0;
    for (int32_t c = b * per_block; c < (b + 1) * per_block; c++) s += (double)dens[c];
    part[b] = s;
  }
  double sum = 0.0;
  for (int b = 0; b < MEAN_BLOCKS; b++) sum += part[b];
  const float mean = (float)(sum / (double)g->n_cells);
  const float thr = density_threshold < mean ? density_threshold : mean;
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1)
  for (int32_t w = 0; w < g->n_words; w++) {
    const float *restrict d = dens + (size_t)w * 64;
    uint64_t word = 0;
    for (int j = 0; j < 64; j++) word |= (uint64_t)(d[j] > thr) << j;
    g->bits[w] = word;
  }
  rebuild_from_bits(g);
  g->threshold = thr;
  g->mean = mean;
}

int fg_occgrid_set_bits(fg_occgrid *g, const uint64_t *bits, int n_threads) {
  (void)n_threads; /* the rebuild is serial: a few ms for N = 128 */
  if (!g || !bits) return fg_fail(FG_EINVAL, "occgrid set_bits: grid and bits must not be NULL");
  memcpy(g->bits, bits, (size_t)g->n_words * sizeof(uint64_t));
  rebuild_from_bits(g);
  return 0;
}

void fg_occgrid_set_stats(fg_occgrid *g, float threshold, float mean) {
  g->threshold = threshold;
  g->mean = mean;
}

/* ---- update --------------------------------------------------------------------------- */

int32_t fg_occgrid_update_count(const fg_occgrid *g, int32_t step, int32_t warmup_steps,
                                int32_t n_points) {
  if (step < warmup_steps) return g->n_cells;
  return n_points > 0 ? n_points : g->n_cells / 4;
}

/* The r-th occupied cell (0 <= r < n_occupied), through the rank table. */
static int32_t select_occupied(const fg_occgrid *g, uint32_t r) {
  /* the last word w with rank[w] <= r (rank[0] = 0 <= r); branchless, the draws are random */
  const uint32_t *base = g->rank;
  for (int32_t len = g->n_words; len > 1;) {
    const int32_t half = len / 2;
    base = base[half] <= r ? base + half : base;
    len -= half;
  }
  const int32_t w = (int32_t)(base - g->rank);
  uint64_t word = g->bits[w];
  uint32_t j = r - g->rank[w]; /* the j-th set bit of word: skip whole bytes, then bits */
  int shift = 0;
  for (uint32_t pc; (pc = (uint32_t)__builtin_popcountll(word & 0xffu)) <= j; shift += 8) {
    j -= pc;
    word >>= 8;
  }
  for (; j > 0; j--) word &= word - 1;
  return w * 64 + shift + __builtin_ctzll(word);
}

int fg_occgrid_update_points(const fg_occgrid *g, int32_t step, uint64_t seed,
                             int32_t warmup_steps, int32_t n_points, int32_t *cells_out,
                             float *x_out, int32_t capacity, int32_t *n_out, int n_threads) {
  if (!g || !cells_out || !x_out || !n_out || step < 0 || n_points < 0 || capacity < 0)
    return fg_fail(FG_EINVAL, "occgrid update: NULL pointer or negative step/n_points/capacity");
  const int32_t M = fg_occgrid_update_count(g, step, warmup_steps, n_points);
  *n_out = M;
  if (M > capacity)
    return fg_fail(FG_ERANGE, "occgrid update: %d points do not fit capacity %d", (int)M,
                   (int)capacity);
  const int warm = step < warmup_steps;
  const int32_t half = M / 2, N = g->N;
  const uint32_t n_occ = (uint32_t)g->n_occupied, n_cells = (uint32_t)g->n_cells;
  const float inv_n = 1.0f / (float)N;
  const int nt = fg_threads(n_threads);
  /* interleaved chunks: the occupied half costs more (select) than the uniform half */
#pragma omp parallel for schedule(static, 1024) num_threads(nt) if (nt > 1 && M > 4096)
  for (int32_t i = 0; i < M; i++) {
    const uint64_t h1 = hash4(seed, step, (uint64_t)i, STREAM_UPDATE);
    const uint64_t h2 = fg_mix64(h1 ^ 0x632be59bd9b4e019ull);
    int32_t cell;
    if (warm)
      cell = i;
    else if (i < half || n_occ == 0)
      cell = (int32_t)below((uint32_t)(h1 >> 32), n_cells);
    else
      cell = select_occupied(g, below((uint32_t)(h1 >> 32), n_occ));
    const int32_t ix = cell % N, iy = (cell / N) % N, iz = cell / (N * N);
    cells_out[i] = cell;
    x_out[3 * (size_t)i + 0] = ((float)ix + unit24(h1, 0)) * inv_n;
    x_out[3 * (size_t)i + 1] = ((float)iy + unit24(h2, 0)) * inv_n;
    x_out[3 * (size_t)i + 2] = ((float)iz + unit24(h2, 32)) * inv_n;
  }
  return 0;
}

int fg_occgrid_update_density(fg_occgrid *g, const int32_t *cells, const float *sigma,
                              int32_t M, float decay, float density_threshold, int n_threads) {
  if (!g || M < 0 || (M > 0 && (!cells || !sigma)))
    return fg_fail(FG_EINVAL, "occgrid update: NULL pointer or negative M");
  if (!(decay >= 0.0f && decay <= 1.0f))
    return fg_fail(FG_EINVAL, "occgrid update: decay must be in [0, 1], got %g", (double)decay);
  for (int32_t i = 0; i < M; i++)
    if (cells[i] < 0 || cells[i] >= g->n_cells)
      return fg_fail(FG_EINVAL, "occgrid update: cell %d of point %d outside [0, %d)",
                     (int)cells[i], (int)i, (int)g->n_cells);
  const int nt = fg_threads(n_threads);
  float *restrict dens = g->density;
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1)
  for (int32_t c = 0; c < g->n_cells; c++) dens[c] *= decay;
  /* A scatter of max with repeated cells: serial, a few ms for N^3/4 points, and fixed order
   * (max does not depend on it anyway; NaN never wins the comparison). */
  for (int32_t i = 0; i < M; i++)
    if (sigma[i] > dens[cells[i]]) dens[cells[i]] = sigma[i];
  fg_occgrid_update_bits(g, density_threshold, n_threads);
  return 0;
}

/* ---- marching ------------------------------------------------------------------------- */

/* The ray's interval inside the cube, [max(0, entry), exit]; 0 when it misses the cube or is
 * degenerate. Divisions only by nonzero components; a zero component requires the origin to
 * lie within the slab. */
static int ray_interval(const float *o, const float *d, float *t_near, float *t_far) {
  float tn = 0.0f, tf = INFINITY;
  int moving = 0;
  for (int i = 0; i < 3; i++) {
    if (!isfinite(o[i]) || !isfinite(d[i])) return 0;
    if (d[i] == 0.0f) {
      if (o[i] < 0.0f || o[i] > 1.0f) return 0;
      continue;
    }
    moving = 1;
    float a = (0.0f - o[i]) / d[i], b = (1.0f - o[i]) / d[i];
    if (a > b) {
      const float tmp = a;
      a = b;
      b = tmp;
    }
    if (a > tn) tn = a;
    if (b < tf) tf = b;
  }
  if (!moving || !(tn <= tf) || !isfinite(tf)) return 0;
  *t_near = tn;
  *t_far = tf;
  return 1;
}

static inline int32_t axis_cell(float p, float Nf, int32_t N) {
  const float f = p * Nf;
  if (!(f >= 0.0f)) return 0;
  if (f >= Nf) return N - 1;
  return (int32_t)f;
}

static inline float lattice_t(float t_start, int32_t k, float dt) {
  return t_start + (float)k * dt;
}

/* The point p and the per-axis cell indices ci of lattice parameter t; returns the cell. */
static inline int32_t cell_at(const fg_occgrid *g, const float *o, const float *d, float t,
                              float *p, int32_t *ci) {
  p[0] = o[0] + t * d[0];
  p[1] = o[1] + t * d[1];
  p[2] = o[2] + t * d[2];
  const float Nf = (float)g->N;
  for (int i = 0; i < 3; i++) ci[i] = axis_cell(p[i], Nf, g->N);
  return ci[0] + g->N * (ci[1] + g->N * ci[2]);
}

/* 1 when the level-m cell of lattice parameter t is the one with indices cm. */
static inline int same_block(const fg_occgrid *g, const float *o, const float *d, float t,
                             int m, const int32_t *cm) {
  float p[3];
  int32_t ci[3];
  cell_at(g, o, d, t, p, ci);
  return (ci[0] >> m) == cm[0] && (ci[1] >> m) == cm[1] && (ci[2] >> m) == cm[2];
}

static inline float clamp01(float v) { return v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v); }

static inline float ray_t_start(float t_near, float dt, uint64_t seed, int32_t step, int32_t r) {
  if (step < 0) return t_near + 0.5f * dt; /* inference: lattice centres, no jitter */
  return t_near + unit24(hash4(seed, step, (uint64_t)r, STREAM_MARCH), 40) * dt;
}

static inline void emit(float *x, float *dt_out, float *t_out, int32_t n, const float *p,
                        float dt, float t) {
  x[3 * (size_t)n + 0] = clamp01(p[0]);
  x[3 * (size_t)n + 1] = clamp01(p[1]);
  x[3 * (size_t)n + 2] = clamp01(p[2]);
  dt_out[n] = dt;
  t_out[n] = t;
}

/* Marches ray r with the DDA; writes its samples from x/dt_out/t_out (when x is not NULL)
 * and returns their number. */
static int32_t march_ray(const fg_occgrid *g, int32_t r, const float *rays_o,
                         const float *rays_d, float dt, int32_t max_n, uint64_t seed,
                         int32_t step, float *x, float *dt_out, float *t_out) {
  const float *o = rays_o + 3 * (size_t)r, *d = rays_d + 3 * (size_t)r;
  float t_near, t_far;
  if (!ray_interval(o, d, &t_near, &t_far)) return 0;
  const float t_start = ray_t_start(t_near, dt, seed, step, r);
  /* the last lattice index worth looking at, with a margin for rounding: bounds the DDA */
  const double span = ((double)t_far - (double)t_start) / (double)dt;
  if (!(span > -2.0)) return 0;
  const int32_t k_last = span + 2.0 < 2147483000.0 ? (int32_t)(span + 2.0) : 2147483000;
  const int32_t N = g->N;
  int32_t n = 0, k = 0;
  while (n < max_n && k <= k_last) {
    const float t = lattice_t(t_start, k, dt);
    if (!(t <= t_far)) break;
    float p[3];
    int32_t ci[3];
    const int32_t c = cell_at(g, o, d, t, p, ci);
    if (occupied(g, c)) {
      if (x) emit(x, dt_out, t_out, n, p, dt, t);
      n++;
      k++;
      continue;
    }
    /* DDA: the coarsest empty level-m block around the point (m = 0: the cell itself), the
     * ray's exact exit distance from it as a lattice index estimate, then corrected to the
     * first index whose computed block differs (see the top of this file) */
    int m = 0;
    while (m < g->n_mips) {
      const int32_t nm = N >> (m + 1);
      if (bit_of(g->mip[m + 1], (ci[0] >> (m + 1)) + nm * ((ci[1] >> (m + 1)) +
                                                           nm * (ci[2] >> (m + 1)))))
        break;
      m++;
    }
    const int32_t cm[3] = {ci[0] >> m, ci[1] >> m, ci[2] >> m};
    double t_exit = INFINITY;
    for (int i = 0; i < 3; i++) {
      if (d[i] == 0.0f) continue;
      const double face = (double)((d[i] > 0.0f ? cm[i] + 1 : cm[i]) << m) / (double)N;
      const double te = (face - (double)o[i]) / (double)d[i];
      if (te < t_exit) t_exit = te;
    }
    const double kf = ceil((t_exit - (double)t_start) / (double)dt);
    int32_t j = kf > (double)k_last ? k_last : (kf > (double)(k + 1) ? (int32_t)kf : k + 1);
    while (j - 1 > k && !same_block(g, o, d, lattice_t(t_start, j - 1, dt), m, cm)) j--;
    while (j <= k_last && lattice_t(t_start, j, dt) <= t_far &&
           same_block(g, o, d, lattice_t(t_start, j, dt), m, cm))
      j++;
    k = j;
  }
  return n;
}

/* The brute-force reference of march_ray: every lattice point, no skipping. */
static int32_t march_ray_ref(const fg_occgrid *g, int32_t r, const float *rays_o,
                             const float *rays_d, float dt, int32_t max_n, uint64_t seed,
                             int32_t step, float *x, float *dt_out, float *t_out) {
  const float *o = rays_o + 3 * (size_t)r, *d = rays_d + 3 * (size_t)r;
  float t_near, t_far;
  if (!ray_interval(o, d, &t_near, &t_far)) return 0;
  const float t_start = ray_t_start(t_near, dt, seed, step, r);
  int32_t n = 0;
  for (int32_t k = 0; n < max_n; k++) {
    const float t = lattice_t(t_start, k, dt);
    if (!(t <= t_far)) break;
    float p[3];
    int32_t ci[3];
    if (occupied(g, cell_at(g, o, d, t, p, ci))) {
      if (x) emit(x, dt_out, t_out, n, p, dt, t);
      n++;
    }
  }
  return n;
}

static int check_march_args(const fg_occgrid *g, int32_t n_rays, const float *rays_o,
                            const float *rays_d, float dt, int32_t max_n, int32_t capacity,
                            const int32_t *ray_offset, const int32_t *ray_count, const float *x,
                            const float *dt_out, const float *t_out, const int32_t *n_samples) {
  if (!g || !n_samples || n_rays < 0 || max_n < 0 || capacity < 0)
    return fg_fail(FG_EINVAL, "occgrid march: NULL grid/n_samples or negative count");
  if (n_rays > 0 && (!rays_o || !rays_d || !ray_offset || !ray_count))
    return fg_fail(FG_EINVAL, "occgrid march: NULL ray or offset array");
  if (capacity > 0 && (!x || !dt_out || !t_out))
    return fg_fail(FG_EINVAL, "occgrid march: NULL sample array");
  if (!(dt > 0.0f) || !isfinite(dt))
    return fg_fail(FG_EINVAL, "occgrid march: dt must be positive and finite, got %g", (double)dt);
  return 0;
}

/* Exclusive prefix sum of the counts; FG_ERANGE (with *n_samples = the total needed,
 * saturated at INT32_MAX) when it exceeds capacity. */
static int prefix_counts(int32_t n_rays, const int32_t *ray_count, int32_t *ray_offset,
                         int32_t capacity, int32_t *n_samples) {
  int64_t total = 0;
  for (int32_t r = 0; r < n_rays; r++) total += ray_count[r];
  *n_samples = total > INT32_MAX ? INT32_MAX : (int32_t)total;
  if (total > capacity)
    return fg_fail(FG_ERANGE, "occgrid march: %lld samples do not fit capacity %d",
                   (long long)total, (int)capacity);
  int32_t acc = 0;
  for (int32_t r = 0; r < n_rays; r++) {
    ray_offset[r] = acc;
    acc += ray_count[r];
  }
  return 0;
}

int fg_occgrid_march(const fg_occgrid *g, int32_t n_rays, const float *rays_o,
                     const float *rays_d, float dt, int32_t max_samples_per_ray, uint64_t seed,
                     int32_t step, int32_t capacity, int32_t *ray_offset, int32_t *ray_count,
                     float *x, float *dt_out, float *t_out, int32_t *n_samples, int n_threads) {
  FG_TRY(check_march_args(g, n_rays, rays_o, rays_d, dt, max_samples_per_ray, capacity,
                          ray_offset, ray_count, x, dt_out, t_out, n_samples));
  const int nt = fg_threads(n_threads);
#pragma omp parallel for schedule(dynamic, RAYS_PER_CHUNK) num_threads(nt) \
    if (nt > 1 && n_rays > RAYS_PER_CHUNK)
  for (int32_t r = 0; r < n_rays; r++)
    ray_count[r] = march_ray(g, r, rays_o, rays_d, dt, max_samples_per_ray, seed, step, NULL,
                             NULL, NULL);
  FG_TRY(prefix_counts(n_rays, ray_count, ray_offset, capacity, n_samples));
  if (*n_samples == 0) return 0; /* x may be NULL: no pointer arithmetic on it */
#pragma omp parallel for schedule(dynamic, RAYS_PER_CHUNK) num_threads(nt) \
    if (nt > 1 && n_rays > RAYS_PER_CHUNK)
  for (int32_t r = 0; r < n_rays; r++) {
    const size_t o = (size_t)ray_offset[r];
    march_ray(g, r, rays_o, rays_d, dt, max_samples_per_ray, seed, step, x + 3 * o,
              dt_out + o, t_out + o);
  }
  return 0;
}

int fg_occgrid_march_ref(const fg_occgrid *g, int32_t n_rays, const float *rays_o,
                         const float *rays_d, float dt, int32_t max_samples_per_ray,
                         uint64_t seed, int32_t step, int32_t capacity, int32_t *ray_offset,
                         int32_t *ray_count, float *x, float *dt_out, float *t_out,
                         int32_t *n_samples) {
  FG_TRY(check_march_args(g, n_rays, rays_o, rays_d, dt, max_samples_per_ray, capacity,
                          ray_offset, ray_count, x, dt_out, t_out, n_samples));
  for (int32_t r = 0; r < n_rays; r++)
    ray_count[r] = march_ray_ref(g, r, rays_o, rays_d, dt, max_samples_per_ray, seed, step,
                                 NULL, NULL, NULL);
  FG_TRY(prefix_counts(n_rays, ray_count, ray_offset, capacity, n_samples));
  if (*n_samples == 0) return 0;
  for (int32_t r = 0; r < n_rays; r++) {
    const size_t o = (size_t)ray_offset[r];
    march_ray_ref(g, r, rays_o, rays_d, dt, max_samples_per_ray, seed, step, x + 3 * o,
                  dt_out + o, t_out + o);
  }
  return 0;
}
