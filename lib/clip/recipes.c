/* CLIP's recipes (recipes.h). */
#include "clip/recipes.h"
#include "core/error.h"
#include "core/norm.h"
#include "io/image.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Whether s holds nothing but ASCII whitespace. */
static int blank(const char *s) {
  for (; *s; s++)
    if (*s != ' ' && *s != '\t' && *s != '\n' && *s != '\r' && *s != '\f' && *s != '\v') return 0;
  return 1;
}

int fg_clip_embed_texts(fg_clip *clip, const fg_tokenizer *tok, const char *const *texts, int n,
                        int truncate, int normalize, float *out, int *bad) {
  if (bad) *bad = -1;
  if (n < 1 || n > FG_CLIP_MAX_TEXTS)
    return fg_fail(FG_EINVAL, "give 1 to %d texts, not %d", FG_CLIP_MAX_TEXTS, n);
  const fg_clip_info *info = fg_clip_get_info(clip);
  const int ctx = info->context_length, E = info->embed_dim;
  int32_t *ids = malloc((size_t)n * (size_t)ctx * sizeof *ids);
  if (!ids) return fg_fail(FG_ENOMEM, "out of memory");
  int rc = 0;
  for (int i = 0; i < n && rc == 0; i++) {
    size_t len = strlen(texts[i]);
    if (blank(texts[i]))
      rc = fg_fail(FG_EINVAL, "the text is empty; give the words to embed");
    else if (len > FG_CLIP_MAX_TEXT_BYTES)
      rc = fg_fail(FG_EINVAL, "the text is %zu bytes long; the limit is %d (and CLIP reads "
                   "only the first %d tokens)", len, FG_CLIP_MAX_TEXT_BYTES, ctx - 2);
    else
      rc = fg_tokenizer_encode(tok, texts[i], ctx, truncate, ids + (size_t)i * ctx, NULL);
    if (rc != 0 && bad) *bad = i;
  }
  if (rc == 0) rc = fg_clip_text(clip, ids, n, out);
  for (int i = 0; rc == 0 && normalize && i < n; i++) {
    if (fg_l2_normalize(out + (size_t)i * E, E) != 0) {
      rc = fg_fail(FG_EINVAL, "its embedding has norm 0 and cannot be normalised");
      if (bad) *bad = i;
    }
  }
  free(ids);
  return rc;
}

/* The size [H][W] F3RM's resize gives a w x h image (clip.h, fg_clip_preprocess), in 64
 * bits: an extreme aspect ratio makes the long side huge. */
static void resized(int S, int w, int h, int64_t *H, int64_t *W) {
  if (w <= h) {
    *W = S;
    *H = (int64_t)((double)S * h / w);
  } else {
    *H = S;
    *W = (int64_t)((double)S * w / h);
  }
}

int fg_clip_image_grid(const fg_clip *clip, int w, int h, int *hp, int *wp) {
  const fg_clip_info *info = fg_clip_get_info(clip);
  if (w < 1 || h < 1) return fg_fail(FG_EINVAL, "the image is %dx%d pixels", w, h);
  int64_t H, W;
  resized(info->image_size, w, h, &H, &W);
  int64_t gh = H / info->patch_size, gw = W / info->patch_size;
  if (gh * gw > FG_CLIP_MAX_PATCHES)
    return fg_fail(FG_ERANGE, "a %dx%d image becomes a %lldx%lld grid of CLIP patches, more "
                   "than the %d this server computes; crop it to an aspect ratio nearer 1:1", w,
                   h, (long long)gw, (long long)gh, FG_CLIP_MAX_PATCHES);
  return fg_clip_dense_grid(clip, (int)H, (int)W, hp, wp);
}

int fg_clip_dense_features(fg_clip *clip, const float *rgb, int w, int h, float **out, int *hp,
                           int *wp) {
  *out = NULL;
  const fg_clip_info *info = fg_clip_get_info(clip);
  FG_TRY(fg_clip_image_grid(clip, w, h, hp, wp)); /* before the resize allocates */
  float *x = NULL;
  int H, W;
  FG_TRY(fg_clip_preprocess(clip, rgb, w, h, 1, &x, &H, &W));
  int rc = fg_clip_dense_grid(clip, H, W, hp, wp);
  float *f = NULL;
  if (rc == 0) {
    f = malloc((size_t)*hp * (size_t)*wp * (size_t)info->embed_dim * sizeof *f);
    rc = f ? fg_clip_image_dense(clip, x, 1, H, W, f) : fg_fail(FG_ENOMEM, "out of memory");
  }
  free(x);
  if (rc != 0) {
    free(f);
    return rc;
  }
  *out = f;
  return 0;
}

/* Python's round() of x / 2 for a whole x >= 0: half to even. */
static int half_even(int x) {
  int q = x / 2;
  return (x % 2 == 1 && q % 2 == 1) ? q + 1 : q;
}

int fg_clip_pooled_embedding(fg_clip *clip, const float *rgb, int w, int h, float *out) {
  const fg_clip_info *info = fg_clip_get_info(clip);
  const int S = info->image_size;
  int64_t H64, W64;
  if (w < 1 || h < 1) return fg_fail(FG_EINVAL, "the image is %dx%d pixels", w, h);
  resized(S, w, h, &H64, &W64);
  if (H64 * W64 > (int64_t)FG_IMAGE_MAX_PIXELS)
    return fg_fail(FG_ERANGE, "a %dx%d image resized to a short side of %d would be %lldx%lld "
                   "pixels; crop it to an aspect ratio nearer 1:1", w, h, S, (long long)W64,
                   (long long)H64);
  float *x = NULL;
  int H, W;
  FG_TRY(fg_clip_preprocess(clip, rgb, w, h, 1, &x, &H, &W));
  if (H < S || W < S) {
    free(x);
    return fg_fail(FG_EINVAL, "the preprocessed image is %dx%d, smaller than the %dx%d crop",
                   W, H, S, S);
  }
  /* x [3][H][W] -> crop [3][S][S] at (top, left) */
  float *crop = malloc((size_t)3 * S * S * sizeof *crop);
  if (!crop) {
    free(x);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  int top = half_even(H - S), left = half_even(W - S);
  for (int c = 0; c < 3; c++)
    for (int y = 0; y < S; y++)
      memcpy(crop + ((size_t)c * S + y) * S, x + ((size_t)c * H + top + y) * W + left,
             (size_t)S * sizeof *crop);
  free(x);
  int rc = fg_clip_image_pooled(clip, crop, 1, out);
  free(crop);
  return rc;
}
