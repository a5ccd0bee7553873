/* Occupancy grid and ray marching: EMA/max update and threshold, bits against densities,
 * update points (warm-up covers every cell, the occupied half draws only occupied cells),
 * the DDA marcher bit-identical to the brute-force reference on sphere, thin-shell and sparse
 * random grids, edge cases (misses, origins inside, axis-parallel and grazing rays), the
 * all-occupied sample count, thread-count determinism and capacity overflow. */
#include "field/occupancy.h"

#include <float.h>
#include <stdint.h>

#include "core/error.h"
#include "test.h"

/* ---- helpers -------------------------------------------------------------------------- */

static uint64_t rng_state = 1234;

static uint32_t rng_u32(void) {
  rng_state += 0x9e3779b97f4a7c15ull; /* splitmix64 */
  uint64_t z = rng_state;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return (uint32_t)((z ^ (z >> 31)) >> 32);
}

static float rng_uniform(float lo, float hi) {
  return lo + (hi - lo) * (float)(rng_u32() >> 8) * (1.0f / 16777216.0f);
}

static void *xcalloc(size_t n, size_t size) {
  void *p = calloc(n ? n : 1, size);
  if (!p) FG_TEST_FAIL("out of memory");
  return p;
}

static int32_t cell_of_point(int N, const float *x) {
  int32_t c[3];
  for (int i = 0; i < 3; i++) {
    ASSERT(x[i] >= 0.0f && x[i] <= 1.0f);
    c[i] = (int32_t)(x[i] * (float)N);
    if (c[i] > N - 1) c[i] = N - 1;
  }
  return c[0] + N * (c[1] + N * c[2]);
}

static void cell_center(int N, int32_t c, double *p) {
  p[0] = (c % N + 0.5) / N;
  p[1] = ((c / N) % N + 0.5) / N;
  p[2] = (c / (N * N) + 0.5) / N;
}

enum { GRID_SPHERE, GRID_SHELL, GRID_SPARSE, GRID_FULL };

/* Densities 100 in the shape, 0 elsewhere, bits rebuilt with threshold 1. */
static void grid_fill(fg_occgrid *g, int kind) {
  const int N = fg_occgrid_resolution(g);
  float *dens = fg_occgrid_density(g);
  for (int32_t c = 0; c < N * N * N; c++) {
    double p[3];
    cell_center(N, c, p);
    const double r = sqrt((p[0] - 0.5) * (p[0] - 0.5) + (p[1] - 0.5) * (p[1] - 0.5) +
                          (p[2] - 0.5) * (p[2] - 0.5));
    int in = 0;
    if (kind == GRID_SPHERE) in = r < 0.25;
    if (kind == GRID_SHELL) in = fabs(r - 0.35) < 0.6 / N;
    if (kind == GRID_SPARSE) in = rng_u32() % 100 < 3;
    if (kind == GRID_FULL) in = 1;
    dens[c] = in ? 100.0f : 0.0f;
  }
  fg_occgrid_update_bits(g, 1.0f, 2);
}

static void random_unit(float *d) {
  for (;;) {
    float n2 = 0.0f;
    for (int i = 0; i < 3; i++) {
      d[i] = rng_uniform(-1.0f, 1.0f);
      n2 += d[i] * d[i];
    }
    if (n2 > 0.01f && n2 <= 1.0f) {
      const float inv = 1.0f / sqrtf(n2);
      for (int i = 0; i < 3; i++) d[i] *= inv;
      return;
    }
  }
}

/* A mix of rays: from a sphere around the cube towards a point in it, from inside the cube,
 * axis-parallel ones (zero components) and rays on faces, edges and corners. */
