/* The control of the physics cell: on the cell.xml that fieldgrip-scenegen (argv[1]) writes,
 * fieldgrip-sim (argv[2]) in its physics mode picks each object at its ground-truth grasp
 * (gt.json) and lifts it, and lifts nothing else; the box's grasp moved 3 cm past the box's
 * end closes on air. If these fail, the cell (its parts, masses, frictions) or the simulated
 * gripper is wrong, and no success rate measured on it means anything. Three layouts, a
 * fresh simulator for every pick. */
#include "cellproc.h"
#include "gt.h"
#include "testutil.h"

#include "core/pose.h"

static const int k_seeds[] = {1, 2, 3};

static void grasp_of(const sg_gt_object *o, double p[3], double rv[3]) {
  double R[9];
  fg_pose_get_rotmat(o->T_world_grasp, R);
  fg_rotvec_from_rotmat(R, rv);
  for (int k = 0; k < 3; k++) p[k] = o->T_world_grasp[4 * k + 3];
}

static json_t *pick(const char *cell, const char *dir, const double p[3], const double rv[3]) {
  cellproc c;
  cellproc_start(&c, cell, "int16", dir, NULL);
  ASSERT_EQ(cellproc_command(&c, 1, 1, p, rv, 0.085, 0.10, 0), 2);
  json_t *r = cellproc_report(&c, 1);
  cellproc_stop(&c);
  return r;
}

static void layout(const char *scenegen, const char *dir, int seed) {
  char seed_s[16], cell[PATH_MAX + 16], gt_path[PATH_MAX + 16];
  snprintf(seed_s, sizeof seed_s, "%d", seed);
  const char *const args[] = {"--out", dir, "--seed", seed_s, "--views", "1", "--width", "32",
                              "--height", "24", "--holdout", "0", NULL};
  ASSERT_EQ(sg_test_run(scenegen, args), 0);
  snprintf(cell, sizeof cell, "%s/cell.xml", dir);
  snprintf(gt_path, sizeof gt_path, "%s/gt.json", dir);
  sg_gt gt;
  ASSERT_OK(sg_gt_load(gt_path, &gt));
  for (int k = 0; k < gt.n_objects; k++) {
    const sg_gt_object *o = &gt.objects[k];
    double p[3], rv[3];
    grasp_of(o, p, rv);
    json_t *r = pick(cell, dir, p, rv);
    for (int j = 0; j < gt.n_objects; j++) {
      json_t *ob = cellproc_object(r, gt.objects[j].name);
      if (j == k && !(cellproc_flag(ob, "lifted") && cellproc_num(ob, "dz_m") > 0.08))
        FG_TEST_FAIL("seed %d: the %s's ground-truth grasp did not lift it: %s", seed, o->name,
                     json_dumps(r, JSON_COMPACT));
      if (j != k) ASSERT(!cellproc_flag(ob, "lifted"));
    }
    fprintf(stderr, "seed %d: %s lifted by %.3f m\n", seed, o->name,
            cellproc_num(cellproc_object(r, o->name), "dz_m"));
    json_decref(r);
    if (strcmp(o->name, "box") != 0) continue;
    /* past the box's end along its length (object +x), 3 cm clear of it */
    double x_world[3], off = o->size[0] / 2 + 0.03;
    fg_pose_rotate(o->shape.T_world_obj, (const double[3]){1, 0, 0}, x_world);
    for (int i = 0; i < 3; i++) p[i] += off * x_world[i];
    r = pick(cell, dir, p, rv);
    ASSERT_EQ(cellproc_gobj(r), 3);
    for (int j = 0; j < gt.n_objects; j++)
      ASSERT(!cellproc_flag(cellproc_object(r, gt.objects[j].name), "lifted"));
    ASSERT(!cellproc_flag(cellproc_object(r, "box"), "touched"));
    json_decref(r);
  }
  sg_gt_free(&gt);
}

int main(int argc, char **argv) {
  if (argc < 3) FG_TEST_FAIL("usage: %s fieldgrip-scenegen fieldgrip-sim", argv[0]);
  char *dir = sg_test_tmpdir("scenegen-physics");
  simproc_init(argv[2], dir);
  for (size_t i = 0; i < sizeof k_seeds / sizeof k_seeds[0]; i++) {
    char sub[PATH_MAX];
    snprintf(sub, sizeof sub, "%s/seed%d", dir, k_seeds[i]);
    layout(argv[1], sub, k_seeds[i]);
  }
  fg_rmtree(dir);
  free(dir);
  return 0;
}
