/* Grasp inference benchmark (issue 12): a grasp request on SPEC.md's default tabletop
 * workspace (0.10 -0.45 0.005 .. 0.80 0.45 0.35 m at 1 cm: 220,500 voxels) with the features
 * of a trained scene, after the voxel cache exists. Targets: <= 1 s on 2 cores and <= 300 MB
 * of extra peak memory per request.
 *
 * The data set comes from outside (tests/bench/run.sh makes it with `fieldgrip-scenegen --dim
 * 512`); this program generates nothing. It trains the set in-process for --steps steps on
 * --threads threads (as the quality test's layouts, tests/quality/layout.h: field scale 2
 * around the workspace, the scene's background; here every view is trained), builds the
 * voxel feature cache (its seconds and bytes are reported on their own: the daemon builds
 * it once per field state, not per request), and records one demo each of the mug's and the
 * box's gt.json grasp (each task is one demo, so Z = z at that pose, 100 query points of the
 * default std). Then it times --runs rounds of both tasks' requests done as the daemon does
 * them: fg_grasp_field_new (its share is reported as grasp_field_new_p50_s) +
 * fg_grasp_search with the default options (candidates at alpha >= 0.1, 24 rotations,
 * n_keep 1024, n_final 64, 100 Adam iterations),
 * the Robotiq 2F-140 open to 0.11 m for the collision checks. p50/min/max are over all 2 x runs requests; poses_optimised, evaluations
 * and lookups are those of the costlier of the two tasks' requests (they differ only by the
 * poses the collision check rejects). lookups = evaluations x N_q x 8 trilinear corners, each a
 * 64-float row of the grasp field: lookup_gb_per_s says how far the search runs from memory
 * bandwidth (the rows mostly come from cache, so it may exceed DRAM's).
 *
 * Memory: VmHWM is reset to the current RSS (/proc/self/clear_refs) after training is freed
 * and the cache is built; extra_peak_mb = VmHWM after the requests minus the RSS before them
 * (peak_reset=no when the kernel refused the reset: the figure is then a lower bound).
 *
 * --dump DIR writes what tests/bench/peer_grasp.py needs to run the same search in PyTorch
 * (the dense alpha*f grid at D = 512 is 220,500 x 512 floats, too big for a file, so the
 * peer rebuilds it from the kept voxels):
 *   alpha.npy       (nz, ny, nx) float32, the cache's alpha
 *   kept_index.npy  (n_kept,) int64 flat indices (iz * ny + iy) * nx + ix, ascending
 *   kept_feat.npy   (n_kept, D) float32 alpha * f (f = W h from the cache's float16 h)
 *   query_points.npy (N_q, 3) float32, gripper frame, metres
 *   Z_mug.npy, Z_box.npy (N_q, D) float32 task embeddings
 *   candidates.npy  (n_cand,) int64 flat indices of the candidate voxels
 *   rotations.npy   (n_rot, 4) float64 unit quaternions [w, x, y, z] (fg_so3_super_fibonacci)
 *   bench_grasp.json  grid {min, max, voxel_size, nx, ny, nz}, dim, tasks, options
 *                     {n_rotations, n_keep, n_final, iterations, lr_translation_m,
 *                     lr_rotation_rad, candidate_alpha, prune_fraction, adam betas and eps}
 *                     and this program's results
 *
 * Usage: bench_grasp --data DIR [--steps N] [--samples N] [--threads N] [--runs N]
 *                    [--rotations N] [--voxel-size M] [--dump DIR]
 * Defaults: 300 steps, the trainer's samples per step (2^17, as the daemon trains), 2 threads,
 * 5 runs, 24 rotations, 0.01 m voxels. --rotations and --voxel-size exist for quick checks at
 * tiny sizes; the benchmark's figures are with the defaults.
 * Output: one line, e.g.
 *   bench=grasp dim=512 ... p50_s=... candidates=... rotations=24 ... pass=yes */
#include <malloc.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

