/* GET /v1/scenes/{s}/points: the solid voxels of the scene's trained field as a compact
 * binary point cloud ("FGPC", below) for the web viewer: one voxel centre, colour and opacity
 * per point, which a browser uploads to the GPU as they are, without parsing text or PLY.
 *
 * The solid voxels are those of GET .../geometry?kind=points at the same threshold: the same
 * opacities (fg_api_solid_get: the field's voxel cache on the scene's own grid, else sampled
 * for the request), the same centres (fg_mesh_points) and colours (fg_mesh_colour). Past
 * max_points they are thinned deterministically: the k-th point kept is solid voxel
 * floor(k * n_solid / max_points) in flat-index order, an even spread over the workspace, the
 * same for the same field and parameters. Runs on the offload pool.
 *
 * FGPC version 1, little-endian:
 *   offset  0  char magic[4] = "FGPC"
 *           4  u32 version = 1
 *           8  u32 header_bytes = 64 (the arrays start there)
 *          12  u32 count          points in this reply
 *          16  u32 n_solid        solid voxels before thinning (count < n_solid: thinned)
 *          20  f32 voxel_size_m
 *          24  f32 alpha_threshold
 *          28  f32 min_m[3]       the grid's min corner, world frame, metres
 *          40  u32 nx, ny, nz     the grid's shape: voxel (ix, iy, iz) has its centre at
 *                                 min_m + (i + 0.5) * voxel_size_m, flat index
 *                                 (iz * ny + iy) * nx + ix, as heatmap .npy grids
 *          52  zero padding to 64
 *   then f32 xyz_m[count][3]       voxel centres, world frame, metres
 *   then u8  rgba[count][4]        sRGB colour of the field; alpha = the voxel's opacity * 255
 */
#include "api.h"
#include "api_decode.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/log.h"
#include "query/geometry.h"
#include "query/heatmap.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FGPC_HEADER_BYTES 64

static const char *const points_keys[] = {"alpha", "voxel_size", "max_points"};
#define N_POINTS_KEYS (sizeof points_keys / sizeof points_keys[0])

int fg_api_parse_points(const fg_api_points_query *q, const fg_scene_params *params,
                        fg_api_points_req *r, fg_resp *resp) {
  if (q->unknown)
    return fg_resp_error(resp, 400, "invalid_request", "unknown query parameter \"%.40s\"; "
                         "points takes \"alpha\", \"voxel_size\" and \"max_points\"",
                         q->unknown), -1;
  /* Checked as the float it is kept as: "1e-300" rounds to 0, which the library refuses. */
  double a = FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  if (q->alpha && (fg_query_number(q->alpha, &a) != 0 || !((float)a > 0.0f && (float)a < 1.0f)))
    return fg_resp_error(resp, 400, "invalid_request", "\"alpha\" must be a number in (0, 1) "
                         "(default %g): a voxel is solid when its opacity 1 - exp(-sigma * "
                         "voxel_size) reaches it; got \"%.40s\"",
                         (double)FG_QUERY_DEFAULT_ALPHA_THRESHOLD, q->alpha), -1;
  r->alpha = (float)a;

  r->voxel_size = params->voxel_size;
  double v = 0;
  if (q->voxel_size && (fg_query_number(q->voxel_size, &v) != 0 || !(v > 0.0)))
    return fg_resp_error(resp, 400, "invalid_request", "\"voxel_size\" must be a positive "
                         "number of metres (default the scene's, %g m), got \"%.40s\"",
                         params->voxel_size, q->voxel_size), -1;
  /* The scene's own size (as a client prints it back) is the cached grid's, exactly. */
  if (q->voxel_size && !(fabs(v - params->voxel_size) <= 1e-9 * params->voxel_size))
    r->voxel_size = v;

  r->max_points = FG_API_POINTS_DEFAULT;
  double m = 0;
  if (q->max_points && (fg_query_number(q->max_points, &m) != 0 || m != floor(m) || m < 1 ||
                        m > (double)FG_API_POINTS_MAX))
    return fg_resp_error(resp, 400, "invalid_request", "\"max_points\" must be an integer "
                         "from 1 to %zu (default %d): more solid voxels are thinned evenly to "
                         "that many; got \"%.40s\"", FG_API_POINTS_MAX, FG_API_POINTS_DEFAULT,
                         q->max_points), -1;
  if (q->max_points) r->max_points = (size_t)m;
  return 0;
}

/* ---------------------------------------------------------------- encoding */

static void put_u32(uint8_t *p, uint32_t v) {
  p[0] = (uint8_t)v;
  p[1] = (uint8_t)(v >> 8);
  p[2] = (uint8_t)(v >> 16);
  p[3] = (uint8_t)(v >> 24);
}

static void put_f32(uint8_t *p, float f) {
  uint32_t v;
  memcpy(&v, &f, sizeof v);
  put_u32(p, v);
}

/* The FGPC body of m's points (p_world, rgb) with their opacities alpha (m->n_vertices) on
 * grid g, into a malloc'd buffer the caller owns; NULL when out of memory. */
