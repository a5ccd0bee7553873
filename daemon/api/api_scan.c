/* POST /v1/scenes/{s}/scan: a scan the robot drives (cell/scan.h). */
#include "api.h"
#include "api_decode.h"

#include "cell/scan.h"
#include "state/json.h"

#include "core/error.h"

#include <stdlib.h>
#include <string.h>

/* "train": true (conf's defaults), false, or a training's body (POST .../train) into *r.
 * 0, or -1 after a 400 (api_decode.h's contract). */
static int parse_scan_train(json_t *body, const fg_conf *conf, fg_scan_request *r,
                            fg_resp *resp) {
  json_t *t = json_object_get(body, "train");
  if (!t || json_is_false(t)) return 0;
  if (!json_is_true(t) && !json_is_object(t))
    return fg_resp_error(resp, 400, "invalid_request", "\"train\": true, false or a "
                         "training's body ({\"steps\": N, ...})"), -1;
  json_t *empty = json_is_true(t) ? json_object() : NULL;
  const int rc = fg_api_parse_train(empty ? empty : t, conf, &r->train_params, resp);
  json_decref(empty);
  r->train = rc == 0;
  return rc;
}

/* {"camera": NAME, "viewpoints": N | [poses], "radius_m", "elevations_deg": [lo, hi],
 * "settle_ms", "train"} into *r. 0, or -1 after a 400 (or a 500: no memory). */
static int parse_scan(json_t *body, const fg_conf *conf, fg_scan_request *r, fg_resp *resp) {
  static const char *const keys[] = {"camera", "viewpoints", "radius_m", "elevations_deg",
                                     "settle_ms", "train", NULL};
  memset(r, 0, sizeof *r);
  r->n = 30;
  r->el_min_deg = 35;
  r->el_max_deg = 75;
  r->settle_ms = 300;
  const char *unknown = fg_json_unknown_key(body, keys), *cam = NULL;
  if (unknown)
    return fg_resp_error(resp, 400, "invalid_request", "unknown key \"%s\"; a scan takes "
                         "camera, viewpoints, radius_m, elevations_deg, settle_ms, train",
                         unknown), -1;
  if (fg_json_string(body, "camera", &cam) != 1 || strlen(cam) > FG_CAMERA_NAME_MAX)
    return fg_resp_error(resp, 400, "invalid_request", "\"camera\": the name of a [camera "
                         "NAME] on the tool is required"), -1;
  snprintf(r->camera, sizeof r->camera, "%s", cam);
  json_t *vp = json_object_get(body, "viewpoints");
  long long n = 30, settle = 300;
  if (json_is_array(vp)) {
    n = (long long)json_array_size(vp);
    if (n < 1 || n > FG_SCAN_MAX_VIEWPOINTS)
      return fg_resp_error(resp, 400, "invalid_request", "\"viewpoints\": 1 to %d poses",
                           FG_SCAN_MAX_VIEWPOINTS), -1;
    r->T_base_tcp = malloc(sizeof *r->T_base_tcp * 16 * (size_t)n);
    if (!r->T_base_tcp)
      return fg_resp_error(resp, 500, "internal_error", "out of memory for %lld viewpoints",
                           n), -1;
    for (long long i = 0; i < n; i++) {
      double q[4];
      char what[48];
      snprintf(what, sizeof what, "viewpoints[%lld]", i);
      if (fg_json_pose_parse(json_array_get(vp, (size_t)i), what, r->T_base_tcp + 16 * i, q) != 0) {
        free(r->T_base_tcp);
        r->T_base_tcp = NULL;
        return fg_resp_error(resp, 400, "invalid_pose", "%s", fg_error_detail()), -1;
      }
    }
  } else if (vp && fg_json_int_range(body, "viewpoints", 1, FG_SCAN_MAX_VIEWPOINTS, &n) != 1) {
    return fg_resp_error(resp, 400, "invalid_request", "\"viewpoints\": a count (1 to %d) or "
                         "a list of TCP poses", FG_SCAN_MAX_VIEWPOINTS), -1;
  }
  r->n = (int)n;
  json_t *el = json_object_get(body, "elevations_deg");
  double e[2] = {r->el_min_deg, r->el_max_deg};
  if ((el && (fg_json_vec(el, e, 2, "elevations_deg") != 0 || !(e[0] >= 0 && e[0] <= e[1] &&
                                                                 e[1] <= 90))) ||
      (json_object_get(body, "radius_m") &&
       (fg_json_number(body, "radius_m", &r->radius_m) != 1 ||
        !(r->radius_m > 0 && r->radius_m <= 5))) ||
      (json_object_get(body, "settle_ms") &&
       fg_json_int_range(body, "settle_ms", 0, 10000, &settle) != 1)) {
    free(r->T_base_tcp);
    r->T_base_tcp = NULL;
    return fg_resp_error(resp, 400, "invalid_request", "elevations_deg: [low, high] from 0 to "
                         "90 degrees, low <= high; radius_m: above 0 and at most 5; settle_ms: "
                         "0 to 10000"), -1;
  }
  r->el_min_deg = e[0];
  r->el_max_deg = e[1];
  r->settle_ms = (int)settle;
  if (parse_scan_train(body, conf, r, resp) != 0) {
    free(r->T_base_tcp);
    r->T_base_tcp = NULL;
    return -1;
  }
  return 0;
}

int fg_api_scene_scan(fg_req *req, fg_resp *resp) {
  fg_scene *s = fg_api_scene_param(req, resp);
  if (!s) return 0;
  json_t *body = fg_api_body_object(req, resp);
  fg_scan_request r;
  if (body && parse_scan(body, req->conf, &r, resp) == 0) {
    fg_job_info job;
    const int listed = r.T_base_tcp != NULL;
    const int rc = fg_scan_submit(req->app, req->conf, s, &r, &job);
    free(r.T_base_tcp); /* NULL once the job took them */
    if (rc < 0) {
      fg_api_fail(resp, rc);
    } else {
      snprintf(resp->location, sizeof resp->location, "/v1/jobs/%s", job.id);
      fg_resp_json(resp, 202, json_pack("{s:s, s:s, s:i, s:o}", "job", job.id, "state",
                                        fg_job_state_name(job.state), "viewpoints", r.n,
                                        "radius_m", listed ? json_null() : json_real(r.radius_m)));
    }
  }
  json_decref(body);
  fg_scene_unref(s);
  return 0;
}
