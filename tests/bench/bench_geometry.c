/* Geometry benchmark (issue 13): a scenegen tabletop with depth maps (RGB-D views), trained
 * in-process with and without the depth loss, with and without the distortion loss, side by
 * side in one run on the same data, threads and steps. For each variant: held-out PSNR over
 * every pixel of the held-out views, the geometry numbers of tests/scenegen/geomeval.h (depth
 * error on object and table pixels, cavity points free, container IoU with the cavity
 * counted), training samples/s and seconds.
 *
 * Usage: bench_geometry --scenegen PROGRAM [--steps N] [--views N] [--width W --height H]
 *                       [--threads N] [--samples N] [--variants LIST] [--seed N]
 *                       [--depth-weight W] [--distortion-weight W] [--depth-margin M]
 * Defaults: 2000 steps, 36 views at 240x180 (every 10th held out), 2 threads, the trainer's
 * 2^17 samples per step, variants none,distortion,depth,depth+distortion, seed 0, depth
 * weight FG_TRAIN_DEPTH_WEIGHT and distortion weight 0.01 where a variant uses them.
 * Output: one line per variant, e.g.
 *   bench=geometry variant=depth steps=2000 psnr_db=... depth_object_median_mm=... */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "field/model.h"
#include "field/train.h"
#include "geomeval.h"
#include "gt.h"
#include "io/dataset.h"

static const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};

static int run_variant(const char *variant, const char *dir, const sg_gt *gt,
                       const fg_frame *frames, size_t n, int steps, int threads, int samples,
                       float depth_w, float dist_w, float margin) {
  const int use_depth = strstr(variant, "depth") != NULL;
  const int use_dist = strstr(variant, "distortion") != NULL;
  fg_field_config cfg;
  fg_field *f = NULL;
  fg_trainer *t = NULL;
  int rc = fg_field_config_for_workspace(&cfg, ws_min, ws_max, 2.0, gt->feature_dim);
  if (rc == 0) rc = fg_field_new(&f, &cfg, 1);
  fg_train_opts o;
  fg_train_opts_default(&o);
  o.n_threads = threads;
  o.holdout_every = 10;
  if (samples) o.target_samples = samples;
  o.depth_weight = use_depth ? depth_w : 0.0f;
  o.distortion_weight = use_dist ? dist_w : 0.0f;
  if (margin > 0.0f) o.depth_margin = margin;
  memcpy(o.background, gt->background_rgb, sizeof o.background);
  if (rc == 0) rc = fg_trainer_new(&t, f, frames, n, &o);
  fg_train_stats st = {0};
  double samples_total = 0.0;
  const double t0 = fg_mono_s();
  for (int s = 0; rc == 0 && s < steps; s++) {
    rc = fg_trainer_step(t, &st);
    samples_total += st.samples;
  }
  const double train_s = fg_mono_s() - t0;
  double psnr = NAN;
  if (rc == 0) rc = fg_trainer_eval(t, 1, &psnr);
  sg_geom_eval ev;
  if (rc == 0) rc = sg_geom_evaluate(gt, dir, f, frames, n, 10, threads, &ev);
  if (rc == 0)
    printf("bench=geometry variant=%s steps=%d views=%zu threads=%d samples_per_step=%d "
           "depth_weight=%g distortion_weight=%g depth_margin=%g train_s=%.1f samples_per_s=%.0f "
           "psnr_db=%.2f depth_object_median_mm=%.2f depth_object_p90_mm=%.2f "
           "depth_table_median_mm=%.2f object_px=%zu %s_cavity_free=%.3f %s_cavity_points=%zu "
           "%s_cavity_free=%.3f %s_cavity_points=%zu %s_iou=%.3f %s_iou=%.3f\n",
           variant, steps, n, threads, o.target_samples, (double)o.depth_weight,
           (double)o.distortion_weight, (double)o.depth_margin, train_s, samples_total / train_s, psnr,
           ev.depth_object_median_mm, ev.depth_object_p90_mm, ev.depth_table_median_mm,
           ev.n_object_px, gt->objects[ev.container[0]].name, ev.cavity_free[0],
           gt->objects[ev.container[0]].name, ev.cavity_points[0],
           gt->objects[ev.container[1]].name, ev.cavity_free[1],
           gt->objects[ev.container[1]].name, ev.cavity_points[1],
           gt->objects[ev.container[0]].name, ev.iou[0], gt->objects[ev.container[1]].name,
           ev.iou[1]);
  for (int k = 0; rc == 0 && k < ev.n_objects; k++)
    printf("bench=geometry_solid variant=%s object=%s solid_recall=%.3f\n", variant,
           gt->objects[k].name, ev.solid_recall[k]);
  if (rc) fprintf(stderr, "bench_geometry: %s: %s\n", variant, fg_error_detail());
  fflush(stdout);
  fg_trainer_free(t);
  fg_field_free(f);
  return rc;
}

