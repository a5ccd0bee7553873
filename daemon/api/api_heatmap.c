/* POST /v1/scenes/{s}/heatmap: a query (api_query.h) scored over the scene's workspace grid, from
 * the voxel feature cache of its trained field (voxcache.h), as a JSON point list, a dense
 * .npy grid or a coloured PLY point cloud. Runs on the offload pool: the first heatmap of a
 * field builds its cache (seconds), later ones only score it. */
#include "api.h"
#include "api_decode.h"
#include "state/json.h"
#include "metrics/metrics.h"
#include "api_query.h"
#include "state/scene_voxels.h"

#include "core/error.h"
#include "core/log.h"
#include "core/strbuf.h"
#include "query/heatmap.h"

#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const heatmap_keys[] = {"voxel_size", "alpha_threshold", "format", "min_score",
                                           "max_points"};
#define N_HEATMAP_KEYS (sizeof heatmap_keys / sizeof heatmap_keys[0])

/* Parses the keys of a heatmap request but its query into *r against the scene's parameters;
 * answers 400 itself and returns -1 when they are wrong. */
int fg_api_parse_heatmap(json_t *body, const fg_scene_params *params,
                         fg_api_heatmap_req *r, fg_resp *resp) {
  const char *key = fg_query_unknown_key(body, heatmap_keys, N_HEATMAP_KEYS);
  if (key)
    return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; a heatmap takes a "
                         "query (\"text\" or \"embedding\", \"negatives\" or "
                         "\"negative_embeddings\", \"temperature\") and \"format\", "
                         "\"alpha_threshold\", \"min_score\", \"max_points\", \"voxel_size\"",
                         key), -1;
  const char *format = "json";
  if (fg_json_string(body, "format", &format) < 0 ||
      (strcmp(format, "json") != 0 && strcmp(format, "npy") != 0 && strcmp(format, "ply") != 0))
    return fg_resp_error(resp, 400, "invalid_request", "\"format\" must be \"json\" (occupied "
                         "voxels and their scores), \"npy\" (dense float32 [nz, ny, nx], NaN "
                         "where free) or \"ply\" (a point cloud coloured by score)"), -1;
  r->format = strcmp(format, "npy") == 0 ? FG_API_HEATMAP_NPY
              : strcmp(format, "ply") == 0 ? FG_API_HEATMAP_PLY
                                           : FG_API_HEATMAP_JSON;
  double a = FG_QUERY_DEFAULT_ALPHA_THRESHOLD;
  int rc = fg_json_number(body, "alpha_threshold", &a);
  /* Compared as the float it becomes: 0.001 must pass the library's 1e-3f floor. */
  if (rc < 0 || !((float)a >= FG_QUERY_ALPHA_FLOOR && a <= 1))
    return fg_resp_error(resp, 400, "invalid_request", "\"alpha_threshold\" must be a number in "
                         "[%g, 1] (default %g): a voxel is occupied when its opacity alpha = 1 - "
                         "exp(-sigma * voxel_size) reaches it", (double)FG_QUERY_ALPHA_FLOOR,
                         (double)FG_QUERY_DEFAULT_ALPHA_THRESHOLD), -1;
  r->alpha_threshold = (float)a;
  double m = 0;
  rc = fg_json_number(body, "min_score", &m);
  if (rc < 0 || (rc > 0 && !(fabs(m) <= FLT_MAX)))
    return fg_resp_error(resp, 400, "invalid_request", "\"min_score\" must be a number: points "
                         "scoring below it are left out"), -1;
  r->min_score = rc > 0 ? (float)m : -INFINITY;
  json_t *mp = json_object_get(body, "max_points");
  r->max_points = 0;
  if (mp && !json_is_null(mp)) {
    if (!json_is_integer(mp) || json_integer_value(mp) < 1)
      return fg_resp_error(resp, 400, "invalid_request", "\"max_points\" must be a positive "
                           "integer: the reply keeps that many best-scoring points"), -1;
    r->max_points = (size_t)json_integer_value(mp);
  }
  if (r->format == FG_API_HEATMAP_NPY && (rc > 0 || r->max_points))
    return fg_resp_error(resp, 400, "invalid_request", "\"min_score\" and \"max_points\" bound "
                         "the point list of \"json\" and \"ply\"; \"npy\" is always the whole "
                         "grid"), -1;
  double vs = params->voxel_size;
  rc = fg_json_number(body, "voxel_size", &vs);
  if (rc < 0 || (rc > 0 && !(fabs(vs - params->voxel_size) <= 1e-9 * params->voxel_size)))
    return fg_resp_error(resp, 400, "invalid_request", "\"voxel_size\" must be the scene's "
                         "voxel size, %g m (or be left out): heatmaps are scored on the "
                         "scene's voxel grid, whose features are cached; create the scene with "
                         "another \"voxel_size\" for another grid", params->voxel_size), -1;
  return 0;
}

