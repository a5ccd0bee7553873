/* Fuzz target for the field checkpoint loader (a scene's field.ckpt, read at start-up and on
 * import): any input either loads a field or fails with *out NULL, never crashes, leaks or
 * allocates without bound. */
#include "core/error.h"
#include "field/checkpoint.h"
#include "field/model.h"

#include "fuzz_file.h"

#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = fuzz_file_write("field.ckpt", data, size);
  fg_field *f = (fg_field *)1;
  int rc = fg_checkpoint_load(path, &f);
  if (rc != 0) {
    if (f || rc > 0) abort();
    return 0;
  }
  if (!f) abort();
  fg_field_free(f);
  return 0;
}
