/* What depth.c shares with the depth decoder in image_codec.c, which cannot live in depth.c
 * without making every user of .npy depth link OpenImageIO. Not part of the public
 * interface (io/depth.h). */
#ifndef FG_IO_DEPTH_PRIV_H
#define FG_IO_DEPTH_PRIV_H

#include <stddef.h>

/* Checks a depth size against FG_IMAGE_MAX_SIDE and FG_IMAGE_MAX_PIXELS before anything of
 * that size is allocated: FG_EINVAL when a side is 0, FG_ERANGE when it is too large; what
 * names the input in the detail ("the depth .npy"). */
int fg_depth_check_size(const char *what, size_t w, size_t h);

/* Makes m, float [h][w] metres, a depth map in place: NaN and -0 become 0 (invalid); a
 * negative or infinite value is FG_EINVAL naming the first such pixel [row, col] and its
 * value. */
int fg_depth_clean_metres(float *m, int w, int h);

#endif
