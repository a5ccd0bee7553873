#include "geomeval.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "gtvox.h"
#include "field/image.h"
#include "io/image.h"
#include "query/heatmap.h"

static const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};

static int cmp_double(const void *a, const void *b) {
  const double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static double percentile(double *v, size_t n, double q) {
  if (!n) return NAN;
  qsort(v, n, sizeof *v, cmp_double);
  return v[(size_t)floor(q * (double)(n - 1) + 0.5)];
}

/* The class mask of view i (mask value per pixel) into a malloc'd w x h array. */
static int read_mask(const char *dir, size_t i, int w, int h, unsigned char **out) {
  char name[64];
  snprintf(name, sizeof name, "masks/%04zu.png", i);
  char *path = fg_path_join(dir, name), *png = NULL;
  size_t len = 0;
  int rc = path ? fg_read_file(path, 1u << 26, &png, &len) : fg_fail(FG_ENOMEM, "no memory");
  free(path);
  fg_image img = {0};
  const float black[3] = {0, 0, 0};
  if (rc == 0) rc = fg_image_decode(png, len, black, &img);
  free(png);
  if (rc == 0 && (img.w != w || img.h != h))
    rc = fg_fail(FG_EFORMAT, "mask %s is %dx%d, the frame %dx%d", name, img.w, img.h, w, h);
  if (rc == 0) {
    *out = malloc((size_t)w * (size_t)h);
    if (!*out) rc = fg_fail(FG_ENOMEM, "no memory");
    for (size_t p = 0; rc == 0 && p < (size_t)w * (size_t)h; p++)
      (*out)[p] = (unsigned char)lroundf(img.rgb[3 * p] * 255.0f);
  }
  fg_image_release(&img);
  return rc;
}

static int depth_errors(const char *dir, const fg_field *f, const fg_frame *frames, size_t n,
                        int every, int nt, sg_geom_eval *out) {
  size_t cap = 0;
  for (size_t i = 0; i < n; i += (size_t)every) cap += (size_t)frames[i].cam.w * frames[i].cam.h;
  double *eo = malloc((cap ? cap : 1) * sizeof *eo), *et = malloc((cap ? cap : 1) * sizeof *et);
  size_t no = 0, ntab = 0;
  int rc = eo && et ? 0 : fg_fail(FG_ENOMEM, "no memory");
  for (size_t i = 0; rc == 0 && i < n; i += (size_t)every) {
    const fg_frame *fr = &frames[i];
    const int w = fr->cam.w, h = fr->cam.h;
    if (!fr->depth) continue; /* a data set without depth maps: no depth numbers */
    const size_t np = (size_t)w * (size_t)h;
    float *depth = malloc(np * sizeof *depth), *op = malloc(np * sizeof *op);
    unsigned char *mask = NULL;
    const float white[3] = {1, 1, 1}; /* any: only depth and opacity are read */
    rc = depth && op ? 0 : fg_fail(FG_ENOMEM, "no memory");
    if (rc == 0) rc = read_mask(dir, i, w, h, &mask);
    if (rc == 0)
      rc = fg_field_render_camera(f, fr->T_world_cam, &fr->cam, white, NULL, depth, op, NULL, nt);
    for (int v = 0; rc == 0 && v < h; v++)
      for (int u = 0; u < w; u++) {
        const size_t p = (size_t)v * (size_t)w + (size_t)u;
        const float z_gt = fr->depth[p];
        if (!(z_gt > 0.0f) || mask[p] < 1 || op[p] < 0.5f) continue;
        const double x = (u + 0.5 - fr->cam.cx) / fr->cam.fl_x;
        const double y = (v + 0.5 - fr->cam.cy) / fr->cam.fl_y;
        const double z = depth[p] / op[p] / sqrt(1.0 + x * x + y * y);
        const double e = fabs(z - z_gt) * 1e3;
        if (mask[p] >= 2) eo[no++] = e;
        else et[ntab++] = e;
      }
    free(depth);
    free(op);
    free(mask);
  }
  if (rc == 0) { /* NaN when no view had depth */
    out->n_object_px = no;
    out->n_table_px = ntab;
    out->depth_object_p90_mm = percentile(eo, no, 0.9);
    out->depth_object_median_mm = percentile(eo, no, 0.5);
    out->depth_table_median_mm = percentile(et, ntab, 0.5);
  }
  free(eo);
  free(et);
  return rc;
}

static int cavities(const sg_gt *gt, const fg_field *f, int nt, sg_geom_eval *out) {
  for (int c = 0; c < out->n_containers; c++) {
    size_t np;
    double *pts = sg_gt_cavity_points(gt, out->container[c], SG_GEOM_CLEARANCE, 0.004, &np);
    float *x = malloc((np ? np : 1) * 3 * sizeof *x), *sigma = malloc((np ? np : 1) * sizeof *sigma);
    int rc = (pts || !np) && x && sigma ? 0 : fg_fail(FG_ENOMEM, "no memory");
    for (size_t i = 0; rc == 0 && i < 3 * np; i++) x[i] = (float)pts[i];
    if (rc == 0 && np) rc = fg_field_density(f, x, (int64_t)np, sigma, nt);
    size_t free_pts = 0;
    for (size_t i = 0; rc == 0 && i < np; i++)
      free_pts += 1.0 - exp(-(double)sigma[i] * SG_GEOM_VOXEL) < FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
    out->cavity_points[c] = np;
    out->cavity_free[c] = np ? (double)free_pts / (double)np : NAN;
    free(pts);
    free(x);
    free(sigma);
    if (rc) return rc;
  }
  return 0;
}

static int container_iou(const sg_gt *gt, const fg_field *f, int nt, sg_geom_eval *out) {
  const int D = f->cfg.feature_dim;
  if (!D || gt->feature_dim != D) return 0;
  fg_voxel_grid g;
  FG_TRY(fg_voxel_grid_init(&g, ws_min, ws_max, SG_GEOM_VOXEL));
  fg_voxel_features *vf;
  FG_TRY(fg_voxel_features_build(&vf, f, &g, nt));
  const size_t N = fg_voxel_grid_count(&g);
  signed char *owner = malloc(N), *cavity = malloc(N);
  float *neg = malloc((size_t)gt->n_classes * (size_t)D * sizeof *neg);
  int rc = owner && cavity && neg ? 0 : fg_fail(FG_ENOMEM, "no memory");
  if (rc == 0) sg_gt_voxelise(gt, &g, owner, cavity);
  const float *alpha = fg_voxel_features_alpha(vf);
  out->n_objects = gt->n_objects < SG_GEOM_MAX_OBJECTS ? gt->n_objects : SG_GEOM_MAX_OBJECTS;
  for (int k = 0; rc == 0 && k < out->n_objects; k++) {
    size_t total = 0, seen = 0;
    for (size_t i = 0; i < N; i++)
      if (owner[i] == k) {
        total++;
        seen += alpha[i] >= FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
      }
    out->solid_recall[k] = total ? (double)seen / (double)total : NAN;
  }
  for (int c = 0; rc == 0 && c < out->n_containers; c++) {
    const int k = out->container[c], cls = gt->objects[k].class_id;
    int nn = 0;
    for (int j = 0; j < gt->n_classes; j++)
      if (j != cls)
        memcpy(neg + (size_t)nn++ * (size_t)D, gt->embeddings + (size_t)j * (size_t)D,
               (size_t)D * sizeof *neg);
    fg_query q;
    fg_heatmap hm;
    rc = fg_query_init(&q, D, gt->embeddings + (size_t)cls * (size_t)D, 1, neg, nn, 0.1f);
    if (rc) break;
    rc = fg_heatmap_compute(vf, &q, NULL, &hm);
    fg_query_release(&q);
    if (rc) break;
    size_t inter = 0, uni = 0;
    for (size_t i = 0; i < N; i++) {
      const int a = !isnan(hm.dense[i]) && hm.dense[i] >= 0.5f, b = owner[i] == k;
      inter += a && b;
      uni += a || b;
    }
    out->iou[c] = uni ? (double)inter / (double)uni : 0.0;
    fg_heatmap_release(&hm);
  }
  free(owner);
  free(cavity);
  free(neg);
  fg_voxel_features_free(vf);
  return rc;
}

int sg_geom_evaluate(const sg_gt *gt, const char *dir, const fg_field *f,
                     const fg_frame *frames, size_t n, int holdout_every, int n_threads,
                     sg_geom_eval *out) {
  memset(out, 0, sizeof *out);
  for (int k = 0; k < gt->n_objects && out->n_containers < 2; k++)
    if (gt->objects[k].shape.type == SG_SHAPE_MUG || gt->objects[k].shape.type == SG_SHAPE_BOWL)
      out->container[out->n_containers++] = k;
  out->iou[0] = out->iou[1] = NAN;
  if (holdout_every < 1) return fg_fail(FG_EINVAL, "holdout_every must be >= 1");
  FG_TRY(depth_errors(dir, f, frames, n, holdout_every, n_threads, out));
  FG_TRY(cavities(gt, f, n_threads, out));
  return container_iou(gt, f, n_threads, out);
}
