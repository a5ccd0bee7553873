/* The scene store: every scene and frame the daemon keeps, under the state dir.
 *
 *   <state>/scenes/<name>/scene.json          parameters (atomic rewrite)
 *   <state>/scenes/<name>/frames/000012.fgf   one frame (lib/io/frame.h), never rewritten;
 *                                             removed with its capture
 *   <state>/scenes/<name>/field.fgc           the trained field (field/checkpoint.h)
 *   <state>/scenes/<name>/field.next.fgc      a training's checkpoint before it is committed
 *   <state>/scenes/<name>/last_job.json       the scene's last job (jobs.h)
 *   <state>/scenes/<name>/clip/000012.<fingerprint>.npy
 *                                             CLIP features of frame 12 computed by a training
 *                                             (clip_features.h), keyed by the model
 *
 * A frame is written completely to ".incoming-*" beside its final name, then renamed into
 * place under the scene's lock, so a crash at any moment leaves either no frame or a whole
 * one. Start-up removes ".incoming-*", "*.tmp.*" and deleted scenes' ".trash-*" folders.
 * All functions are thread-safe. */
#ifndef FG_DAEMON_STORE_H
#define FG_DAEMON_STORE_H

#include <stddef.h>
#include <stdint.h>

#include "field/model.h"
#include "io/frame.h"
#include "scene_params.h"
#include "voxcache.h"

typedef struct fg_store fg_store;
typedef struct fg_scene fg_scene;

/* A trained field shared by reference count: the scene holds one reference, every render
 * in flight another, so a training that installs a new field never pulls one from under a
 * render. Each carries the field's voxel feature cache (voxcache.h), which therefore goes
 * with the field it was built from.
 *
 * Memory: at most max_loaded_fields fields (with their voxel caches and grasp fields, the
 * big allocations) stay loaded. A trained scene whose field is not loaded keeps it in
 * field.fgc and loads it again at its next fg_scene_field_acquire, after evicting the least
 * recently acquired field that nothing holds (the scene's reference is its only one) and
 * that field.fgc can bring back (a partial field still in field.next.fgc stays). An evicted
 * field lives on for the requests that hold it. */
typedef struct fg_field_ref fg_field_ref;

/* The caps of the store ([state] max_scenes and max_loaded_fields); 0 stands for no
 * limit. */
typedef struct fg_store_limits {
  size_t max_scenes;        /* scenes fg_store_create makes, counting the existing ones */
  size_t max_loaded_fields; /* trained fields held in memory at once */
} fg_store_limits;

#define FG_JOB_ID_MAX 40

/* A consistent copy of a scene's description, taken under its lock. */
typedef struct fg_scene_info {
  char name[65];
  fg_scene_params params;
  int declared_in_config;
  int64_t created_ms;
  size_t n_frames;
  size_t n_captures;      /* captures that hold frames */
  int64_t latest_capture; /* the newest capture that holds frames (a training's default) */
  int feature_dim; /* D of the frames' uploaded features; 0 while no frame has any */
  int field_feature_dim; /* D of the trained field (uploaded or CLIP features); 0 when
                            untrained or trained on colour only */
  int trained;     /* the scene holds a field */
  int loaded;      /* that field is in memory now (else it is loaded at its next use) */
  int partial;     /* that field is the checkpoint of an interrupted training */
  int64_t trained_steps;
  double field_box_min[3], field_box_size; /* the trained field's cube (metres) ... */
  int field_learn_background;              /* ... and background; zero when untrained */
  int64_t checkpoint_bytes;        /* size of the field's checkpoint file; 0 when untrained */
  char checkpoint_error[512];      /* why the checkpoint did not load; "" when it did */
  fg_voxcache_info voxel_cache;    /* the field's voxel features (all zero when untrained) */
  char last_job_id[FG_JOB_ID_MAX]; /* "" when the scene never had a job */
  char last_job_state[16];
} fg_scene_info;

/* Opens (creating if needed) the state dir and loads every scene's description, frame
 * headers and trained field. Scenes or frames that cannot be read are logged and left on
 * disk untouched. A field.fgc that does not load is logged and left on disk; its scene is
 * then untrained and reports the reason (checkpoint_error). A field.next.fgc left by a
 * training the daemon did not finish is loaded as the field (partial) when there is no
 * field.fgc, else removed. Every checkpoint is read once, so that a bad one shows at
 * start-up, but only limits->max_loaded_fields of them stay loaded (partial ones always do:
 * field.fgc cannot bring them back). Scenes on disk beyond limits->max_scenes are all
 * opened (nothing is dropped); only creation is refused. The caller owns *out
 * (fg_store_close). */
int fg_store_open(fg_store **out, const char *state_dir, const fg_store_limits *limits);
void fg_store_close(fg_store *store);

/* Applies new caps (a configuration reload): fields over the new max_loaded_fields are
 * evicted now as far as nothing holds them, the rest as they are released and others
 * acquired. */
