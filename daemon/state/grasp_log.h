/* The grasps a search returned, kept for POST /v1/scenes/{s}/grasps/{id}/execute, and the
 * identity of the field each came from, which tells execute that a grasp is stale.
 *
 * The search itself is lib/grasp's (grasp/grasp.h), on the grasp field a scene's voxels keep
 * (voxcache.h); handlers call it directly. What lives here is only the daemon's own: grasp
 * ids outlive the request that made them, so the log keeps them in memory (not across a
 * restart), and a field version that is the same after a restart and differs after a
 * training lets a grasp id name "this pose on this field". */
#ifndef FG_DAEMON_GRASP_LOG_H
#define FG_DAEMON_GRASP_LOG_H

#include <stdint.h>

#include "conf/conf.h"
#include "query/voxfeat.h"

#define FG_GRASP_LOG_PER_SCENE 1000 /* grasps execute can find, per scene (newest) */
#define FG_GRASP_LOG_SCENES 64      /* scenes whose grasps are kept (most recently used) */

/* The identity of the field state vf was sampled from: a 64-bit hash of its trained_steps,
 * grid, D, alpha grid and stored features. Equal for the same field after a restart (the
 * cache is a deterministic function of the field), different after a training commits a
 * field that differs in any voxel. Reads every byte of the cache once (about a millisecond
 * per megabyte). */
uint64_t fg_grasp_log_field_version(const fg_voxel_features *vf);

/* A grasp a search returned, as execute needs it. */
typedef struct fg_grasp_entry {
  char id[24];                          /* "g" + 16 hex digits */
  char scene[FG_SCENE_NAME_MAX + 1];
  char task[FG_SCENE_NAME_MAX + 1];     /* task names follow the scene name rules */
  uint64_t field_version;               /* fg_grasp_log_field_version of the field searched */
  double T_world_gripper[16];           /* row-major, metres */
  double width_m;
  double approach_m;                    /* the task's approach: where pre_grasp stands */
  int place;                            /* 1: the task is a place task, 0: a grasp task */
} fg_grasp_entry;

/* The newest FG_GRASP_LOG_PER_SCENE grasps of each of the FG_GRASP_LOG_SCENES scenes used
 * most recently, in memory (they do not survive a restart). Thread-safe. */
typedef struct fg_grasp_log fg_grasp_log;

/* An empty log; the caller owns *out (fg_grasp_log_free). FG_ENOMEM. */
int fg_grasp_log_new(fg_grasp_log **out);
/* Accepts NULL. */
void fg_grasp_log_free(fg_grasp_log *log);

/* Records n entries (copied; they stay the caller's), all of one scene; an entry whose id is
 * there already replaces it. When memory for a new scene's ring runs out nothing is kept, and
 * execute answers 404 for those ids. */
void fg_grasp_log_put(fg_grasp_log *log, const fg_grasp_entry *e, int n);

/* Copies the entry of grasp id of scene into *out: 0, or FG_ENOENT. */
int fg_grasp_log_get(fg_grasp_log *log, const char *scene, const char *id, fg_grasp_entry *out);

#endif
