/* One frame from a V4L2 video device (a USB camera), through OpenCV's videoio: opened, a few
 * frames read so that the exposure settles, the last one encoded as PNG. No C++ crosses this
 * header. */
#ifndef FG_IO_VIDEO_H
#define FG_IO_VIDEO_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* 0 with a malloc'd PNG, or FG_EUNAVAIL naming the device when it does not open or gives no
 * frame. */
int fg_v4l2_grab_png(const char *device, uint8_t **png, size_t *len);

#ifdef __cplusplus
}
#endif

#endif
