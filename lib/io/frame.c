/* Training frames: ingest (decode, undistort, downscale, quantise) and the .fgf file format.
 *
 * The file is written and read field by field in little-endian, so its layout does not depend
 * on the compiler's struct packing or the host's byte order; the struct below only documents
 * the layout and gives every field its offset. */
#include "io/frame.h"
#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "core/pose.h"
#include "io/image.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <zlib.h>

#define FRAME_MAGIC "FGFRAME\0"

struct fg_frame_file_header {
  char magic[8];                /*   0: "FGFRAME\0" */
  uint32_t version;             /*   8: FG_FRAME_VERSION */
  uint32_t header_size;         /*  12: FG_FRAME_HEADER_SIZE, lets a later version grow it */
  double T_world_cam[16];       /*  16: camera-to-world, OpenGL convention, metres */
  double fl_x, fl_y, cx, cy;    /* 144: pinhole intrinsics of the stored image, pixels */
  int32_t w, h;                 /* 176: stored image size */
  int32_t model;                /* 184: always FG_CAMERA_PINHOLE in version 1 */
  int32_t src_w, src_h;         /* 188: size as received */
  int32_t undistorted;          /* 196: 0 or 1 */
  int64_t created_ms;           /* 200: Unix time, milliseconds */
  int32_t feat_h, feat_w;       /* 208: feature grid, 0 when absent */
  int32_t feat_d, feat_dtype;   /* 216: fg_dtype */
  char source[FG_FRAME_SOURCE_MAX]; /* 224: NUL-terminated */
  int32_t depth_w, depth_h;     /* 480: depth map, 0 when absent (version 2) */
  double depth_valid;           /* 488: share of valid depth pixels (version 2) */
  int64_t capture;              /* 496: the frame's capture (version 3) */
  int32_t has_robot_pose;       /* 504: 0 or 1 (version 3) */
  int32_t pad;                  /* 508: zero */
  double T_world_tcp[16];       /* 512: the robot's TCP pose, world frame (version 3) */
  uint8_t reserved[384];        /* 640: zero */
};
_Static_assert(sizeof(struct fg_frame_file_header) == FG_FRAME_HEADER_SIZE,
               "the frame header must be exactly FG_FRAME_HEADER_SIZE bytes");
_Static_assert(offsetof(struct fg_frame_file_header, created_ms) == 200, "header layout");
_Static_assert(offsetof(struct fg_frame_file_header, source) == 224, "header layout");
_Static_assert(offsetof(struct fg_frame_file_header, depth_valid) == 488, "header layout");
_Static_assert(offsetof(struct fg_frame_file_header, capture) == 496, "header layout");
_Static_assert(offsetof(struct fg_frame_file_header, T_world_tcp) == 512, "header layout");
_Static_assert(offsetof(struct fg_frame_file_header, reserved) == 640, "header layout");

/* The header's size in versions 1 and 2: everything before `capture`. */
#define HEADER_SIZE_V2 512

#define HOFF(field) offsetof(struct fg_frame_file_header, field)

/* ---- little-endian field access ----------------------------------------------------- */

