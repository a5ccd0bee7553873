/* Heatmap library, unit level: the score rule against a double-precision reference on random
 * data, the voxel cache's 64-d fast path against direct cosines of the field's full features,
 * grid shape and centres, the alpha floor and threshold, min_score and max_points, the npy and
 * PLY encodings read back, the turbo table against OpenCV, the blend, and bad inputs. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "field/model.h"
#include "io/npy.h"
#include "query/colormap_cv.h"
#include "query/colormap.h"
#include "query/heatmap.h"
#include "test.h"

static uint64_t rng = 88172645463325252ull;

/* Uniform in [-1, 1) (xorshift64). */
static float urand(void) {
  rng ^= rng << 13;
  rng ^= rng >> 7;
  rng ^= rng << 17;
  return (float)((rng >> 11) * (1.0 / 9007199254740992.0)) * 2.0f - 1.0f;
}

static void fill(float *v, size_t n) {
  for (size_t i = 0; i < n; i++) v[i] = urand();
}

/* The score rule of the fast kernel against fg_query_score_ref on random features, and
 * known values of the rule itself. */
static void test_scores(void) {
  enum { D = 40, N = 500, NN = 4 };
  float *pos = malloc(3 * D * sizeof *pos), *neg = malloc(NN * D * sizeof *neg);
  float *feat = malloc((size_t)N * D * sizeof *feat), *s = malloc(N * sizeof *s);
  fill(pos, 3 * D);
  fill(neg, NN * D);
  fill(feat, (size_t)N * D);
  for (int k = 0; k < D; k++) feat[7 * D + k] = 0.0f; /* a zero feature */
  for (int with_neg = 0; with_neg < 2; with_neg++) {
    fg_query q;
    ASSERT_OK(fg_query_init(&q, D, pos, 3, neg, with_neg ? NN : 0, 0.1f));
    ASSERT_OK(fg_query_check(&q));
    /* the positive is the renormalised mean of the normalised positives */
    double mean[D], len = 0.0;
    for (int k = 0; k < D; k++) {
      mean[k] = 0.0;
      for (int p = 0; p < 3; p++) {
        double l = 0.0;
        for (int j = 0; j < D; j++) l += (double)pos[p * D + j] * pos[p * D + j];
        mean[k] += pos[p * D + k] / sqrt(l);
      }
      len += mean[k] * mean[k];
    }
    for (int k = 0; k < D; k++) ASSERT_NEAR(q.q[k], mean[k] / sqrt(len), 1e-6);
    ASSERT_OK(fg_query_score_features(&q, feat, N, D, NULL, 0.0f, s, 2));
    ASSERT(isnan(s[7]));
    ASSERT(isnan(fg_query_score_ref(&q, feat + 7 * D)));
    double mx = -1e9, mn = 1e9;
    for (int i = 0; i < N; i++) {
      if (i == 7) continue;
      double r = fg_query_score_ref(&q, feat + (size_t)i * D);
      ASSERT_NEAR(s[i], r, 2e-6);
      if (with_neg) ASSERT(r >= 0.0 && r <= 1.0);
      mx = r > mx ? r : mx;
      mn = r < mn ? r : mn;
    }
    ASSERT(mx - mn > 0.1); /* the random data spans a range of scores */
    /* opacity masking */
    float op[N];
    for (int i = 0; i < N; i++) op[i] = (i % 2) ? 1.0f : 0.0f;
    ASSERT_OK(fg_query_score_features(&q, feat, N, D, op, 0.5f, s, 1));
    ASSERT(isnan(s[0]) && !isnan(s[1]));
    fg_query_release(&q);
    ASSERT(q.q == NULL);
  }
  /* the rule by hand: D = 2, q = e0, one negative e1, T = 0.1; f = (1, 1): cq = cn -> 0.5;
   * f = (1, 0): 1 / (1 + exp(-10)); several negatives: the minimum */
  float e0[2] = {1, 0}, e1[4] = {0, 1, 0.6f, 0.8f};
  fg_query q;
  ASSERT_OK(fg_query_init(&q, 2, e0, 1, e1, 1, 0.1f));
  float f11[2] = {1, 1}, f10[2] = {2, 0};
  ASSERT_NEAR(fg_query_score_ref(&q, f11), 0.5, 1e-12);
  ASSERT_NEAR(fg_query_score_ref(&q, f10), 1.0 / (1.0 + exp(-10.0)), 1e-7);
  fg_query_release(&q);
  ASSERT_OK(fg_query_init(&q, 2, e0, 1, e1, 2, 0.1f));
  /* f = (1,0): cn = {0, 0.6}: min is at 0.6: 1 / (1 + exp(-4)) */
  ASSERT_NEAR(fg_query_score_ref(&q, f10), 1.0 / (1.0 + exp(-4.0)), 1e-7);
  float cn[2] = {0.0f, 0.6f};
  ASSERT_NEAR(fg_query_score_from_cos(&q, 1.0f, cn), 1.0 / (1.0 + exp(-4.0)), 1e-6);
  fg_query_release(&q);
  free(pos);
  free(neg);
  free(feat);
  free(s);
}