/* ---------------------------------------------------------------- the JSON reply */

/* x with six decimals, trailing zeros dropped ("0.105", "-1", "0.000001"); null when not
 * finite. Fixed point keeps a reply of 10^5 points to a few milliseconds, where printf's %g
 * takes ten times longer; micrometres and 1e-6 of a score are finer than the grid's truth. */
static void put_num(fg_strbuf *b, double x) {
  if (!isfinite(x) || fabs(x) > 9e12) {
    fg_strbuf_puts(b, isfinite(x) ? (x > 0 ? "9e12" : "-9e12") : "null");
    return;
  }
  char tmp[40], *e = tmp + sizeof tmp, *p = e;
  long long v = llround(x * 1e6);
  int neg = v < 0;
  unsigned long long u = neg ? (unsigned long long)(-v) : (unsigned long long)v;
  unsigned long long ip = u / 1000000ULL, fp = u % 1000000ULL;
  int digits = 6;
  while (digits > 0 && fp % 10 == 0) {
    fp /= 10;
    digits--;
  }
  for (int i = 0; i < digits; i++) {
    *--p = (char)('0' + fp % 10);
    fp /= 10;
  }
  if (digits) *--p = '.';
  do {
    *--p = (char)('0' + ip % 10);
    ip /= 10;
  } while (ip);
  if (neg && (u != 0)) *--p = '-';
  fg_strbuf_add(b, p, (size_t)(e - p));
}

static void put_vec(fg_strbuf *b, const double *v, int n) {
  fg_strbuf_puts(b, "[");
  for (int i = 0; i < n; i++) {
    if (i) fg_strbuf_puts(b, ",");
    put_num(b, v[i]);
  }
  fg_strbuf_puts(b, "]");
}

/* The json format: {"voxel_size", "alpha_threshold", "grid": {"min", "max", "shape"},
 * "occupied", "returned", "best": {"position", "score"} or null, "points": [[x, y, z, score],
 * ...]} with the points by score, best first. Written by hand: a reply has up to millions of
 * numbers. A malloc'd NUL-terminated text, or NULL when out of memory. */
static char *heatmap_json(const fg_heatmap *hm, size_t *len) {
  fg_strbuf b = {0};
  const fg_voxel_grid *g = &hm->grid;
  fg_strbuf_puts(&b, "{\"voxel_size\":");
  put_num(&b, g->voxel_size);
  fg_strbuf_puts(&b, ",\"alpha_threshold\":");
  put_num(&b, hm->alpha_threshold);
  fg_strbuf_puts(&b, ",\"grid\":{\"min\":");
  put_vec(&b, g->min, 3);
  fg_strbuf_puts(&b, ",\"max\":");
  put_vec(&b, g->max, 3);
  fg_strbuf_printf(&b, ",\"shape\":[%d,%d,%d]},\"occupied\":%zu,\"returned\":%zu,"
                   "\"best\":", g->nz, g->ny, g->nx, hm->n_occupied, hm->n_points);
  if (hm->has_best) {
    fg_strbuf_puts(&b, "{\"position\":");
    put_vec(&b, hm->best_p_world, 3);
    fg_strbuf_puts(&b, ",\"score\":");
    put_num(&b, hm->best_score);
    fg_strbuf_puts(&b, "}");
  } else {
    fg_strbuf_puts(&b, "null");
  }
  fg_strbuf_puts(&b, ",\"points\":[");
  fg_strbuf_reserve(&b, hm->n_points * 48);
  for (size_t i = 0; i < hm->n_points; i++) {
    const fg_heatmap_point *pt = &hm->points[i];
    fg_strbuf_puts(&b, i ? ",[" : "[");
    for (int k = 0; k < 3; k++) {
      put_num(&b, pt->p_world[k]);
      fg_strbuf_puts(&b, ",");
    }
    put_num(&b, pt->score);
    fg_strbuf_puts(&b, "]");
  }
  fg_strbuf_puts(&b, "]}");
  return fg_strbuf_take(&b, len);
}

