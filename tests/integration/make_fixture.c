/* it_make_fixture FIELDGRIPD FIELDGRIP-SCENEGEN OUT: builds the trained fixture (trained.h)
 * into the new folder OUT with the daemon itself, over HTTP, as the tests would: the data
 * set, five scenes imported from it, three of them trained. */
#include "grasp_util.h"

#include <jansson.h>

static void write_nofeat(const char *dir) {
  char *tf = h_fmt("%s/transforms.json", dir), *tf2 = h_fmt("%s/transforms_nofeat.json", dir);
  json_error_t e;
  json_t *tj = json_load_file(tf, 0, &e);
  ASSERT(tj);
  json_t *frames = JGET(tj, "frames");
  for (size_t i = 0; i < json_array_size(frames); i++)
    json_object_del(json_array_get(frames, i), "features_path");
  ASSERT_EQ(json_dump_file(tj, tf2, 0), 0);
  json_decref(tj);
  free(tf2);
  free(tf);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 4) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN OUT", argv[0]);
  const double t0 = t_now();
  char *imports = g_dataset(argv[2]);
  write_nofeat(g_dir());
  g_config(imports, NULL);
  h_start();
  t_scene_from_dataset("t250", g_dir(), G_VIEWS);
  t_scene_from_dataset("raw1", g_dir(), G_VIEWS);
  g_scene("t60", NULL);
  g_scene("nofeat", "transforms_nofeat.json");
  g_scene("raw", NULL);
  /* the hang guards are sized for a sanitized build on two busy cores */
  t_train_done("t250", "{\"steps\": 250}", 3000);
  t_train_done("t60", "{\"steps\": 60}", 3000);
  t_train_done("nofeat", "{\"steps\": 2}", 3000);
  h_stop();
  /* a copied scene starts with no job of its own */
  const char *const trained[] = {"t250", "t60", "nofeat"};
  for (size_t i = 0; i < sizeof trained / sizeof *trained; i++) {
    char *last = h_fmt("%s/scenes/%s/last_job.json", h_state_dir(), trained[i]);
    h_remove_tree(last);
    free(last);
  }
  h_mkdirs(argv[3]);
  char *scenes = h_fmt("%s/scenes", h_state_dir()), *out_scenes = h_fmt("%s/scenes", argv[3]);
  char *out_sg = h_fmt("%s/sg", argv[3]);
  h_copy_tree(scenes, out_scenes);
  h_copy_tree(g_dir(), out_sg);
  printf("trained fixture in %s: %.1f s\n", argv[3], t_now() - t0);
  free(out_sg);
  free(out_scenes);
  free(scenes);
  free(imports);
  h_done();
  return 0;
}
