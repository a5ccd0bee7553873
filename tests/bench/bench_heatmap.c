/* Open-vocabulary heatmaps on the default tabletop workspace (0.10 -0.45 0.005 .. 0.80 0.45
 * 0.35 m at 1 cm: 70 x 90 x 35 = 220,500 voxels) with a D = 512 feature field, randomly
 * initialised (its density puts most voxels above the feature floor, so the per-heatmap cost
 * is close to the worst case of every voxel kept). Prints key=value lines: the voxel feature
 * build, the heatmap p50 / p90 over the runs (dense grid and sorted point list, as the daemon
 * asks for them) with and without four negatives, at the alpha floor (every kept voxel
 * occupied) and at the default alpha threshold, and the cache's bytes.
 * Usage: bench_heatmap [threads [runs]] */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "benchstat.h"
#include "core/error.h"
#include "field/model.h"
#include "query/heatmap.h"

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void die(const char *what, int rc) {
  fprintf(stderr, "%s: %s (%s)\n", what, fg_strerror(rc), fg_error_detail());
  exit(1);
}

/* Runs `runs` heatmaps of q and prints their p50 and p90 in ms under the given key. */
static void time_heatmaps(const fg_voxel_features *vf, const fg_query *q, float alpha_threshold,
                          int runs, int nt, const char *key) {
  double *ms = malloc((size_t)runs * sizeof *ms);
  fg_heatmap_options o;
  fg_heatmap_options_default(&o);
  o.n_threads = nt;
  o.alpha_threshold = alpha_threshold;
  size_t n_points = 0;
  for (int r = 0; r < runs; r++) {
    fg_heatmap hm;
    double t0 = now_s();
    int rc = fg_heatmap_compute(vf, q, &o, &hm);
    ms[r] = 1e3 * (now_s() - t0);
    if (rc < 0) die("fg_heatmap_compute", rc);
    n_points = hm.n_points;
    fg_heatmap_release(&hm);
  }
  const double p50 = bench_percentile(ms, runs, 0.5), p90 = bench_percentile(ms, runs, 0.9);
  printf("%s_p50_ms=%.3f\n%s_p90_ms=%.3f\n%s_points=%zu\n", key, p50, key, p90, key,
         n_points);
  free(ms);
}

int main(int argc, char **argv) {
  const int nt = argc > 1 ? atoi(argv[1]) : 0;
  const int runs = argc > 2 ? atoi(argv[2]) : 50;
  const int D = 512;
  const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};
  fg_field_config cfg;
  int rc = fg_field_config_for_workspace(&cfg, ws_min, ws_max, 2.0, D);
  if (rc < 0) die("config", rc);
  fg_field *f;
  if ((rc = fg_field_new(&f, &cfg, 1)) < 0) die("fg_field_new", rc);
  fg_voxel_grid g;
  if ((rc = fg_voxel_grid_init(&g, ws_min, ws_max, 0.01)) < 0) die("grid", rc);
  fg_voxel_features *vf;
  double t0 = now_s();
  if ((rc = fg_voxel_features_build(&vf, f, &g, nt)) < 0) die("build", rc);
  const double build_s = now_s() - t0;
  printf("field=random_init_seed1\nfeature_dim=%d\nthreads=%d\nvoxels=%zu\nkept_voxels=%zu\n"
         "voxel_build_s=%.3f\ncache_bytes=%zu\ncache_mib=%.2f\n",
         D, nt, fg_voxel_grid_count(&g), fg_voxel_features_n_kept(vf), build_s,
         fg_voxel_features_bytes(vf), fg_voxel_features_bytes(vf) / 1048576.0);
  /* a query and four negatives: random unit vectors */
  float *v = malloc(5 * (size_t)D * sizeof *v);
  uint64_t s = 12345;
  for (int i = 0; i < 5 * D; i++) {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    v[i] = (float)((double)(s >> 11) / 9007199254740992.0) - 0.5f;
  }
  fg_query q0, q4;
  if ((rc = fg_query_init(&q0, D, v, 1, NULL, 0, 0.1f)) < 0) die("query", rc);
  if ((rc = fg_query_init(&q4, D, v, 1, v + D, 4, 0.1f)) < 0) die("query", rc);
  /* the floor threshold makes every kept voxel occupied (the worst case: all of them scored,
   * sorted and listed); the default threshold of 0.1 leaves a fresh field almost empty */
  time_heatmaps(vf, &q0, FG_QUERY_ALPHA_FLOOR, runs, nt, "heatmap_all");
  time_heatmaps(vf, &q4, FG_QUERY_ALPHA_FLOOR, runs, nt, "heatmap_all_neg4");
  time_heatmaps(vf, &q0, FG_QUERY_DEFAULT_ALPHA_THRESHOLD, runs, nt, "heatmap_default");
  time_heatmaps(vf, &q4, FG_QUERY_DEFAULT_ALPHA_THRESHOLD, runs, nt, "heatmap_default_neg4");
  fg_query_release(&q0);
  fg_query_release(&q4);
  free(v);
  fg_voxel_features_free(vf);
  fg_field_free(f);
  return 0;
}
