/* fieldgrip-scenegen's (argv[1]) --remove and --move: the same layout after the scene changed.
 * With the bowl removed and the box moved 10 cm to where it stood: gt.json lists the mug, box
 * and ball, the mug and the ball where they were, the box and its grasp 10 cm along -x; no pixel of any
 * view shows the bowl, and the cameras are where they were; cell.xml has no bowl body. A move
 * off the table or onto another object, an unknown object, and an object both removed and
 * moved are refused. */
#include "testutil.h"

#include <math.h>

#include "gt.h"
#include "io/image.h"
#include "scene.h"

#define VIEWS 3

static const char *program;

static char *generate(const char *const *extra) {
  char *dir = sg_test_tmpdir("scenegen-edit");
  const char *args[24] = {"--out",   dir,  "--seed",  "11", "--views",   "3",
                          "--width", "48", "--height", "36", "--dim",     "8",
                          "--patch", "8",  "--holdout", "0"};
  int n = 14;
  while (extra && *extra) args[n++] = *extra++;
  args[n] = NULL;
  ASSERT_EQ(sg_test_run(program, args), 0);
  return dir;
}

static void load_gt(const char *dir, sg_gt *gt) {
  char *path = fg_path_join(dir, "gt.json");
  ASSERT_OK(sg_gt_load(path, gt));
  free(path);
}

static const sg_gt_object *find(const sg_gt *gt, const char *name) {
  for (int k = 0; k < gt->n_objects; k++)
    if (strcmp(gt->objects[k].name, name) == 0) return &gt->objects[k];
  return NULL;
}

/* Pixels of class cls over every view's mask. */
static long class_pixels(const char *dir, int cls) {
  long n = 0;
  for (int i = 0; i < VIEWS; i++) {
    char name[64], *buf;
    size_t len;
    snprintf(name, sizeof name, "masks/%04d.png", i);
    sg_test_read(dir, name, &buf, &len);
    fg_image img;
    ASSERT_OK(fg_image_decode(buf, len, NULL, &img));
    for (size_t p = 0; p < (size_t)img.w * (size_t)img.h; p++)
      n += lrintf(img.rgb[3 * p] * 255.0f) == cls;
    fg_image_release(&img);
    free(buf);
  }
  return n;
}

int main(int argc, char **argv) {
  ASSERT(argc >= 2);
  program = argv[1];
  char *before = generate(NULL);
  /* into where the bowl stood */
  const char *edit[] = {"--remove", "bowl", "--move", "box,-0.1,0", NULL};
  char *after = generate(edit);
  sg_gt a, b;
  load_gt(before, &a);
  load_gt(after, &b);
  ASSERT_EQ(a.n_objects, 4);
  ASSERT_EQ(b.n_objects, 3);
  ASSERT(find(&b, "bowl") == NULL);
  for (int k = 0; k < b.n_objects; k++) {
    const sg_gt_object *o = &b.objects[k], *was = find(&a, o->name);
    ASSERT(was != NULL);
    ASSERT_EQ(o->class_id, was->class_id);
    const double dx = strcmp(o->name, "box") == 0 ? -0.1 : 0.0;
    ASSERT_NEAR(o->position[0], was->position[0] + dx, 1e-9);
    ASSERT_NEAR(o->position[1], was->position[1], 1e-9);
    ASSERT_NEAR(o->T_world_grasp[3], was->T_world_grasp[3] + dx, 1e-9);
    ASSERT_NEAR(o->T_world_grasp[7], was->T_world_grasp[7], 1e-9);
    for (int i = 0; i < 4; i++) ASSERT_NEAR(o->quaternion[i], was->quaternion[i], 1e-12);
  }
  /* the bowl is in no view any more, the others still are; the cameras stayed */
  ASSERT(class_pixels(before, SG_CLASS_BOWL) > 0);
  ASSERT_EQ(class_pixels(after, SG_CLASS_BOWL), 0);
  ASSERT(class_pixels(after, SG_CLASS_BOX) > 0);
  char *ta, *tb, *xml;
  size_t la, lb, lx;
  sg_test_read(before, "transforms.json", &ta, &la);
  sg_test_read(after, "transforms.json", &tb, &lb);
  ASSERT(la == lb && memcmp(ta, tb, la) == 0);
  sg_test_read(after, "cell.xml", &xml, &lx);
  ASSERT(strstr(xml, "name=\"bowl\"") == NULL);
  ASSERT_STRCONTAINS(xml, "name=\"box\"");
  free(ta);
  free(tb);
  free(xml);
  sg_gt_free(&a);
  sg_gt_free(&b);

  /* refused: off the table, onto another object, an unknown object, removed and moved */
  const char *const bad[][5] = {
      {"--move", "ball,0.9,0", NULL},
      {"--move", "cup,0.1,0", NULL},
      {"--move", "box,0.1", NULL},
      {"--remove", "plate", NULL},
      {"--remove", "box", "--move", "box,0.05,0", NULL},
  };
  char *dir = sg_test_tmpdir("scenegen-edit-bad");
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    const char *args[12] = {"--out", dir, "--seed", "11", "--views", "1"};
    int n = 6;
    for (int j = 0; bad[i][j]; j++) args[n++] = bad[i][j];
    args[n] = NULL;
    if (sg_test_run(program, args) == 0) FG_TEST_FAIL("case %zu was accepted", i);
  }
  /* onto another object: the mug moved onto the ball */
  sg_gt g;
  load_gt(before, &g);
  const sg_gt_object *mug = find(&g, "mug"), *ball = find(&g, "ball");
  char move[64];
  snprintf(move, sizeof move, "mug,%.4f,%.4f", ball->position[0] - mug->position[0],
           ball->position[1] - mug->position[1]);
  const char *onto[] = {"--out", dir, "--seed", "11", "--views", "1", "--move", move, NULL};
  ASSERT(sg_test_run(program, onto) != 0);
  sg_gt_free(&g);
  ASSERT_OK(fg_rmtree(dir));
  ASSERT_OK(fg_rmtree(before));
  ASSERT_OK(fg_rmtree(after));
  free(dir);
  free(before);
  free(after);
  printf("scenegen_edit: ok\n");
  return 0;
}
