/* F3RM's CLIP preprocessing: CLIP's transform (Resize(n_px, BICUBIC) on a PIL image,
 * ToTensor, Normalize) without its CenterCrop.
 *
 * The resize is PIL's (Pillow's Resample.c): a separable convolution, horizontal pass
 * first, with the bicubic kernel (a = -0.5) stretched by the scale factor when shrinking
 * (antialiasing), coefficients normalised to sum 1 per output pixel. On 8-bit images PIL
 * works in fixed point with 22 fractional bits and rounds each pass to 8 bits; with quantize
 * set this file does the same, integer for integer, so its output equals PIL's. Without
 * it the passes run in floating point (for float sources), clipped to [0, 1] as PIL clips. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "clip/clip.h"
#include "core/error.h"

#define PRECISION_BITS (32 - 8 - 2)
#define BICUBIC_SUPPORT 2.0

static const float CLIP_MEAN[3] = {0.48145466f, 0.4578275f, 0.40821073f};
static const float CLIP_STD[3] = {0.26862954f, 0.26130258f, 0.27577711f};

static double bicubic(double x) {
  const double a = -0.5;
  if (x < 0.0) x = -x;
  if (x < 1.0) return ((a + 2.0) * x - (a + 3.0)) * x * x + 1;
  if (x < 2.0) return (((x - 5) * x + 8) * x - 4) * a;
  return 0.0;
}

/* Filter taps from in_size samples to out_size: for output i, taps k[i * ksize + j] apply to
 * input bound[2i] + j, j < bound[2i + 1]. Returns ksize, or 0 when out of memory. */
static int coeffs(int in_size, int out_size, int **bounds, double **kk) {
  const double scale = (double)in_size / out_size;
  const double filterscale = scale < 1.0 ? 1.0 : scale;
  const double support = BICUBIC_SUPPORT * filterscale;
  const int ksize = (int)ceil(support) * 2 + 1;
  *bounds = malloc((size_t)out_size * 2 * sizeof(int));
  *kk = calloc((size_t)out_size * ksize, sizeof(double));
  if (!*bounds || !*kk) return 0;
  for (int i = 0; i < out_size; i++) {
    const double center = (i + 0.5) * scale, ss = 1.0 / filterscale;
    int lo = (int)(center - support + 0.5), hi = (int)(center + support + 0.5);
    if (lo < 0) lo = 0;
    if (hi > in_size) hi = in_size;
    hi -= lo;
    double *k = *kk + (size_t)i * ksize, sum = 0.0;
    for (int j = 0; j < hi; j++) sum += (k[j] = bicubic((j + lo - center + 0.5) * ss));
    if (sum != 0.0)
      for (int j = 0; j < hi; j++) k[j] /= sum;
    (*bounds)[2 * i] = lo;
    (*bounds)[2 * i + 1] = hi;
  }
  return ksize;
}

/* PIL's 8-bit fixed-point taps. */
static int32_t fixed_tap(double k) {
  return (int32_t)(k < 0 ? -0.5 + k * (1 << PRECISION_BITS) : 0.5 + k * (1 << PRECISION_BITS));
}

static uint8_t clip8(int32_t v) {
  v >>= PRECISION_BITS;
  return (uint8_t)(v < 0 ? 0 : (v > 255 ? 255 : v));
}

/* One pass over a [rows][cols][3] image along rows (stride 3) or columns (stride 3 * cols)
 * is what both directions share: dst sample (r, i) = sum_j k[i][j] src(r, bound + j). */
typedef struct pass {
  int ksize, *bounds;
  double *kk;
  int32_t *kfix;
} pass;

static void pass_free(pass *p) {
  free(p->bounds), free(p->kk), free(p->kfix);
}

static int pass_init(pass *p, int in_size, int out_size) {
  memset(p, 0, sizeof *p);
  p->ksize = coeffs(in_size, out_size, &p->bounds, &p->kk);
  p->kfix = p->ksize ? malloc((size_t)out_size * p->ksize * sizeof(int32_t)) : NULL;
  if (!p->kfix) {
    pass_free(p);
    return fg_fail(FG_ENOMEM, "cannot allocate resampling filters");
  }
  for (size_t i = 0; i < (size_t)out_size * p->ksize; i++) p->kfix[i] = fixed_tap(p->kk[i]);
  return 0;
}

/* Horizontal pass: src [h][sw][3] -> dst [h][dw][3]. */
static void horiz_u8(const uint8_t *src, int h, int sw, uint8_t *dst, int dw, const pass *p) {
  for (int y = 0; y < h; y++)
    for (int x = 0; x < dw; x++) {
      const int lo = p->bounds[2 * x], n = p->bounds[2 * x + 1];
      const int32_t *k = p->kfix + (size_t)x * p->ksize;
      int32_t s[3] = {1 << (PRECISION_BITS - 1), 1 << (PRECISION_BITS - 1),
                      1 << (PRECISION_BITS - 1)};
      const uint8_t *r = src + ((size_t)y * sw + lo) * 3;
      for (int j = 0; j < n; j++)
        for (int ch = 0; ch < 3; ch++) s[ch] += r[j * 3 + ch] * k[j];
      for (int ch = 0; ch < 3; ch++) dst[((size_t)y * dw + x) * 3 + ch] = clip8(s[ch]);
    }
}

