/* The store's caps (store.h): max_scenes refuses one scene more, and max_loaded_fields keeps
 * the least recently used trained fields on disk only, loads them again on demand, never
 * evicts one in use and says so (FG_EBUSY) when it cannot load. The integration test
 * (tests/integration/test_caps.c) checks the same over HTTP with trained scenes; this one
 * reaches the states a black-box test cannot hold still: a field pinned by a request. */
#include "state/store.h"

#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "field/checkpoint.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const double WS_MIN[3] = {0.1, -0.45, 0.005}, WS_MAX[3] = {0.8, 0.45, 0.35};
static char g_tmp[64];

static void make_scene(fg_store *st, const char *name) {
  fg_scene_params p = {.workspace_min = {0.1, -0.45, 0.005}, .workspace_max = {0.8, 0.45, 0.35},
                       .voxel_size = 0.01, .background = {1, 1, 1}};
  ASSERT_OK(fg_store_create(st, name, &p, 0));
}

/* Gives scene `name` a small field of `steps` trained steps, the way a training commits. */
static void commit_field(fg_store *st, const char *name, int64_t steps) {
  fg_field_config cfg;
  ASSERT_OK(fg_field_config_for_workspace(&cfg, WS_MIN, WS_MAX, 2.0, 0));
  cfg.grid.log2_table_size = 10;
  fg_field *f;
  ASSERT_OK(fg_field_new(&f, &cfg, (uint64_t)steps));
  f->trained_steps = steps;
  fg_scene *s = fg_store_get(st, name);
  ASSERT(s);
  char *next = fg_path_join(fg_scene_dir(s), "field.next.fgc");
  ASSERT_OK(fg_checkpoint_save(f, next, 0));
  ASSERT_OK(fg_scene_commit_field(s, f, next));
  free(next);
  fg_scene_unref(s);
}

static fg_scene_info info_of(fg_store *st, const char *name) {
  fg_scene *s = fg_store_get(st, name);
  ASSERT(s);
  fg_scene_info info;
  fg_scene_get_info(s, &info);
  fg_scene_unref(s);
  return info;
}

/* Acquires the field of scene `name`: rc of fg_scene_field_acquire, the reference in *ref. */
static int acquire(fg_store *st, const char *name, fg_field_ref **ref) {
  fg_scene *s = fg_store_get(st, name);
  ASSERT(s);
  int rc = fg_scene_field_acquire(s, ref);
  fg_scene_unref(s);
  return rc;
}

static fg_store_field_stats stats(fg_store *st) {
  fg_store_field_stats fs;
  fg_store_field_stats_get(st, &fs);
  return fs;
}

static void test_scene_limit(void) {
  char dir[96];
  snprintf(dir, sizeof dir, "%s/scenes_cap", g_tmp);
  fg_store_limits lim = {.max_scenes = 2, .max_loaded_fields = 1};
  fg_store *st;
  ASSERT_OK(fg_store_open(&st, dir, &lim));
  make_scene(st, "a");
  make_scene(st, "b");
  fg_scene_params p = info_of(st, "a").params;
  ASSERT_ERR(fg_store_create(st, "c", &p, 0), FG_ERANGE, "[state] max_scenes = 2");
  size_t n, frames;
  fg_store_totals(st, &n, &frames);
  ASSERT_EQ(n, 2);
  ASSERT_OK(fg_store_delete(st, "a"));
  make_scene(st, "c");
  /* raised by a reload */
  lim.max_scenes = 0;
  fg_store_set_limits(st, &lim);
  make_scene(st, "d");
  fg_store_close(st);
  /* a state dir over the cap opens whole */
  lim.max_scenes = 1;
  ASSERT_OK(fg_store_open(&st, dir, &lim));
  fg_store_totals(st, &n, &frames);
  ASSERT_EQ(n, 3);
  ASSERT_ERR(fg_store_create(st, "e", &p, 0), FG_ERANGE, "max_scenes");
  fg_store_close(st);
}

