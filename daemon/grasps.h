/* The daemon's side of lib/grasp (grasp/grasp.h): demo samples and grasp searches on a
 * scene's voxel features (voxcache.h), the identity of the field a grasp came from, and the
 * recent results that POST /v1/scenes/{s}/grasps/{id}/execute looks grasp ids up in.
 *
 * Why a header of its own: daemon/conf.h and grasp/gripper.h both define fg_gripper_model
 * (the configuration's enum and the library's, with the same names), so no file can include
 * both. Handlers, which see conf.h through api.h, name the gripper by its configuration name
 * ("panda", "robotiq-2f85", "robotiq-2f140"); grasps.c maps the name with
 * fg_gripper_model_parse. Nothing of lib/grasp appears in this header. */
#ifndef FG_DAEMON_GRASPS_H
#define FG_DAEMON_GRASPS_H

#include <stddef.h>
#include <stdint.h>

#include "query/heatmap.h"

#define FG_GRASPS_NAME_MAX 64       /* scene and task names (FG_SCENE_NAME_MAX) */
#define FG_GRASPS_MAX_QUERY_POINTS 1000
#define FG_GRASPS_DEFAULT_QUERY_POINTS 100
#define FG_GRASPS_DEFAULT_STD_M 0.0075
#define FG_GRASPS_DEFAULT_ROTATIONS 24
#define FG_GRASPS_MAX_TOP_K 100
#define FG_GRASPS_MIN_ROTATIONS 8
#define FG_GRASPS_MAX_ROTATIONS 4096
#define FG_GRASPS_LOG_PER_SCENE 1000 /* grasps execute can find, per scene (newest) */
#define FG_GRASPS_LOG_SCENES 64      /* scenes whose grasps are kept (most recently used) */

/* ---- field samples and searches ----------------------------------------------------------- */

/* fg_grasp_query_points: n points (n, 3) of N(mean_m, std_m^2 I) in the gripper frame
 * (metres) into the caller's p_gripper. FG_EINVAL with a detail for bad arguments. */
int fg_grasps_query_points(int n, const double mean_m[3], double std_m, float *p_gripper);

/* The largest opening of gripper model `gripper` (a configuration name) into *stroke_m.
 * FG_EINVAL for an unknown name. */
int fg_grasps_stroke(const char *gripper, double *stroke_m);

/* The F3RM sample z (n, D) = alpha f at the query points p_gripper (n, 3) placed by
 * T_world_gripper (row-major 4x4, metres), D = fg_voxel_features_dim(vf), into the caller's
 * z. vf stays the caller's. FG_EINVAL, FG_ENOMEM. */
int fg_grasps_sample(const fg_voxel_features *vf, const double T_world_gripper[16],
                     const float *p_gripper, int n, float *z, int n_threads);

/* A search (fg_grasp_search) on the voxel features vf. Arrays stay the caller's. */
typedef struct fg_grasps_query {
  const fg_voxel_features *vf;
  int n_points;                  /* N_q */
  int dim;                       /* D, the features' */
  const float *p_gripper;        /* (N_q, 3) gripper frame, metres */
  const float *Z;                /* (N_q, D) the task embedding */
  const float *q;                /* (D) unit language query, or NULL */
  const uint8_t *candidate_mask; /* (nz, ny, nx) or NULL */
  const char *gripper;           /* configuration name of the model */
  double width_m;                /* opening for the collision check, 0..stroke */
  int top_k;                     /* 1..FG_GRASPS_MAX_TOP_K */
  int rotations;                 /* FG_GRASPS_MIN_ROTATIONS..FG_GRASPS_MAX_ROTATIONS */
  uint64_t seed;
  int n_threads;
} fg_grasps_query;

typedef struct fg_grasps_pose {
  double T_world_gripper[16]; /* row-major, metres */
  double score;               /* cos(z_T, Z) */
  double cost;                /* J or J_lang, lower is better */
  int collision_free;
} fg_grasps_pose;

typedef struct fg_grasps_result {
  fg_grasps_pose *poses; /* (n) best first; owned; NULL when n = 0 */
  int n;
  size_t candidates, poses_scored, poses_optimised, evaluations;
  int rotations, iterations;
  double seconds;
  const char *reason;    /* static text when n = 0, else NULL */
} fg_grasps_result;

/* Builds the grasp field of vf and runs the search. On success the caller owns what *out
 * holds (fg_grasps_result_release), an empty result included; on failure *out holds
 * nothing. FG_EINVAL with a detail (bad arguments, an unknown gripper, a width beyond its
 * stroke), FG_ERANGE (too many poses), FG_ENOMEM. */
int fg_grasps_find(const fg_grasps_query *q, fg_grasps_result *out);

/* Frees what *r owns and zeroes it; accepts a zeroed struct. */
void fg_grasps_result_release(fg_grasps_result *r);

/* The identity of the field state vf was sampled from: a 64-bit hash of its trained_steps,
 * grid, D, alpha grid and stored features. Equal for the same field after a restart (the
 * cache is a deterministic function of the field), different after a training commits a
 * field that differs in any voxel. Reads every byte of the cache once (about a millisecond
 * per megabyte). */
uint64_t fg_grasps_field_version(const fg_voxel_features *vf);

/* ---- recent results ----------------------------------------------------------------------- */

/* A grasp a search returned, as execute needs it. */
typedef struct fg_grasp_entry {
  char id[24];                          /* "g" + 16 hex digits */
  char scene[FG_GRASPS_NAME_MAX + 1];
  char task[FG_GRASPS_NAME_MAX + 1];
  uint64_t field_version;               /* fg_grasps_field_version of the field searched */
  double T_world_gripper[16];           /* row-major, metres */
  double width_m;
  int place;                            /* 1: the task is a place task, 0: a grasp task */
} fg_grasp_entry;

/* The newest FG_GRASPS_LOG_PER_SCENE grasps of each of the FG_GRASPS_LOG_SCENES scenes
 * used most recently, in memory (they do not survive a restart). Thread-safe. */
typedef struct fg_grasp_log fg_grasp_log;

/* An empty log; the caller owns *out (fg_grasp_log_free). FG_ENOMEM. */
int fg_grasp_log_new(fg_grasp_log **out);
/* Accepts NULL. */
void fg_grasp_log_free(fg_grasp_log *log);

/* Records n entries (copied); an entry whose id is there already replaces it. */
void fg_grasp_log_put(fg_grasp_log *log, const fg_grasp_entry *e, int n);

/* Copies the entry of grasp id of scene into *out: 0, or FG_ENOENT. */
int fg_grasp_log_get(fg_grasp_log *log, const char *scene, const char *id, fg_grasp_entry *out);

#endif