static void random_rays(int32_t R, float *o, float *d) {
  for (int32_t r = 0; r < R; r++) {
    float *ro = o + 3 * (size_t)r, *rd = d + 3 * (size_t)r;
    const int kind = (int)(rng_u32() % 7);
    if (kind <= 1) { /* camera outside, looking at a point in (or near) the cube */
      float u[3], target[3];
      random_unit(u);
      float n2 = 0.0f;
      for (int i = 0; i < 3; i++) {
        ro[i] = 0.5f + 1.5f * u[i];
        target[i] = rng_uniform(-0.1f, 1.1f);
        rd[i] = target[i] - ro[i];
        n2 += rd[i] * rd[i];
      }
      for (int i = 0; i < 3; i++) rd[i] /= sqrtf(n2);
    } else if (kind == 2) { /* inside */
      for (int i = 0; i < 3; i++) ro[i] = rng_uniform(0.0f, 1.0f);
      random_unit(rd);
    } else if (kind == 3) { /* axis-parallel, or in a coordinate plane */
      for (int i = 0; i < 3; i++) ro[i] = rng_uniform(-0.5f, 1.5f);
      random_unit(rd);
      const int zero = (int)(rng_u32() % 3);
      rd[zero] = 0.0f;
      if (rng_u32() % 2) rd[(zero + 1) % 3] = 0.0f;
      float n2 = rd[0] * rd[0] + rd[1] * rd[1] + rd[2] * rd[2];
      for (int i = 0; i < 3; i++) rd[i] /= sqrtf(n2);
      ro[zero] = rng_uniform(0.0f, 1.0f);
    } else if (kind == 4) { /* on the cube's lattice of faces/edges/corners */
      for (int i = 0; i < 3; i++) ro[i] = (float)(rng_u32() % 3) * 0.5f;
      random_unit(rd);
      if (rng_u32() % 2) rd[rng_u32() % 3] = 0.0f;
      float n2 = rd[0] * rd[0] + rd[1] * rd[1] + rd[2] * rd[2];
      for (int i = 0; i < 3; i++) rd[i] /= sqrtf(n2);
    } else if (kind == 5) { /* start on a cell boundary (cell faces of N = 32) */
      for (int i = 0; i < 3; i++) ro[i] = (float)(rng_u32() % 33) / 32.0f;
      random_unit(rd);
    } else { /* inside, one tiny (or subnormal) direction component */
      static const float tiny[] = {1e-7f, -1e-12f, 1e-30f, -1e-40f};
      for (int i = 0; i < 3; i++) ro[i] = rng_uniform(0.0f, 1.0f);
      random_unit(rd);
      rd[rng_u32() % 3] = tiny[rng_u32() % 4];
    }
  }
}

typedef struct {
  int32_t R, cap;
  int32_t *offset, *count, S;
  float *x, *dt, *t;
} marched;

static marched marched_new(int32_t R, int32_t cap) {
  marched m = {R, cap, xcalloc((size_t)R, 4), xcalloc((size_t)R, 4), 0,
               xcalloc(3 * (size_t)cap, 4), xcalloc((size_t)cap, 4), xcalloc((size_t)cap, 4)};
  return m;
}

static void marched_free(marched *m) {
  free(m->offset);
  free(m->count);
  free(m->x);
  free(m->dt);
  free(m->t);
}

static int march(const fg_occgrid *g, const float *o, const float *d, float dt, int32_t max_n,
                 int32_t step, marched *m, int threads) {
  if (threads < 0)
    return fg_occgrid_march_ref(g, m->R, o, d, dt, max_n, 77, step, m->cap, m->offset,
                                m->count, m->x, m->dt, m->t, &m->S);
  return fg_occgrid_march(g, m->R, o, d, dt, max_n, 77, step, m->cap, m->offset, m->count,
                          m->x, m->dt, m->t, &m->S, threads);
}

static void assert_same(const marched *a, const marched *b) {
  ASSERT_EQ(a->S, b->S);
  ASSERT(memcmp(a->count, b->count, (size_t)a->R * 4) == 0);
  ASSERT(memcmp(a->offset, b->offset, (size_t)a->R * 4) == 0);
  ASSERT(memcmp(a->x, b->x, 3 * (size_t)a->S * 4) == 0);
  ASSERT(memcmp(a->dt, b->dt, (size_t)a->S * 4) == 0);
  ASSERT(memcmp(a->t, b->t, (size_t)a->S * 4) == 0);
}

