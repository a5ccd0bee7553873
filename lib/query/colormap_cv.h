/* Private C interface of colormap_cv.cpp, OpenCV's own turbo map, for the test that checks
 * fg_turbo_rgb against it. Plain C types only; no C++ exception crosses it. */
#ifndef FG_QUERY_COLORMAP_CV_H
#define FG_QUERY_COLORMAP_CV_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* cv::applyColorMap(COLORMAP_TURBO) of the grey ramp 0..255, as RGB, into rgb (256, 3).
 * 0, or FG_EIO with a detail when OpenCV throws. */
int fg_cv_turbo_table(uint8_t rgb[256][3]);

#ifdef __cplusplus
}
#endif

#endif
