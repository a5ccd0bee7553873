/* Helpers of the CLIP integration tests: tiny random weights written with clipgen, the real
 * vocabulary, and the library's own results computed in the test process, which the daemon's
 * answers over HTTP must equal. Like the harness, every helper asserts. */
#ifndef FG_IT_CLIP_UTIL_H
#define FG_IT_CLIP_UTIL_H

#include "clipgen.h"
#include "harness.h"

/* Writes clipgen's tiny model (embedding 24, image 32, patch 8) with naming, dtype and seed to
 * path (atomically: clipgen renames a temp file over it). */
void c_write_model(const char *path, clipgen_naming naming, clipgen_dtype dtype, uint64_t seed);

/* $FG_SHARED_DATA/clip/bpe_simple_vocab_16e6.txt.gz; caller frees. */
char *c_vocab_path(void);

/* The [clip] configuration text for weights and vocab, plus [train] threads = 2 and, when
 * imports is not NULL, [state] import_dirs. Caller frees. */
char *c_config(const char *weights, const char *vocab, const char *imports);

/* The embedding dimension of the model at weights. */
int c_embed_dim(const char *weights);

/* The text embedding of text as the library computes it in this process: out [E]. */
void c_local_text(const char *weights, const char *vocab, const char *text, int truncate,
                  float *out);

/* Dense features of an encoded image decoded here (white background) and preprocessed as
 * F3RM does: a malloc'd [*hp][*wp][E]. */
float *c_local_dense(const char *weights, const void *image, size_t len, int *hp, int *wp);

/* Dense features of an RGB image already decoded: rgb [h][w][3] in [0, 1]. */
float *c_local_dense_rgb(const char *weights, const float *rgb, int w, int h, int *hp, int *wp);

/* The pooled embedding of an encoded image: F3RM preprocessing, then the centre crop at
 * (left, top), which the caller works out as torchvision's CenterCrop would. out [E]. */
void c_local_pooled(const char *weights, const void *image, size_t len, int left, int top,
                    float *out);

/* A JSON array of numbers as a malloc'd float array; asserts the length when n >= 0, else
 * stores it in *len. */
float *c_floats(json_t *arr, int n, int *len);

/* Largest |a[i] - b[i]|. */
double c_max_diff(const float *a, const float *b, size_t n);

/* Asserts |a[i] - b[i]| <= tol for all i, naming what and the worst index. */
void c_assert_close_at(const char *file, int line, const float *a, const float *b, size_t n,
                       double tol, const char *what);
#define C_ASSERT_CLOSE(a, b, n, tol, what) \
  c_assert_close_at(__FILE__, __LINE__, (a), (b), (n), (tol), (what))

#endif