/* Ray interval in double, for checking. */
static int interval_d(const float *o, const float *d, double *tn, double *tf) {
  double a0 = 0.0, b0 = INFINITY;
  for (int i = 0; i < 3; i++) {
    if (d[i] == 0.0f) {
      if (o[i] < 0.0f || o[i] > 1.0f) return 0;
      continue;
    }
    double a = (0.0 - o[i]) / d[i], b = (1.0 - o[i]) / d[i];
    if (a > b) {
      double tmp = a;
      a = b;
      b = tmp;
    }
    a0 = fmax(a0, a);
    b0 = fmin(b0, b);
  }
  *tn = a0;
  *tf = b0;
  return a0 <= b0;
}

/* Structural checks on a marched batch: layout, order, finiteness, occupancy, interval. */
static void check_samples(const fg_occgrid *g, const float *o, const float *d, float dt,
                          int32_t max_n, const marched *m) {
  const int N = fg_occgrid_resolution(g);
  int32_t acc = 0;
  for (int32_t r = 0; r < m->R; r++) {
    ASSERT_EQ(m->offset[r], acc);
    ASSERT(m->count[r] >= 0 && m->count[r] <= max_n);
    acc += m->count[r];
    double tn = 0.0, tf = -1.0;
    if (!interval_d(o + 3 * (size_t)r, d + 3 * (size_t)r, &tn, &tf)) ASSERT(tf - tn > -1e-5 || m->count[r] == 0);
    for (int32_t i = 0; i < m->count[r]; i++) {
      const int32_t s = m->offset[r] + i;
      const float *xs = m->x + 3 * (size_t)s;
      ASSERT(isfinite(xs[0]) && isfinite(xs[1]) && isfinite(xs[2]) && isfinite(m->t[s]));
      ASSERT(m->dt[s] == dt);
      ASSERT(fg_occgrid_occupied(g, cell_of_point(N, xs)));
      ASSERT(m->t[s] >= tn - 1e-5 && m->t[s] <= tf + 1e-5);
      if (i > 0) ASSERT(m->t[s] > m->t[s - 1]);
      /* x is the ray's point at t (clamped to the cube) */
      for (int k = 0; k < 3; k++)
        ASSERT_NEAR(xs[k], fmin(1.0, fmax(0.0, o[3 * r + k] + (double)m->t[s] * d[3 * r + k])),
                    1e-5);
    }
  }
  ASSERT_EQ(acc, m->S);
}

/* ---- tests ---------------------------------------------------------------------------- */

static void test_create(void) {
  fg_occgrid *g = NULL;
  ASSERT_ERR(fg_occgrid_new(&g, 6), FG_EINVAL, "multiple of 4");
  ASSERT_ERR(fg_occgrid_new(&g, 0), FG_EINVAL, "multiple of 4");
  ASSERT_EQ(fg_occgrid_size(7), 0);
  ASSERT_OK(fg_occgrid_new(&g, 16));
  ASSERT_EQ(fg_occgrid_resolution(g), 16);
  ASSERT_EQ(fg_occgrid_n_occupied(g), 16 * 16 * 16); /* new grid: everything occupied */
  for (int32_t c = 0; c < 4096; c++) ASSERT_EQ(fg_occgrid_density(g)[c], 0.0f);
  fg_occgrid_free(g);
  fg_occgrid_free(NULL);

  const size_t size = fg_occgrid_size(128);
  ASSERT(size >= 128u * 128u * 128u * 4u + 128u * 128u * 128u / 8u);
  ASSERT(size < 128u * 128u * 128u * 5u);
  void *mem = aligned_alloc(64, (size + 63) & ~(size_t)63);
  ASSERT(mem);
  ASSERT_ERR(fg_occgrid_init(&g, 128, mem, size - 1), FG_ERANGE, "needs");
  ASSERT_OK(fg_occgrid_init(&g, 128, mem, size));
  ASSERT_EQ(fg_occgrid_n_occupied(g), 128 * 128 * 128);
  fg_occgrid_free(g); /* caller-owned: no-op */
  ASSERT_EQ(fg_occgrid_resolution(g), 128);
  free(mem);
  ASSERT_NEAR(fg_occgrid_density_threshold(FG_OCCGRID_DEFAULT_DT), 0.01 * 1024 / sqrt(3.0),
              1e-4);
  ASSERT_NEAR(FG_OCCGRID_DEFAULT_DT, sqrt(3.0) / 1024, 1e-9);
}

