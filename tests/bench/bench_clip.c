/* CLIP throughput: dense MaskCLIP features per second at 224x224 and at a 640x360 frame
 * (preprocessed to 224x398), text embeddings per second, against OpenBLAS's SGEMM rate on
 * the same machine, and the peak resident memory beside the weights' size.
 *
 *   bench_clip WEIGHTS.safetensors [--threads N] [--seconds S] [--batch B]
 *
 * Prints one line of key=value pairs:
 *   bench=clip dtype=F32 weights_mb=570.8 threads=2 ... dense224_images_per_s=5.05
 *   dense224_gflops=165.9 ... sgemm2048_gflops=198.0 dense224_of_sgemm=0.84 ...
 * Each figure is the rate over at least S seconds (default 10) after one warm-up call. */
#include <cblas.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "benchmem.h"
#include "clip/clip.h"
#include "core/error.h"

void openblas_set_num_threads(int n);

static double now_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void *xmalloc(size_t n) {
  void *p = malloc(n);
  if (!p) {
    fprintf(stderr, "bench_clip: out of memory (%zu bytes)\n", n);
    exit(1);
  }
  return p;
}

static float *random_f(size_t n, uint64_t seed) {
  float *p = xmalloc(n * sizeof(float));
  for (size_t i = 0; i < n; i++) {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    p[i] = (float)(seed >> 40) * 0x1p-23f - 1.0f;
  }
  return p;
}

static double sgemm_gflops(int threads) {
  const int n = 2048;
  float *a = random_f((size_t)n * n, 1), *b = random_f((size_t)n * n, 2);
  float *c = xmalloc((size_t)n * n * sizeof(float));
  openblas_set_num_threads(threads);
  double best = 1e30;
  for (int r = 0; r < 4; r++) {
    const double t0 = now_s();
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, n, n, 1.0f, a, n, b, n, 0.0f, c,
                n);
    const double t = now_s() - t0;
    if (r > 0 && t < best) best = t;
  }
  free(a), free(b), free(c);
  return 2.0 * n * n * (double)n / best * 1e-9;
}

/* FLOPs of one transformer block over T tokens of width w (attention included). */
static double block_flops(double T, double w) {
  return 2 * T * w * 3 * w + 4 * T * T * w + 2 * T * w * w + 16 * T * w * w;
}

/* FLOPs of one dense image of hp x wp patches. */
static double dense_flops(const fg_clip_info *in, int hp, int wp) {
  const double np = (double)hp * wp, T = np + 1, w = in->vision_width, p = in->patch_size;
  return 2 * np * 3 * p * p * w + (in->vision_layers - 1) * block_flops(T, w) + 4 * T * w * w +
         2 * np * w * in->embed_dim;
}

static double text_flops(const fg_clip_info *in, int T) {
  return in->text_layers * block_flops(T, in->text_width) + 2.0 * in->text_width * in->embed_dim;
}

/* Calls run() until S seconds have passed (after a warm-up call); returns calls per second. */
typedef int (*run_fn)(fg_clip *c, void *ud);

static double rate(fg_clip *c, run_fn run, void *ud, double seconds) {
  if (run(c, ud) != 0) {
    fprintf(stderr, "bench_clip: %s\n", fg_error_detail());
    exit(1);
  }
  int n = 0;
  const double t0 = now_s();
  double t = t0;
  while (t - t0 < seconds || n < 2) {
    if (run(c, ud) != 0) exit(1);
    n++;
    t = now_s();
  }
  return n / (t - t0);
}

typedef struct dense_job {
  const float *x;
  int n, H, W;
  float *out;
} dense_job;

static int run_dense(fg_clip *c, void *ud) {
  dense_job *j = ud;
  return fg_clip_image_dense(c, j->x, j->n, j->H, j->W, j->out);
}

typedef struct text_job {
  const int32_t *ids;
  int n;
  float *out;
} text_job;

static int run_text(fg_clip *c, void *ud) {
  text_job *j = ud;
  return fg_clip_text(c, j->ids, j->n, j->out);
}

