/* Trained scenegen layouts for the quality checks: see layout.h. */
#include "layout.h"

#include "testutil.h"

#include "core/clock.h"

/* The tabletop workspace of SPEC.md's example configuration. */
static const double ws_min[3] = {0.10, -0.45, 0.005}, ws_max[3] = {0.80, 0.45, 0.35};

void sg_layout_prepare(const char *scenegen, const sg_layout_spec *spec, sg_layout *L) {
  memset(L, 0, sizeof *L);
  L->spec = *spec;
  L->dir = sg_test_tmpdir("quality");
  const char *args[32] = {"--out", L->dir, "--seed", spec->seed, "--embedding-seed",
                          spec->embedding_seed, "--views", "30", "--width", "160", "--height",
                          "120", "--dim", "32", "--patch", "4", "--holdout", "0"};
  int n = 18;
  for (const char *const *e = spec->edit; e && *e && n < 28; e++) args[n++] = *e;
  if (spec->depth) {
    args[n++] = "--depth";
    args[n++] = "png";
  }
  args[n] = NULL;
  ASSERT_EQ(sg_test_run(scenegen, args), 0);
  char *transforms = fg_path_join(L->dir, "transforms.json");
  char *gt_path = fg_path_join(L->dir, "gt.json");
  ASSERT_OK(sg_gt_load(gt_path, &L->gt));
  memcpy(L->background, L->gt.background_rgb, sizeof L->background);
  fg_ingest_opts io = {.background_rgb = {L->background[0], L->background[1], L->background[2]}};
  const int threads = spec->threads > 0 ? spec->threads : SG_LAYOUT_THREADS;
  ASSERT_OK(fg_dataset_load(transforms, &io, threads, &L->frames, &L->n_frames));
  ASSERT_EQ(L->n_frames, SG_LAYOUT_VIEWS);

  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, ws_min, ws_max, 2.0, L->gt.feature_dim));
  if (spec->init)
    ASSERT_OK(fg_field_copy_for_update(spec->init, &L->field));
  else
    ASSERT_OK(fg_field_new(&L->field, &cfg, 1));
  fg_train_opts o;
  fg_train_opts_default(&o);
  o.n_threads = threads;
  o.holdout_every = spec->holdout_every;
  o.target_samples = 1 << 15;
  memcpy(o.background, L->background, sizeof o.background);
  ASSERT_OK(fg_trainer_new(&L->trainer, L->field, L->frames, L->n_frames, &o));
  if (spec->init && spec->focus > 0.0f) {
    fg_train_focus_stats st;
    const double t0 = fg_mono_s();
    ASSERT_OK(fg_trainer_focus(L->trainer, spec->init, spec->focus, &st));
    L->train_s += fg_mono_s() - t0;
    printf("seed %s: focus on %lld of %lld cells (%lld changed), %.2f s\n", spec->seed,
           (long long)st.kept, (long long)st.cells, (long long)st.changed, fg_mono_s() - t0);
  }
  free(transforms);
  free(gt_path);
}

void sg_layout_steps(sg_layout *L, int n) {
  fg_train_stats st;
  const double t0 = fg_mono_s();
  for (int s = 0; s < n; s++) ASSERT_OK(fg_trainer_step(L->trainer, &st));
  L->train_s += fg_mono_s() - t0;
  L->steps_done += n;
  if (n > 0) L->loss = st.loss;
}

void sg_layout_voxels(sg_layout *L) {
  const int threads = L->spec.threads > 0 ? L->spec.threads : SG_LAYOUT_THREADS;
  fg_voxel_features_free(L->vf);
  L->vf = NULL;
  fg_voxel_grid g;
  ASSERT_OK(fg_voxel_grid_init(&g, ws_min, ws_max, 0.01));
  ASSERT_OK(fg_voxel_features_build(&L->vf, L->field, &g, threads));
}

void sg_layout_train(const char *scenegen, const sg_layout_spec *spec, sg_layout *L) {
  sg_layout_prepare(scenegen, spec, L);
  sg_layout_steps(L, spec->steps > 0 ? spec->steps : SG_LAYOUT_STEPS);
  fg_trainer_free(L->trainer);
  L->trainer = NULL;
  sg_layout_voxels(L);
  const fg_voxel_grid *g = fg_voxel_features_grid(L->vf);
  printf("seed %s%s%s%s: %d steps in %.1f s, loss %.4f; voxel features: %zu of %zu voxels "
         "kept, %.2f s, %.1f MB\n", spec->seed, spec->depth ? " (with depth)" : "",
         spec->edit ? " changed" : "", spec->init ? ", updated" : "", L->steps_done,
         L->train_s, L->loss, fg_voxel_features_n_kept(L->vf), fg_voxel_grid_count(g),
         fg_voxel_features_build_seconds(L->vf), fg_voxel_features_bytes(L->vf) / 1e6);
  fflush(stdout);
}

void sg_layout_free(sg_layout *L) {
  fg_trainer_free(L->trainer);
  fg_voxel_features_free(L->vf);
  fg_field_free(L->field);
  fg_dataset_free(L->frames, L->n_frames);
  sg_gt_free(&L->gt);
  fg_rmtree(L->dir);
  free(L->dir);
  memset(L, 0, sizeof *L);
}