static void check_bits(const fg_occgrid *g, float thr) {
  fg_occgrid *gm = (fg_occgrid *)g;
  const int N = fg_occgrid_resolution(g);
  const float *dens = fg_occgrid_density(gm);
  double sum = 0.0;
  int64_t n_occ = 0;
  for (int32_t c = 0; c < N * N * N; c++) sum += dens[c];
  const float mean = (float)(sum / (N * N * N));
  ASSERT_NEAR(fg_occgrid_mean_density(g), mean, 1e-6 * fabs(mean) + 1e-30);
  ASSERT_EQ(fg_occgrid_threshold(g), fminf(thr, fg_occgrid_mean_density(g)));
  for (int32_t c = 0; c < N * N * N; c++) {
    const int occ = dens[c] > fg_occgrid_threshold(g);
    ASSERT_EQ(fg_occgrid_occupied(g, c), occ);
    ASSERT_EQ((fg_occgrid_bits(g)[c / 64] >> (c % 64)) & 1, occ);
    n_occ += occ;
  }
  ASSERT_EQ(fg_occgrid_n_occupied(g), n_occ);
}

static void test_update_density(void) {
  fg_occgrid *g = NULL;
  ASSERT_OK(fg_occgrid_new(&g, 8));
  float *dens = fg_occgrid_density(g);
  for (int32_t c = 0; c < 512; c++) dens[c] = (float)(c % 7);
  float before[512];
  memcpy(before, dens, sizeof before);
  /* cell 3 drawn twice (the larger sigma wins), cell 10 below its decayed value, a NaN */
  const int32_t cells[] = {3, 3, 10, 20, 21, 500};
  const float sigma[] = {9.0f, 11.0f, 0.5f, NAN, -4.0f, 2.0f};
  ASSERT_OK(fg_occgrid_update_density(g, cells, sigma, 6, 0.95f, 100.0f, 2));
  for (int32_t c = 0; c < 512; c++) {
    float expect = before[c] * 0.95f;
    for (int i = 0; i < 6; i++)
      if (cells[i] == c && sigma[i] > expect) expect = sigma[i];
    ASSERT_EQ(dens[c], expect); /* exact: max(old * decay, sigma) */
  }
  ASSERT_EQ(dens[3], 11.0f);
  ASSERT_EQ(dens[10], (float)(10 % 7) * 0.95f);
  ASSERT_EQ(dens[500], 2.0f);
  /* threshold 100 > mean: the mean is the threshold */
  check_bits(g, 100.0f);
  ASSERT(fg_occgrid_threshold(g) < 100.0f);
  /* threshold below the mean: it is used */
  ASSERT_OK(fg_occgrid_update_density(g, cells, sigma, 0, 1.0f, 1.5f, 1));
  check_bits(g, 1.5f);
  ASSERT_EQ(fg_occgrid_threshold(g), 1.5f);
  /* errors leave the grid alone */
  memcpy(before, dens, sizeof before);
  const int32_t bad[] = {1, 512};
  ASSERT_ERR(fg_occgrid_update_density(g, bad, sigma, 2, 0.95f, 1.0f, 1), FG_EINVAL, "outside");
  ASSERT_ERR(fg_occgrid_update_density(g, cells, sigma, 2, 1.5f, 1.0f, 1), FG_EINVAL, "decay");
  ASSERT(memcmp(before, dens, sizeof before) == 0);
  /* an all-zero grid has nothing occupied (0 > 0 is false) */
  memset(dens, 0, 512 * sizeof(float));
  fg_occgrid_update_bits(g, 5.0f, 1);
  ASSERT_EQ(fg_occgrid_n_occupied(g), 0);
  fg_occgrid_free(g);

  /* a larger random grid, several thread counts */
  ASSERT_OK(fg_occgrid_new(&g, 32));
  dens = fg_occgrid_density(g);
  for (int32_t c = 0; c < 32 * 32 * 32; c++) dens[c] = rng_u32() % 4 ? 0.0f : rng_uniform(0, 20);
  fg_occgrid_update_bits(g, 3.0f, 1);
  check_bits(g, 3.0f);
  uint64_t bits1[512];
  memcpy(bits1, fg_occgrid_bits(g), sizeof bits1);
  fg_occgrid_update_bits(g, 3.0f, 2);
  ASSERT(memcmp(bits1, fg_occgrid_bits(g), sizeof bits1) == 0);
  fg_occgrid_free(g);
}

