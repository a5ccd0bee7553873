/* Fuzz target for transforms.json (dataset import): the input is the file; any input either
 * fails with an error code and leaves nothing owned, or yields frames with finite poses and
 * a camera that completes for a plausible image size. */
#include "core/error.h"
#include "io/transforms.h"

#include "fuzz_file.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = fuzz_file_write("transforms.json", data, size);
  fg_transforms t;
  int rc = fg_transforms_load(path, &t);
  if (rc != 0) {
    if (rc > 0 || t.frames || t.n_frames) abort(); /* a failure owns nothing */
    return 0;
  }
  if (t.n_missing > t.n_frames) abort();
  for (size_t i = 0; i < t.n_frames; i++) (void)fg_transforms_complete_camera(&t.frames[i], 640, 480);
  fg_transforms_free(&t);
  return 0;
}
