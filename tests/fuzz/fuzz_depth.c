/* Fuzz target for depth decoding (uploaded depth: .npy float32 metres, or a PNG/TIFF/EXR
 * image of integer units or float metres): any input either fails or yields a map whose
 * values are finite and not negative (0 marks invalid). */
#include "core/error.h"
#include "io/depth.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fg_depth_map d = {0};
  if (fg_depth_read(data, size, FG_DEPTH_DEFAULT_SCALE, &d) != 0) return 0;
  if (d.w <= 0 || d.h <= 0 || !d.m) abort();
  size_t n = (size_t)d.w * (size_t)d.h;
  for (size_t i = 0; i < n; i++)
    if (!(d.m[i] >= 0.0f) || !isfinite(d.m[i])) abort();
  (void)fg_depth_valid_fraction(d.m, n);
  fg_depth_release(&d);
  return 0;
}
