/* Fuzz target for the frame files of the state dir (.fgf, io/frame.h), read back at start-up,
 * in listings and for training: the input is the file, loaded as a header and whole. Since a
 * mutated file almost always fails the CRC, each input is also loaded with its last four
 * bytes replaced by the CRC of the rest, so the checks past the CRC are reached too. */
#include "core/error.h"
#include "io/frame.h"

#include "fuzz_file.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Loads the file at path both ways; a success must hold what the header says. */
static void load_both(const char *path) {
  fg_frame f;
  memset(&f, 0, sizeof f);
  if (fg_frame_load_header(path, &f) == 0) {
    if (f.rgb || f.feat || f.depth || f.cam.w <= 0 || f.cam.h <= 0) abort();
    fg_frame_clear(&f);
  }
  memset(&f, 0, sizeof f);
  if (fg_frame_load(path, &f) == 0) {
    if (!f.rgb || (f.feat_d > 0) != (f.feat != NULL) || (f.depth_w > 0) != (f.depth != NULL))
      abort();
    size_t n = (size_t)f.cam.w * (size_t)f.cam.h * 3;
    volatile uint16_t sink = 0;
    sink ^= f.rgb[n - 1]; /* the pixels are all there */
    (void)sink;
    fg_frame_clear(&f);
  }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  load_both(fuzz_file_write("frame.fgf", data, size));
  if (size < 4) return 0;
  uint8_t *fixed = malloc(size);
  if (!fixed) abort();
  memcpy(fixed, data, size);
  uint32_t crc = (uint32_t)crc32(0L, fixed, (uInt)(size - 4));
  for (int k = 0; k < 4; k++) fixed[size - 4 + k] = (uint8_t)(crc >> (8 * k));
  load_both(fuzz_file_write("frame.fgf", fixed, size));
  free(fixed);
  return 0;
}
