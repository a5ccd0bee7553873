/* A scene's field and voxel features, acquired in one place (scene_voxels.h). */
#include "scene_voxels.h"

#include "metrics/metrics.h"

#include "core/error.h"
#include "core/log.h"

#include <string.h>

int fg_scene_field_get(fg_scene *s, fg_field_ref **out) {
  *out = NULL;
  const int rc = fg_scene_field_acquire(s, out);
  if (rc == FG_EBUSY || rc == FG_ENOMEM)
    return fg_fail_as(rc, "memory_limit", "%s", fg_error_detail());
  if (rc != 0) return fg_fail_as(rc, "internal_error", "%s", fg_error_detail());
  if (*out) return 0;
  /* Asked again: a checkpoint that no longer loads shows only now. */
  fg_scene_info now;
  fg_scene_get_info(s, &now);
  if (now.checkpoint_error[0])
    return fg_fail_as(FG_ENOENT, "not_trained", "scene '%s' has no trained field: its "
                      "checkpoint does not load (%s); POST /v1/scenes/%s/train to train it "
                      "again, and wait until the job is done", now.name, now.checkpoint_error,
                      now.name);
  return fg_fail_as(FG_ENOENT, "not_trained", "scene '%s' is not trained yet; train it first: "
                    "POST /v1/scenes/%s/train, and wait until the job is done", now.name,
                    now.name);
}

int fg_field_features_fit(const fg_field *f, const char *scene, int dim, const char *purpose) {
  const int D = f->cfg.feature_dim;
  if (D == 0)
    return fg_fail_as(FG_EINVAL, "no_features", "scene '%s' was trained on colour only, "
                      "without features, so %s; upload frames with \"features\" (.npy) or "
                      "configure [clip], then train it again", scene, purpose);
  if (dim && D != dim)
    return fg_fail_as(FG_EINVAL, "feature_dim_mismatch", "scene '%s' was trained again "
                      "meanwhile and its features now have D = %d, not %d; ask again with a "
                      "query of that D", scene, D, dim);
  return 0;
}

int fg_field_voxels(fg_field_ref *ref, const fg_voxel_grid *g, const char *name, int n_threads,
                    fg_voxels **out) {
  double built_s = 0;
  const int rc = fg_voxcache_get(fg_field_ref_voxcache(ref), fg_field_ref_field(ref), g,
                                 n_threads, out, &built_s);
  if (rc != 0)
    return fg_fail_as(rc, "internal_error", "cannot build the voxel features of scene "
                      "'%s': %s", name, fg_error_detail());
  if (built_s > 0) {
    const fg_voxel_features *vf = fg_voxels_features(*out);
    fg_metrics_add_voxel_build(built_s);
    fg_info("scene %s: voxel features built in %.2f s: %zu voxels at %g m, %zu occupied, %.1f MB",
            name, built_s, fg_voxel_grid_count(g), g->voxel_size, fg_voxel_features_n_kept(vf),
            (double)fg_voxel_features_bytes(vf) / 1048576.0);
  }
  return 0;
}

int fg_scene_voxels_acquire(fg_scene *s, int dim, const char *purpose, int n_threads,
                            fg_scene_voxels *out) {
  memset(out, 0, sizeof *out);
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  int rc = fg_voxel_grid_init(&out->grid, info.params.workspace_min, info.params.workspace_max,
                              info.params.voxel_size);
  if (rc == FG_ERANGE)
    return fg_fail_as(rc, "grid_too_large", "scene '%s': its workspace at voxel_size %g m has "
                      "more than %zu voxels, the most the voxel features take (%s); create "
                      "the scene with a larger \"voxel_size\" or a smaller \"workspace\"",
                      info.name, info.params.voxel_size, FG_QUERY_MAX_VOXELS,
                      fg_error_detail());
  if (rc != 0)
    return fg_fail_as(rc, "internal_error", "scene '%s': %s", info.name, fg_error_detail());
  fg_field_ref *ref;
  FG_TRY(fg_scene_field_get(s, &ref));
  rc = fg_field_features_fit(fg_field_ref_field(ref), info.name, dim, purpose);
  if (rc == 0) rc = fg_field_voxels(ref, &out->grid, info.name, n_threads, &out->vox);
  fg_field_ref_release(ref); /* the voxels do not refer to the field */
  if (rc != 0) return rc;
  out->vf = fg_voxels_features(out->vox);
  return 0;
}

void fg_scene_voxels_release(fg_scene_voxels *sv) {
  fg_voxels_release(sv->vox);
  sv->vox = NULL;
  sv->vf = NULL;
}