static void test_update_points(void) {
  const int N = 16;
  const int32_t n_cells = N * N * N;
  fg_occgrid *g = NULL;
  ASSERT_OK(fg_occgrid_new(&g, N));
  int32_t *cells = xcalloc((size_t)n_cells, 4), *cells2 = xcalloc((size_t)n_cells, 4);
  float *x = xcalloc(3 * (size_t)n_cells, 4), *x2 = xcalloc(3 * (size_t)n_cells, 4);
  int32_t M = 0;

  /* warm-up: every cell once, in order, its point inside it */
  ASSERT_EQ(fg_occgrid_update_count(g, 5, 16, 0), n_cells);
  ASSERT_OK(fg_occgrid_update_points(g, 5, 9, 16, 0, cells, x, n_cells, &M, 1));
  ASSERT_EQ(M, n_cells);
  for (int32_t i = 0; i < M; i++) {
    ASSERT_EQ(cells[i], i);
    double lo[3];
    cell_center(N, i, lo);
    for (int k = 0; k < 3; k++) {
      ASSERT(x[3 * i + k] >= lo[k] - 0.5 / N && x[3 * i + k] <= lo[k] + 0.5 / N);
    }
  }

  /* afterwards: N^3/4 points, the second half in occupied cells only */
  grid_fill(g, GRID_SPHERE);
  const int64_t n_occ = fg_occgrid_n_occupied(g);
  ASSERT(n_occ > 100 && n_occ < n_cells / 8);
  ASSERT_EQ(fg_occgrid_update_count(g, 16, 16, 0), n_cells / 4);
  ASSERT_EQ(fg_occgrid_update_count(g, 16, 16, 1000), 1000);
  ASSERT_ERR(fg_occgrid_update_points(g, 16, 9, 16, 0, cells, x, n_cells / 4 - 1, &M, 1),
             FG_ERANGE, "capacity");
  ASSERT_EQ(M, n_cells / 4);
  ASSERT_OK(fg_occgrid_update_points(g, 16, 9, 16, 0, cells, x, n_cells, &M, 1));
  ASSERT_EQ(M, n_cells / 4);
  int64_t occ_first_half = 0;
  int32_t *hits = xcalloc((size_t)n_cells, 4);
  for (int32_t i = 0; i < M; i++) {
    ASSERT(cells[i] >= 0 && cells[i] < n_cells);
    ASSERT_EQ(cell_of_point(N, x + 3 * (size_t)i), cells[i]);
    if (i < M / 2)
      occ_first_half += fg_occgrid_occupied(g, cells[i]);
    else
      ASSERT(fg_occgrid_occupied(g, cells[i]));
  }
  /* the uniform half hits occupied cells at about the occupied fraction */
  ASSERT_NEAR((double)occ_first_half / (M / 2), (double)n_occ / n_cells, 0.03);
  /* the occupied half is uniform over the occupied cells: over 40 steps every occupied cell
   * is drawn about 40 * (M/2) / n_occ times */
  for (int32_t step = 100; step < 140; step++) {
    ASSERT_OK(fg_occgrid_update_points(g, step, 9, 16, 0, cells, x, n_cells, &M, 1));
    for (int32_t i = M / 2; i < M; i++) hits[cells[i]]++;
  }
  const double expect = 40.0 * (M - M / 2) / (double)n_occ;
  for (int32_t c = 0; c < n_cells; c++) {
    if (!fg_occgrid_occupied(g, c)) ASSERT_EQ(hits[c], 0);
    else ASSERT(hits[c] > 0.5 * expect && hits[c] < 1.6 * expect);
  }
  /* determinism over thread counts; a different step gives different points */
  ASSERT_OK(fg_occgrid_update_points(g, 200, 9, 16, 0, cells, x, n_cells, &M, 1));
  ASSERT_OK(fg_occgrid_update_points(g, 200, 9, 16, 0, cells2, x2, n_cells, &M, 2));
  ASSERT(memcmp(cells, cells2, (size_t)M * 4) == 0);
  ASSERT(memcmp(x, x2, 3 * (size_t)M * 4) == 0);
  ASSERT_OK(fg_occgrid_update_points(g, 201, 9, 16, 0, cells2, x2, n_cells, &M, 2));
  ASSERT(memcmp(x, x2, 3 * (size_t)M * 4) != 0);
  /* no occupied cell: the second half falls back to uniform */
  memset(fg_occgrid_density(g), 0, (size_t)n_cells * 4);
  fg_occgrid_update_bits(g, 1.0f, 1);
  ASSERT_OK(fg_occgrid_update_points(g, 300, 9, 16, 0, cells, x, n_cells, &M, 2));
  for (int32_t i = 0; i < M; i++) ASSERT(cells[i] >= 0 && cells[i] < n_cells);

  /* a full update round trip: sigma = 100 inside the sphere, the grid learns it */
  for (int32_t step = 0; step < 3; step++) {
    ASSERT_OK(fg_occgrid_update_points(g, step, 9, 2, 0, cells, x, n_cells, &M, 2));
    float *sigma = xcalloc((size_t)M, 4);
    for (int32_t i = 0; i < M; i++) {
      double r2 = 0;
      for (int k = 0; k < 3; k++) r2 += (x[3 * i + k] - 0.5) * (x[3 * i + k] - 0.5);
      sigma[i] = r2 < 0.3 * 0.3 ? 100.0f : 0.0f;
    }
    ASSERT_OK(fg_occgrid_update_density(g, cells, sigma, M, 0.95f,
                                        fg_occgrid_density_threshold(FG_OCCGRID_DEFAULT_DT), 2));
    free(sigma);
  }
  double c0[3];
  cell_center(N, N / 2 + N * (N / 2 + N * (N / 2)), c0);
  ASSERT(fg_occgrid_occupied(g, N / 2 + N * (N / 2 + N * (N / 2))));
  ASSERT(!fg_occgrid_occupied(g, 0));
  check_bits(g, fg_occgrid_density_threshold(FG_OCCGRID_DEFAULT_DT));

  free(hits);
  free(cells);
  free(cells2);
  free(x);
  free(x2);
  fg_occgrid_free(g);
}

