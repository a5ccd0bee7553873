/* Training benchmark: trains a field on a data set in-process and reports speed, quality and
 * memory.
 *
 * Usage: bench_train --data TRANSFORMS [--threads N] [--max-side PX] [--holdout K]
 *                    [--seconds S] [--steps N] [--eval-at S1,S2,...] [--samples N]
 *                    [--workspace x0 y0 z0 x1 y1 z1] [--field-scale F] [--no-features]
 *                    [--background R G B] [--seed N] [--render-out PNG]
 *                    [--learned-background] [--depth-weight W] [--distortion-weight W]
 * Defaults: 2 threads, 400 px, holdout 10, 300 s, no step limit, eval at 60,120,300 s,
 * workspace -1.5 -1.5 -1.5 1.5 1.5 1.5 (the NeRF synthetic scenes' box), field scale 1,
 * white background, the trainer's loss weights (the depth loss acts only on frames whose data
 * set has depth maps). Held-out PSNR is measured over every pixel of the held-out frames at each
 * eval time; evaluation time is excluded from the training clock.
 * Output, key=value lines:
 *   bench=train_eval seconds=60.0 steps=... psnr=... samples_per_s=...
 *   bench=train frames=... heldout=... steps=... seconds=... samples_per_s=... rays_per_step=...
 *   samples_per_step=... psnr=... feature_dim=... depth_weight=... distortion_weight=...
 *   peak_rss_mb=...
 *   bench=train_render width=... height=... seconds=...   (held-out frame 0, timed; with
 *   --render-out it is written beside its image) */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "benchmem.h"
#include "core/error.h"
#include "field/image.h"
#include "field/model.h"
#include "field/train.h"
#include "io/dataset.h"
#include "io/image.h"

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double peak_rss_mb(void) { return bench_status_kb("VmHWM:") / 1024.0; }