/* ---------------------------------------------------------------- the handler */

/* Answers heatmap hm in format f. */
static void send_heatmap(fg_resp *resp, const fg_heatmap *hm, fg_api_heatmap_format f) {
  uint8_t *bytes = NULL;
  size_t len = 0;
  if (f == FG_API_HEATMAP_JSON) {
    char *text = heatmap_json(hm, &len);
    if (!text) {
      fg_resp_error(resp, 500, "internal_error", "out of memory writing %zu points",
                    hm->n_points);
      return;
    }
    fg_resp_take(resp, 200, "application/json", text, len);
    fg_metrics_count_heatmap(FG_METRICS_HEATMAP_JSON);
  } else if (f == FG_API_HEATMAP_NPY) {
    if (fg_heatmap_encode_npy(hm, &bytes, &len) != 0) {
      fg_resp_error(resp, 500, "internal_error", "cannot encode the grid: %s", fg_error_detail());
      return;
    }
    fg_resp_take(resp, 200, "application/x-npy", (char *)bytes, len);
    fg_metrics_count_heatmap(FG_METRICS_HEATMAP_NPY);
  } else {
    if (fg_heatmap_encode_ply(hm, NAN, NAN, &bytes, &len) != 0) {
      fg_resp_error(resp, 500, "internal_error", "cannot encode the point cloud: %s",
                    fg_error_detail());
      return;
    }
    fg_resp_take(resp, 200, "application/octet-stream", (char *)bytes, len);
    fg_metrics_count_heatmap(FG_METRICS_HEATMAP_PLY);
  }
}

/* The heatmap of query q on voxel features vf as request r asks for it. */
static int compute(const fg_voxel_features *vf, const fg_query *q, const fg_api_heatmap_req *r,
                   int n_threads, fg_heatmap *hm) {
  fg_heatmap_options o;
  fg_heatmap_options_default(&o);
  o.alpha_threshold = r->alpha_threshold;
  o.min_score = r->min_score;
  o.max_points = r->max_points;
  o.want_dense = r->format == FG_API_HEATMAP_NPY;
  o.want_points = r->format != FG_API_HEATMAP_NPY;
  o.n_threads = n_threads;
  const int rc = fg_heatmap_compute(vf, q, &o, hm);
  if (rc != 0 && rc != FG_EINVAL)
    return fg_fail(rc, "cannot compute the heatmap: %s", fg_error_detail());
  return rc;
}

int fg_api_scene_heatmap(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  fg_query q = {0};
  fg_scene_voxels sv = {0};
  fg_heatmap hm = {0};
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_api_heatmap_req r;
  /* The query is checked first, against the trained field's D, else the frames'. */
  if (!body || fg_api_parse_heatmap(body, &info.params, &r, resp) != 0 ||
      fg_query_parse(req, resp, body, info.field_feature_dim ? info.field_feature_dim
                     : info.feature_dim, &q) != 0)
    goto out;
  const int threads = fg_conf_threads(req->conf);
  int rc = fg_scene_voxels_acquire(s, q.dim, "a query has nothing to score", threads, &sv);
  if (rc == 0) rc = compute(sv.vf, &q, &r, threads, &hm);
  if (rc == 0)
    send_heatmap(resp, &hm, r.format);
  else
    fg_api_fail(resp, rc);
out:
  fg_heatmap_release(&hm);
  fg_scene_voxels_release(&sv);
  fg_query_release(&q);
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}
