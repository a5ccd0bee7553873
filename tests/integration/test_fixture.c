/* The trained fixture (trained.h) on its own: built with this build's daemon unless
 * $FG_IT_FIXTURE names one, then checked: every scene's scene.json, a trained field in the
 * three trained scenes and none in the two raw ones. CI's release stage runs it so that its
 * sanitized stage's integration tests copy a fixture the release daemon trained. */
#include "harness.h"
#include "trained.h"

#include <unistd.h>

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  const char *dir = f_fixture(argv[2]);
  static const struct {
    const char *scene;
    int trained;
  } want[] = {{"t250", 1}, {"raw1", 0}, {"t60", 1}, {"nofeat", 1}, {"raw", 0}};
  for (size_t i = 0; i < sizeof want / sizeof want[0]; i++) {
    char *params = h_fmt("%s/scenes/%s/scene.json", dir, want[i].scene);
    char *field = h_fmt("%s/scenes/%s/field.fgc", dir, want[i].scene);
    ASSERT_EQ(access(params, R_OK), 0);
    ASSERT_EQ(access(field, R_OK) == 0, want[i].trained);
    free(field);
    free(params);
  }
  printf("ok: the trained fixture in %s\n", dir);
  return 0;
}