static uint8_t *fgpc_encode(const fg_voxel_grid *g, const fg_mesh *m, const float *alpha,
                            size_t n_solid, float threshold, size_t *len) {
  const size_t n = m->n_vertices;
  *len = FGPC_HEADER_BYTES + n * (3 * sizeof(float) + 4);
  uint8_t *b = calloc(1, *len);
  if (!b) return NULL;
  memcpy(b, "FGPC", 4);
  put_u32(b + 4, 1);
  put_u32(b + 8, FGPC_HEADER_BYTES);
  put_u32(b + 12, (uint32_t)n);
  put_u32(b + 16, (uint32_t)n_solid);
  put_f32(b + 20, (float)g->voxel_size);
  put_f32(b + 24, threshold);
  for (int a = 0; a < 3; a++) put_f32(b + 28 + 4 * a, (float)g->min[a]);
  put_u32(b + 40, (uint32_t)g->nx);
  put_u32(b + 44, (uint32_t)g->ny);
  put_u32(b + 48, (uint32_t)g->nz);
  uint8_t *xyz = b + FGPC_HEADER_BYTES, *rgba = xyz + n * 3 * sizeof(float);
  for (size_t i = 0; i < 3 * n; i++) put_f32(xyz + 4 * i, m->p_world[i]);
  for (size_t i = 0; i < n; i++) {
    memcpy(rgba + 4 * i, m->rgb + 3 * i, 3);
    const float a = alpha[i] < 0.0f ? 0.0f : alpha[i] > 1.0f ? 1.0f : alpha[i];
    rgba[4 * i + 3] = (uint8_t)lrintf(a * 255.0f);
  }
  return b;
}

/* Keeps max_points of m's n_solid points, evenly spread, and their opacities: m->p_world is
 * compacted in place and the opacities of the kept points (read from the grid's alpha in the
 * flat order fg_mesh_points lists them) go into kept_alpha (max_points or n_solid). */
static void points_thin(fg_mesh *m, const float *grid_alpha, size_t n_voxels, float threshold,
                        size_t max_points, float *kept_alpha) {
  const size_t n_solid = m->n_vertices, keep = n_solid < max_points ? n_solid : max_points;
  size_t solid = 0, k = 0;
  for (size_t i = 0; i < n_voxels && k < keep; i++) {
    if (!(grid_alpha[i] >= threshold)) continue; /* fg_mesh_points' rule: NaN is empty */
    /* the k-th kept point is solid voxel floor(k * n_solid / keep) */
    if (solid == (size_t)((uint64_t)k * n_solid / keep)) {
      memmove(m->p_world + 3 * k, m->p_world + 3 * solid, 3 * sizeof *m->p_world);
      kept_alpha[k++] = grid_alpha[i];
    }
    solid++;
  }
  m->n_vertices = k;
}

/* ---------------------------------------------------------------- handler */

int fg_api_scene_points(fg_req *req, fg_resp *resp) {
  const double t0 = fg_mono_s();
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_api_solid sv = {0};
  float *kept_alpha = NULL;
  fg_mesh m = {0};
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  const fg_api_points_query q = {
    .unknown = fg_req_query_unknown(req, points_keys, N_POINTS_KEYS),
    .alpha = fg_req_query(req, "alpha"),
    .voxel_size = fg_req_query(req, "voxel_size"),
    .max_points = fg_req_query(req, "max_points")};
  fg_api_points_req r;
  if (fg_api_parse_points(&q, &info.params, &r, resp) != 0) goto out;
  const int threads = fg_conf_threads(req->conf);
  if (fg_api_solid_get(s, &info, r.voxel_size, threads, &sv, resp) != 0) goto out;
  const fg_voxel_grid *grid = &sv.grid;
  int rc = fg_mesh_points(grid, sv.alpha, r.alpha, &m);
  const size_t n_solid = m.n_vertices;
  if (rc == 0 && !(kept_alpha = malloc((n_solid ? n_solid : 1) * sizeof *kept_alpha)))
    rc = fg_fail(FG_ENOMEM, "out of memory for %zu points", n_solid);
  if (rc == 0) {
    points_thin(&m, sv.alpha, fg_voxel_grid_count(grid), r.alpha, r.max_points, kept_alpha);
    /* Colours of the points left only: a thinned cloud costs what it shows. */
    rc = fg_mesh_colour(&m, fg_field_ref_field(sv.ref), (float)(0.5 * grid->voxel_size),
                        threads);
  }
  if (rc != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot make the points of scene '%s': %s",
                  info.name, fg_error_detail());
    goto out;
  }
  /* Nothing below reads the field: let a new training's field replace it meanwhile. */
  fg_field_ref_release(sv.ref);
  sv.ref = NULL;

  size_t len = 0;
  uint8_t *body = fgpc_encode(grid, &m, kept_alpha, n_solid, r.alpha, &len);
  if (!body) {
    fg_resp_error(resp, 500, "internal_error", "out of memory for %zu points", m.n_vertices);
    goto out;
  }
  fg_resp_take(resp, 200, "application/octet-stream", (char *)body, len);
  snprintf(resp->header, sizeof resp->header, "X-Point-Count: %zu\r\nX-Solid-Count: %zu",
           m.n_vertices, n_solid);
  fg_info("scene %s: points (%g m, alpha >= %g%s): %zu of %zu solid voxels, %zu bytes in "
          "%.0f ms", info.name, grid->voxel_size, (double)r.alpha, sv.vox ? ", cached voxels" : "",
          m.n_vertices, n_solid, len, (fg_mono_s() - t0) * 1e3);
out:
  fg_mesh_release(&m);
  free(kept_alpha);
  fg_api_solid_release(&sv);
  fg_scene_unref(s);
  return 0;
}