static void test_query_errors(void) {
  fg_query q;
  float z[4] = {0, 0, 0, 0}, v[4] = {1, 2, 3, 4}, opp[8] = {1, 0, 0, 0, -1, 0, 0, 0};
  float bad[4] = {1, NAN, 0, 0};
  ASSERT_ERR(fg_query_init(&q, 0, v, 1, NULL, 0, 0.1f), FG_EINVAL, "dimension");
  ASSERT_ERR(fg_query_init(&q, 4, z, 1, NULL, 0, 0.1f), FG_EINVAL, "all zeros");
  ASSERT_ERR(fg_query_init(&q, 4, bad, 1, NULL, 0, 0.1f), FG_EINVAL, "not finite");
  ASSERT_ERR(fg_query_init(&q, 4, opp, 2, NULL, 0, 0.1f), FG_EINVAL, "cancel");
  ASSERT_ERR(fg_query_init(&q, 4, v, 1, z, 1, 0.1f), FG_EINVAL, "negative embedding 0");
  ASSERT_ERR(fg_query_init(&q, 4, v, 1, v, 1, 0.0f), FG_EINVAL, "temperature");
  ASSERT_ERR(fg_query_init(&q, 4, v, 1, v, 1, INFINITY), FG_EINVAL, "temperature");
  ASSERT_ERR(fg_query_init(&q, 4, v, 1, v, FG_QUERY_MAX_NEGATIVES + 1, 0.1f), FG_EINVAL,
             "negatives");
  ASSERT(q.q == NULL);
  /* a hand-built query with a non-unit vector */
  fg_query h = {.dim = 4, .q = v, .n_neg = 0, .neg = NULL, .temperature = 0.1f};
  ASSERT_ERR(fg_query_check(&h), FG_EINVAL, "unit vector");
  float u[4] = {1, 0, 0, 0};
  h.q = u;
  ASSERT_OK(fg_query_check(&h));
  h.n_neg = 1;
  h.neg = v;
  ASSERT_ERR(fg_query_check(&h), FG_EINVAL, "negative 0");
  h.neg = u;
  h.temperature = -1.0f;
  ASSERT_ERR(fg_query_check(&h), FG_EINVAL, "temperature");
  h.temperature = 0.1f;
  float s[1];
  ASSERT_ERR(fg_query_score_features(&h, u, 1, 3, NULL, 0, s, 1), FG_EINVAL, "dimensions");
}