/* DDA against brute force, on three grids, two resolutions, several step sizes. */
static void test_march_matches_ref(void) {
  const int32_t R = 3000;
  float *o = xcalloc(3 * (size_t)R, 4), *d = xcalloc(3 * (size_t)R, 4);
  const int res[] = {32, 128};
  const float dts[] = {FG_OCCGRID_DEFAULT_DT, 0.0123f, 0.1f};
  for (int ri = 0; ri < 2; ri++) {
    fg_occgrid *g = NULL;
    ASSERT_OK(fg_occgrid_new(&g, res[ri]));
    for (int kind = GRID_SPHERE; kind <= GRID_FULL; kind++) {
      grid_fill(g, kind);
      for (int di = 0; di < 3; di++) {
        random_rays(R, o, d);
        const int32_t max_n = di == 2 ? 7 : 4096;
        const int32_t cap = R * (int32_t)(2.0f / dts[di] + 2);
        marched a = marched_new(R, cap), b = marched_new(R, cap), c = marched_new(R, cap);
        ASSERT_OK(march(g, o, d, dts[di], max_n, 3, &a, -1));
        ASSERT_OK(march(g, o, d, dts[di], max_n, 3, &b, 1));
        ASSERT_OK(march(g, o, d, dts[di], max_n, 3, &c, 2));
        assert_same(&a, &b);
        assert_same(&a, &c);
        check_samples(g, o, d, dts[di], max_n, &b);
        ASSERT(kind == GRID_FULL || b.S < R * 2.0f / dts[di]);
        if (kind != GRID_FULL) ASSERT(b.S > 0);
        marched_free(&a);
        marched_free(&b);
        marched_free(&c);
      }
    }
    fg_occgrid_free(g);
  }
  free(o);
  free(d);
}

