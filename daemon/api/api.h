/* The HTTP API: its route table, the handlers (one api_*.c file per group of endpoints) and
 * the helpers they share. Only handlers and main.c include this header; the modules below
 * them (jobs, CLIP, robot, store) reach the application object through app.h. */
#ifndef FG_DAEMON_API_H
#define FG_DAEMON_API_H

#include <stddef.h>

#include "state/app.h"
#include "http/http.h"
#include "query/grid.h"
#include "query/query.h"

/* The route table. */
extern const fg_route fg_api_routes[];
extern const size_t fg_api_n_routes;

/* Handlers, by file. */
int fg_api_health(fg_req *req, fg_resp *resp);
int fg_api_metrics(fg_req *req, fg_resp *resp);
int fg_api_scenes_list(fg_req *req, fg_resp *resp);
int fg_api_scenes_create(fg_req *req, fg_resp *resp);
int fg_api_scene_get(fg_req *req, fg_resp *resp);
int fg_api_scene_patch(fg_req *req, fg_resp *resp);
int fg_api_scene_delete(fg_req *req, fg_resp *resp);
int fg_api_frames_upload(fg_req *req, fg_resp *resp);
int fg_api_frames_list(fg_req *req, fg_resp *resp);
int fg_api_frame_image(fg_req *req, fg_resp *resp);
int fg_api_scene_import(fg_req *req, fg_resp *resp);
int fg_api_captures_list(fg_req *req, fg_resp *resp);
int fg_api_capture_delete(fg_req *req, fg_resp *resp);
int fg_api_train_start(fg_req *req, fg_resp *resp);
int fg_api_jobs_list(fg_req *req, fg_resp *resp);
int fg_api_job_get(fg_req *req, fg_resp *resp);
int fg_api_job_cancel(fg_req *req, fg_resp *resp);
int fg_api_job_events(fg_req *req, fg_resp *resp);
int fg_api_scene_render(fg_req *req, fg_resp *resp);
int fg_api_scene_heatmap(fg_req *req, fg_resp *resp);
int fg_api_scene_geometry(fg_req *req, fg_resp *resp);
int fg_api_scene_points(fg_req *req, fg_resp *resp);
int fg_api_viewer_index(fg_req *req, fg_resp *resp);
int fg_api_viewer_file(fg_req *req, fg_resp *resp);
int fg_api_embed_text(fg_req *req, fg_resp *resp);
int fg_api_embed_image(fg_req *req, fg_resp *resp);
int fg_api_robot_command(fg_req *req, fg_resp *resp);
int fg_api_robot_command_get(fg_req *req, fg_resp *resp);
int fg_api_robot_get(fg_req *req, fg_resp *resp);
int fg_api_robot_stop(fg_req *req, fg_resp *resp);
int fg_api_robot_reset(fg_req *req, fg_resp *resp);
int fg_api_gripper_get(fg_req *req, fg_resp *resp);
int fg_api_gripper_action(fg_req *req, fg_resp *resp);
int fg_api_tasks_list(fg_req *req, fg_resp *resp);
int fg_api_task_get(fg_req *req, fg_resp *resp);
int fg_api_task_delete(fg_req *req, fg_resp *resp);
int fg_api_task_demo_add(fg_req *req, fg_resp *resp);
int fg_api_task_demo_delete(fg_req *req, fg_resp *resp);
int fg_api_scene_grasps(fg_req *req, fg_resp *resp);
int fg_api_calibration_board(fg_req *req, fg_resp *resp);
int fg_api_cameras_list(fg_req *req, fg_resp *resp);
int fg_api_camera_get(fg_req *req, fg_resp *resp);
int fg_api_camera_capture(fg_req *req, fg_resp *resp);
int fg_api_camera_view_upload(fg_req *req, fg_resp *resp);
int fg_api_camera_views_clear(fg_req *req, fg_resp *resp);
int fg_api_camera_calibrate(fg_req *req, fg_resp *resp);
int fg_api_scene_scan(fg_req *req, fg_resp *resp);
int fg_api_grasp_execute(fg_req *req, fg_resp *resp);
/* api_audit.c: the routes that may move something, each its handler above under the audit
 * log; and the log read back. */
int fg_api_audit_robot_command(fg_req *req, fg_resp *resp);
int fg_api_audit_robot_stop(fg_req *req, fg_resp *resp);
int fg_api_audit_robot_reset(fg_req *req, fg_resp *resp);
int fg_api_audit_scene_scan(fg_req *req, fg_resp *resp);
int fg_api_audit_camera_calibrate(fg_req *req, fg_resp *resp);
int fg_api_audit_gripper_action(fg_req *req, fg_resp *resp);
int fg_api_audit_grasp_execute(fg_req *req, fg_resp *resp);
int fg_api_robot_log(fg_req *req, fg_resp *resp);

