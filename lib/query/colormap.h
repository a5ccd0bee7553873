/* The heatmaps' colours: OpenCV's turbo map, and a score image blended over a render. */
#ifndef FG_QUERY_COLORMAP_H
#define FG_QUERY_COLORMAP_H

#include <stdint.h>

/* OpenCV's COLORMAP_TURBO as RGB (not OpenCV's BGR order): entry i is the colour of grey
 * level i. Generated from cv::applyColorMap; a test checks it against OpenCV. */
extern const uint8_t fg_turbo_rgb[256][3];

/* Turbo colour of t in [0, 1] (clamped; NaN -> entry 0): entry round(255 * t) into rgb (3). */
void fg_colormap_turbo(float t, uint8_t rgb[3]);

/* Blends a score image over a render into RGB8 for the PNG encoder: rgb (n, 3) sRGB in [0, 1],
 * scores (n), out (n, 3) uint8, the caller's buffers. With t = clamp((score - lo) / (hi - lo),
 * 0, 1) and c = fg_turbo(t) / 255, a pixel is (1 - a) * rgb + a * c with a = 0.25 + 0.6 * t
 * (so the whole view reads as a heatmap and the hottest parts are nearly opaque); a NaN score
 * (empty pixel) shows rgb unchanged. When lo >= hi (or either is NaN), lo and hi are the lowest
 * and highest finite score of the image. Values are rounded to nearest. */
void fg_heatmap_blend(const float *rgb, const float *scores, int64_t n, float lo, float hi,
                      uint8_t *out);

#endif
