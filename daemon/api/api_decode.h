/* The request decoders of the HTTP API: each endpoint's JSON body (or query string) read
 * into a plain struct, apart from the handler that acts on it, so that they run without a
 * live daemon (tests/fuzz/fuzz_api.c feeds them arbitrary bodies). The handlers in api_*.c
 * call exactly these functions.
 *
 * One return contract: a decoder answers a wrong request itself (fg_resp_error: status,
 * code, message; a 400 but where it says otherwise) and returns -1; 0 when it decoded.
 * Strings in the decoded structs are borrowed from the JSON body: they live as long as it. */
#ifndef FG_DAEMON_API_DECODE_H
#define FG_DAEMON_API_DECODE_H

#include <stddef.h>

#include <jansson.h>

#include "state/clip_svc.h"
#include "conf/conf.h"
#include "grasp/grasp.h"
#include "http/http.h"
#include "io/transforms.h"
#include "state/jobs.h"
#include "robot/robot.h"
#include "state/store.h"
#include "state/tasks.h"

/* The largest render: FG_API_RENDER_MAX_SIDE pixels on either side. */
#define FG_API_RENDER_MAX_SIDE 4096

/* POST /v1/scenes: reads the optional workspace, voxel_size and background of body over the
 * SPEC.md tabletop defaults into *p and validates them (fg_scene_params_validate; its
 * reason, such as grid_too_large, decides the status). 0, or -1 after answering. */
int fg_api_parse_scene_params(json_t *body, fg_scene_params *p, fg_resp *resp);

/* POST /v1/scenes/{s}/train: reads body (an object) over conf's defaults into *p, refusing
 * unknown keys. 0, or -1 after answering 400. */
int fg_api_parse_train(json_t *body, const fg_conf *conf, fg_job_params *p, fg_resp *resp);

typedef enum {
  FG_API_HEATMAP_JSON = 0,
  FG_API_HEATMAP_NPY,
  FG_API_HEATMAP_PLY
} fg_api_heatmap_format;

typedef struct fg_api_heatmap_req {
  fg_api_heatmap_format format;
  float alpha_threshold;
  float min_score;   /* -INFINITY: none */
  size_t max_points; /* 0: none */
} fg_api_heatmap_req;

/* POST /v1/scenes/{s}/heatmap: the keys of body but its query (api_query.h resolves that with
 * the CLIP model) into *r, against the scene's params. 0, or -1 after answering 400. */
int fg_api_parse_heatmap(json_t *body, const fg_scene_params *params, fg_api_heatmap_req *r,
                         fg_resp *resp);

/* GET /v1/scenes/{s}/geometry's query string, as the handler looked it up: each value NULL
 * when absent; unknown is the first parameter that is none of kind, threshold, alpha and
 * voxel_size (fg_req_query_unknown), or NULL. */
typedef struct fg_api_geometry_query {
  const char *unknown, *kind, *threshold, *alpha, *voxel_size;
} fg_api_geometry_query;

typedef struct fg_api_geometry_req {
  int points;        /* kind=points, else mesh */
  float threshold;   /* voxel alpha in (0, 1) */
  double voxel_size; /* metres, > 0 */
} fg_api_geometry_req;

/* The geometry query q against the scene's params into *r. 0, or -1 after answering 400. */
int fg_api_parse_geometry(const fg_api_geometry_query *q, const fg_scene_params *params,
                          fg_api_geometry_req *r, fg_resp *resp);

/* GET /v1/scenes/{s}/points's query string, as the handler looked it up (each value NULL
 * when absent; unknown as for geometry). */
typedef struct fg_api_points_query {
  const char *unknown, *alpha, *voxel_size, *max_points;
} fg_api_points_query;

/* The most points one reply carries (64 MiB of FGPC): max_points is 1..this. */
#define FG_API_POINTS_MAX ((size_t)4 << 20)
#define FG_API_POINTS_DEFAULT 200000