int main(int argc, char **argv) {
  const char *data = NULL, *render_out = NULL;
  int threads = 2, max_side = 400, holdout = 10, features = 1, learn_bg = 0;
  double seconds = 300.0, ws[6] = {-1.5, -1.5, -1.5, 1.5, 1.5, 1.5}, scale = 1.0;
  long long max_steps = -1;
  double eval_at[16] = {60, 120, 300};
  int n_eval = 3;
  fg_train_opts opts;
  fg_train_opts_default(&opts);
  for (int i = 1; i < argc; i++) {
    const char *a = argv[i];
    const int more = i + 1 < argc;
    if (!strcmp(a, "--data") && more) data = argv[++i];
    else if (!strcmp(a, "--threads") && more) threads = atoi(argv[++i]);
    else if (!strcmp(a, "--max-side") && more) max_side = atoi(argv[++i]);
    else if (!strcmp(a, "--holdout") && more) holdout = atoi(argv[++i]);
    else if (!strcmp(a, "--seconds") && more) seconds = atof(argv[++i]);
    else if (!strcmp(a, "--steps") && more) max_steps = atoll(argv[++i]);
    else if (!strcmp(a, "--samples") && more) opts.target_samples = atoi(argv[++i]);
    else if (!strcmp(a, "--seed") && more) opts.seed = strtoull(argv[++i], NULL, 10);
    else if (!strcmp(a, "--field-scale") && more) scale = atof(argv[++i]);
    else if (!strcmp(a, "--no-features")) features = 0;
    else if (!strcmp(a, "--learned-background")) learn_bg = 1;
    else if (!strcmp(a, "--depth-weight") && more) opts.depth_weight = (float)atof(argv[++i]);
    else if (!strcmp(a, "--distortion-weight") && more)
      opts.distortion_weight = (float)atof(argv[++i]);
    else if (!strcmp(a, "--render-out") && more) render_out = argv[++i];
    else if (!strcmp(a, "--eval-at") && more) {
      n_eval = 0;
      for (char *s = argv[++i], *end; *s && n_eval < 16; s = *end ? end + 1 : end)
        eval_at[n_eval++] = strtod(s, &end);
    } else if (!strcmp(a, "--workspace") && i + 6 < argc) {
      for (int k = 0; k < 6; k++) ws[k] = atof(argv[++i]);
    } else if (!strcmp(a, "--background") && i + 3 < argc) {
      for (int k = 0; k < 3; k++) opts.background[k] = (float)atof(argv[++i]);
    } else {
      fprintf(stderr, "usage: see the comment at the top of bench_train.c (bad '%s')\n", a);
      return 2;
    }
  }
  if (!data) {
    fprintf(stderr, "bench_train: --data TRANSFORMS is required\n");
    return 2;
  }
  fg_ingest_opts io = {.background_rgb = {opts.background[0], opts.background[1],
                                          opts.background[2]},
                       .max_image_side = max_side};
  fg_frame *frames;
  size_t n;
  double t0 = now_s();
  if (fg_dataset_load(data, &io, threads, &frames, &n) != 0) {
    fprintf(stderr, "bench_train: %s\n", fg_error_detail());
    return 1;
  }
  const double load_s = now_s() - t0;
  int D = 0;
  if (features)
    for (size_t i = 0; i < n; i++)
      if (frames[i].feat_d) D = frames[i].feat_d;
  if (!D)
    for (size_t i = 0; i < n; i++) frames[i].feat_d = 0;
  fg_field_config cfg;
  fg_field *f;
  fg_trainer *t;
  opts.n_threads = threads;
  opts.holdout_every = holdout;
  if (fg_field_config_for_workspace(&cfg, ws, ws + 3, scale, D) != 0 ||
      (cfg.learn_background = learn_bg, fg_field_new(&f, &cfg, opts.seed)) != 0 || fg_trainer_new(&t, f, frames, n, &opts) != 0) {
    fprintf(stderr, "bench_train: %s\n", fg_error_detail());
    return 1;
  }
  printf("bench=train_load frames=%zu heldout=%zu load_s=%.2f feature_dim=%d params=%zu\n", n,
         fg_trainer_n_heldout(t), load_s, D, f->n_params);
  fflush(stdout);
  double train_s = 0.0, samples = 0.0, rays = 0.0, psnr = NAN;
  long long steps = 0;
  int next_eval = 0;
  fg_train_stats st = {0};
  while (train_s < seconds && (max_steps < 0 || steps < max_steps)) {
    const double s0 = now_s();
    if (fg_trainer_step(t, &st) != 0) {
      fprintf(stderr, "bench_train: step %lld: %s\n", steps + 1, fg_error_detail());
      return 1;
    }
    train_s += now_s() - s0;
    steps++;
    samples += st.samples;
    rays += st.rays;
    if (steps % 50 == 0) {
      printf("bench=train_progress steps=%lld seconds=%.1f loss=%.5f loss_feat=%.5f rays=%d "
             "samples=%d occupancy=%.3f\n", steps, train_s, st.loss, st.loss_feat, st.rays,
             st.samples, st.occupancy);
      fflush(stdout);
    }
    if (next_eval < n_eval && train_s >= eval_at[next_eval]) {
      fg_trainer_eval(t, 1, &psnr);
      printf("bench=train_eval seconds=%.1f steps=%lld psnr=%.3f samples_per_s=%.0f\n", train_s,
             steps, psnr, samples / train_s);
      fflush(stdout);
      next_eval++;
    }
  }
  if (fg_trainer_n_heldout(t)) fg_trainer_eval(t, 1, &psnr);
  printf("bench=train frames=%zu heldout=%zu threads=%d steps=%lld seconds=%.2f "
         "samples_per_s=%.0f rays_per_step=%.0f samples_per_step=%.0f psnr=%.3f "
         "feature_dim=%d depth_weight=%g distortion_weight=%g peak_rss_mb=%.1f\n",
         n, fg_trainer_n_heldout(t), threads, steps, train_s, samples / train_s, rays / steps,
         samples / steps, psnr, D, (double)opts.depth_weight, (double)opts.distortion_weight,
         peak_rss_mb());
  double render_s = NAN;
  int render_w = 0, render_h = 0;
  if (holdout > 0) {
    /* Held-out frame 0: a timed render, written beside its image with --render-out. */
    const fg_frame *fr = &frames[0];
    const int w = fr->cam.w, h = fr->cam.h;
    float *rgb = malloc((size_t)w * h * 3 * sizeof(float));
    float *pair = malloc((size_t)w * h * 6 * sizeof(float));
    const double r0 = now_s();
    if (rgb && pair &&
        fg_field_render_camera(f, fr->T_world_cam, &fr->cam, opts.background, rgb, NULL, NULL,
                               NULL, threads) == 0) {
      render_s = now_s() - r0;
      render_w = w;
      render_h = h;
      for (int v = 0; v < h; v++)
        for (int u = 0; u < w; u++)
          for (int c = 0; c < 3; c++) {
            pair[((size_t)v * 2 * w + u) * 3 + c] = rgb[((size_t)v * w + u) * 3 + c];
            pair[((size_t)v * 2 * w + w + u) * 3 + c] =
                fr->rgb[((size_t)v * w + u) * 3 + c] / 65535.0f;
          }
      if (render_out) fg_image_write_file(render_out, pair, 2 * w, h, 3);
    }
    free(pair);
    free(rgb);
  }
  printf("bench=train_render width=%d height=%d seconds=%.3f\n", render_w, render_h, render_s);
  fg_trainer_free(t);
  fg_field_free(f);
  fg_dataset_free(frames, n);
  return 0;
}
