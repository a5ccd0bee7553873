/* Helpers of the CLIP integration tests; see clip_util.h. */
#include "clip_util.h"

#include "clip/clip.h"
#include "clip/tokenizer.h"
#include "core/error.h"
#include "io/image.h"

#include <math.h>

void c_write_model(const char *path, clipgen_naming naming, clipgen_dtype dtype, uint64_t seed) {
  clipgen_cfg cfg;
  ASSERT_OK(clipgen_cfg_preset(&cfg, CLIPGEN_TINY));
  cfg.naming = naming;
  cfg.dtype = dtype;
  cfg.seed = seed;
  ASSERT_OK(clipgen_write(path, &cfg, NULL));
}

char *c_vocab_path(void) {
  char *data = h_shared_data();
  char *p = h_fmt("%s/clip/bpe_simple_vocab_16e6.txt.gz", data);
  free(data);
  return p;
}

char *c_config(const char *weights, const char *vocab, const char *imports) {
  char *state = imports ? h_fmt("[state]\nimport_dirs = %s\n\n", imports) : h_fmt("%s", "");
  char *s = h_fmt("%s[clip]\nweights = %s\nvocab = %s\n\n[train]\nthreads = 2\n", state,
                  weights, vocab);
  free(state);
  return s;
}

static fg_clip *load(const char *weights) {
  fg_clip *c = NULL;
  ASSERT_OK(fg_clip_load(&c, weights));
  fg_clip_set_threads(c, 2);
  return c;
}

int c_embed_dim(const char *weights) {
  fg_clip *c = load(weights);
  int E = fg_clip_get_info(c)->embed_dim;
  fg_clip_free(c);
  return E;
}

void c_local_text(const char *weights, const char *vocab, const char *text, int truncate,
                  float *out) {
  fg_clip *c = load(weights);
  fg_tokenizer *tok = NULL;
  ASSERT_OK(fg_tokenizer_load(&tok, vocab));
  int ctx = fg_clip_get_info(c)->context_length;
  int32_t *ids = calloc((size_t)ctx, sizeof *ids);
  ASSERT(ids);
  ASSERT_OK(fg_tokenizer_encode(tok, text, ctx, truncate, ids, NULL));
  ASSERT_OK(fg_clip_text(c, ids, 1, out));
  free(ids);
  fg_tokenizer_free(tok);
  fg_clip_free(c);
}

float *c_local_dense_rgb(const char *weights, const float *rgb, int w, int h, int *hp, int *wp) {
  fg_clip *c = load(weights);
  float *x = NULL;
  int H, W;
  ASSERT_OK(fg_clip_preprocess(c, rgb, w, h, 1, &x, &H, &W));
  ASSERT_OK(fg_clip_dense_grid(c, H, W, hp, wp));
  int E = fg_clip_get_info(c)->embed_dim;
  float *out = malloc((size_t)*hp * (size_t)*wp * (size_t)E * sizeof *out);
  ASSERT(out);
  ASSERT_OK(fg_clip_image_dense(c, x, 1, H, W, out));
  free(x);
  fg_clip_free(c);
  return out;
}

float *c_local_dense(const char *weights, const void *image, size_t len, int *hp, int *wp) {
  static const float white[3] = {1, 1, 1};
  fg_image img = {0};
  ASSERT_OK(fg_image_decode(image, len, white, &img));
  float *out = c_local_dense_rgb(weights, img.rgb, img.w, img.h, hp, wp);
  fg_image_release(&img);
  return out;
}

void c_local_pooled(const char *weights, const void *image, size_t len, int left, int top,
                    float *out) {
  static const float white[3] = {1, 1, 1};
  fg_image img = {0};
  ASSERT_OK(fg_image_decode(image, len, white, &img));
  fg_clip *c = load(weights);
  float *x = NULL;
  int H, W;
  ASSERT_OK(fg_clip_preprocess(c, img.rgb, img.w, img.h, 1, &x, &H, &W));
  const int S = fg_clip_get_info(c)->image_size;
  ASSERT(top + S <= H && left + S <= W);
  float *crop = malloc((size_t)3 * S * S * sizeof *crop);
  ASSERT(crop);
  for (int ch = 0; ch < 3; ch++)
    for (int y = 0; y < S; y++)
      for (int xx = 0; xx < S; xx++)
        crop[((size_t)ch * S + y) * S + xx] = x[((size_t)ch * H + top + y) * W + left + xx];
  ASSERT_OK(fg_clip_image_pooled(c, crop, 1, out));
  free(crop);
  free(x);
  fg_clip_free(c);
  fg_image_release(&img);
}

float *c_floats(json_t *arr, int n, int *len) {
  ASSERT(json_is_array(arr));
  int k = (int)json_array_size(arr);
  if (n >= 0) ASSERT_EQ(k, n);
  if (len) *len = k;
  float *v = malloc((size_t)(k ? k : 1) * sizeof *v);
  ASSERT(v);
  for (int i = 0; i < k; i++) {
    json_t *x = json_array_get(arr, (size_t)i);
    ASSERT(json_is_number(x));
    v[i] = (float)json_number_value(x);
  }
  return v;
}

double c_max_diff(const float *a, const float *b, size_t n) {
  double m = 0;
  for (size_t i = 0; i < n; i++) {
    double d = fabs((double)a[i] - (double)b[i]);
    if (!(d <= m)) m = d; /* NaN counts as the largest */
  }
  return m;
}

void c_assert_close_at(const char *file, int line, const float *a, const float *b, size_t n,
                       double tol, const char *what) {
  for (size_t i = 0; i < n; i++) {
    double d = fabs((double)a[i] - (double)b[i]);
    if (!(d <= tol)) {
      fprintf(stderr, "%s:%d: %s differ at [%zu]: %.9g vs %.9g (tol %g)\n", file, line, what, i,
              (double)a[i], (double)b[i], tol);
      exit(1);
    }
  }
}
