// A frame from a V4L2 device with OpenCV's videoio (video.h). Catches every exception.
#include "io/video.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <cstdlib>
#include <cstring>
#include <vector>

extern "C" {
#include "core/error.h"
}

extern "C" int fg_v4l2_grab_png(const char *device, uint8_t **png, size_t *len) {
  *png = NULL;
  try {
    cv::VideoCapture cap(device, cv::CAP_V4L2);
    if (!cap.isOpened())
      return fg_fail(FG_EUNAVAIL, "cannot open the video device %s", device);
    cv::Mat frame;
    for (int i = 0; i < 5; i++) // the first frames of a camera just opened are often dark
      if (!cap.read(frame)) break;
    if (frame.empty()) return fg_fail(FG_EUNAVAIL, "%s gave no frame", device);
    std::vector<uchar> buf;
    if (!cv::imencode(".png", frame, buf))
      return fg_fail(FG_EUNAVAIL, "%s: its frame could not be encoded", device);
    *png = (uint8_t *)std::malloc(buf.size());
    if (!*png) return fg_fail(FG_ENOMEM, "a frame of %zu bytes", buf.size());
    std::memcpy(*png, buf.data(), buf.size());
    *len = buf.size();
    return 0;
  } catch (const std::exception &e) {
    return fg_fail(FG_EUNAVAIL, "%s: OpenCV: %s", device, e.what());
  }
}