/* An all-occupied grid: floor((t_far - t_start) / dt) + 1 samples (t_start = t_out[0]). */
static void test_march_full_count(void) {
  const int32_t R = 2000;
  fg_occgrid *g = NULL;
  ASSERT_OK(fg_occgrid_new(&g, 64)); /* new grid: all occupied */
  float *o = xcalloc(3 * (size_t)R, 4), *d = xcalloc(3 * (size_t)R, 4);
  random_rays(R, o, d);
  const float dt = 0.01f;
  marched m = marched_new(R, R * 200);
  ASSERT_OK(march(g, o, d, dt, 100000, 0, &m, 2));
  int32_t n_checked = 0;
  for (int32_t r = 0; r < R; r++) {
    double tn, tf;
    if (!interval_d(o + 3 * r, d + 3 * r, &tn, &tf) || tf - tn < dt + 1e-4) continue;
    ASSERT(m.count[r] > 0);
    const double t0 = m.t[m.offset[r]];
    ASSERT(t0 >= tn - 1e-6 && t0 < tn + dt + 1e-6); /* jitter in [0, dt) */
    const double q = (tf - t0) / dt;
    if (fabs(q - floor(q + 0.5)) < 1e-3) continue; /* float rounding decides the last one */
    ASSERT_EQ(m.count[r], (int32_t)floor(q) + 1);
    for (int32_t i = 0; i < m.count[r]; i++) /* the exact lattice */
      ASSERT_EQ(m.t[m.offset[r] + i], (float)t0 + (float)i * dt);
    n_checked++;
  }
  ASSERT(n_checked > R / 2);
  /* max_samples_per_ray caps the count */
  ASSERT_OK(march(g, o, d, dt, 5, 0, &m, 2));
  for (int32_t r = 0; r < R; r++) ASSERT(m.count[r] <= 5);
  /* the jitter depends on (seed, step, ray): another step moves t_start */
  marched m2 = marched_new(R, R * 200);
  ASSERT_OK(march(g, o, d, dt, 5, 1, &m2, 2));
  ASSERT(memcmp(m.t, m2.t, (size_t)m.S * 4) != 0);
  marched_free(&m);
  marched_free(&m2);
  free(o);
  free(d);
  fg_occgrid_free(g);
}