static void test_field_lru(void) {
  char dir[96];
  snprintf(dir, sizeof dir, "%s/fields", g_tmp);
  fg_store_limits lim = {.max_scenes = 0, .max_loaded_fields = 1};
  fg_store *st;
  ASSERT_OK(fg_store_open(&st, dir, &lim));
  make_scene(st, "a");
  make_scene(st, "b");
  make_scene(st, "c");
  commit_field(st, "a", 11);
  ASSERT_EQ(stats(st).loaded, 1);
  /* b's training commits: a, in nobody's use, leaves memory but stays trained */
  commit_field(st, "b", 22);
  fg_store_field_stats fs = stats(st);
  ASSERT_EQ(fs.loaded, 1);
  ASSERT_EQ(fs.evictions, 1);
  fg_scene_info ia = info_of(st, "a");
  ASSERT_EQ(ia.trained, 1);
  ASSERT_EQ(ia.loaded, 0);
  ASSERT_EQ(ia.trained_steps, 11);
  ASSERT_EQ(info_of(st, "b").loaded, 1);

  /* a's next use loads it from field.fgc and evicts b */
  fg_field_ref *ra = NULL, *rb = NULL;
  ASSERT_OK(acquire(st, "a", &ra));
  ASSERT(ra);
  ASSERT_EQ(fg_field_ref_field(ra)->trained_steps, 11);
  fs = stats(st);
  ASSERT_EQ(fs.loaded, 1);
  ASSERT_EQ(fs.loads, 1);
  ASSERT_EQ(fs.evictions, 2);
  ASSERT_EQ(info_of(st, "b").loaded, 0);

  /* a is in use: b cannot be loaded, and a stays */
  ASSERT_ERR(acquire(st, "b", &rb), FG_EBUSY, "max_loaded_fields");
  ASSERT(rb == NULL);
  ASSERT_EQ(info_of(st, "a").loaded, 1);
  ASSERT_EQ(stats(st).loaded, 1);

  /* a commit while everything is in use keeps its field on disk only */
  commit_field(st, "c", 33);
  fg_scene_info ic = info_of(st, "c");
  ASSERT_EQ(ic.trained, 1);
  ASSERT_EQ(ic.loaded, 0);
  ASSERT_EQ(ic.trained_steps, 33);
  ASSERT_EQ(stats(st).loaded, 1);

  /* released, a makes way */
  fg_field_ref_release(ra);
  ra = NULL;
  ASSERT_OK(acquire(st, "b", &rb));
  ASSERT_EQ(fg_field_ref_field(rb)->trained_steps, 22);
  ASSERT_EQ(info_of(st, "a").loaded, 0);

  /* a field held by a request outlives its scene's deletion */
  ASSERT_OK(fg_store_delete(st, "b"));
  ASSERT_EQ(fg_field_ref_field(rb)->trained_steps, 22);
  ASSERT_EQ(stats(st).loaded, 0);
  fg_field_ref_release(rb);

  /* no limit: both load */
  lim.max_loaded_fields = 0;
  fg_store_set_limits(st, &lim);
  ASSERT_OK(acquire(st, "a", &ra));
  fg_field_ref *rc = NULL;
  ASSERT_OK(acquire(st, "c", &rc));
  ASSERT_EQ(fg_field_ref_field(rc)->trained_steps, 33);
  ASSERT_EQ(stats(st).loaded, 2);
  fg_field_ref_release(ra);
  fg_field_ref_release(rc);
  /* a reload lowering the cap evicts what nobody uses, at once */
  lim.max_loaded_fields = 1;
  fg_store_set_limits(st, &lim);
  ASSERT_EQ(stats(st).loaded, 1);
  fg_store_close(st);

  /* a restart checks both checkpoints but keeps one in memory */
  ASSERT_OK(fg_store_open(&st, dir, &lim));
  ASSERT_EQ(stats(st).loaded, 1);
  ASSERT_EQ(info_of(st, "a").trained, 1);
  ASSERT_EQ(info_of(st, "c").trained, 1);
  ASSERT_EQ(info_of(st, "a").loaded + info_of(st, "c").loaded, 1);
  fg_store_close(st);
}

/* A field.fgc that no longer loads when its field is needed again leaves the scene
 * untrained with the reason, as at start-up. */
static void test_reload_fails(void) {
  char dir[96];
  snprintf(dir, sizeof dir, "%s/broken", g_tmp);
  fg_store_limits lim = {.max_scenes = 0, .max_loaded_fields = 1};
  fg_store *st;
  ASSERT_OK(fg_store_open(&st, dir, &lim));
  make_scene(st, "a");
  make_scene(st, "b");
  commit_field(st, "a", 5);
  commit_field(st, "b", 6);
  ASSERT_EQ(info_of(st, "a").loaded, 0);
  char *path = fg_path_join(dir, "scenes/a/field.fgc");
  FILE *f = fopen(path, "w");
  ASSERT(f);
  fputs("not a checkpoint", f);
  fclose(f);
  free(path);
  fg_field_ref *ra = NULL;
  ASSERT_OK(acquire(st, "a", &ra));
  ASSERT(ra == NULL);
  fg_scene_info ia = info_of(st, "a");
  ASSERT_EQ(ia.trained, 0);
  ASSERT_STRCONTAINS(ia.checkpoint_error, "field.fgc");
  /* Room is made before the load, so that the cap holds even during it: b went in vain,
   * but stays trained and comes back at its next use. */
  ASSERT_EQ(stats(st).loaded, 0);
  fg_field_ref *rb = NULL;
  ASSERT_OK(acquire(st, "b", &rb));
  ASSERT_EQ(fg_field_ref_field(rb)->trained_steps, 6);
  fg_field_ref_release(rb);
  fg_store_close(st);
}

int main(void) {
  snprintf(g_tmp, sizeof g_tmp, "/tmp/fg_store_fields.XXXXXX");
  ASSERT(mkdtemp(g_tmp));
  test_scene_limit();
  test_field_lru();
  test_reload_fails();
  ASSERT_OK(fg_rmtree(g_tmp));
  printf("ok\n");
  return 0;
}
