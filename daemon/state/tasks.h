/* The demonstration library: tasks ("pick up the mug by its handle") and their demos, each a
 * gripper pose on a scene with the F3RM sample z of the field at the task's query points,
 * kept under the state dir:
 *
 *   <state>/tasks/<name>/task.json        the task and its demos (atomic rewrite)
 *   <state>/tasks/<name>/demo-<id>.npy    float32 [N_q, D]: the demo's z
 *
 * A demo stores z, not a reference to its scene, so it stays valid after the scene is
 * trained again or deleted. The task's embedding Z is the mean of its demos' z.
 *
 * Writes are ordered so that a crash or kill -9 at any moment leaves a task that loads: a
 * new demo's .npy is written (atomically) before the task.json that names it, a deleted
 * demo leaves task.json before its .npy is removed, a deleted task is renamed to
 * ".trash-*" before it is removed. Start-up removes ".trash-*" folders, "*.tmp.*" files and
 * demo files that task.json does not name; a task that does not load is logged and left on
 * disk untouched (and its name refused for new demos until it is fixed or removed).
 *
 * Readers get immutable snapshots (fg_task) by reference count: a change builds a new
 * snapshot and swaps it in, so a grasp search never sees half a change. Changes are
 * serialised. All functions are thread-safe. */
#ifndef FG_DAEMON_TASKS_H
#define FG_DAEMON_TASKS_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

#include "conf/conf.h" /* FG_SCENE_NAME_MAX: task names follow the scene name rules */

#define FG_TASK_MAX_DEMOS 256
#define FG_TASK_DEFAULT_APPROACH_M 0.10

typedef enum { FG_TASK_GRASP = 0, FG_TASK_PLACE = 1 } fg_task_kind;

const char *fg_task_kind_name(fg_task_kind k); /* "grasp", "place" */

typedef struct fg_task_demo {
  int id;                               /* 1, 2, ... never reused within the task */
  char scene[FG_SCENE_NAME_MAX + 1];    /* the scene it was shown on */
  double T_world_gripper[16];           /* row-major, metres */
  fg_task_kind kind;
  double width_m;                       /* gripper opening */
  double approach_m;                    /* pre-grasp distance along the gripper's -z */
  int64_t created_ms;                   /* Unix time */
  const float *z;                       /* (n_points, dim), owned by the snapshot */
} fg_task_demo;

/* A task as one immutable snapshot; every pointer is owned by it. */
typedef struct fg_task {
  char name[FG_SCENE_NAME_MAX + 1];
  int64_t created_ms;
  fg_task_kind kind;         /* its demos' (all alike) */
  int dim;                   /* D of its demos' z; 0 while it has none */
  int n_points;              /* N_q */
  int qp_layout;             /* query points (grasp.h): fg_grasp_qp_layout, gripper frame ... */
  double qp_mean_m[3];       /* ... the centre, metres; */
  double qp_std_m;           /* the Gaussian's std (FG_GRASP_QP_GAUSSIAN), or */
  double qp_size_m[3];       /* the box's edges (FG_GRASP_QP_BOX); the other is 0 */
  const float *p_gripper;    /* (n_points, 3) */
  double width_m;            /* mean of the demos' widths; 0 without demos */
  double approach_m;         /* mean of the demos' approach distances; 0 without demos */
  int next_id;
  int n_demos;
  const fg_task_demo *demos; /* (n_demos) by id */
  const float *Z;            /* (n_points, dim) mean of the demos' z; NULL without demos */
} fg_task;

typedef struct fg_tasks fg_tasks;

/* Opens (creating) <state_dir>/tasks and loads every task, as described above. The caller
 * owns *out (fg_tasks_free). FG_EIO when the folder cannot be made or read, FG_ENOMEM. */
int fg_tasks_open(fg_tasks **out, const char *state_dir);
/* Accepts NULL. */
void fg_tasks_free(fg_tasks *ts);

/* Task `name` with a reference the caller drops with fg_task_unref; NULL when absent. */
const fg_task *fg_tasks_get(fg_tasks *ts, const char *name);
/* Accepts NULL. */
void fg_task_unref(const fg_task *t);
/* Another reference to t (fg_task_unref); returns t. */
const fg_task *fg_task_ref(const fg_task *t);

/* Every task by name, each with a reference, in a malloc'd array; the caller drops them with
 * fg_tasks_list_free. FG_ENOMEM. */
int fg_tasks_list(fg_tasks *ts, const fg_task ***out, size_t *n);
void fg_tasks_list_free(const fg_task **list, size_t n);

/* A demo to add: its pose and the sample z taken at the query points it names. */
typedef struct fg_task_demo_new {
  const char *scene;
  double T_world_gripper[16];
  fg_task_kind kind;
  double width_m, approach_m;
  int n_points;
  int qp_layout;  /* as fg_task's */
  double qp_mean_m[3], qp_std_m, qp_size_m[3];
  int dim;
  const float *z; /* (n_points, dim), the caller's */
} fg_task_demo_new;

/* Why a demo does not fit a task. */
typedef enum {
  FG_TASK_FITS = 0,
  FG_TASK_QUERY_POINTS_DIFFER, /* other query points than the task's */
  FG_TASK_KIND_DIFFERS,        /* a place demo for a grasp task or the reverse */
  FG_TASK_DIM_DIFFERS,         /* a scene of another feature dimension */
  FG_TASK_FULL,                /* FG_TASK_MAX_DEMOS demos already */
} fg_task_fit;

/* The query points of task t as the API and task.json show them: {"n", "layout":
 * "gaussian", "std", "mean"} or {"n", "layout": "box", "size", "mean"}. NULL when out of
 * memory; the caller owns the reference. */
json_t *fg_task_query_points_json(const fg_task *t);

/* Whether demo d fits task t (NULL: a new task, which any demo fits; a task without demos
 * takes everything from its next demo). When it does not, records a detail that says why and
 * how to fix it (fg_error_detail). Only d's query point parameters, kind and dim are read. */
fg_task_fit fg_task_check_demo(const fg_task *t, const fg_task_demo_new *d);

/* Adds demo d to task `name` (created by it when absent), after checking it again under the
 * store's lock. On success *task (may be NULL) receives the new snapshot with a reference and
 * *demo_id the demo's id. Errors: FG_EEXIST with *fit set when it does not fit (detail as
 * fg_task_check_demo); FG_EBUSY when a task folder of that name is on disk but did not load
 * at start-up (detail says where); FG_EIO, FG_ENOMEM. Nothing is stored on failure. */
int fg_tasks_add_demo(fg_tasks *ts, const char *name, const fg_task_demo_new *d,
                      fg_task_fit *fit, const fg_task **task, int *demo_id);

/* Removes demo id of task `name`. On success *task (may be NULL) receives the new snapshot.
 * FG_ENOENT (no such task), FG_ERANGE (no such demo), FG_EIO, FG_ENOMEM. */
int fg_tasks_delete_demo(fg_tasks *ts, const char *name, int id, const fg_task **task);

/* Removes task `name` with its demos. FG_ENOENT, FG_EIO. */
int fg_tasks_delete(fg_tasks *ts, const char *name);

#endif