void fg_store_set_limits(fg_store *store, const fg_store_limits *limits);

/* Creates a scene. FG_EEXIST if the name is taken, FG_EINVAL for a bad name or parameters,
 * FG_ERANGE when the store holds max_scenes scenes already (the detail names the limit and
 * the key that raises it). */
int fg_store_create(fg_store *store, const char *name, const fg_scene_params *params,
                    int declared_in_config);

/* Makes the declared scenes exist with the declared parameters (creating them, or rewriting
 * the parameters of an existing scene that differ) and clears the declared flag of the rest.
 * Logs what it changes; returns the first error but goes on with the other scenes. */
struct fg_conf;
int fg_store_sync_declared(fg_store *store, const struct fg_conf *conf);

/* Returns a scene with a reference the caller drops with fg_scene_unref; NULL if absent. */
fg_scene *fg_store_get(fg_store *store, const char *name);
/* Takes another reference to a scene the caller holds one of. */
void fg_scene_ref(fg_scene *scene);
void fg_scene_unref(fg_scene *scene);

/* Sets the scene's field settings (fg_scene_params.field_scale and learn_background; NULL
 * keeps one as it is) and writes scene.json; trainings that start afterwards use them.
 * FG_ENOENT when the scene was deleted; FG_EINVAL (with a detail) for
 * values fg_scene_params_validate refuses; FG_EPERM declared_in_config for a scene of the
 * configuration file (its settings are the file's: a reload would undo them); the state
 * dir's write errors (fg_state_write_failed), the settings then unchanged. */
int fg_scene_set_field_settings(fg_scene *s, const double *field_scale,
                                const int *learn_background);

/* Removes a scene and its data. FG_ENOENT if absent. Requests still holding the scene finish
 * against a deleted scene and their writes fail with FG_ENOENT. */
int fg_store_delete(fg_store *store, const char *name);

/* Descriptions of every scene, sorted by name, in a malloc'd array the caller frees. */
int fg_store_list(fg_store *store, fg_scene_info **out, size_t *n);

/* Totals for metrics. */
void fg_store_totals(fg_store *store, size_t *scenes, size_t *frames);
size_t fg_store_trained(fg_store *store);
/* Heap bytes of every scene's voxel feature cache (voxcache.h). */
size_t fg_store_voxel_cache_bytes(fg_store *store);

/* The trained fields in memory now, and since the store opened: the loads on demand and the
 * evictions of fields to stay within max_loaded_fields. */
typedef struct fg_store_field_stats {
  size_t loaded;
  size_t max_loaded; /* 0: no limit */
  unsigned long long loads, evictions;
} fg_store_field_stats;
void fg_store_field_stats_get(fg_store *store, fg_store_field_stats *out);

/* The scene's folder and name; constant for the scene's lifetime, owned by the scene. */
const char *fg_scene_dir(const fg_scene *scene);
const char *fg_scene_name(const fg_scene *scene);

void fg_scene_get_info(fg_scene *scene, fg_scene_info *out);

/* Adds prepared frames to a scene, all or none: their feature dimension must agree with each
 * other and with the scene's (FG_EINVAL with a detail otherwise). Frame files are written in
 * parallel outside the scene's lock, then renamed into place under it. On success
 * first_index receives the number of frames[0]; the others follow consecutively. The frames
 * stay owned by the caller. `source` of each frame is stored as given; a frame whose
 * `capture` is 0 is given the newest capture (fg_scene_latest_capture; a new one when the
 * scene has none) before it is written, which the caller then reads in frames[i].capture.
 * A capture above every one the scene has makes it the newest. */
int fg_scene_add_frames(fg_scene *scene, fg_frame *frames, size_t n, int *first_index);

/* Copies the headers of every frame (rgb and feat NULL) and their numbers, sorted by number,
 * into malloc'd arrays the caller frees. */
int fg_scene_list_frames(fg_scene *scene, fg_frame **frames, int **indices, size_t *n);

/* Loads the frames of the captures captures[0..n_captures) whole (pixels and features, CRC
 * checked; every frame when captures is NULL), sorted by number, into a malloc'd array; on
 * success the caller owns it (fg_scene_frames_free) and, when indices is not NULL, the
 * malloc'd array of the frames' numbers in *indices (free). *n may be 0. stop, when not
 * NULL, is asked between frames and ends the load with FG_ECANCELED when it returns
 * nonzero. */
int fg_scene_load_frames(fg_scene *scene, const int64_t *captures, size_t n_captures,
                         fg_frame **frames, int **indices, size_t *n, int (*stop)(void *),
                         void *stop_ud);
void fg_scene_frames_free(fg_frame *frames, size_t n);

/* Loads frame number `number` whole (pixels, features, depth; CRC checked) into *out, which
 * the caller then owns (fg_frame_clear); on failure *out holds nothing. FG_ENOENT when the
 * scene has no frame of that number, else the errors of fg_frame_load, with a detail. */