static void test_grid(void) {
  fg_voxel_grid g;
  const double mn[3] = {0.10, -0.45, 0.005}, mx[3] = {0.80, 0.45, 0.35};
  ASSERT_OK(fg_voxel_grid_init(&g, mn, mx, 0.01));
  ASSERT_EQ(g.nx, 70);
  ASSERT_EQ(g.ny, 90);
  ASSERT_EQ(g.nz, 35);
  ASSERT_EQ(fg_voxel_grid_count(&g), 220500);
  double p[3];
  fg_voxel_grid_centre(&g, 0, 0, 0, p);
  ASSERT_NEAR(p[0], 0.105, 1e-12);
  ASSERT_NEAR(p[1], -0.445, 1e-12);
  ASSERT_NEAR(p[2], 0.010, 1e-12);
  fg_voxel_grid_centre(&g, 69, 89, 34, p);
  ASSERT_NEAR(p[0], 0.795, 1e-12);
  ASSERT_NEAR(p[1], 0.445, 1e-12);
  ASSERT_NEAR(p[2], 0.350, 1e-12);
  /* flat order: x fastest */
  float *c = malloc(220500 * 3 * sizeof *c);
  fg_voxel_grid_centres(&g, c);
  size_t i = ((size_t)7 * 90 + 11) * 70 + 5;
  fg_voxel_grid_centre(&g, 5, 11, 7, p);
  for (int a = 0; a < 3; a++) ASSERT_NEAR(c[3 * i + a], p[a], 1e-6);
  free(c);
  /* a partial voxel is kept; an exact multiple is not rounded up by float noise */
  const double a0[3] = {0, 0, 0}, a1[3] = {0.105, 0.3, 0.07};
  ASSERT_OK(fg_voxel_grid_init(&g, a0, a1, 0.01));
  ASSERT_EQ(g.nx, 11);
  ASSERT_EQ(g.ny, 30);
  ASSERT_EQ(g.nz, 7);
  ASSERT_ERR(fg_voxel_grid_init(&g, a0, a1, 0.0), FG_EINVAL, "voxel_size");
  ASSERT_ERR(fg_voxel_grid_init(&g, a1, a0, 0.01), FG_EINVAL, "greater than min");
  const double big[3] = {2.57, 2.56, 2.56};
  ASSERT_ERR(fg_voxel_grid_init(&g, a0, big, 0.01), FG_ERANGE, "256^3");
  const double ok[3] = {2.56, 2.56, 2.56};
  ASSERT_OK(fg_voxel_grid_init(&g, a0, ok, 0.01));
  ASSERT_EQ(fg_voxel_grid_count(&g), FG_QUERY_MAX_VOXELS);
}

/* A small random field over a 20 x 20 x 10 grid: the cache against the full-feature
 * reference, thresholds, lists, encoders. */