/* Runs robot request r (a pick or place the caller built) as POST /v1/robot/commands does:
 * under the request's Idempotency-Key, answering with the command (or its error). */
struct fg_robot_request;
int fg_api_robot_run(fg_req *req, fg_resp *resp, struct fg_robot_request *r);

/* The Idempotency-Key of a request that moves the robot or the gripper, looked up before the
 * handler looks at anything else: a retry gets its first answer even when what it named is
 * gone since (a grasp forgotten at a restart, or stale after a training). Returns 1 when it
 * answered (a replay, a conflict, a malformed key), 0 when the request is to be handled. */
int fg_api_idem_replay(fg_req *req, fg_resp *resp);

/* fg_robot_svc_on_finish hook (ctx: the fg_app): stores the final answer of a command that
 * came with an Idempotency-Key, so that a retry sees how it ended. */
struct fg_robot_cmd_view;
void fg_api_robot_finished(void *ctx, const struct fg_robot_cmd_view *v);

/* Called by fg_api_robot_finished: writes the end of a command that was answered before it
 * ended (wait false) to the audit log. */
void fg_api_audit_finished(fg_app *app, const struct fg_robot_cmd_view *v);

/* Most Server-Sent Events streams (GET /v1/jobs/{id}/events) open at once; more get 503. */
#define FG_API_MAX_EVENT_STREAMS 64

/* api_status.c: the one table from an error's code ("task_not_found") to its HTTP status (500
 * for a code it does not know). A handler answers a service's failure with fg_api_fail. */
int fg_api_status(const char *code);

/* The code of the calling thread's failure rc: the reason it was given (fg_fail_as), else a
 * default of rc (invalid_request for FG_EINVAL, ...; internal_error). */
const char *fg_api_fail_code(int rc);

/* Answers the calling thread's failure rc: its code (fg_api_fail_code), that code's status
 * and fg_error_detail() as the message; memory_limit also gets Retry-After: 1. Returns 0. */
int fg_api_fail(fg_resp *resp, int rc);

/* Shared by handlers: the JSON body as an object, or NULL after answering 400. */
json_t *fg_api_body_object(fg_req *req, fg_resp *resp);

/* Brings info's last job state up to date from the job registry (the scene's own copy lags
 * behind a job that is finishing). */
void fg_api_scene_info_refresh(fg_app *app, fg_scene_info *info);

/* The CLIP model with a reference (fg_clip_model_release), or NULL after answering 409
 * clip_not_configured with a message that says how to configure it. */
struct fg_clip_model;
struct fg_clip_model *fg_api_clip_model(fg_req *req, fg_resp *resp);

/* Answers a failed write to the state dir (store.h: fg_state_write_failed): 507
 * insufficient_storage when the disk is full, else 500 internal_error. Returns 0. */
int fg_api_storage_error(fg_resp *resp, int rc, const char *what);

/* The scene named by the first path parameter with a reference, or NULL after answering 404. */
fg_scene *fg_api_scene_param(fg_req *req, fg_resp *resp);

/* Scene s's field with a reference (fg_field_ref_release), or NULL after answering
 * fg_scene_field_get's failure (409 not_trained, 503 memory_limit). */
fg_field_ref *fg_api_scene_field(fg_scene *s, fg_resp *resp);

/* A scene's trained field with its voxel opacities on a grid of its workspace: what the
 * geometry and the point cloud are made of. */
typedef struct fg_api_solid {
  fg_voxel_grid grid;    /* the workspace at the request's voxel size */
  fg_field_ref *ref;     /* the field; a handler may release it early (and set it NULL) */
  struct fg_voxels *vox; /* the voxel cache's features, when alpha is theirs; else NULL */
  float *own;            /* alpha sampled for this request alone; else NULL */
  const float *alpha;    /* (nz, ny, nx) opacities, vox's or own */
} fg_api_solid;

/* Fills *out for scene s (info: its state now) at voxel_size metres. The opacities come from
 * the field's voxel cache (fg_field_voxels) when the grid is the scene's own (the voxel
 * size of info) and the field has features (only then is there a cache); else they are
 * sampled for this request alone, so that a one-off grid does not evict the cache that
 * heatmaps use. 0 on success (release with fg_api_solid_release); else -1 after answering
 * 400 grid_too_large, 409 not_trained or 500, with *out holding nothing. */
int fg_api_solid_get(fg_scene *s, const fg_scene_info *info, double voxel_size, int n_threads,
                     fg_api_solid *out, fg_resp *resp);

/* Releases what *sv holds (each part may be NULL already). */
void fg_api_solid_release(fg_api_solid *sv);

#endif
