// fieldgrip-grab: one frame from a V4L2 device, as PNG on stdout. fieldgripd runs it for each
// capture from a camera whose source is v4l2:DEVICE (cell/snapshot.c), so that the daemon
// itself never loads OpenCV's videoio or an image codec.
//
//   fieldgrip-grab DEVICE [WARMUP]
//
// Opens DEVICE (/dev/videoN) with OpenCV's V4L2 backend, reads WARMUP frames (default 5: the
// camera's automatic exposure settles on them) and writes the next one, 8-bit BGR as the
// device gives it, as a PNG to stdout. Exit status 0; 2 with one line on stderr saying what
// went wrong (the device does not open, gives no frame, the PNG cannot be written).
//
// The test build (FG_GRAB_TEST_HOOKS, fieldgrip-grab-test, never installed) opens any DEVICE
// that is not under /dev/ with OpenCV's image-sequence reader instead, so that the tests can
// play a camera from a few PNG files, and for DEVICE "hang" never answers.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

static int fail(const char *what, const char *device) {
  std::fprintf(stderr, "%s %s\n", what, device);
  return 2;
}

int main(int argc, char **argv) {
  if (argc < 2 || argc > 3) {
    std::fprintf(stderr, "usage: fieldgrip-grab DEVICE [WARMUP]\n");
    return 2;
  }
  const char *device = argv[1];
  const int warmup = argc > 2 ? std::atoi(argv[2]) : 5;
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR); // one line on failure
  int api = cv::CAP_V4L2;
#ifdef FG_GRAB_TEST_HOOKS
  if (std::strcmp(device, "hang") == 0)
    for (;;) pause();
  if (std::strncmp(device, "/dev/", 5) != 0) api = cv::CAP_IMAGES;
#endif
  cv::Mat frame;
  try {
    cv::VideoCapture cap(device, api);
    if (!cap.isOpened()) return fail("cannot open", device);
    // the last frame read of warmup + 1 (a short image sequence ends early: its last)
    cv::Mat next;
    for (int i = 0; i <= warmup && cap.read(next); i++) frame = next.clone();
    if (frame.empty()) return fail("no frame from", device);
    if (frame.depth() != CV_8U) frame.convertTo(frame, CV_8U);
    std::vector<unsigned char> png;
    if (!cv::imencode(".png", frame, png)) return fail("cannot encode a PNG of a frame from", device);
    if (std::fwrite(png.data(), 1, png.size(), stdout) != png.size() || std::fflush(stdout) != 0)
      return fail("cannot write the PNG of", device);
  } catch (const cv::Exception &e) {
    std::fprintf(stderr, "%s: %s\n", device, e.what());
    return 2;
  }
  return 0;
}