static void test_cache(void) {
  enum { D = 48 };
  const double mn[3] = {0.0, 0.0, 0.0}, mx[3] = {0.2, 0.2, 0.1};
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, mn, mx, 1.0, D));
  fg_field *f = NULL;
  ASSERT_OK(fg_field_new(&f, &cfg, 7));
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, mn, mx, 0.01));
  const size_t N = fg_voxel_grid_count(&g);
  ASSERT_EQ(N, 4000);
  fg_voxel_features *vf = NULL;
  ASSERT_OK(fg_voxel_features_build(&vf, f, &g, 2));
  ASSERT_EQ(fg_voxel_features_dim(vf), D);
  ASSERT_EQ(fg_voxel_features_grid(vf)->nx, 20);
  const float *alpha = fg_voxel_features_alpha(vf);
  /* alpha against the field's mean density over each voxel's 4^3 sub-cell centres (a new
   * field's occupancy grid is full), the features against the field's at the centres */
  enum { S = 4, S3 = S * S * S };
  float *x = malloc(N * S3 * 3 * sizeof *x), *sig = malloc(N * S3 * sizeof *sig);
  float *feat = malloc(N * D * sizeof *feat), *centres = malloc(N * 3 * sizeof *centres);
  for (size_t i = 0; i < N; i++)
    for (int s = 0; s < S3; s++) {
      const size_t iv[3] = {i % 20, (i / 20) % 20, i / 400};
      const int sub[3] = {s % S, (s / S) % S, s / (S * S)};
      for (int a = 0; a < 3; a++)
        x[(i * S3 + s) * 3 + a] = (float)(mn[a] + (iv[a] + (sub[a] + 0.5) / S) * 0.01);
    }
  fg_voxel_grid_centres(&g, centres);
  ASSERT_OK(fg_field_features(f, centres, (int64_t)N, sig, NULL, feat, 2)); /* sig: scratch */
  ASSERT_OK(fg_field_density(f, x, (int64_t)(N * S3), sig, 2));
  size_t above_floor = 0;
  float *sorted = malloc(N * sizeof *sorted);
  for (size_t i = 0; i < N; i++) {
    double sum = 0.0;
    for (int s = 0; s < S3; s++) sum += sig[i * S3 + s] > 0.0f ? sig[i * S3 + s] : 0.0f;
    ASSERT_NEAR(alpha[i], 1.0 - exp(-sum / S3 * 0.01), 1e-6);
    above_floor += alpha[i] >= FG_QUERY_ALPHA_FLOOR;
    sorted[i] = alpha[i];
  }
  ASSERT_EQ(fg_voxel_features_n_kept(vf), above_floor);
  ASSERT(above_floor > N / 2);
  /* full features from the float16 cache against the field's own */
  float fv[D];
  for (size_t i = 0; i < N; i += 37) {
    if (alpha[i] < FG_QUERY_ALPHA_FLOOR) {
      ASSERT_ERR(fg_voxel_features_feature(vf, i, fv), FG_ENOENT, "empty");
      continue;
    }
    ASSERT_OK(fg_voxel_features_feature(vf, i, fv));
    double num = 0, den = 0;
    for (int d = 0; d < D; d++) {
      num += (fv[d] - feat[i * D + d]) * (double)(fv[d] - feat[i * D + d]);
      den += (double)feat[i * D + d] * feat[i * D + d];
    }
    ASSERT(sqrt(num) <= 2e-3 * sqrt(den) + 1e-7);
  }
  ASSERT_ERR(fg_voxel_features_feature(vf, N, fv), FG_EINVAL, "outside");
  size_t bytes = fg_voxel_features_bytes(vf);
  ASSERT(bytes >= N * 4 + above_floor * (64 * 2 + 8));
  ASSERT(bytes < N * 4 + above_floor * (64 * 2 + 8) + D * 64 * 4 + 4096);

  /* a median alpha threshold: half the voxels occupied */
  int cmp_done = 0;
  for (size_t i = 1; i < N && !cmp_done; i++) /* insertion sort is fine at 4000 */
    for (size_t j = i; j > 0 && sorted[j - 1] > sorted[j]; j--) {
      float t = sorted[j];
      sorted[j] = sorted[j - 1];
      sorted[j - 1] = t;
    }
  const float thr = sorted[N / 2] > FG_QUERY_ALPHA_FLOOR ? sorted[N / 2] : FG_QUERY_ALPHA_FLOOR;
  float *pos = malloc(D * sizeof *pos), *neg = malloc(4 * D * sizeof *neg);
  /* a query near one voxel's feature so that scores spread */
  memcpy(pos, feat + 1234 * D, D * sizeof *pos);
  fill(neg, 4 * D);
  float *s_fast = malloc(N * sizeof *s_fast), *s_ref = malloc(N * sizeof *s_ref);
  float *s_1 = malloc(N * sizeof *s_1);
  for (int with_neg = 0; with_neg < 2; with_neg++) {
    fg_query q;
    ASSERT_OK(fg_query_init(&q, D, pos, 1, neg, with_neg ? 4 : 0, 0.1f));
    ASSERT_OK(fg_voxel_features_score(vf, &q, thr, s_fast, 2));
    ASSERT_OK(fg_voxel_features_score(vf, &q, thr, s_1, 1));
    ASSERT(memcmp(s_fast, s_1, N * sizeof *s_1) == 0); /* thread count independent */
    ASSERT_OK(fg_heatmap_score_grid_ref(f, &g, &q, thr, s_ref, 2));
    size_t n_occ = 0;
    for (size_t i = 0; i < N; i++) {
      ASSERT_EQ(isnan(s_fast[i]), isnan(s_ref[i]));
      ASSERT_EQ(isnan(s_fast[i]), !(alpha[i] >= thr));
      if (isnan(s_ref[i])) continue;
      n_occ++;
      ASSERT_NEAR(s_fast[i], s_ref[i], 2e-3);
    }
    ASSERT(n_occ >= N / 2 - 1 && n_occ <= N / 2 + 8); /* a few voxels tie at the median */

    /* heatmap: list order, min_score, max_points, best */
    fg_heatmap_options o;
    fg_heatmap_options_default(&o);
    o.alpha_threshold = thr;
    o.n_threads = 2;
    fg_heatmap hm;
    ASSERT_OK(fg_heatmap_compute(vf, &q, &o, &hm));
    ASSERT_EQ(hm.n_occupied, n_occ);
    ASSERT_EQ(hm.n_points, n_occ);
    ASSERT(memcmp(hm.dense, s_fast, N * sizeof *s_fast) == 0);
    for (size_t k = 1; k < hm.n_points; k++) {
      ASSERT(hm.points[k - 1].score >= hm.points[k].score);
      if (hm.points[k - 1].score == hm.points[k].score)
        ASSERT(hm.points[k - 1].index < hm.points[k].index);
    }
    const fg_heatmap_point *top = &hm.points[0];
    ASSERT(hm.has_best);
    ASSERT_EQ(hm.best_index, top->index);
    ASSERT(hm.best_score == top->score);
    for (int a = 0; a < 3; a++) {
      ASSERT_NEAR(hm.best_p_world[a], top->p_world[a], 1e-6);
      ASSERT_NEAR(top->p_world[a], centres[3 * top->index + a], 1e-6);
    }
    ASSERT(top->alpha == alpha[top->index]);
    const float median_score = hm.points[hm.n_points / 2].score;
    /* the list with min_score: exactly the scores >= it */
    fg_heatmap h2;
    o.min_score = median_score;
    o.want_dense = 0;
    ASSERT_OK(fg_heatmap_compute(vf, &q, &o, &h2));
    size_t expect = 0;
    for (size_t i = 0; i < N; i++) expect += !isnan(s_fast[i]) && s_fast[i] >= median_score;
    ASSERT_EQ(h2.n_points, expect);
    ASSERT(h2.dense == NULL);
    ASSERT_EQ(h2.n_occupied, n_occ);
    for (size_t k = 0; k < h2.n_points; k++) ASSERT(h2.points[k].index == hm.points[k].index);
    fg_heatmap_release(&h2);
    o.max_points = 10;
    ASSERT_OK(fg_heatmap_compute(vf, &q, &o, &h2));
    ASSERT_EQ(h2.n_points, 10);
    for (size_t k = 0; k < 10; k++) ASSERT(h2.points[k].index == hm.points[k].index);
    fg_heatmap_release(&h2);
    o.min_score = 2.0f; /* nothing qualifies; best still reported */
    ASSERT_OK(fg_heatmap_compute(vf, &q, &o, &h2));
    ASSERT_EQ(h2.n_points, 0);
    ASSERT(h2.points == NULL && h2.has_best && h2.best_index == hm.best_index);
    uint8_t *ply = NULL;
    size_t ply_len = 0;
    ASSERT_OK(fg_heatmap_encode_ply(&h2, 0.0f, 1.0f, &ply, &ply_len));
    ASSERT(strstr((const char *)ply, "element vertex 0\n") != NULL);
    free(ply);
    fg_heatmap_release(&h2);

    /* npy round trip */
    uint8_t *npy = NULL;
    size_t npy_len = 0;
    ASSERT_OK(fg_heatmap_encode_npy(&hm, &npy, &npy_len));
    fg_npy arr;
    ASSERT_OK(fg_npy_parse(npy, npy_len, &arr));
    ASSERT_EQ(arr.dtype, FG_DTYPE_F32);
    ASSERT_EQ(arr.ndim, 3);
    ASSERT_EQ(arr.shape[0], 10);
    ASSERT_EQ(arr.shape[1], 20);
    ASSERT_EQ(arr.shape[2], 20);
    ASSERT(memcmp(arr.data, hm.dense, N * sizeof(float)) == 0);
    free(npy);

    /* PLY: header, vertex count, records */
    ASSERT_OK(fg_heatmap_encode_ply(&hm, NAN, NAN, &ply, &ply_len));
    const char *end = strstr((const char *)ply, "end_header\n");
    ASSERT(end != NULL);
    size_t hl = (size_t)(end - (const char *)ply) + strlen("end_header\n");
    char head[1024];
    ASSERT(hl < sizeof head);
    memcpy(head, ply, hl);
    head[hl] = 0;
    ASSERT(strncmp(head, "ply\nformat binary_little_endian 1.0\n", 36) == 0);
    unsigned long nv = 0;
    const char *ev = strstr(head, "element vertex ");
    ASSERT(ev && sscanf(ev, "element vertex %lu", &nv) == 1);
    ASSERT_EQ(nv, hm.n_points);
    ASSERT(strstr(head, "property float x\nproperty float y\nproperty float z\n"
                        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                        "property float score\nend_header\n") != NULL);
    ASSERT_EQ(ply_len, hl + nv * 19);
    const float lo = hm.points[hm.n_points - 1].score, hi = hm.points[0].score;
    for (size_t k = 0; k < nv; k += 97) {
      const uint8_t *r = ply + hl + k * 19;
      float px, sc;
      memcpy(&px, r, 4); /* the host is little-endian on every supported target */
      memcpy(&sc, r + 15, 4);
      ASSERT(px == hm.points[k].p_world[0]);
      ASSERT(sc == hm.points[k].score);
      uint8_t rgb[3];
      fg_colormap_turbo((sc - lo) / (hi - lo), rgb);
      ASSERT(r[12] == rgb[0] && r[13] == rgb[1] && r[14] == rgb[2]);
    }
    /* the top point is red end of the map, the last the blue end */
    ASSERT(ply[hl + 12] == fg_turbo_rgb[255][0] && ply[hl + 14] == fg_turbo_rgb[255][2]);
    free(ply);
    fg_heatmap_release(&hm);

    /* bad inputs */
    ASSERT_ERR(fg_voxel_features_score(vf, &q, 1e-4f, s_fast, 1), FG_EINVAL, "alpha_threshold");
    ASSERT_ERR(fg_voxel_features_score(vf, &q, NAN, s_fast, 1), FG_EINVAL, "alpha_threshold");
    ASSERT_ERR(fg_voxel_features_score(vf, &q, 1.5f, s_fast, 1), FG_EINVAL, "alpha_threshold");
    o.min_score = NAN;
    ASSERT_ERR(fg_heatmap_compute(vf, &q, &o, &hm), FG_EINVAL, "min_score");
    fg_query_release(&q);
  }
  /* on disk: the same scores after a round trip; corruption and a missing file refused */
  {
    const char *base = getenv("TMPDIR");
    char dir[512];
    snprintf(dir, sizeof dir, "%s/fg-voxf-XXXXXX", base && *base ? base : "/tmp");
    ASSERT(mkdtemp(dir) != NULL);
    char *path = fg_path_join(dir, "voxel.cache");
    ASSERT_OK(fg_voxel_features_save(vf, path));
    fg_voxel_features *back = NULL;
    ASSERT_OK(fg_voxel_features_load(path, &back));
    ASSERT_EQ(fg_voxel_features_n_kept(back), fg_voxel_features_n_kept(vf));
    ASSERT_EQ(fg_voxel_features_trained_steps(back), fg_voxel_features_trained_steps(vf));
    ASSERT_EQ(fg_voxel_features_bytes(back), fg_voxel_features_bytes(vf));
    fg_query q;
    ASSERT_OK(fg_query_init(&q, D, pos, 1, neg, 4, 0.1f));
    ASSERT_OK(fg_voxel_features_score(vf, &q, thr, s_fast, 2));
    ASSERT_OK(fg_voxel_features_score(back, &q, thr, s_1, 2));
    ASSERT(memcmp(s_fast, s_1, N * sizeof *s_1) == 0);
    fg_query_release(&q);
    fg_voxel_features_free(back);
    char *file;
    size_t blen;
    ASSERT_OK(fg_read_file(path, (size_t)1 << 30, &file, &blen));
    file[blen / 2] ^= 0x10;
    ASSERT_OK(fg_write_file_atomic(path, file, blen));
    ASSERT_ERR(fg_voxel_features_load(path, &back), FG_EFORMAT, "checksum");
    ASSERT(back == NULL);
    ASSERT_OK(fg_write_file_atomic(path, file, blen - 1));
    ASSERT_ERR(fg_voxel_features_load(path, &back), FG_EFORMAT, "bytes");
    file[blen / 2] ^= 0x10; /* intact again, but version 1: its alpha meant something else */
    const uint32_t v1 = 1;
    memcpy(file + 8, &v1, 4);
    ASSERT_OK(fg_write_file_atomic(path, file, blen));
    ASSERT_ERR(fg_voxel_features_load(path, &back), FG_EFORMAT, "version");
    memcpy(file, "NOTVOXEL", 8);
    ASSERT_OK(fg_write_file_atomic(path, file, blen));
    ASSERT_ERR(fg_voxel_features_load(path, &back), FG_EFORMAT, "magic");
    free(file);
    ASSERT_OK(fg_rmtree(dir));
    ASSERT(fg_voxel_features_load(path, &back) == FG_ENOENT);
    free(path);
  }
  fg_query q8;
  float p8[8] = {1, 0, 0, 0, 0, 0, 0, 0};
  ASSERT_OK(fg_query_init(&q8, 8, p8, 1, NULL, 0, 0.1f));
  ASSERT_ERR(fg_voxel_features_score(vf, &q8, 0.1f, s_fast, 1), FG_EINVAL, "48");
  fg_query_release(&q8);
  fg_voxel_features_free(vf);
  fg_voxel_features_free(NULL);

  /* a field without features */
  fg_field_config c0;
  ASSERT_OK(fg_field_config_for_workspace(&c0, mn, mx, 1.0, 0));
  fg_field *f0 = NULL;
  ASSERT_OK(fg_field_new(&f0, &c0, 1));
  ASSERT_ERR(fg_voxel_features_build(&vf, f0, &g, 1), FG_EINVAL, "feature branch");
  fg_field_free(f0);
  fg_field_free(f);
  free(x);
  free(centres);
  free(sig);
  free(feat);
  free(sorted);
  free(pos);
  free(neg);
  free(s_fast);
  free(s_ref);
  free(s_1);
}