#include "benchmem.h"
#include "benchstat.h"
#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "field/model.h"
#include "field/train.h"
#include "grasp/grasp.h"
#include "gt.h"
#include "io/dataset.h"
#include "io/npy.h"
#include "query/voxfeat.h"

#define N_QUERY FG_GRASP_DEFAULT_QUERY_POINTS
#define WIDTH_M 0.11
#define TARGET_MAX_S 1.0
#define TARGET_MAX_EXTRA_MB 300.0
#define PRUNE_FRACTION 0.025 /* lib/grasp/search.c's; the peer needs it */

enum { TASK_MUG, TASK_BOX, N_TASKS };
static const char *const task_object[N_TASKS] = {"mug", "box"};

static const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};

static void die(const char *what, int rc) {
  fprintf(stderr, "bench_grasp: %s: %s (%s)\n", what, fg_strerror(rc), fg_error_detail());
  exit(1);
}

#define TRY(what, expr)          \
  do {                           \
    const int rc_ = (expr);      \
    if (rc_ < 0) die(what, rc_); \
  } while (0)

static void *xmalloc(size_t n) {
  void *p = malloc(n ? n : 1);
  if (!p) die("out of memory", FG_ENOMEM);
  return p;
}

/* ---------------------------------------------------------------- dump */

/* An .npy of a dtype npy.h does not encode (descr "<i8", "<f8"): version 1.0 header padded
 * to 64 bytes, then the data. */
static int npy_write_raw(const char *path, const char *descr, int ndim, const size_t *shape,
                         const void *data, size_t elem_size) {
  char dict[256], shp[128] = "";
  size_t count = 1, off = 0;
  for (int k = 0; k < ndim; k++) {
    off += (size_t)snprintf(shp + off, sizeof shp - off, "%zu,%s", shape[k],
                            k + 1 < ndim ? " " : "");
    count *= shape[k];
  }
  if (ndim > 1) shp[off - 1] = '\0'; /* (a, b) rather than (a, b,) */
  int n = snprintf(dict, sizeof dict, "{'descr': '%s', 'fortran_order': False, 'shape': (%s), }",
                   descr, shp);
  const size_t unpadded = 10 + (size_t)n + 1;
  const size_t hlen = (size_t)n + 1 + (64 - unpadded % 64) % 64;
  const size_t len = 10 + hlen + count * elem_size;
  uint8_t *buf = xmalloc(len);
  memcpy(buf, "\x93NUMPY\x01\x00", 8);
  buf[8] = (uint8_t)(hlen & 0xff);
  buf[9] = (uint8_t)(hlen >> 8);
  memset(buf + 10, ' ', hlen);
  memcpy(buf + 10, dict, (size_t)n);
  buf[10 + hlen - 1] = '\n';
  memcpy(buf + 10 + hlen, data, count * elem_size);
  const int rc = fg_write_file_atomic(path, buf, len);
  free(buf);
  return rc;
}

static void dump_f32(const char *dir, const char *name, int ndim, const size_t *shape,
                     const float *data) {
  uint8_t *buf;
  size_t len;
  TRY(name, fg_npy_encode(FG_DTYPE_F32, ndim, shape, data, &buf, &len));
  char *path = fg_path_join(dir, name);
  TRY(name, fg_write_file_atomic(path, buf, len));
  free(path);
  free(buf);
}

static void dump_raw(const char *dir, const char *name, const char *descr, int ndim,
                     const size_t *shape, const void *data, size_t elem_size) {
  char *path = fg_path_join(dir, name);
  TRY(name, npy_write_raw(path, descr, ndim, shape, data, elem_size));
  free(path);
}

/* Everything the peer needs, as described at the top; results is a JSON object of this
 * program's figures (stolen). */
