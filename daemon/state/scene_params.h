/* A scene's parameters (its workspace, voxel size, background and field settings) and their
 * file, scene.json in the scene's folder. Plain data and a file: the store (store.h) holds
 * them under the scene's lock. */
#ifndef FG_DAEMON_SCENE_PARAMS_H
#define FG_DAEMON_SCENE_PARAMS_H

#include <stdint.h>

/* The settings of the field a training makes (field/model.h): its cube is field_scale times
 * the workspace's largest extent, and it learns a background colour or not; "auto" asks the
 * training's frames (field/extent.h). */
#define FG_FIELD_SCALE_AUTO 0.0
#define FG_LEARN_BACKGROUND_AUTO (-1)

typedef struct fg_scene_params {
  double workspace_min[3], workspace_max[3]; /* metres, world frame */
  double voxel_size;                         /* metres */
  double background[3];                      /* RGB in [0,1] */
  double field_scale;   /* 1..64, or FG_FIELD_SCALE_AUTO */
  int learn_background; /* 0, 1 or FG_LEARN_BACKGROUND_AUTO */
} fg_scene_params;

/* Checks scene parameters: finite, min < max per axis, 0 < voxel_size, background in [0,1],
 * field_scale auto or in [1, 64], learn_background auto, 0 or 1. FG_EINVAL with a detail. */
int fg_scene_params_validate(const fg_scene_params *p);

/* 1 when a and b are the same parameters. */
int fg_scene_params_equal(const fg_scene_params *a, const fg_scene_params *b);

/* Writes dir/scene.json (atomically) for the scene called name: its parameters and when it
 * was created (Unix milliseconds). The fsutil errors. */
int fg_scene_json_write(const char *dir, const char *name, const fg_scene_params *params,
                        int64_t created_ms);

/* Reads dir/scene.json into *params and *created_ms: FG_EFORMAT naming the file when it is
 * malformed or its parameters are not valid; the field settings are auto when it has none
 * (scenes made before them). */
int fg_scene_json_read(const char *dir, fg_scene_params *params, int64_t *created_ms);

#endif
