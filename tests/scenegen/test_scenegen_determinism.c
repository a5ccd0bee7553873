/* fieldgrip-scenegen (argv[1]) writes the same bytes for the same arguments whatever the
 * thread count, different bytes for another seed, and refuses bad arguments. */
#include "testutil.h"

static const char *program;

enum { VIEWS = 6 };

static char *generate(const char *seed, const char *threads) {
  char *dir = sg_test_tmpdir("scenegen-det");
  ASSERT(setenv("OMP_NUM_THREADS", threads, 1) == 0);
  const char *args[] = {"--out",   dir,   "--seed",  seed, "--views", "6",     "--width",
                        "160",     "--height", "120", "--dim",   "32",    "--patch", "10",
                        "--holdout", "3",  NULL};
  ASSERT_EQ(sg_test_run(program, args), 0);
  return dir;
}

static int same_file(const char *a, const char *b, const char *name) {
  char *x, *y;
  size_t nx, ny;
  sg_test_read(a, name, &x, &nx);
  sg_test_read(b, name, &y, &ny);
  int same = nx == ny && memcmp(x, y, nx) == 0;
  free(x);
  free(y);
  return same;
}

static void test_same_bytes(void) {
  char *a = generate("11", "1");
  /* One thread: views in turn; four threads for six views: each view's rows in parallel;
   * two threads: whole views in parallel. */
  char *b = generate("11", "4");
  char *d = generate("11", "2");
  char *c = generate("12", "2");
  static const char *const files[] = {"gt.json", "transforms.json", "transforms_test.json",
                                      "cell.xml"};
  for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
    if (!same_file(a, b, files[i]) || !same_file(a, d, files[i]))
      FG_TEST_FAIL("%s differs between runs", files[i]);
    if (same_file(a, c, files[i]))
      FG_TEST_FAIL("%s is the same for seeds 11 and 12", files[i]);
  }
  for (int v = 0; v < VIEWS; v++) {
    char name[64];
    snprintf(name, sizeof name, "images/%04d.png", v);
    if (!same_file(a, b, name) || !same_file(a, d, name))
      FG_TEST_FAIL("%s differs between runs", name);
    if (same_file(a, c, name)) FG_TEST_FAIL("%s is the same for seeds 11 and 12", name);
    snprintf(name, sizeof name, "masks/%04d.png", v);
    if (!same_file(a, b, name)) FG_TEST_FAIL("%s differs between runs", name);
    snprintf(name, sizeof name, "features/%04d.npy", v);
    if (!same_file(a, b, name) || !same_file(a, d, name))
      FG_TEST_FAIL("%s differs between runs", name);
    if (same_file(a, c, name)) FG_TEST_FAIL("%s is the same for seeds 11 and 12", name);
  }
  char *dirs[] = {a, b, c, d};
  for (int i = 0; i < 4; i++) {
    ASSERT_OK(fg_rmtree(dirs[i]));
    free(dirs[i]);
  }
}

static void test_bad_arguments(void) {
  char *dir = sg_test_tmpdir("scenegen-args");
  const char *no_out[] = {"--views", "2", NULL};
  ASSERT_EQ(sg_test_run(program, no_out), 2);
  const char *small_dim[] = {"--out", dir, "--dim", "3", NULL};
  ASSERT_EQ(sg_test_run(program, small_dim), 2);
  const char *bad_views[] = {"--out", dir, "--views", "ten", NULL};
  ASSERT_EQ(sg_test_run(program, bad_views), 2);
  const char *bad_noise[] = {"--out", dir, "--noise", "-1", NULL};
  ASSERT_EQ(sg_test_run(program, bad_noise), 2);
  const char *bad_seed[] = {"--out", dir, "--seed", "-5", NULL};
  ASSERT_EQ(sg_test_run(program, bad_seed), 2);
  const char *extra[] = {"--out", dir, "stray", NULL};
  ASSERT_EQ(sg_test_run(program, extra), 2);
  ASSERT_OK(fg_rmtree(dir));
  free(dir);
}

int main(int argc, char **argv) {
  if (argc < 2) FG_TEST_FAIL("usage: %s PATH-TO-fieldgrip-scenegen", argv[0]);
  program = argv[1];
  test_same_bytes();
  test_bad_arguments();
  return 0;
}