static void put_u32(uint8_t *p, uint32_t v) {
  for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void put_u64(uint8_t *p, uint64_t v) {
  for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void put_f64(uint8_t *p, double d) {
  uint64_t v;
  memcpy(&v, &d, sizeof v);
  put_u64(p, v);
}
static uint32_t get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static uint64_t get_u64(const uint8_t *p) {
  return (uint64_t)get_u32(p) | (uint64_t)get_u32(p + 4) << 32;
}
static double get_f64(const uint8_t *p) {
  uint64_t v = get_u64(p);
  double d;
  memcpy(&d, &v, sizeof d);
  return d;
}

static int host_is_le(void) {
  const uint16_t one = 1;
  uint8_t b;
  memcpy(&b, &one, 1);
  return b == 1;
}

/* Serialises the header struct into its FG_FRAME_HEADER_SIZE on-disk bytes. */
static void header_encode(const struct fg_frame_file_header *h, uint8_t b[FG_FRAME_HEADER_SIZE]) {
  memset(b, 0, FG_FRAME_HEADER_SIZE);
  memcpy(b + HOFF(magic), h->magic, 8);
  put_u32(b + HOFF(version), h->version);
  put_u32(b + HOFF(header_size), h->header_size);
  for (int i = 0; i < 16; i++) put_f64(b + HOFF(T_world_cam) + 8 * (size_t)i, h->T_world_cam[i]);
  put_f64(b + HOFF(fl_x), h->fl_x);
  put_f64(b + HOFF(fl_y), h->fl_y);
  put_f64(b + HOFF(cx), h->cx);
  put_f64(b + HOFF(cy), h->cy);
  put_u32(b + HOFF(w), (uint32_t)h->w);
  put_u32(b + HOFF(h), (uint32_t)h->h);
  put_u32(b + HOFF(model), (uint32_t)h->model);
  put_u32(b + HOFF(src_w), (uint32_t)h->src_w);
  put_u32(b + HOFF(src_h), (uint32_t)h->src_h);
  put_u32(b + HOFF(undistorted), (uint32_t)h->undistorted);
  put_u64(b + HOFF(created_ms), (uint64_t)h->created_ms);
  put_u32(b + HOFF(feat_h), (uint32_t)h->feat_h);
  put_u32(b + HOFF(feat_w), (uint32_t)h->feat_w);
  put_u32(b + HOFF(feat_d), (uint32_t)h->feat_d);
  put_u32(b + HOFF(feat_dtype), (uint32_t)h->feat_dtype);
  memcpy(b + HOFF(source), h->source, sizeof h->source);
  put_u32(b + HOFF(depth_w), (uint32_t)h->depth_w);
  put_u32(b + HOFF(depth_h), (uint32_t)h->depth_h);
  put_f64(b + HOFF(depth_valid), h->depth_valid);
  put_u64(b + HOFF(capture), (uint64_t)h->capture);
  put_u32(b + HOFF(has_robot_pose), (uint32_t)h->has_robot_pose);
  for (int i = 0; i < 16; i++) put_f64(b + HOFF(T_world_tcp) + 8 * (size_t)i, h->T_world_tcp[i]);
}

static void header_decode(const uint8_t b[FG_FRAME_HEADER_SIZE], struct fg_frame_file_header *h) {
  memset(h, 0, sizeof *h);
  memcpy(h->magic, b + HOFF(magic), 8);
  h->version = get_u32(b + HOFF(version));
  h->header_size = get_u32(b + HOFF(header_size));
  for (int i = 0; i < 16; i++) h->T_world_cam[i] = get_f64(b + HOFF(T_world_cam) + 8 * (size_t)i);
  h->fl_x = get_f64(b + HOFF(fl_x));
  h->fl_y = get_f64(b + HOFF(fl_y));
  h->cx = get_f64(b + HOFF(cx));
  h->cy = get_f64(b + HOFF(cy));
  h->w = (int32_t)get_u32(b + HOFF(w));
  h->h = (int32_t)get_u32(b + HOFF(h));
  h->model = (int32_t)get_u32(b + HOFF(model));
  h->src_w = (int32_t)get_u32(b + HOFF(src_w));
  h->src_h = (int32_t)get_u32(b + HOFF(src_h));
  h->undistorted = (int32_t)get_u32(b + HOFF(undistorted));
  h->created_ms = (int64_t)get_u64(b + HOFF(created_ms));
  h->feat_h = (int32_t)get_u32(b + HOFF(feat_h));
  h->feat_w = (int32_t)get_u32(b + HOFF(feat_w));
  h->feat_d = (int32_t)get_u32(b + HOFF(feat_d));
  h->feat_dtype = (int32_t)get_u32(b + HOFF(feat_dtype));
  memcpy(h->source, b + HOFF(source), sizeof h->source);
  h->source[sizeof h->source - 1] = '\0';
  h->depth_w = (int32_t)get_u32(b + HOFF(depth_w));
  h->depth_h = (int32_t)get_u32(b + HOFF(depth_h));
  h->depth_valid = get_f64(b + HOFF(depth_valid));
  if (h->version < 3) return; /* the bytes beyond HEADER_SIZE_V2 are not the header's */
  h->capture = (int64_t)get_u64(b + HOFF(capture));
  h->has_robot_pose = (int32_t)get_u32(b + HOFF(has_robot_pose));
  for (int i = 0; i < 16; i++) h->T_world_tcp[i] = get_f64(b + HOFF(T_world_tcp) + 8 * (size_t)i);
}

/* ---- sizes -------------------------------------------------------------------------- */

static size_t rgb_bytes(const fg_frame *f) { return (size_t)f->cam.w * (size_t)f->cam.h * 3 * 2; }

static size_t feat_bytes(const fg_frame *f) {
  if (f->feat_d == 0) return 0;
  return (size_t)f->feat_h * (size_t)f->feat_w * (size_t)f->feat_d * fg_dtype_size(f->feat_dtype);
}

static size_t depth_bytes(const fg_frame *f) {
  return (size_t)f->depth_w * (size_t)f->depth_h * sizeof(float);
}

/* Checks the declared sizes of a frame (from a header or from a caller) against the limits,
 * so that the byte counts computed from them cannot overflow. */
static int check_frame_sizes(const fg_frame *f) {
  if ((f->depth_w || f->depth_h) && (f->depth_w != f->cam.w || f->depth_h != f->cam.h))
    return fg_fail(FG_EFORMAT, "depth map %dx%d is not the image's size %dx%d", f->depth_w,
                   f->depth_h, f->cam.w, f->cam.h);
  if (!(f->depth_valid >= 0.0 && f->depth_valid <= 1.0))
    return fg_fail(FG_EFORMAT, "depth valid fraction %g is outside [0, 1]", f->depth_valid);
  if (f->cam.w <= 0 || f->cam.h <= 0 || f->cam.w > FG_IMAGE_MAX_SIDE ||
      f->cam.h > FG_IMAGE_MAX_SIDE ||
      (size_t)f->cam.w * (size_t)f->cam.h > (size_t)FG_IMAGE_MAX_PIXELS)
    return fg_fail(FG_EFORMAT, "image size %dx%d is outside the supported range", f->cam.w,
                   f->cam.h);
  if (f->feat_d == 0) {
    if (f->feat_h != 0 || f->feat_w != 0 || f->feat_dtype != FG_DTYPE_NONE)
      return fg_fail(FG_EFORMAT, "feature grid is %dx%d with depth 0", f->feat_h, f->feat_w);
    return 0;
  }
  if (f->feat_dtype != FG_DTYPE_F32 && f->feat_dtype != FG_DTYPE_F16)
    return fg_fail(FG_EFORMAT, "unknown feature dtype %d", (int)f->feat_dtype);
  if (f->feat_d < 0 || f->feat_d > FG_FRAME_MAX_FEAT_D || f->feat_h <= 0 || f->feat_w <= 0 ||
      f->feat_h > FG_IMAGE_MAX_SIDE || f->feat_w > FG_IMAGE_MAX_SIDE)
    return fg_fail(FG_EFORMAT, "feature grid [%d, %d, %d] is outside the supported range",
                   f->feat_h, f->feat_w, f->feat_d);
  return 0;
}

/* ---- ingest ------------------------------------------------------------------------- */

static int value_is_finite(fg_dtype t, const void *data, size_t i) {
  if (t == FG_DTYPE_F16) {
    uint16_t h;
    memcpy(&h, (const uint8_t *)data + 2 * i, 2);
    return (h & 0x7c00) != 0x7c00;
  }
  uint32_t u;
  memcpy(&u, (const uint8_t *)data + 4 * i, 4);
  return (u & 0x7f800000u) != 0x7f800000u;
}

int fg_frame_check_features(const fg_npy *features) {
  if (!features) return fg_fail(FG_EINVAL, "no features given");
  if (features->ndim != 3)
    return fg_fail(FG_EINVAL, "features must have shape [h, w, D]; got %d dimensions",
                   features->ndim);
  if (features->dtype != FG_DTYPE_F32 && features->dtype != FG_DTYPE_F16)
    return fg_fail(FG_EINVAL, "features must be float32 or float16");
  size_t fh = features->shape[0], fw = features->shape[1], fd = features->shape[2];
  if (fh == 0 || fw == 0 || fh > FG_IMAGE_MAX_SIDE || fw > FG_IMAGE_MAX_SIDE)
    return fg_fail(FG_EINVAL, "features grid is %zux%zu; each side must be 1..%d", fh, fw,
                   FG_IMAGE_MAX_SIDE);
  if (fd == 0 || fd > FG_FRAME_MAX_FEAT_D)
    return fg_fail(FG_EINVAL, "features have D = %zu; D must be 1..%d", fd, FG_FRAME_MAX_FEAT_D);
  size_t n = fh * fw * fd;
  if (features->count != n || !features->data)
    return fg_fail(FG_EINVAL, "features hold %zu values but their shape says %zu",
                   features->count, n);
  for (size_t i = 0; i < n; i++)
    if (!value_is_finite(features->dtype, features->data, i))
      return fg_fail(FG_EINVAL,
                     "features contain a NaN or infinite value at [%zu, %zu, %zu]; send finite "
                     "numbers",
                     i / (fw * fd), i / fd % fw, i % fd);
  return 0;
}

/* Copies checked features into f, aligned and owned, in their own dtype. */
static int features_copy(fg_frame *f, const fg_npy *features) {
  size_t bytes = features->count * fg_dtype_size(features->dtype);
  f->feat = malloc(bytes);
  if (!f->feat) return fg_fail(FG_ENOMEM, "out of memory copying %zu bytes of features", bytes);
  memcpy(f->feat, features->data, bytes);
  f->feat_h = (int)features->shape[0];
  f->feat_w = (int)features->shape[1];
  f->feat_d = (int)features->shape[2];
  f->feat_dtype = features->dtype;
  return 0;
}

/* Resamples the feature grid f->feat ([fh][fw][D], fg_dtype) through the undistortion that
 * turned dist (W x H) into pin (same size): each output cell centre, in undistorted pixels,
 * is taken through pin back to normalised coordinates, distorted, and projected by dist into
 * the source grid, which is sampled bilinearly with edge clamping. Sums run in double so that
 * a constant grid stays exactly constant after rounding back to the stored type. */
static int features_undistort(fg_frame *f, const fg_camera *dist, const fg_camera *pin) {
  int fh = f->feat_h, fw = f->feat_w, D = f->feat_d;
  size_t n = (size_t)fh * (size_t)fw * (size_t)D;
  float *src = NULL, *dst = malloc(n * sizeof(float));
  if (f->feat_dtype == FG_DTYPE_F16) {
    src = malloc(n * sizeof(float));
    if (src) fg_half_to_float_n(f->feat, src, n);
  } else {
    src = f->feat;
  }
  if (!src || !dst) {
    if (src != f->feat) free(src);
    free(dst);
    return fg_fail(FG_ENOMEM, "out of memory resampling features");
  }
  double W = dist->w, H = dist->h;
  for (int i = 0; i < fh; i++) {
    for (int j = 0; j < fw; j++) {
      double u = (j + 0.5) * W / fw, v = (i + 0.5) * H / fh;
      double x = (u - pin->cx) / pin->fl_x, y = (v - pin->cy) / pin->fl_y, xd, yd;
      fg_camera_distort_normalized(dist, x, y, &xd, &yd);
      double gx = (dist->fl_x * xd + dist->cx) * fw / W - 0.5;
      double gy = (dist->fl_y * yd + dist->cy) * fh / H - 0.5;
      gx = fmin(fmax(gx, 0.0), fw - 1.0); /* fmin/fmax also tame a NaN from a wild lens */
      gy = fmin(fmax(gy, 0.0), fh - 1.0);
      int x0 = (int)gx, y0 = (int)gy;
      int x1 = x0 + 1 < fw ? x0 + 1 : x0, y1 = y0 + 1 < fh ? y0 + 1 : y0;
      double tx = gx - x0, ty = gy - y0;
      const float *a = src + ((size_t)y0 * (size_t)fw + (size_t)x0) * (size_t)D;
      const float *b = src + ((size_t)y0 * (size_t)fw + (size_t)x1) * (size_t)D;
      const float *c = src + ((size_t)y1 * (size_t)fw + (size_t)x0) * (size_t)D;
      const float *d = src + ((size_t)y1 * (size_t)fw + (size_t)x1) * (size_t)D;
      float *o = dst + ((size_t)i * (size_t)fw + (size_t)j) * (size_t)D;
      for (int k = 0; k < D; k++) {
        double top = a[k] + tx * ((double)b[k] - a[k]);
        double bot = c[k] + tx * ((double)d[k] - c[k]);
        o[k] = (float)(top + ty * (bot - top));
      }
    }
  }
  if (f->feat_dtype == FG_DTYPE_F16) {
    fg_float_to_half_n(dst, f->feat, n);
    free(src);
    free(dst);
  } else {
    free(f->feat);
    f->feat = dst;
  }
  return 0;
}

/* From decoded pixels to the stored frame: undistort (pixels and features), downscale,
 * quantise. rgb is float [h][w][3] and only read; every step writes a new buffer, so the
 * caller's image needs no copy. cam (sized w x h) becomes the stored pinhole camera. */
static int image_pipeline(fg_frame *out, const float *rgb, int w, int h, fg_camera *cam,
                          int max_side) {
  float *owned = NULL; /* the latest intermediate image, when there is one */
  const float *cur = rgb;
  if (cam->model == FG_CAMERA_OPENCV && fg_camera_is_distorted(cam)) {
    float *und = malloc((size_t)w * (size_t)h * 3 * sizeof(float));
    if (!und) return fg_fail(FG_ENOMEM, "out of memory undistorting a %dx%d image", w, h);
    fg_camera pin;
    int rc = fg_image_undistort(cur, cam, und, &pin);
    if (rc == 0 && out->feat) rc = features_undistort(out, cam, &pin);
    if (rc < 0) {
      free(und);
      return rc;
    }
    cur = owned = und;
    *cam = pin;
    out->undistorted = 1;
  }
  cam->model = FG_CAMERA_PINHOLE;
  cam->k1 = cam->k2 = cam->k3 = cam->p1 = cam->p2 = 0;

  int longest = w > h ? w : h;
  if (max_side > 0 && longest > max_side) {
    double s = (double)max_side / longest;
    int nw = (int)lround(w * s), nh = (int)lround(h * s);
    if (nw < 1) nw = 1;
    if (nh < 1) nh = 1;
    float *small = malloc((size_t)nw * (size_t)nh * 3 * sizeof(float));
    int rc = small ? fg_image_resize_area(cur, w, h, 3, small, nw, nh)
                   : fg_fail(FG_ENOMEM, "out of memory downscaling to %dx%d", nw, nh);
    free(owned);
    if (rc < 0) {
      free(small);
      return rc;
    }
    cur = owned = small;
    double sx = (double)nw / w, sy = (double)nh / h;
    cam->fl_x *= sx;
    cam->cx *= sx;
    cam->fl_y *= sy;
    cam->cy *= sy;
    cam->w = w = nw;
    cam->h = h = nh;
  }

  size_t n = (size_t)w * (size_t)h * 3;
  out->rgb = malloc(n * sizeof(uint16_t));
  if (!out->rgb) {
    free(owned);
    return fg_fail(FG_ENOMEM, "out of memory for a %dx%d frame", w, h);
  }
  for (size_t i = 0; i < n; i++) {
    float v = cur[i];
    v = !(v > 0.0f) ? 0.0f : v > 1.0f ? 1.0f : v; /* comparisons: fminf is a libm call */
    out->rgb[i] = (uint16_t)(v * 65535.0f + 0.5f);
  }
  free(owned);
  return 0;
}

/* Checks a depth map's values: NaN is invalid (read as 0), negative or infinite is an error. */
static int depth_check_values(const fg_depth_map *d) {
  for (int v = 0; v < d->h; v++)
    for (int u = 0; u < d->w; u++) {
      const float z = d->m[(size_t)v * (size_t)d->w + (size_t)u];
      if (!isnan(z) && !(z >= 0.0f && isfinite(z)))
        return fg_fail(FG_EINVAL, "depth pixel [row %d, column %d] is %g m; depth must be finite "
                                  "and >= 0 metres (0 or NaN where the camera has no value)",
                       v, u, (double)z);
    }
  return 0;
}

/* Resamples depth d of the image as received (camera src, sized to the image) onto the
 * stored camera dst by nearest sampling: each stored pixel's centre goes to undistorted
 * normalised coordinates, through src's distortion, to the received image's pixels and so
 * to the depth pixel under it. Outside the map: invalid. */
static int depth_resample(fg_frame *out, const fg_depth_map *d, const fg_camera *src,
                          const fg_camera *dst) {
  const int W = dst->w, H = dst->h;
  float *m = malloc((size_t)W * (size_t)H * sizeof *m);
  if (!m) return fg_fail(FG_ENOMEM, "out of memory for a %dx%d depth map", W, H);
  const int distorted = src->model == FG_CAMERA_OPENCV && fg_camera_is_distorted(src);
  size_t valid = 0;
  for (int v = 0; v < H; v++)
    for (int u = 0; u < W; u++) {
      double x = (u + 0.5 - dst->cx) / dst->fl_x, y = (v + 0.5 - dst->cy) / dst->fl_y;
      if (distorted) fg_camera_distort_normalized(src, x, y, &x, &y);
      const double du = (src->fl_x * x + src->cx) * d->w / src->w;
      const double dv = (src->fl_y * y + src->cy) * d->h / src->h;
      float z = 0.0f;
      if (du >= 0.0 && dv >= 0.0 && du < d->w && dv < d->h) { /* false for NaN too */
        z = d->m[(size_t)dv * (size_t)d->w + (size_t)du];
        if (isnan(z)) z = 0.0f;
      }
      m[(size_t)v * (size_t)W + (size_t)u] = z;
      valid += z > 0.0f;
    }
  out->depth = m;
  out->depth_w = W;
  out->depth_h = H;
  out->depth_valid = (double)valid / ((double)W * (double)H);
  return 0;
}

/* The checks of fg_frame_prepare that need no pixels, so that a bad pose or feature file
 * costs no image decode; copies the features into out. */
static int prepare_inputs(fg_frame *out, const fg_camera *cam, const double T_world_cam[16],
                          const fg_npy *features, const fg_ingest_opts *opts) {
  if (!cam || !T_world_cam || !opts)
    return fg_fail(FG_EINVAL, "frame ingest: camera, pose and options are required");
  if (opts->max_image_side < 0)
    return fg_fail(FG_EINVAL, "max_image_side must be 0 (keep) or positive, got %d",
                   opts->max_image_side);
  FG_TRY(fg_pose_validate(T_world_cam));
  if (features) {
    FG_TRY(fg_frame_check_features(features));
    FG_TRY(features_copy(out, features));
  }
  return 0;
}

/* The rest of the ingest once the pixels are known: camera against image size, then the
 * image pipeline. */
static int prepare_pixels(fg_frame *out, const fg_image *img, const fg_camera *cam,
                          const double T_world_cam[16], const fg_depth_map *depth,
                          const fg_ingest_opts *opts) {
  fg_camera c = *cam;
  if (c.w == 0) c.w = img->w;
  if (c.h == 0) c.h = img->h;
  if (c.w != img->w || c.h != img->h)
    return fg_fail(FG_EINVAL, "camera says %dx%d but the image is %dx%d; fix w and h or send "
                              "the image the intrinsics belong to",
                   c.w, c.h, img->w, img->h);
  FG_TRY(fg_camera_validate(&c));
  if (depth) {
    if (!depth->m) return fg_fail(FG_EINVAL, "depth map without values");
    FG_TRY(fg_depth_check_grid(depth->w, depth->h, img->w, img->h));
    FG_TRY(depth_check_values(depth));
  }
  const fg_camera received = c;
  out->src_w = img->w;
  out->src_h = img->h;
  FG_TRY(image_pipeline(out, img->rgb, img->w, img->h, &c, opts->max_image_side));
  if (depth) FG_TRY(depth_resample(out, depth, &received, &c));
  memcpy(out->T_world_cam, T_world_cam, 16 * sizeof(double));
  out->cam = c;
  out->created_ms = fg_real_ms();
  return 0;
}

/* fg_frame_prepare, the one frame function that decodes, is in image_codec.c: this file stays
 * free of OpenImageIO so that the daemon, which decodes in a child process, links without it. */

int fg_frame_prepare_image(fg_frame *out, const fg_image *img, const fg_camera *cam,
                           const double T_world_cam[16], const fg_npy *features,
                           const fg_ingest_opts *opts) {
  return fg_frame_prepare_image_depth(out, img, cam, T_world_cam, features, NULL, opts);
}

int fg_frame_prepare_image_depth(fg_frame *out, const fg_image *img, const fg_camera *cam,
                                 const double T_world_cam[16], const fg_npy *features,
                                 const fg_depth_map *depth, const fg_ingest_opts *opts) {
  if (!out) return fg_fail(FG_EINVAL, "fg_frame_prepare_image: no output frame");
  memset(out, 0, sizeof *out);
  if (!img || !img->rgb || img->w <= 0 || img->h <= 0)
    return fg_fail(FG_EINVAL, "fg_frame_prepare_image: no decoded image given");
  int rc = prepare_inputs(out, cam, T_world_cam, features, opts);
  if (rc == 0) rc = prepare_pixels(out, img, cam, T_world_cam, depth, opts);
  if (rc < 0) fg_frame_clear(out);
  return rc;
}

void fg_frame_clear(fg_frame *frame) {
  if (!frame) return;
  free(frame->rgb);
  free(frame->feat);
  free(frame->depth);
  memset(frame, 0, sizeof *frame);
}

/* ---- save --------------------------------------------------------------------------- */

/* Writes n elements of `size` bytes (1, 2 or 4) little-endian, updating the CRC. On a
 * little-endian host that is the memory as is; elsewhere it goes through a swap buffer. */
static int write_le(FILE *fp, const void *data, size_t n, size_t size, uLong *crc) {
  const uint8_t *p = data;
  if (size == 1 || host_is_le()) {
    size_t bytes = n * size;
    if (bytes && fwrite(p, 1, bytes, fp) != bytes) return -1;
    *crc = crc32_z(*crc, p, bytes);
    return 0;
  }
  uint8_t buf[4096];
  size_t per = sizeof buf / size;
  for (size_t i = 0; i < n; i += per) {
    size_t m = n - i < per ? n - i : per;
    for (size_t e = 0; e < m; e++)
      for (size_t k = 0; k < size; k++) buf[e * size + k] = p[(i + e) * size + size - 1 - k];
    if (fwrite(buf, 1, m * size, fp) != m * size) return -1;
    *crc = crc32_z(*crc, buf, m * size);
  }
  return 0;
}

int fg_frame_save(const fg_frame *f, const char *path) {
  if (!f || !path || !f->rgb) return fg_fail(FG_EINVAL, "fg_frame_save: no frame, pixels or path");
  if (check_frame_sizes(f) < 0) {
    char why[256];
    snprintf(why, sizeof why, "%s", fg_error_detail());
    return fg_fail(FG_EINVAL, "cannot save frame to %s: %s", path, why);
  }
  if (f->feat_d > 0 && !f->feat) return fg_fail(FG_EINVAL, "cannot save frame: features missing");
  if (f->depth_w > 0 && !f->depth) return fg_fail(FG_EINVAL, "cannot save frame: depth missing");
  if (f->cam.model != FG_CAMERA_PINHOLE || fg_camera_is_distorted(&f->cam))
    return fg_fail(FG_EINVAL, "cannot save frame to %s: its camera must be the undistorted "
                              "PINHOLE one that fg_frame_prepare produces",
                   path);
  FG_TRY(fg_camera_validate(&f->cam));
  if (f->capture < 0)
    return fg_fail(FG_EINVAL, "cannot save frame to %s: capture %lld is negative", path,
                   (long long)f->capture);
  if (f->has_robot_pose && fg_pose_validate(f->T_world_tcp) != 0) {
    char why[256];
    snprintf(why, sizeof why, "%s", fg_error_detail());
    return fg_fail(FG_EINVAL, "cannot save frame to %s: its robot pose is invalid (%s)", path,
                   why);
  }

  struct fg_frame_file_header h;
  memset(&h, 0, sizeof h);
  memcpy(h.magic, FRAME_MAGIC, 8);
  h.version = FG_FRAME_VERSION;
  h.header_size = FG_FRAME_HEADER_SIZE;
  memcpy(h.T_world_cam, f->T_world_cam, sizeof h.T_world_cam);
  h.fl_x = f->cam.fl_x;
  h.fl_y = f->cam.fl_y;
  h.cx = f->cam.cx;
  h.cy = f->cam.cy;
  h.w = f->cam.w;
  h.h = f->cam.h;
  h.model = FG_CAMERA_PINHOLE;
  h.src_w = f->src_w;
  h.src_h = f->src_h;
  h.undistorted = f->undistorted ? 1 : 0;
  h.created_ms = f->created_ms;
  h.feat_h = f->feat_h;
  h.feat_w = f->feat_w;
  h.feat_d = f->feat_d;
  h.feat_dtype = (int32_t)f->feat_dtype;
  memcpy(h.source, f->source, sizeof h.source);
  h.source[sizeof h.source - 1] = '\0';
  h.depth_w = f->depth_w;
  h.depth_h = f->depth_h;
  h.depth_valid = f->depth_valid;
  h.capture = f->capture;
  h.has_robot_pose = f->has_robot_pose ? 1 : 0;
  if (f->has_robot_pose) memcpy(h.T_world_tcp, f->T_world_tcp, sizeof h.T_world_tcp);
  uint8_t hb[FG_FRAME_HEADER_SIZE];
  header_encode(&h, hb);

  fg_atomic_file af;
  FG_TRY(fg_atomic_file_open(&af, path));
  uLong crc = crc32_z(0L, Z_NULL, 0);
  size_t esize = fg_dtype_size(f->feat_dtype);
  size_t nfeat = esize ? feat_bytes(f) / esize : 0;
  if (write_le(af.fp, hb, sizeof hb, 1, &crc) < 0 ||
      write_le(af.fp, f->rgb, rgb_bytes(f) / 2, 2, &crc) < 0 ||
      (nfeat > 0 && write_le(af.fp, f->feat, nfeat, esize, &crc) < 0) ||
      (f->depth_w > 0 &&
       write_le(af.fp, f->depth, depth_bytes(f) / sizeof(float), sizeof(float), &crc) < 0)) {
    int e = errno;
    fg_atomic_file_abort(&af);
    return fg_fail(fg_io_error(e), "writing %s failed: %s", path, strerror(e));
  }
  uint8_t cb[4];
  put_u32(cb, (uint32_t)crc);
  if (fwrite(cb, 1, 4, af.fp) != 4) {
    int e = errno;
    fg_atomic_file_abort(&af);
    return fg_fail(fg_io_error(e), "writing %s failed: %s", path, strerror(e));
  }
  return fg_atomic_file_commit(&af);
}

/* ---- load --------------------------------------------------------------------------- */

static void swap_in_place(void *data, size_t n, size_t size) {
  if (host_is_le() || size == 1) return;
  uint8_t *p = data;
  for (size_t i = 0; i < n; i++)
    for (size_t k = 0; k < size / 2; k++) {
      uint8_t t = p[i * size + k];
      p[i * size + k] = p[i * size + size - 1 - k];
      p[i * size + size - 1 - k] = t;
    }
}

/* Opens path, reads and checks its header and the file's length, and fills out's scalar
 * fields. On success *fpp is open at the first pixel byte, hb holds the raw header and
 * *hb_len its size (512 bytes before version 3). */
static int open_and_read_header(const char *path, fg_frame *out, FILE **fpp,
                                uint8_t hb[FG_FRAME_HEADER_SIZE], size_t *hb_len) {
  memset(out, 0, sizeof *out);
  *fpp = NULL;
  FILE *fp = fopen(path, "rb");
  if (!fp) {
    int e = errno;
    return fg_fail(e == ENOENT ? FG_ENOENT : FG_EIO, "cannot open frame file %s: %s", path,
                   strerror(e));
  }
  struct stat st;
  if (fstat(fileno(fp), &st) != 0 || !S_ISREG(st.st_mode)) {
    fclose(fp);
    return fg_fail(FG_EIO, "%s is not a regular file", path);
  }
  int rc;
  if (fread(hb, 1, HEADER_SIZE_V2, fp) != HEADER_SIZE_V2) {
    rc = fg_fail(FG_EFORMAT, "frame file %s is truncated: it is shorter than its header", path);
    goto error;
  }
  const uint32_t version = get_u32(hb + HOFF(version));
  const uint32_t header_size = get_u32(hb + HOFF(header_size));
  if (memcmp(hb + HOFF(magic), FRAME_MAGIC, 8) != 0) {
    rc = fg_fail(FG_EFORMAT, "%s is not a fieldgrip frame file (bad magic)", path);
    goto error;
  }
  if (version < 1 || version > FG_FRAME_VERSION ||
      header_size != (version < 3 ? HEADER_SIZE_V2 : FG_FRAME_HEADER_SIZE)) {
    rc = fg_fail(FG_EFORMAT, "frame file %s has version %u (header %u bytes); this build reads "
                             "versions 1 to %d",
                 path, version, header_size, FG_FRAME_VERSION);
    goto error;
  }
  if (header_size > HEADER_SIZE_V2 &&
      fread(hb + HEADER_SIZE_V2, 1, header_size - HEADER_SIZE_V2, fp) !=
        header_size - HEADER_SIZE_V2) {
    rc = fg_fail(FG_EFORMAT, "frame file %s is truncated: it is shorter than its header", path);
    goto error;
  }
  struct fg_frame_file_header h;
  header_decode(hb, &h);
  memcpy(out->T_world_cam, h.T_world_cam, sizeof out->T_world_cam);
  out->cam.fl_x = h.fl_x;
  out->cam.fl_y = h.fl_y;
  out->cam.cx = h.cx;
  out->cam.cy = h.cy;
  out->cam.w = h.w;
  out->cam.h = h.h;
  out->cam.model = FG_CAMERA_PINHOLE;
  out->src_w = h.src_w;
  out->src_h = h.src_h;
  out->undistorted = h.undistorted != 0;
  out->created_ms = h.created_ms;
  out->feat_h = h.feat_h;
  out->feat_w = h.feat_w;
  out->feat_d = h.feat_d;
  out->feat_dtype = (fg_dtype)h.feat_dtype;
  memcpy(out->source, h.source, sizeof out->source);
  if (h.version >= 2) {
    out->depth_w = h.depth_w;
    out->depth_h = h.depth_h;
    out->depth_valid = h.depth_valid;
  }
  out->capture = h.version >= 3 ? h.capture : 1;
  out->has_robot_pose = h.has_robot_pose != 0;
  if (out->has_robot_pose) memcpy(out->T_world_tcp, h.T_world_tcp, sizeof out->T_world_tcp);
  const int pose_bad = out->has_robot_pose && fg_pose_validate(out->T_world_tcp) != 0;
  if (h.model != FG_CAMERA_PINHOLE || check_frame_sizes(out) < 0 ||
      fg_camera_validate(&out->cam) < 0 || out->capture < 0 || pose_bad ||
      (h.has_robot_pose != 0 && h.has_robot_pose != 1)) {
    char why[256];
    snprintf(why, sizeof why, "%s", fg_error_detail());
    if (out->capture < 0)
      snprintf(why, sizeof why, "capture %lld", (long long)out->capture);
    else if (h.has_robot_pose != 0 && h.has_robot_pose != 1)
      snprintf(why, sizeof why, "robot pose flag %d", (int)h.has_robot_pose);
    else if (pose_bad)
      snprintf(why, sizeof why, "robot pose: %s", fg_error_detail());
    if (h.model != FG_CAMERA_PINHOLE) snprintf(why, sizeof why, "camera model %d", h.model);
    rc = fg_fail(FG_EFORMAT, "frame file %s has an invalid header (%s)", path, why);
    goto error;
  }
  size_t want = header_size + rgb_bytes(out) + feat_bytes(out) + depth_bytes(out) + 4;
  if ((unsigned long long)st.st_size != want) {
    rc = fg_fail(FG_EFORMAT, "frame file %s is %lld bytes but its header declares %zu; it is %s",
                 path, (long long)st.st_size, want,
                 (size_t)st.st_size < want ? "truncated" : "followed by stray bytes");
    goto error;
  }
  *fpp = fp;
  *hb_len = header_size;
  return 0;
error:
  fclose(fp);
  memset(out, 0, sizeof *out);
  return rc;
}

int fg_frame_load_header(const char *path, fg_frame *out) {
  if (!path || !out) return fg_fail(FG_EINVAL, "fg_frame_load_header: null argument");
  FILE *fp;
  uint8_t hb[FG_FRAME_HEADER_SIZE];
  size_t hb_len;
  FG_TRY(open_and_read_header(path, out, &fp, hb, &hb_len));
  fclose(fp);
  return 0;
}

int fg_frame_load(const char *path, fg_frame *out) {
  if (!path || !out) return fg_fail(FG_EINVAL, "fg_frame_load: null argument");
  FILE *fp;
  uint8_t hb[FG_FRAME_HEADER_SIZE];
  size_t hb_len;
  FG_TRY(open_and_read_header(path, out, &fp, hb, &hb_len));
  int rc = 0;
  size_t nrgb = rgb_bytes(out), nfeat = feat_bytes(out), ndepth = depth_bytes(out);
  out->rgb = malloc(nrgb);
  if (nfeat) out->feat = malloc(nfeat);
  if (ndepth) out->depth = malloc(ndepth);
  if (!out->rgb || (nfeat && !out->feat) || (ndepth && !out->depth)) {
    rc = fg_fail(FG_ENOMEM, "out of memory loading frame %s", path);
    goto error;
  }
  uint8_t cb[4];
  if (fread(out->rgb, 1, nrgb, fp) != nrgb || (nfeat && fread(out->feat, 1, nfeat, fp) != nfeat) ||
      (ndepth && fread(out->depth, 1, ndepth, fp) != ndepth) || fread(cb, 1, 4, fp) != 4) {
    rc = fg_fail(FG_EFORMAT, "frame file %s is truncated (it shrank while being read)", path);
    goto error;
  }
  uLong crc = crc32_z(0L, Z_NULL, 0);
  crc = crc32_z(crc, hb, hb_len);
  crc = crc32_z(crc, (const Bytef *)out->rgb, nrgb);
  if (nfeat) crc = crc32_z(crc, out->feat, nfeat);
  if (ndepth) crc = crc32_z(crc, (const Bytef *)out->depth, ndepth);
  if ((uint32_t)crc != get_u32(cb)) {
    rc = fg_fail(FG_EFORMAT, "frame file %s is corrupt: CRC mismatch (stored %08x, computed "
                             "%08x); delete the frame and upload it again",
                 path, get_u32(cb), (uint32_t)crc);
    goto error;
  }
  swap_in_place(out->rgb, nrgb / 2, 2);
  size_t esize = fg_dtype_size(out->feat_dtype);
  if (nfeat) swap_in_place(out->feat, nfeat / esize, esize);
  if (ndepth) swap_in_place(out->depth, ndepth / sizeof(float), sizeof(float));
  fclose(fp);
  return 0;
error:
  fclose(fp);
  fg_frame_clear(out);
  return rc;
}
