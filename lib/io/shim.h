/* Private C interface of the two C++ shims (oiio_shim.cpp, cv_shim.cpp); used only by
 * image.c. Plain C types only. Every function returns 0 or a negative FG_E* code and, on
 * failure, has recorded a detail with fg_fail(); no C++ exception crosses it. */
#ifndef FG_IO_SHIM_H
#define FG_IO_SHIM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Sample types of decoded pixels. */
enum { FG_SHIM_U8 = 0, FG_SHIM_U16 = 1, FG_SHIM_F32 = 2 };

/* What fg_oiio_decode read: pixels [h][w][nch] of the given sample type (8- and 16-bit files
 * stay integer, everything else becomes float) in a malloc'd buffer. */
typedef struct fg_shim_decoded {
  void *px;           /* owned by the caller after success */
  int type;           /* FG_SHIM_U8, FG_SHIM_U16 or FG_SHIM_F32 */
  int w, h;
  int nch;            /* channels in px: 1, 2, 3 or 4 */
  int alpha;          /* index of the alpha channel in px, or -1 */
  int associated;     /* 1 when colour is premultiplied by alpha (EXR), 0 when straight */
  int linear;         /* 1 when the values are linear light (EXR, float TIFF) */
} fg_shim_decoded;

/* Decodes an image from memory with OpenImageIO. ext ("png", "jpg", "exr", "tif") picks the
 * reader; format_name ("PNG", ...) is used in messages. Sizes beyond max_side or max_pixels
 * are FG_ERANGE before any pixel buffer is allocated. */
int fg_oiio_decode(const void *bytes, size_t len, const char *ext, const char *format_name,
                   int max_side, size_t max_pixels, fg_shim_decoded *out);

/* Sample kinds of a file, as fg_oiio_probe reports them. */
enum { FG_SHIM_SAMPLE_UINT = 0, FG_SHIM_SAMPLE_INT = 1, FG_SHIM_SAMPLE_FLOAT = 2 };

/* What an image file holds, read from its header alone. */
typedef struct fg_shim_info {
  int w, h;
  int nch;    /* channels in the file, alpha included */
  int sample; /* FG_SHIM_SAMPLE_* */
  int bits;   /* bits per sample as stored (1, 2, 4, 8, 12, 16, 32, ...) */
} fg_shim_info;

/* Reads the header of an image in memory, as fg_oiio_decode would open it, without reading
 * any pixels: for callers that must refuse some files (depth: one channel, no 8-bit) before
 * fg_oiio_decode allocates and converts. Sizes are not checked here. */
int fg_oiio_probe(const void *bytes, size_t len, const char *ext, const char *format_name,
                  fg_shim_info *out);

/* Encodes [h][w][channels] uint8 or uint16 pixels as PNG into a malloc'd buffer. */
int fg_oiio_encode_png(const void *pixels, int w, int h, int channels, int bits, uint8_t **out,
                       size_t *out_len);

/* Writes float [h][w][channels] pixels to a file in the format its extension names. */
int fg_oiio_write_file(const char *path, const float *pixels, int w, int h, int channels);

/* cv::resize INTER_AREA of float [sh][sw][c] into float [dh][dw][c]. */
int fg_cv_resize_area(const float *src, int sw, int sh, int c, float *dst, int dw, int dh);

/* Intrinsics in OpenCV's own pixel convention (pixel centres at integers): K is
 * {fx, fy, cx, cy}, dist is {k1, k2, p1, p2, k3}. */
typedef struct fg_cv_intrinsics {
  double K[4];
  double dist[5];
} fg_cv_intrinsics;

/* getOptimalNewCameraMatrix(alpha 0) + initUndistortRectifyMap + remap (bilinear, replicated
 * border) of float [h][w][3]; new_K receives {fx, fy, cx, cy} of the pinhole output. */
int fg_cv_undistort(const float *src, int w, int h, const fg_cv_intrinsics *in, float *dst,
                    double new_K[4]);

/* undistortPoints(xy, K, dist, R = I, P = new_K) in place; xy is [n][2] pixels. */
int fg_cv_undistort_points(const fg_cv_intrinsics *in, const double new_K[4], double *xy, int n);

#ifdef __cplusplus
}
#endif

#endif