/* Hand-made edge cases. */
static void test_march_edges(void) {
  fg_occgrid *g = NULL;
  ASSERT_OK(fg_occgrid_new(&g, 32));
  enum { R = 14 };
  const float s = 0.70710678f;
  const float o[R * 3] = {
      2.0f, 2.0f, 2.0f,   /* 0: points away: miss */
      -1.0f, 2.0f, 0.5f,  /* 1: passes beside the cube: miss */
      0.3f, 0.4f, 0.5f,   /* 2: inside, +x */
      -1.0f, 0.3f, 0.7f,  /* 3: axis-parallel through the cube */
      1.5f, 0.5f, 0.5f,   /* 4: axis-parallel, -x, entering at t = 0.5 */
      0.5f, 1.5f, 0.5f,   /* 5: moves along x with y outside: miss */
      -1.0f, 0.0f, 0.0f,  /* 6: along an edge */
      0.0f, -1.0f, 0.5f,  /* 7: touches the edge x = 1, y = 0 only */
      1.0f, 0.0f, 0.5f,   /* 8: on an edge, leaving the cube */
      -0.5f, -0.5f, -0.5f, /* 9: through two corners (the diagonal) */
      0.5f, 0.5f, 0.5f,   /* 10: zero direction */
      NAN, 0.5f, 0.5f,    /* 11: NaN origin */
      0.5f, 0.5f, 1.0f,   /* 12: on the top face, moving in its plane */
      1.0f, 1.0f, 1.0f,   /* 13: at a corner, looking out */
  };
  const float k3 = 0.57735027f;
  const float d[R * 3] = {
      1, 0, 0,   0, 0, 1,   1, 0, 0,    1, 0, 0,   -1, 0, 0,  1, 0, 0,  1, 0, 0,
      s, s, 0,   s, -s, 0,  k3, k3, k3, 0, 0, 0,   1, 0, 0,   s, s, 0, k3, k3, k3,
  };
  marched a = marched_new(R, 10000), b = marched_new(R, 10000);
  ASSERT_OK(march(g, o, d, 0.01f, 10000, 0, &a, -1));
  ASSERT_OK(march(g, o, d, 0.01f, 10000, 0, &b, 2));
  assert_same(&a, &b);
  check_samples(g, o, d, 0.01f, 10000, &b);
  ASSERT_EQ(b.count[0], 0);
  ASSERT_EQ(b.count[1], 0);
  ASSERT(b.count[2] >= 69 && b.count[2] <= 70); /* t in [0, 0.7] */
  ASSERT(b.count[3] >= 99 && b.count[3] <= 101);
  ASSERT(b.count[4] >= 99 && b.count[4] <= 101);
  ASSERT_EQ(b.count[5], 0);
  ASSERT(b.count[6] >= 99 && b.count[6] <= 101);
  ASSERT(b.count[7] <= 1 && b.count[8] <= 1); /* a single point at most */
  ASSERT(b.count[9] >= 172 && b.count[9] <= 174);            /* sqrt(3) / 0.01 */
  ASSERT_EQ(b.count[10], 0);
  ASSERT_EQ(b.count[11], 0);
  ASSERT(b.count[12] >= 70 && b.count[12] <= 71); /* t in [0, 0.5 sqrt(2)] */
  ASSERT(b.count[13] <= 1);
  /* the sphere grid: the same rays */
  grid_fill(g, GRID_SPHERE);
  ASSERT_OK(march(g, o, d, 0.01f, 10000, 0, &a, -1));
  ASSERT_OK(march(g, o, d, 0.01f, 10000, 0, &b, 1));
  assert_same(&a, &b);
  check_samples(g, o, d, 0.01f, 10000, &b);
  ASSERT(b.count[3] == 0);                             /* y = 0.3, z = 0.7: r > 0.25 */
  /* the diagonal crosses the cells (i,i,i) whose centres lie within 0.25 of the centre:
   * |i - 15.5| < 0.25 * 32 / sqrt(3), i = 11..20, 10 cells of sqrt(3)/32 each: 0.54 */
  ASSERT(b.count[9] >= 53 && b.count[9] <= 55);
  marched_free(&a);
  marched_free(&b);
  fg_occgrid_free(g);
}

static void test_march_errors(void) {
  fg_occgrid *g = NULL;
  ASSERT_OK(fg_occgrid_new(&g, 32));
  enum { R = 64 };
  float o[R * 3], d[R * 3];
  random_rays(R, o, d);
  marched m = marched_new(R, 50);
  for (int i = 0; i < 150; i++) m.x[i] = -7.0f;
  ASSERT_ERR(march(g, o, d, 0.01f, 1000, 0, &m, 2), FG_ERANGE, "capacity");
  ASSERT(m.S > 50);
  int64_t sum = 0;
  for (int32_t r = 0; r < R; r++) sum += m.count[r];
  ASSERT_EQ(m.S, sum); /* the number needed, and the counts, for a retry */
  for (int i = 0; i < 150; i++) ASSERT_EQ(m.x[i], -7.0f); /* samples untouched */
  ASSERT_ERR(march(g, o, d, 0.0f, 1000, 0, &m, 2), FG_EINVAL, "dt");
  ASSERT_ERR(march(g, o, d, NAN, 1000, 0, &m, 2), FG_EINVAL, "dt");
  ASSERT_ERR(march(g, o, d, 0.01f, -1, 0, &m, 2), FG_EINVAL, "negative");
  /* no rays and nothing to write: fine with NULL sample arrays */
  int32_t S = -1;
  ASSERT_OK(fg_occgrid_march(g, 0, NULL, NULL, 0.01f, 10, 0, 0, 0, NULL, NULL, NULL, NULL,
                             NULL, &S, 2));
  ASSERT_EQ(S, 0);
  marched_free(&m);
  fg_occgrid_free(g);
}

int main(void) {
  test_create();
  test_update_density();
  test_update_points();
  test_march_matches_ref();
  test_march_full_count();
  test_march_edges();
  test_march_errors();
  printf("test_occupancy: ok\n");
  return 0;
}
