/* GET /v1/scenes/{s}/geometry: the solid part of the scene's trained field, what a gripper
 * would collide with, as a binary little-endian PLY: a closed marching-cubes mesh or the
 * centres of the solid voxels (query/geometry.h), coloured by the field.
 *
 * On the scene's own voxel grid the voxel opacities come from the voxel feature cache of the
 * field (voxcache.h), which heatmaps and grasps share: the first of them builds it. On another
 * voxel size, or for a field trained without features (which has no cache), the field's
 * density is sampled for this request alone, so that a one-off coarse or fine mesh does not
 * evict the cache the heatmaps use. Runs on the offload pool. */
#include "api.h"
#include "api_decode.h"
#include "metrics/metrics.h"
#include "state/voxcache.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/log.h"
#include "query/geometry.h"
#include "query/heatmap.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const geometry_keys[] = {"kind", "threshold", "alpha", "voxel_size"};
#define N_GEOMETRY_KEYS (sizeof geometry_keys / sizeof geometry_keys[0])

/* Parses the query string against the scene's parameters into *r; answers 400 itself and
 * returns -1 when it is wrong. */
int fg_api_parse_geometry(const fg_api_geometry_query *q, const fg_scene_params *params,
                          fg_api_geometry_req *r, fg_resp *resp) {
  const char *key = q->unknown;
  if (key)
    return fg_resp_error(resp, 400, "invalid_request", "unknown query parameter \"%.40s\"; "
                         "geometry takes \"kind\" (mesh or points), \"threshold\" and "
                         "\"voxel_size\"", key), -1;
  const char *kind = q->kind;
  if (kind && strcmp(kind, "mesh") != 0 && strcmp(kind, "points") != 0)
    return fg_resp_error(resp, 400, "invalid_request", "\"kind\" must be \"mesh\" (the default: "
                         "a closed triangle mesh of the solid's surface) or \"points\" (the "
                         "centres of the solid voxels), got \"%.40s\"", kind), -1;
  r->points = kind && strcmp(kind, "points") == 0;

  /* "alpha" is the name SPEC.md's endpoint table uses; "threshold" the one documented. */
  const char *thr = q->threshold, *alias = q->alpha;
  if (thr && alias)
    return fg_resp_error(resp, 400, "invalid_request", "give \"threshold\" or its synonym "
                         "\"alpha\", not both"), -1;
  if (!thr) thr = alias;
  /* Checked as the float it is kept as: "1e-300" rounds to 0, which the library refuses. */
  double a = FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  if (thr && (fg_query_number(thr, &a) != 0 || !((float)a > 0.0f && (float)a < 1.0f)))
    return fg_resp_error(resp, 400, "invalid_request", "\"threshold\" must be a number in (0, 1) "
                         "(default %g): a voxel is solid when its opacity alpha = 1 - "
                         "exp(-sigma * voxel_size) reaches it; got \"%.40s\"",
                         (double)FG_QUERY_DEFAULT_ALPHA_THRESHOLD, thr), -1;
  r->threshold = (float)a;

  r->voxel_size = params->voxel_size;
  const char *vs = q->voxel_size;
  double v = 0;
  if (vs && (fg_query_number(vs, &v) != 0 || !(v > 0.0)))
    return fg_resp_error(resp, 400, "invalid_request", "\"voxel_size\" must be a positive "
                         "number of metres (default the scene's, %g m), got \"%.40s\"",
                         params->voxel_size, vs), -1;
  /* The scene's own size (as a client prints it back) is the cached grid's, exactly. */
  if (vs && !(fabs(v - params->voxel_size) <= 1e-9 * params->voxel_size)) r->voxel_size = v;
  return 0;
}

int fg_api_scene_geometry(fg_req *req, fg_resp *resp) {
  const double t0 = fg_mono_s();
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  fg_api_solid sv = {0};
  fg_mesh m = {0};
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  const fg_api_geometry_query q = {
    .unknown = fg_req_query_unknown(req, geometry_keys, N_GEOMETRY_KEYS),
    .kind = fg_req_query(req, "kind"),
    .threshold = fg_req_query(req, "threshold"),
    .alpha = fg_req_query(req, "alpha"),
    .voxel_size = fg_req_query(req, "voxel_size")};
  fg_api_geometry_req r;
  if (fg_api_parse_geometry(&q, &info.params, &r, resp) != 0) goto out;
  const int threads = fg_conf_threads(req->conf);
  if (fg_api_solid_get(s, &info, r.voxel_size, threads, &sv, resp) != 0) goto out;
  const fg_voxel_grid *grid = &sv.grid;
  const int cached = sv.vox != NULL;

  int rc = r.points ? fg_mesh_points(grid, sv.alpha, r.threshold, &m)
                    : fg_mesh_marching_cubes(grid, sv.alpha, r.threshold, &m);
  /* Colours are taken half a voxel inside the surface, where the field was trained on it. */
  if (rc == 0)
    rc = fg_mesh_colour(&m, fg_field_ref_field(sv.ref), (float)(0.5 * grid->voxel_size),
                        threads);
  if (rc != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot make the geometry of scene '%s': %s",
                  info.name, fg_error_detail());
    goto out;
  }
  /* Nothing below reads the field: let a new training's field replace it meanwhile. */
  fg_field_ref_release(sv.ref);
  sv.ref = NULL;

  char comment[192];
  snprintf(comment, sizeof comment, "fieldgrip scene %s %s: voxel_size %.9g m, alpha threshold "
           "%.6g, world frame, metres", info.name, r.points ? "points" : "mesh",
           grid->voxel_size, (double)r.threshold);
  uint8_t *bytes = NULL;
  size_t len = 0;
  if (fg_mesh_encode_ply(&m, comment, &bytes, &len) != 0) {
    fg_resp_error(resp, 500, "internal_error", "cannot encode the PLY: %s", fg_error_detail());
    goto out;
  }
  fg_resp_take(resp, 200, "application/octet-stream", (char *)bytes, len);
  snprintf(resp->header, sizeof resp->header, "X-Vertex-Count: %zu\r\nX-Face-Count: %zu",
           m.n_vertices, m.n_faces);
  fg_info("scene %s: geometry (%s, %g m, alpha >= %g%s): %zu vertices, %zu faces, %zu bytes "
          "in %.0f ms", info.name, r.points ? "points" : "mesh", grid->voxel_size,
          (double)r.threshold, cached ? ", cached voxels" : "", m.n_vertices, m.n_faces, len,
          (fg_mono_s() - t0) * 1e3);
out:
  fg_mesh_release(&m);
  fg_api_solid_release(&sv);
  fg_scene_unref(s);
  return 0;
}