typedef struct fg_api_points_req {
  float alpha;       /* solid voxels have alpha >= this, in (0, 1) */
  double voxel_size; /* metres, > 0 */
  size_t max_points; /* 1..FG_API_POINTS_MAX */
} fg_api_points_req;

/* The points query q against the scene's params into *r. 0, or -1 after answering 400. */
int fg_api_parse_points(const fg_api_points_query *q, const fg_scene_params *params,
                        fg_api_points_req *r, fg_resp *resp);

typedef struct fg_api_render_req {
  double T_world_cam[16]; /* OpenGL convention */
  fg_camera cam;          /* PINHOLE, w and h set, at most FG_API_RENDER_MAX_SIDE */
  int depth;              /* output depth, else rgb */
  int normal;             /* output normal, else rgb */
  int heatmap;            /* output heatmap: the body also holds a query (api_query.h) */
} fg_api_render_req;

/* POST /v1/scenes/{s}/render: the camera, pose and output of body but its query into *r.
 * 0, or -1 after answering 400. */
int fg_api_parse_render(json_t *body, fg_api_render_req *r, fg_resp *resp);

typedef struct fg_api_grasp_req {
  const char *task;     /* NULL: retrieved by the query */
  int has_query;
  int language_weight;  /* optimise J_lang (grasp.h) instead of J; needs a query */
  fg_grasp_options opt; /* lib/grasp's defaults with the request's top_k, rotations, seed */
} fg_api_grasp_req;

/* POST /v1/scenes/{s}/grasps: the keys of body but its query into *r. 0, or -1 after
 * answering 400. */
int fg_api_parse_grasp(json_t *body, fg_api_grasp_req *r, fg_resp *resp);

/* POST /v1/robot/commands and /v1/gripper/{action}: the keys of body into *r; allowed is the
 * NULL-terminated list of keys the endpoint takes. 0, or -1 after answering 400. */
int fg_api_parse_robot_request(json_t *body, const char *const *allowed, fg_robot_request *r,
                               fg_resp *resp);

/* POST /v1/tasks/{t}/demos: the demo's keys but its feature sample into *d (scene name,
 * pose, kind, width up to the stroke of conf's gripper, approach, query points). t is the
 * task when it exists (its query points are the defaults), else NULL. 0, or -1 after
 * answering 400. */
int fg_api_parse_demo(json_t *body, const fg_conf *conf, const fg_task *t, fg_task_demo_new *d,
                      fg_resp *resp);

/* The "query_points" of a demo's body into d, over t's (or the defaults when t is NULL or
 * has no demos: the box between the pads of gripper `model` open to d->width_m, which the
 * caller sets first). 0, or -1 after answering 400. */
int fg_api_parse_query_points(json_t *body, const fg_task *t, fg_gripper_model model,
                              fg_task_demo_new *d, fg_resp *resp);

/* POST /v1/scenes/{s}/frames: the pose (into T, camera-to-world, OpenGL) and camera (into
 * *camera; its file_path is a static "upload") of the upload's meta part. 0, or -1 after
 * answering 400. */
int fg_api_parse_meta(json_t *meta, double T[16], fg_transforms_frame *camera, fg_resp *resp);

/* meta's optional depth_scale (metres per unit of an integer depth image) into *scale,
 * unchanged when absent; has_depth says whether the upload has a depth part, source names the
 * frame in messages. 0, or -1 after answering 400. */
int fg_api_parse_depth_scale(json_t *meta, int has_depth, const char *source, double *scale,
                             fg_resp *resp);

typedef struct fg_api_embed_text_req {
  const char *texts[FG_CLIP_MAX_TEXTS]; /* n of them */
  int n;
  int truncate, normalize;
} fg_api_embed_text_req;

/* POST /v1/embed/text: the texts and flags of body into *r, refusing unknown keys. 0, or -1
 * after answering 400. */
int fg_api_parse_embed_text(json_t *body, fg_api_embed_text_req *r, fg_resp *resp);

#endif