static void test_colour(void) {
  uint8_t cv[256][3];
  ASSERT_OK(fg_cv_turbo_table(cv));
  for (int i = 0; i < 256; i++)
    for (int c = 0; c < 3; c++) ASSERT_EQ(fg_turbo_rgb[i][c], cv[i][c]);
  uint8_t rgb[3];
  fg_colormap_turbo(0.0f, rgb);
  ASSERT(rgb[0] == cv[0][0] && rgb[2] == cv[0][2]);
  fg_colormap_turbo(2.0f, rgb);
  ASSERT(rgb[0] == cv[255][0] && rgb[1] == cv[255][1]);
  fg_colormap_turbo(0.5f, rgb);
  ASSERT(rgb[1] == cv[128][1] && rgb[0] == cv[128][0]);
  fg_colormap_turbo(NAN, rgb);
  ASSERT(rgb[2] == cv[0][2]);
  /* blend: NaN keeps the render, lo -> a = 0.25 of entry 0, hi -> a = 0.85 of entry 255 */
  const float img[9] = {0.2f, 0.4f, 0.6f, 1.0f, 1.0f, 1.0f, 0.0f, 0.0f, 0.0f};
  const float sc[3] = {NAN, 0.0f, 1.0f};
  uint8_t out[9];
  fg_heatmap_blend(img, sc, 3, 0.0f, 1.0f, out);
  ASSERT(out[0] == 51 && out[1] == 102 && out[2] == 153);
  for (int c = 0; c < 3; c++) {
    ASSERT_NEAR(out[3 + c], 255.0 * (0.75 + 0.25 * cv[0][c] / 255.0), 0.51);
    ASSERT_NEAR(out[6 + c], 255.0 * (0.85 * cv[255][c] / 255.0), 0.51);
  }
  /* auto range gives the same picture for scores 3 and 5 */
  const float sc2[3] = {NAN, 3.0f, 5.0f};
  uint8_t out2[9];
  fg_heatmap_blend(img, sc2, 3, NAN, NAN, out2);
  ASSERT(memcmp(out, out2, 9) == 0);
}

int main(void) {
  test_scores();
  test_query_errors();
  test_grid();
  test_cache();
  test_colour();
  printf("query unit: ok\n");
  return 0;
}