int main(int argc, char **argv) {
  const char *scenegen = NULL, *variants = "none,distortion,depth,depth+distortion";
  int steps = 2000, views = 36, width = 240, height = 180, threads = 2, samples = 0;
  const char *seed = "0";
  float depth_w = (float)FG_TRAIN_DEPTH_WEIGHT, dist_w = 0.01f, margin = 0.0f;
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!v) {
      fprintf(stderr, "bench_geometry: %s needs a value\n", a);
      return 2;
    }
    i++;
    if (!strcmp(a, "--scenegen")) scenegen = v;
    else if (!strcmp(a, "--steps")) steps = atoi(v);
    else if (!strcmp(a, "--views")) views = atoi(v);
    else if (!strcmp(a, "--width")) width = atoi(v);
    else if (!strcmp(a, "--height")) height = atoi(v);
    else if (!strcmp(a, "--threads")) threads = atoi(v);
    else if (!strcmp(a, "--samples")) samples = atoi(v);
    else if (!strcmp(a, "--variants")) variants = v;
    else if (!strcmp(a, "--seed")) seed = v;
    else if (!strcmp(a, "--depth-weight")) depth_w = (float)atof(v);
    else if (!strcmp(a, "--distortion-weight")) dist_w = (float)atof(v);
    else if (!strcmp(a, "--depth-margin")) margin = (float)atof(v);
    else {
      fprintf(stderr, "bench_geometry: unknown option %s\n", a);
      return 2;
    }
  }
  if (!scenegen || steps < 1 || views < 11 || threads < 1) {
    fprintf(stderr, "usage: bench_geometry --scenegen PROGRAM [--steps N] [--views N >= 11] "
                    "[--width W --height H] [--threads N] [--samples N] [--variants LIST] "
                    "[--seed N] [--depth-weight W] [--distortion-weight W]\n");
    return 2;
  }
  char tmpl[] = "/tmp/bench_geometry.XXXXXX";
  const char *dir = mkdtemp(tmpl);
  if (!dir) return 1;
  char cmd[1024];
  snprintf(cmd, sizeof cmd, "'%s' --out '%s' --seed %s --views %d --width %d --height %d "
           "--dim 32 --patch 4 --holdout 0 --depth png > /dev/null", scenegen, dir, seed, views,
           width, height);
  int rc = system(cmd) == 0 ? 0 : fg_fail(FG_EIO, "%s failed", scenegen);
  char *tf = fg_path_join(dir, "transforms.json"), *gtp = fg_path_join(dir, "gt.json");
  sg_gt gt = {0};
  fg_frame *frames = NULL;
  size_t n = 0;
  if (rc == 0) rc = sg_gt_load(gtp, &gt);
  if (rc == 0) {
    fg_ingest_opts io = {.background_rgb = {gt.background_rgb[0], gt.background_rgb[1],
                                            gt.background_rgb[2]}};
    rc = fg_dataset_load(tf, &io, threads, &frames, &n);
  }
  char list[256];
  snprintf(list, sizeof list, "%s", variants);
  for (char *save = NULL, *v = strtok_r(list, ",", &save); rc == 0 && v;
       v = strtok_r(NULL, ",", &save))
    rc = run_variant(v, dir, &gt, frames, n, steps, threads, samples, depth_w, dist_w, margin);
  if (rc) fprintf(stderr, "bench_geometry: %s\n", fg_error_detail());
  fg_dataset_free(frames, n);
  if (gt.objects) sg_gt_free(&gt);
  fg_rmtree(dir);
  free(tf);
  free(gtp);
  return rc ? 1 : 0;
}