int fg_scene_load_frame(fg_scene *scene, int number, fg_frame *out);

/* ---- captures ----
 * A capture is the scene at one moment: the frames of one scan, or of one upload session.
 * Every frame belongs to one (fg_frame.capture), numbered from 1 in the order the scene
 * hands them out; frames stored before captures existed are in capture 1. A capture exists
 * while it holds frames. */

#define FG_CAPTURE_MAX INT64_C(1000000000) /* the largest capture number a client may give */

typedef struct fg_scene_capture_info {
  int64_t capture;
  size_t n_frames;
  size_t n_depth;              /* of those, frames with a depth map */
  size_t n_robot_pose;         /* of those, frames with the robot's TCP pose */
  int first_frame, last_frame; /* the numbers of its first and last frames */
  int64_t first_ms, last_ms;   /* when its first and last frames were stored */
} fg_scene_capture_info;

/* The captures that hold frames, by number, in a malloc'd array the caller frees (*n may be
 * 0). */
int fg_scene_list_captures(fg_scene *scene, fg_scene_capture_info **out, size_t *n);

/* The newest capture: the highest the scene handed out (fg_scene_new_capture) or stored a
 * frame with; 0 when there is none. After a restart or a deletion, the highest that holds
 * frames. */
int64_t fg_scene_latest_capture(fg_scene *scene);

/* Hands out a new capture, above every one the scene has or handed out, and makes it the
 * newest (a scan takes one before its first frame). */
int64_t fg_scene_new_capture(fg_scene *scene);

/* Removes every frame of the capture, and their cached CLIP features, from disk and from the
 * scene; the newest capture is then the highest left. A crash half way is finished at the
 * next start (the frames to remove are listed first). *n_removed (may be NULL) receives how
 * many. FG_ENOENT when the capture holds no frame (or the scene was deleted), FG_EIO. */
int fg_scene_delete_capture(fg_scene *scene, int64_t capture, size_t *n_removed);

/* ---- the trained field ---- */

/* The scene's field with a reference the caller drops with fg_field_ref_release, loaded
 * from field.fgc first when it is not in memory (see fg_field_ref for the eviction). *out is
 * NULL and 0 returned when the scene is untrained, which it becomes, with the reason in its
 * checkpoint_error, when field.fgc no longer loads. FG_EBUSY with a detail when the field is
 * not loaded and cannot be: max_loaded_fields are loaded and every one is in use (send the
 * request again later); FG_ENOMEM. The field is read-only while shared. */
int fg_scene_field_acquire(fg_scene *scene, fg_field_ref **out);
const fg_field *fg_field_ref_field(const fg_field_ref *ref);
void fg_field_ref_release(fg_field_ref *ref);
/* The field's voxel feature cache (voxcache.h), owned by ref and living as long as it. */
fg_voxcache *fg_field_ref_voxcache(fg_field_ref *ref);

/* Commits a finished training: renames next_path (field's checkpoint, already written in the
 * scene's folder) over field.fgc and makes field the scene's field for new renders (renders
 * in flight finish with the old one). On success the scene owns field; when the scene had no
 * field loaded and no other can be evicted to stay within max_loaded_fields, field is freed
 * at once and loaded from field.fgc at its first use. FG_ENOENT when the
 * scene was deleted meanwhile (next_path is removed; field stays the caller's), FG_EIO when
 * the rename fails (field stays the caller's, field.fgc is untouched). */
int fg_scene_commit_field(fg_scene *scene, fg_field *field, const char *next_path);

/* When the scene's field was loaded from field.next.fgc (partial), renames that file to
 * field.fgc, so that a training about to overwrite or remove field.next.fgc cannot lose it.
 * The scene goes on reporting partial until a training commits. Logs what it does. */
void fg_scene_keep_partial(fg_scene *scene);

/* 1 when field.next.fgc was in the scene's folder as the store opened (before the start-up
 * loaded or removed it). A training that recorded itself committing (jobs.c) and whose
 * field.next.fgc was gone by then had renamed it over field.fgc: it finished. */
int fg_scene_had_next_checkpoint(fg_scene *scene);

/* Records the scene's last job for its description (jobs.c keeps it current). */
void fg_scene_set_last_job(fg_scene *scene, const char *id, const char *state);

/* Whether the scene was deleted (a job holding it must not write into its folder). */
int fg_scene_deleted(fg_scene *scene);

/* Wraps the failure rc of a write to the state dir: insufficient_storage when the disk (or
 * the quota) is full (FG_ENOSPC), saying that nothing was stored and to retry once space is
 * freed; else internal_error. `what` says what was not stored ("the frame"); the message ends
 * with the failure's detail. Returns rc. */
int fg_state_write_failed(int rc, const char *what);

#endif
