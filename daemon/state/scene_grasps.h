/* Demos and grasps on a scene: a demo sampled on the scene's voxel features and added to its
 * task; a scene's grasps: a task of the library (or the one a query retrieves) planned on the
 * scene's current voxel features by lib/grasp (grasp/plan.h), each grasp given an id and kept
 * in the grasp log for execution; and a logged grasp looked up again for execution, refused
 * when the scene's field has changed since it was planned.
 *
 * Ids: "g" + 16 hex digits mixing the field's identity (fg_grasp_log_field_version), the
 * request (its canonical text, with the scene's name) and the rank, so the same request on
 * the same field gets the same ids, also after a restart.
 *
 * Failures carry their reason (core/error.h), besides scene_voxels.h's: for demos
 * pose_outside_workspace, query_points_mismatch, kind_mismatch, feature_dim_mismatch,
 * too_many_demos, invalid_query_points, demo_in_free_space, task_unreadable, and a failed
 * write's (fg_state_write_failed); for grasps task_not_found, task_empty,
 * feature_dim_mismatch, no_matching_task, invalid_request (the search refused the request),
 * grasp_not_found, grasp_stale, internal_error. */
#ifndef FG_DAEMON_STATE_SCENE_GRASPS_H
#define FG_DAEMON_STATE_SCENE_GRASPS_H

#include "grasp_log.h"
#include "store.h"
#include "tasks.h"

#include "grasp/plan.h"

/* Demo d (all but its dim and z, which are sampled here) of task `name` (t: the task now, or
 * NULL for a new one) shown on scene s: sampled at its pose on the scene's voxel features and
 * added to the task (fg_tasks_add_demo). *task gets the new snapshot (fg_task_unref) and *id
 * the demo's id. */
int fg_scene_demo_add(fg_scene *s, fg_tasks *ts, const char *name, const fg_task *t,
                      fg_task_demo_new *d, int n_threads, const fg_task **task, int *id);

/* Task `name` of ts with a reference (fg_task_unref), when it has a demo. FG_ENOENT
 * task_not_found, FG_EINVAL task_empty. */
int fg_tasks_get_demonstrated(fg_tasks *ts, const char *name, const fg_task **out);

typedef struct fg_scene_grasps_req {
  const fg_task *task;     /* the task (the caller keeps its reference), or NULL: retrieved */
  const fg_query *query;   /* NULL: none; else of the scene's D, checked by the caller */
  int language_weight;     /* 1: the query also weights the cost */
  fg_grasp_options opt;    /* the search's: the request's top_k, rotations and seed; the
                            * gripper, the motion limits, the robot's retreat, n_threads */
  const char *request;     /* the request's canonical text, hashed into the ids */
} fg_scene_grasps_req;

typedef struct fg_scene_grasps {
  fg_grasp_plan plan;
  const fg_task **tasks;   /* (n_tasks) references: the tasks the plan's indices name */
  int n_tasks;
  fg_grasp_entry *entries; /* (plan.result.n) the grasps as logged, with their ids */
} fg_scene_grasps;

/* Plans r on scene s into *out (fg_scene_grasps_release) and puts the grasps in log. Also a
 * success when nothing was found (plan.result.n 0 with a reason). */
int fg_scene_grasps_plan(fg_scene *s, fg_tasks *ts, fg_grasp_log *log,
                         const fg_scene_grasps_req *r, fg_scene_grasps *out);

/* Accepts a zeroed struct. */
void fg_scene_grasps_release(fg_scene_grasps *g);

/* The grasp `id` of scene s from log into *out, when the scene's field is still the one it
 * was planned on. FG_ENOENT grasp_not_found, FG_EINVAL grasp_stale (trained again, or its
 * workspace changed), memory_limit, internal_error. */
int fg_scene_grasp_current(fg_scene *s, fg_grasp_log *log, const char *id, int n_threads,
                           fg_grasp_entry *out);

#endif
