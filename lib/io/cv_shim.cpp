// OpenCV behind a C interface (shim.h): area resampling and lens undistortion. The caller's
// buffers are wrapped in cv::Mat headers, so OpenCV reads and writes them without copies.
// Every entry point catches all exceptions.
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cstring>
#include <exception>
#include <new>
#include <vector>

extern "C" {
#include "core/error.h"
}
#include "io/shim.h"

namespace {

cv::Matx33d camera_matrix(const double K[4]) {
  return cv::Matx33d(K[0], 0, K[2], 0, K[1], K[3], 0, 0, 1);
}

cv::Mat dist_coeffs(const fg_cv_intrinsics *in) {
  return cv::Mat(1, 5, CV_64F, const_cast<double *>(in->dist)).clone();
}

int resize_impl(const float *src, int sw, int sh, int c, float *dst, int dw, int dh) {
  cv::Mat s(sh, sw, CV_MAKETYPE(CV_32F, c), const_cast<float *>(src));
  cv::Mat d(dh, dw, CV_MAKETYPE(CV_32F, c), dst);
  if (c <= 4) {
    cv::resize(s, d, cv::Size(dw, dh), 0, 0, cv::INTER_AREA);
    // resize reuses d when its size and type match, which they do; copy if it ever did not.
    if (d.data != reinterpret_cast<uchar *>(dst))
      std::memcpy(dst, d.data, (size_t)dw * (size_t)dh * (size_t)c * sizeof(float));
    return 0;
  }
  // INTER_AREA handles at most 4 channels at non-integer ratios: resample feature grids in
  // groups of 4, gathered and scattered with mixChannels.
  for (int c0 = 0; c0 < c; c0 += 4) {
    int g = c - c0 < 4 ? c - c0 : 4;
    cv::Mat gs(sh, sw, CV_MAKETYPE(CV_32F, g)), gd;
    std::vector<int> from_to;
    for (int k = 0; k < g; k++) from_to.insert(from_to.end(), {c0 + k, k});
    cv::mixChannels(&s, 1, &gs, 1, from_to.data(), (size_t)g);
    cv::resize(gs, gd, cv::Size(dw, dh), 0, 0, cv::INTER_AREA);
    for (int k = 0; k < g; k++) from_to[2 * k] = k, from_to[2 * k + 1] = c0 + k;
    cv::mixChannels(&gd, 1, &d, 1, from_to.data(), (size_t)g);
  }
  return 0;
}

int undistort_impl(const float *src, int w, int h, const fg_cv_intrinsics *in, float *dst,
                   double new_K[4]) {
  cv::Matx33d K = camera_matrix(in->K);
  cv::Mat dist = dist_coeffs(in);
  cv::Size size(w, h);
  // alpha 0: the new camera sees only valid pixels, so no output pixel is a black border.
  cv::Mat nk = cv::getOptimalNewCameraMatrix(K, dist, size, 0.0, size);
  cv::Mat map1, map2;
  cv::initUndistortRectifyMap(K, dist, cv::noArray(), nk, size, CV_32FC1, map1, map2);
  cv::Mat s(h, w, CV_32FC3, const_cast<float *>(src));
  cv::Mat d(h, w, CV_32FC3, dst);
  cv::remap(s, d, map1, map2, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  if (d.data != reinterpret_cast<uchar *>(dst))
    std::memcpy(dst, d.data, (size_t)w * (size_t)h * 3 * sizeof(float));
  new_K[0] = nk.at<double>(0, 0);
  new_K[1] = nk.at<double>(1, 1);
  new_K[2] = nk.at<double>(0, 2);
  new_K[3] = nk.at<double>(1, 2);
  return 0;
}

int undistort_points_impl(const fg_cv_intrinsics *in, const double new_K[4], double *xy, int n) {
  cv::Mat pts(n, 1, CV_64FC2, xy);
  cv::Mat res;
  // OpenCV's default stops after 5 iterations, which leaves a visible error near the corners
  // of a strongly distorted lens; iterate to convergence instead.
  cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200, 1e-14);
  cv::undistortPoints(pts, res, camera_matrix(in->K), dist_coeffs(in), cv::noArray(),
                      camera_matrix(new_K), crit);
  res.convertTo(res, CV_64FC2);
  std::memcpy(xy, res.ptr<double>(), (size_t)n * 2 * sizeof(double));
  return 0;
}

}  // namespace

extern "C" int fg_cv_resize_area(const float *src, int sw, int sh, int c, float *dst, int dw,
                                 int dh) {
  try {
    return resize_impl(src, sw, sh, c, dst, dw, dh);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory resizing a %dx%d image", sw, sh);
  } catch (const std::exception &e) {
    return fg_fail(FG_EINVAL, "resizing %dx%d to %dx%d failed: %s", sw, sh, dw, dh, e.what());
  } catch (...) {
    return fg_fail(FG_EINVAL, "resizing %dx%d to %dx%d failed", sw, sh, dw, dh);
  }
}

extern "C" int fg_cv_undistort(const float *src, int w, int h, const fg_cv_intrinsics *in,
                               float *dst, double new_K[4]) {
  try {
    return undistort_impl(src, w, h, in, dst, new_K);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory undistorting a %dx%d image", w, h);
  } catch (const std::exception &e) {
    return fg_fail(FG_EINVAL, "undistorting a %dx%d image failed: %s", w, h, e.what());
  } catch (...) {
    return fg_fail(FG_EINVAL, "undistorting a %dx%d image failed", w, h);
  }
}

extern "C" int fg_cv_undistort_points(const fg_cv_intrinsics *in, const double new_K[4],
                                      double *xy, int n) {
  if (n <= 0) return 0;
  try {
    return undistort_points_impl(in, new_K, xy, n);
  } catch (const std::bad_alloc &) {
    return fg_fail(FG_ENOMEM, "out of memory undistorting %d points", n);
  } catch (const std::exception &e) {
    return fg_fail(FG_EINVAL, "undistorting %d points failed: %s", n, e.what());
  } catch (...) {
    return fg_fail(FG_EINVAL, "undistorting %d points failed", n);
  }
}
