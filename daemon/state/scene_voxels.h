/* A scene's trained field and its voxel features, acquired in one place: the field (loaded
 * again when it was evicted), the scene's grid, the field's voxel cache (voxcache.h), and the
 * field let go once the voxels are held, so that a training may replace it meanwhile.
 *
 * Failures carry their reason (core/error.h: fg_fail_as) and a message that names the scene
 * and says what to do: not_trained, memory_limit (the field cannot be loaded now: every
 * loaded one is in use), grid_too_large, no_features, feature_dim_mismatch, internal_error. */
#ifndef FG_DAEMON_STATE_SCENE_VOXELS_H
#define FG_DAEMON_STATE_SCENE_VOXELS_H

#include "store.h"
#include "voxcache.h"

#include "query/grid.h"

/* Scene s's field with a reference (fg_field_ref_release). FG_ENOENT not_trained (saying
 * why when its checkpoint no longer loads); FG_EBUSY or FG_ENOMEM memory_limit. */
int fg_scene_field_get(fg_scene *s, fg_field_ref **out);

/* 0 when field f of scene `scene` has features of D dim (0: of any D); else FG_EINVAL
 * no_features (trained on colour only; purpose ends the message: "a query has nothing to
 * score") or feature_dim_mismatch (trained again, to another D, since a query of dim was
 * checked against the scene). */
int fg_field_features_fit(const fg_field *f, const char *scene, int dim, const char *purpose);

/* The voxel features of ref's field on grid g from the field's voxel cache, built on first use
 * (counted in the metrics and logged for scene `scene`) into *out (fg_voxels_release).
 * internal_error when they cannot be built. */
int fg_field_voxels(fg_field_ref *ref, const fg_voxel_grid *g, const char *scene, int n_threads,
                    fg_voxels **out);

typedef struct fg_scene_voxels {
  fg_voxel_grid grid;           /* the scene's workspace at its voxel size */
  fg_voxels *vox;               /* the field's voxel features on it; NULL when released */
  const fg_voxel_features *vf;  /* vox's */
} fg_scene_voxels;

/* The voxel features of scene s's field on the scene's grid into *out (release with
 * fg_scene_voxels_release), built on first use (counted in the metrics and logged). dim: the
 * D a query was checked against, or 0 for any; purpose as fg_field_features_fit's. Besides
 * the failures of fg_scene_field_get, fg_field_features_fit and fg_field_voxels: FG_ERANGE
 * grid_too_large. On failure *out holds nothing. */
int fg_scene_voxels_acquire(fg_scene *s, int dim, const char *purpose, int n_threads,
                            fg_scene_voxels *out);

/* Lets go of what *sv holds; accepts a zeroed or released one. */
void fg_scene_voxels_release(fg_scene_voxels *sv);

#endif
