/* The scene store: every scene and frame the daemon keeps, under the state dir.
 *
 *   <state>/scenes/<name>/scene.json          parameters (atomic rewrite)
 *   <state>/scenes/<name>/frames/000012.fgf   one frame (lib/io/frame.h), never rewritten
 *
 * A frame is written completely to ".incoming-*" beside its final name, then renamed into
 * place under the scene's lock, so a crash at any moment leaves either no frame or a whole
 * one. Start-up removes ".incoming-*", "*.tmp.*" and deleted scenes' ".trash-*" folders.
 * All functions are thread-safe. */
#ifndef FG_DAEMON_STORE_H
#define FG_DAEMON_STORE_H

#include <stddef.h>
#include <stdint.h>

#include "io/frame.h"

typedef struct fg_store fg_store;
typedef struct fg_scene fg_scene;

typedef struct fg_scene_params {
  double workspace_min[3], workspace_max[3]; /* metres, world frame */
  double voxel_size;                         /* metres */
  double background[3];                      /* RGB in [0,1] */
} fg_scene_params;

/* A consistent copy of a scene's description, taken under its lock. */
typedef struct fg_scene_info {
  char name[65];
  fg_scene_params params;
  int declared_in_config;
  int64_t created_ms;
  size_t n_frames;
  int feature_dim; /* 0 while no frame has features */
} fg_scene_info;

/* Opens (creating if needed) the state dir and loads every scene's description and frame
 * headers. Scenes or frames that cannot be read are logged and left on disk untouched.
 * The caller owns *out (fg_store_close). */
int fg_store_open(fg_store **out, const char *state_dir);
void fg_store_close(fg_store *store);

/* Checks scene parameters: finite, min < max per axis, 0 < voxel_size, background in [0,1].
 * FG_EINVAL with a detail. */
int fg_scene_params_validate(const fg_scene_params *p);

/* Creates a scene. FG_EEXIST if the name is taken, FG_EINVAL for a bad name or parameters. */
int fg_store_create(fg_store *store, const char *name, const fg_scene_params *params,
                    int declared_in_config);

/* Makes the declared scenes exist with the declared parameters (creating them, or rewriting
 * the parameters of an existing scene that differ) and clears the declared flag of the rest.
 * Logs what it changes; returns the first error but goes on with the other scenes. */
struct fg_conf;
int fg_store_sync_declared(fg_store *store, const struct fg_conf *conf);

/* Returns a scene with a reference the caller drops with fg_scene_unref; NULL if absent. */
fg_scene *fg_store_get(fg_store *store, const char *name);
void fg_scene_unref(fg_scene *scene);

/* Removes a scene and its data. FG_ENOENT if absent. Requests still holding the scene finish
 * against a deleted scene and their writes fail with FG_ENOENT. */
int fg_store_delete(fg_store *store, const char *name);

/* Descriptions of every scene, sorted by name, in a malloc'd array the caller frees. */
int fg_store_list(fg_store *store, fg_scene_info **out, size_t *n);

/* Totals for metrics. */
void fg_store_totals(fg_store *store, size_t *scenes, size_t *frames);

void fg_scene_get_info(fg_scene *scene, fg_scene_info *out);

/* Adds prepared frames to a scene, all or none: their feature dimension must agree with each
 * other and with the scene's (FG_EINVAL with a detail otherwise). Frame files are written in
 * parallel outside the scene's lock, then renamed into place under it. On success
 * first_index receives the number of frames[0]; the others follow consecutively. The frames
 * stay owned by the caller. `source` of each frame is stored as given. */
int fg_scene_add_frames(fg_scene *scene, const fg_frame *frames, size_t n, int *first_index);

/* Copies the headers of every frame (rgb and feat NULL) and their numbers, sorted by number,
 * into malloc'd arrays the caller frees. */
int fg_scene_list_frames(fg_scene *scene, fg_frame **frames, int **indices, size_t *n);

#endif