static void dump_inputs(const char *dir, const fg_voxel_features *vf, const float *p_gripper,
                        float *const Z[N_TASKS], const fg_grasp_options *o, json_t *results) {
  TRY(dir, fg_mkdir_p(dir));
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  const int D = fg_voxel_features_dim(vf);
  const size_t N = fg_voxel_grid_count(g), n_kept = fg_voxel_features_n_kept(vf);
  const float *alpha = fg_voxel_features_alpha(vf);
  const uint32_t *kept;
  fg_voxel_features_raw(vf, &kept, NULL, NULL);

  const size_t s_grid[3] = {(size_t)g->nz, (size_t)g->ny, (size_t)g->nx};
  dump_f32(dir, "alpha.npy", 3, s_grid, alpha);

  int64_t *idx = xmalloc((n_kept > N ? n_kept : N) * sizeof *idx);
  for (size_t k = 0; k < n_kept; k++) idx[k] = kept[k];
  dump_raw(dir, "kept_index.npy", "<i8", 1, &n_kept, idx, sizeof *idx);
  float *feat = xmalloc(n_kept * (size_t)D * sizeof *feat);
  for (size_t k = 0; k < n_kept; k++) {
    float *f = feat + k * (size_t)D;
    TRY("kept feature", fg_voxel_features_feature(vf, kept[k], f));
    for (int d = 0; d < D; d++) f[d] *= alpha[kept[k]];
  }
  const size_t s_feat[2] = {n_kept, (size_t)D};
  dump_f32(dir, "kept_feat.npy", 2, s_feat, feat);
  free(feat);

  const size_t s_q[2] = {N_QUERY, 3}, s_z[2] = {N_QUERY, (size_t)D};
  dump_f32(dir, "query_points.npy", 2, s_q, p_gripper);
  for (int task = 0; task < N_TASKS; task++) {
    char name[64];
    snprintf(name, sizeof name, "Z_%s.npy", task_object[task]);
    dump_f32(dir, name, 2, s_z, Z[task]);
  }

  /* the search's candidates: voxel centres with alpha >= candidate_alpha, no mask */
  size_t n_cand = 0;
  for (size_t i = 0; i < N; i++)
    if (alpha[i] >= o->candidate_alpha) idx[n_cand++] = (int64_t)i;
  dump_raw(dir, "candidates.npy", "<i8", 1, &n_cand, idx, sizeof *idx);
  free(idx);

  /* the SO(3) cover (seed 0: not turned) */
  double *q = xmalloc((size_t)o->n_rotations * 4 * sizeof *q);
  fg_so3_super_fibonacci(o->n_rotations, q);
  const size_t s_rot[2] = {(size_t)o->n_rotations, 4};
  dump_raw(dir, "rotations.npy", "<f8", 2, s_rot, q, sizeof *q);
  free(q);

  json_t *tasks = json_array();
  for (int task = 0; task < N_TASKS; task++)
    json_array_append_new(tasks, json_string(task_object[task]));
  json_t *j = json_pack(
      "{s:{s:[f,f,f], s:[f,f,f], s:f, s:i, s:i, s:i}, s:i, s:i, s:o, "
      "s:{s:f, s:i, s:i, s:i, s:i, s:f, s:f, s:f, s:f, s:f, s:f, s:s, s:f, s:b}, s:o}",
      "grid", "min", g->min[0], g->min[1], g->min[2], "max", g->max[0], g->max[1], g->max[2],
      "voxel_size", g->voxel_size, "nx", g->nx, "ny", g->ny, "nz", g->nz,
      "dim", D, "n_query", N_QUERY, "tasks", tasks,
      "options", "candidate_alpha", (double)o->candidate_alpha, "n_rotations", o->n_rotations,
      "n_keep", o->n_keep, "n_final", o->n_final, "iterations", o->iterations,
      "lr_translation_m", o->lr_translation_m, "lr_rotation_rad", o->lr_rotation_rad,
      "prune_fraction", PRUNE_FRACTION, "adam_beta1", 0.9, "adam_beta2", 0.999, "adam_eps", 1e-8,
      "gripper", "robotiq-2f140", "width_m", o->width_m, "check_collisions",
      o->check_collisions, "results", results);
  if (!j) die("bench_grasp.json: json_pack", FG_ENOMEM);
  char *text = json_dumps(j, JSON_INDENT(2) | JSON_REAL_PRECISION(17));
  char *path = fg_path_join(dir, "bench_grasp.json");
  if (!text || !path) die("bench_grasp.json", FG_ENOMEM);
  TRY("bench_grasp.json", fg_write_file_atomic(path, text, strlen(text)));
  free(text);
  free(path);
  json_decref(j);
}