int main(int argc, char **argv) {
  if (argc < 2 || argv[1][0] == '-') {
    fprintf(stderr, "usage: bench_clip WEIGHTS.safetensors [--threads N] [--seconds S] "
                    "[--batch B]\n");
    return 2;
  }
  int threads = 2, batch = 1;
  double seconds = 10.0;
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!strcmp(argv[i], "--threads")) threads = atoi(argv[i + 1]);
    else if (!strcmp(argv[i], "--seconds")) seconds = atof(argv[i + 1]);
    else if (!strcmp(argv[i], "--batch")) batch = atoi(argv[i + 1]);
    else {
      fprintf(stderr, "bench_clip: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  /* The machine's SGEMM rate: the better of a measurement before and one after the rest, so
   * that a moment of load on a shared machine does not flatter the ratios. */
  double sgemm = sgemm_gflops(threads);
  bench_reset_peak();
  const long rss0 = bench_status_kb("VmRSS:");
  const double t_load = now_s();
  fg_clip *c;
  if (fg_clip_load(&c, argv[1]) != 0) {
    fprintf(stderr, "bench_clip: %s\n", fg_error_detail());
    return 1;
  }
  const double load_s = now_s() - t_load;
  fg_clip_set_threads(c, threads);
  const fg_clip_info *in = fg_clip_get_info(c);
  const int S = in->image_size, p = in->patch_size, E = in->embed_dim;
  printf("bench=clip dtype=%s weights_mb=%.1f threads=%d batch=%d load_s=%.2f", in->dtype,
         in->weights_bytes / 1048576.0, threads, batch, load_s);

  /* 224x224 and a 640x360 frame at short side 224 (224 x 398 pixels, 14 x 24 patches). */
  const int sizes[2][2] = {{S, S}, {S, (int)((double)S * 640 / 360)}};
  const char *names[2] = {"dense224", "dense640x360"};
  double dense_gf[2];
  for (int k = 0; k < 2; k++) {
    const int H = sizes[k][0], W = sizes[k][1], hp = H / p, wp = W / p;
    float *x = random_f((size_t)batch * 3 * H * W, 7 + k);
    float *out = xmalloc((size_t)batch * hp * wp * E * sizeof(float));
    dense_job j = {x, batch, H, W, out};
    const double ips = rate(c, run_dense, &j, seconds) * batch;
    dense_gf[k] = ips * dense_flops(in, hp, wp) * 1e-9;
    printf(" %s_input=%dx%d %s_images_per_s=%.3f %s_gflops=%.1f", names[k], W, H, names[k], ips,
           names[k], dense_gf[k]);
    free(x), free(out);
  }

  /* Text: a batch of 8 phrases of a few words (the usual query), and 8 contexts filled to
   * the end (what a full-length run costs). */
  const int ctx = in->context_length, n_text = 8;
  int32_t *ids = xmalloc((size_t)n_text * ctx * sizeof(int32_t));
  float *temb = xmalloc((size_t)n_text * E * sizeof(float));
  for (int full = 0; full < 2; full++) {
    const int len = full ? ctx : 6;
    memset(ids, 0, (size_t)n_text * ctx * sizeof(int32_t));
    for (int q = 0; q < n_text; q++) {
      int32_t *r = ids + (size_t)q * ctx;
      r[0] = in->vocab_size - 2 > 0 ? in->vocab_size - 2 : 0;
      for (int t = 1; t < len - 1; t++) r[t] = (320 + 37 * q + 11 * t) % (in->vocab_size - 2);
      r[len - 1] = in->vocab_size - 1;
    }
    text_job j = {ids, n_text, temb};
    const double tps = rate(c, run_text, &j, seconds / 2) * n_text;
    printf(" text%d_per_s=%.1f text%d_gflops=%.1f", len, tps, len,
           tps * text_flops(in, len) * 1e-9);
  }
  free(ids), free(temb);

  const long hwm = bench_status_kb("VmHWM:");
  const double sgemm_after = sgemm_gflops(threads);
  if (sgemm_after > sgemm) sgemm = sgemm_after;
  printf(" sgemm2048_gflops=%.1f", sgemm);
  for (int k = 0; k < 2; k++) printf(" %s_of_sgemm=%.2f", names[k], dense_gf[k] / sgemm);
  printf(" rss_before_load_mb=%.1f peak_rss_mb=%.1f peak_over_weights_mb=%.1f\n", rss0 / 1024.0,
         hwm / 1024.0, (hwm - rss0) / 1024.0 - in->weights_bytes / 1048576.0);
  fg_clip_free(c);
  return 0;
}
