// OpenCV's COLORMAP_TURBO behind a C function (colormap_cv.h), so that a test can compare the
// library's built-in table with OpenCV's output.
#include "query/colormap_cv.h"

#include <opencv2/imgproc.hpp>

#include <exception>

extern "C" {
#include "core/error.h"
}

namespace {

int turbo_impl(uint8_t rgb[256][3]) {
  cv::Mat grey(1, 256, CV_8UC1);
  for (int i = 0; i < 256; i++) grey.at<uchar>(0, i) = static_cast<uchar>(i);
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  for (int i = 0; i < 256; i++) {
    cv::Vec3b bgr = colour.at<cv::Vec3b>(0, i);
    rgb[i][0] = bgr[2];
    rgb[i][1] = bgr[1];
    rgb[i][2] = bgr[0];
  }
  return 0;
}

}  // namespace

extern "C" int fg_cv_turbo_table(uint8_t rgb[256][3]) {
  try {
    return turbo_impl(rgb);
  } catch (const std::exception &e) {
    return fg_fail(FG_EIO, "OpenCV applyColorMap failed: %s", e.what());
  }
}