/* ---------------------------------------------------------------- main */

static int object_index(const sg_gt *gt, const char *name) {
  for (int k = 0; k < gt->n_objects; k++)
    if (strcmp(gt->objects[k].name, name) == 0) return k;
  fprintf(stderr, "bench_grasp: gt.json has no %s\n", name);
  exit(1);
}

static void usage(const char *bad) {
  fprintf(stderr,
          "bench_grasp: bad argument '%s'\n"
          "usage: bench_grasp --data DIR [--steps N] [--samples N] [--threads N] [--runs N]\n"
          "                   [--rotations N] [--voxel-size M] [--dump DIR]\n"
          "  (see the comment at the top of tests/bench/bench_grasp.c)\n",
          bad);
  exit(2);
}

int main(int argc, char **argv) {
  const char *data = NULL, *dump = NULL;
  int steps = 300, threads = 2, runs = 5, samples = 0, rotations = 0;
  double voxel_size = 0.01;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const int more = i + 1 < argc;
    if (!strcmp(a, "--data") && more) data = argv[++i];
    else if (!strcmp(a, "--dump") && more) dump = argv[++i];
    else if (!strcmp(a, "--steps") && more) steps = atoi(argv[++i]);
    else if (!strcmp(a, "--samples") && more) samples = atoi(argv[++i]);
    else if (!strcmp(a, "--threads") && more) threads = atoi(argv[++i]);
    else if (!strcmp(a, "--runs") && more) runs = atoi(argv[++i]);
    else if (!strcmp(a, "--rotations") && more) rotations = atoi(argv[++i]);
    else if (!strcmp(a, "--voxel-size") && more) voxel_size = atof(argv[++i]);
    else usage(a);
  }
  if (!data || steps < 0 || threads < 1 || runs < 1 || samples < 0 || rotations < 0 ||
      !(voxel_size > 0))
    usage(data ? "(a value out of range)" : "(--data is required)");

  /* ---- the scene: data set, training, voxel cache */
  char *transforms = fg_path_join(data, "transforms.json"), *gt_path = fg_path_join(data, "gt.json");
  sg_gt gt;
  TRY(gt_path, sg_gt_load(gt_path, &gt));
  fg_ingest_opts io = {.background_rgb = {gt.background_rgb[0], gt.background_rgb[1],
                                          gt.background_rgb[2]}};
  fg_frame *frames;
  size_t n_frames;
  TRY(transforms, fg_dataset_load(transforms, &io, threads, &frames, &n_frames));
  const int D = gt.feature_dim;
  fg_field_config cfg;
  TRY("field config", fg_field_config_for_workspace(&cfg, ws_min, ws_max, 2.0, D));
  fg_field *field;
  TRY("fg_field_new", fg_field_new(&field, &cfg, 1));
  fg_train_opts to;
  fg_train_opts_default(&to);
  to.n_threads = threads;
  to.holdout_every = 0;
  if (samples > 0) to.target_samples = samples;
  memcpy(to.background, gt.background_rgb, sizeof to.background);
  fg_trainer *trainer;
  TRY("fg_trainer_new", fg_trainer_new(&trainer, field, frames, n_frames, &to));
  fg_train_stats ts = {0};
  double t0 = fg_mono_s();
  for (int s = 0; s < steps; s++) TRY("fg_trainer_step", fg_trainer_step(trainer, &ts));
  const double train_s = fg_mono_s() - t0;
  fg_trainer_free(trainer);
  fg_dataset_free(frames, n_frames);

  fg_voxel_grid grid;
  TRY("voxel grid", fg_voxel_grid_init(&grid, ws_min, ws_max, voxel_size));
  fg_voxel_features *vf;
  t0 = fg_mono_s();
  TRY("fg_voxel_features_build", fg_voxel_features_build(&vf, field, &grid, threads));
  const double cache_s = fg_mono_s() - t0;
  fg_field_free(field);

  /* ---- demos: one per task at its gt.json grasp */
  float p_gripper[N_QUERY * 3];
  const double mean[3] = {0, 0, 0};
  TRY("query points", fg_grasp_query_points(N_QUERY, mean, FG_GRASP_DEFAULT_STD_M, p_gripper));
  float *Z[N_TASKS];
  {
    fg_grasp_field *gf;
    TRY("fg_grasp_field_new", fg_grasp_field_new(&gf, vf, threads));
    for (int task = 0; task < N_TASKS; task++) {
      Z[task] = xmalloc((size_t)N_QUERY * D * sizeof *Z[task]);
      const sg_gt_object *ob = &gt.objects[object_index(&gt, task_object[task])];
      TRY("fg_grasp_sample", fg_grasp_sample(gf, ob->T_world_grasp, p_gripper, N_QUERY, Z[task]));
    }
    fg_grasp_field_free(gf);
  }

  fg_grasp_options o;
  fg_grasp_options_default(&o);
  o.gripper = FG_GRIPPER_ROBOTIQ_2F140;
  o.width_m = WIDTH_M;
  o.n_threads = threads;
  if (rotations > 0) o.n_rotations = rotations;

  /* ---- the requests, measured from here: what training left is given back first */
  malloc_trim(0);
  const int peak_reset = bench_reset_peak();
  const long rss0_kb = bench_status_kb("VmRSS:");
  const long hwm0_kb = bench_status_kb("VmHWM:");
  const long base_kb = peak_reset ? rss0_kb : hwm0_kb;
  const int n_req = runs * N_TASKS;
  double *secs = xmalloc((size_t)n_req * sizeof *secs);
  double *secs_field = xmalloc((size_t)n_req * sizeof *secs_field);
  fg_grasp_stats st = {0};
  size_t field_bytes = 0;
  double top_score[N_TASKS], top_cost[N_TASKS], top_T[N_TASKS][16];
  int found[N_TASKS];
  const char *reason[N_TASKS];
  for (int r = 0; r < runs; r++)
    for (int task = 0; task < N_TASKS; task++) {
      const fg_grasp_target t = {N_QUERY, D, p_gripper, Z[task], NULL};
      fg_grasp_result res;
      fg_grasp_field *gf;
      t0 = fg_mono_s();
      TRY("fg_grasp_field_new", fg_grasp_field_new(&gf, vf, threads));
      const double t1 = fg_mono_s();
      TRY("fg_grasp_search", fg_grasp_search(gf, &t, &o, &res));
      secs[r * N_TASKS + task] = fg_mono_s() - t0;
      secs_field[r * N_TASKS + task] = t1 - t0;
      field_bytes = fg_grasp_field_bytes(gf);
      fg_grasp_field_free(gf);
      found[task] = res.n;
      reason[task] = res.reason;
      top_score[task] = res.n > 0 ? res.poses[0].score : NAN;
      top_cost[task] = res.n > 0 ? res.poses[0].cost : NAN;
      if (res.n > 0) memcpy(top_T[task], res.poses[0].T_world_gripper, sizeof top_T[task]);
      if (res.stats.evaluations >= st.evaluations) st = res.stats;
      fg_grasp_result_release(&res);
    }
  const long hwm1_kb = bench_status_kb("VmHWM:");
  const double extra_mb = (double)(hwm1_kb - base_kb) / 1024.0;
  const double p50 = bench_median(secs, n_req), p50_field = bench_median(secs_field, n_req);
  const double lo = secs[0], hi = secs[n_req - 1];
  const size_t lookups = st.evaluations * N_QUERY * 8;
  /* each lookup reads one row of 64 floats of the grasp field */
  const double gb_per_s = (double)lookups * FG_FIELD_FEATURE_HIDDEN * sizeof(float) / p50 * 1e-9;
  const int pass = p50 <= TARGET_MAX_S && extra_mb <= TARGET_MAX_EXTRA_MB && found[TASK_MUG] > 0 &&
                   found[TASK_BOX] > 0;
  for (int task = 0; task < N_TASKS; task++)
    if (!found[task])
      fprintf(stderr, "bench_grasp: no %s grasp: %s\n", task_object[task], reason[task]);

  printf("bench=grasp dim=%d threads=%d voxels=%zu voxel_size_m=%g kept_voxels=%zu "
         "train_steps=%d train_samples_per_step=%d train_s=%.1f train_loss=%.4f "
         "cache_build_s=%.3f cache_bytes=%zu cache_mb=%.1f grasp_field_bytes=%zu "
         "grasp_field_mb=%.1f tasks=mug,box runs=%d requests=%d p50_s=%.4f min_s=%.4f "
         "max_s=%.4f grasp_field_new_p50_s=%.4f candidates=%zu rotations=%d poses_scored=%zu poses_optimised=%zu "
         "n_final=%d iterations=%d evaluations=%zu query_points=%d lookups=%zu "
         "lookup_gb_per_s=%.1f collision_checks=%zu rejected_collisions=%zu gripper=robotiq-2f140 "
         "width_m=%.2f top_score_mug=%.4f top_score_box=%.4f peak_reset=%s base_rss_mb=%.1f "
         "extra_peak_mb=%.1f target_max_s=%g target_max_extra_mb=%g pass=%s\n",
         D, threads, fg_voxel_grid_count(&grid), voxel_size, fg_voxel_features_n_kept(vf), steps,
         to.target_samples, train_s, (double)ts.loss, cache_s, fg_voxel_features_bytes(vf),
         fg_voxel_features_bytes(vf) / 1048576.0, field_bytes, field_bytes / 1048576.0, runs,
         n_req, p50, lo, hi, p50_field, st.candidates, st.rotations, st.poses_scored, st.poses_optimised,
         o.n_final, st.iterations, st.evaluations, N_QUERY, lookups, gb_per_s,
         st.collision_checks, st.rejected_collisions, o.width_m, top_score[TASK_MUG],
         top_score[TASK_BOX], peak_reset ? "yes" : "no", base_kb / 1024.0, extra_mb,
         TARGET_MAX_S, TARGET_MAX_EXTRA_MB, pass ? "yes" : "no");
  fflush(stdout);

  if (dump) {
    /* our figures, and each task's best pose with its cost: the peer evaluates its own cost
     * there as a check that both compute the same J */
    json_t *results = json_pack("{s:f, s:f, s:f, s:I, s:I}", "p50_s", p50, "min_s", lo,
                                "max_s", hi, "candidates", (json_int_t)st.candidates,
                                "evaluations", (json_int_t)st.evaluations);
    for (int task = 0; task < N_TASKS; task++) {
      if (!found[task]) continue;
      char key[64];
      json_t *T = json_array();
      for (int k = 0; k < 16; k++) json_array_append_new(T, json_real(top_T[task][k]));
      snprintf(key, sizeof key, "top_pose_%s", task_object[task]);
      json_object_set_new(results, key, T);
      snprintf(key, sizeof key, "top_cost_%s", task_object[task]);
      json_object_set_new(results, key, json_real(top_cost[task]));
      snprintf(key, sizeof key, "top_score_%s", task_object[task]);
      json_object_set_new(results, key, json_real(top_score[task]));
    }
    dump_inputs(dump, vf, p_gripper, Z, &o, results);
  }

  for (int task = 0; task < N_TASKS; task++) free(Z[task]);
  free(secs);
  free(secs_field);
  fg_voxel_features_free(vf);
  sg_gt_free(&gt);
  free(transforms);
  free(gt_path);
  return 0;
}
