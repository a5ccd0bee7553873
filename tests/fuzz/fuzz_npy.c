/* Fuzz target for the .npy reader (uploaded depth maps, features): any input either fails to
 * parse or yields an array whose data lies inside the input and whose shape agrees with its
 * element count; a parsed array is also turned into a depth map the way an upload is. */
#include "core/error.h"
#include "io/depth.h"
#include "io/npy.h"

#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  fg_npy npy;
  if (fg_npy_parse(data, size, &npy) != 0) return 0;
  if (npy.ndim < 0 || npy.ndim > FG_NPY_MAX_DIMS) abort();
  size_t count = 1;
  for (int k = 0; k < npy.ndim; k++) count *= npy.shape[k]; /* the parser proved it fits */
  if (count != npy.count) abort();
  size_t es = fg_dtype_size(npy.dtype);
  const uint8_t *p = npy.data;
  if (es == 0 || p < data || p > data + size) abort();
  if (npy.count * es != (size_t)(data + size - p)) abort(); /* the data runs to the end */
  volatile uint8_t sink = 0;
  for (size_t i = 0; i < npy.count * es; i++) sink ^= p[i]; /* every byte is readable */
  (void)sink;
  fg_depth_map d = {0};
  if (fg_depth_from_npy(&npy, &d) == 0) {
    if (d.w <= 0 || d.h <= 0 || !d.m || (size_t)d.w * (size_t)d.h != npy.count) abort();
    fg_depth_release(&d);
  }
  return 0;
}