/* Vertical pass: src [sh][w][3] -> dst [dh][w][3]. */
static void vert_u8(const uint8_t *src, int w, uint8_t *dst, int dh, const pass *p) {
  for (int y = 0; y < dh; y++) {
    const int lo = p->bounds[2 * y], n = p->bounds[2 * y + 1];
    const int32_t *k = p->kfix + (size_t)y * p->ksize;
    for (int x = 0; x < w * 3; x++) {
      int32_t s = 1 << (PRECISION_BITS - 1);
      for (int j = 0; j < n; j++) s += src[((size_t)(lo + j) * w) * 3 + x] * k[j];
      dst[(size_t)y * w * 3 + x] = clip8(s);
    }
  }
}

/* The bicubic kernel overshoots at edges; PIL clips each pass to the 8-bit range, and so do
 * the floating-point passes (to [0, 1]). */
static float clip01(double v) { return (float)(v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v)); }

static void horiz_f(const float *src, int h, int sw, float *dst, int dw, const pass *p) {
  for (int y = 0; y < h; y++)
    for (int x = 0; x < dw; x++) {
      const int lo = p->bounds[2 * x], n = p->bounds[2 * x + 1];
      const double *k = p->kk + (size_t)x * p->ksize;
      double s[3] = {0, 0, 0};
      const float *r = src + ((size_t)y * sw + lo) * 3;
      for (int j = 0; j < n; j++)
        for (int ch = 0; ch < 3; ch++) s[ch] += r[j * 3 + ch] * k[j];
      for (int ch = 0; ch < 3; ch++) dst[((size_t)y * dw + x) * 3 + ch] = clip01(s[ch]);
    }
}

static void vert_f(const float *src, int w, float *dst, int dh, const pass *p) {
  for (int y = 0; y < dh; y++) {
    const int lo = p->bounds[2 * y], n = p->bounds[2 * y + 1];
    const double *k = p->kk + (size_t)y * p->ksize;
    for (int x = 0; x < w * 3; x++) {
      double s = 0.0;
      for (int j = 0; j < n; j++) s += src[((size_t)(lo + j) * w) * 3 + x] * k[j];
      dst[(size_t)y * w * 3 + x] = clip01(s);
    }
  }
}

int fg_clip_preprocess(const fg_clip *c, const float *rgb, int w, int h, int quantize,
                       float **out, int *H, int *W) {
  *out = NULL;
  if (w < 1 || h < 1) return fg_fail(FG_EINVAL, "image size %dx%d is empty", w, h);
  const int S = fg_clip_get_info(c)->image_size;
  /* torchvision's Resize(int): the short side becomes S, the long one int(S * long / short). */
  const int shrt = w < h ? w : h, lng = w < h ? h : w;
  const double ln = (double)S * lng / shrt;
  if (ln > 65536.0)
    return fg_fail(FG_ERANGE, "an image of %dx%d pixels is too elongated for CLIP (aspect "
                   "ratio above %d:1)", w, h, 65536 / S);
  const int dw = w < h ? S : (int)ln, dh = w < h ? (int)ln : S;
  const size_t n_in = (size_t)w * h * 3, n_mid = (size_t)dw * h * 3, n_out = (size_t)dw * dh * 3;
  pass px = {0}, py = {0};
  float *res = malloc(3 * (size_t)dw * dh * sizeof(float));
  void *a = quantize ? malloc(n_in) : NULL;
  void *b = malloc(n_mid * (quantize ? 1 : sizeof(float)));
  void *o = malloc(n_out * (quantize ? 1 : sizeof(float)));
  int rc = res && (a || !quantize) && b && o ? 0 : fg_fail(FG_ENOMEM, "cannot allocate a %dx%d image", dw, dh);
  if (rc == 0) rc = pass_init(&px, w, dw);
  if (rc == 0) rc = pass_init(&py, h, dh);
  if (rc != 0) goto done;
  if (quantize) {
    uint8_t *src = a;
    for (size_t i = 0; i < n_in; i++) {
      const float v = rgb[i] * 255.0f + 0.5f;
      src[i] = (uint8_t)(v >= 255.0f ? 255 : (v > 0.0f ? (int)v : 0));
    }
    /* PIL skips a pass whose size does not change. */
    const uint8_t *mid = src;
    if (dw != w) {
      horiz_u8(src, h, w, b, dw, &px);
      mid = b;
    }
    const uint8_t *fin = mid;
    if (dh != h) {
      vert_u8(mid, dw, o, dh, &py);
      fin = o;
    }
    for (int y = 0; y < dh; y++)
      for (int x = 0; x < dw; x++)
        for (int ch = 0; ch < 3; ch++)
          res[((size_t)ch * dh + y) * dw + x] =
              ((float)fin[((size_t)y * dw + x) * 3 + ch] / 255.0f - CLIP_MEAN[ch]) / CLIP_STD[ch];
  } else {
    const float *mid = rgb;
    if (dw != w) {
      horiz_f(rgb, h, w, b, dw, &px);
      mid = b;
    }
    const float *fin = mid;
    if (dh != h) {
      vert_f(mid, dw, o, dh, &py);
      fin = o;
    }
    for (int y = 0; y < dh; y++)
      for (int x = 0; x < dw; x++)
        for (int ch = 0; ch < 3; ch++)
          res[((size_t)ch * dh + y) * dw + x] =
              (fin[((size_t)y * dw + x) * 3 + ch] - CLIP_MEAN[ch]) / CLIP_STD[ch];
  }
  *out = res;
  res = NULL;
  *H = dh;
  *W = dw;
done:
  pass_free(&px), pass_free(&py);
  free(res), free(a), free(b), free(o);
  return rc;
}
