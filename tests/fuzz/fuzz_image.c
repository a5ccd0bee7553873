/* Fuzz target for the image decoder (uploaded frames: PNG, JPEG, OpenEXR, TIFF through
 * OpenImageIO, in the daemon's decoder processes): any input either fails or yields an image
 * within the size limits whose pixels are finite and in [0, 1]. */
#include "core/error.h"
#include "io/image.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  static const float bg[3] = {1.0f, 1.0f, 1.0f};
  fg_image img = {0};
  if (fg_image_decode(data, size, bg, &img) != 0) return 0;
  if (fg_image_check_size("image", img.w, img.h) != 0 || !img.rgb) abort();
  size_t n = (size_t)img.w * (size_t)img.h * 3;
  for (size_t i = 0; i < n; i++)
    if (!(img.rgb[i] >= 0.0f && img.rgb[i] <= 1.0f)) abort();
  fg_image_release(&img);
  return 0;
}
