/* A camera's image from its source (cell/snapshot.c), for a v4l2: source: the grabber child
 * (fieldgrip-grab) run, its PNG read, its failures and its hang turned into camera_unavailable
 * and camera_timeout. The test build of the grabber plays the camera from PNG files (OpenCV's
 * image-sequence reader); the real one is run on a device that is not there.
 * argv[1]: fieldgrip-grab-test, argv[2]: fieldgrip-grab. */
#include "cell/cameras.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "core/error.h"
#include "core/clock.h"
#include "io/image.h"
#include "test.h"

#define MAX_BYTES (8u << 20)

static char g_dir[64];

int main(int argc, char **argv) {
  ASSERT(argc >= 3);
  const char *grab_test = argv[1], *grab = argv[2];
  const char *src = getenv("FG_SHARED_DATA");
  ASSERT(src);
  snprintf(g_dir, sizeof g_dir, "/tmp/fg-snap-XXXXXX");
  ASSERT(mkdtemp(g_dir));
  /* two frames of the lego data set play the camera: the grabber keeps the last it read */
  char cmd[512];
  snprintf(cmd, sizeof cmd, "cp '%s/lego/train/r_0.png' %s/frame_00.png && "
           "cp '%s/lego/train/r_1.png' %s/frame_01.png", src, g_dir, src, g_dir);
  ASSERT_EQ(system(cmd), 0);

  char source[128];
  snprintf(source, sizeof source, FG_SOURCE_V4L2 "%s/frame_%%02d.png", g_dir);
  uint8_t *img;
  size_t len;
  ASSERT_OK(fg_snapshot_fetch(grab_test, source, 10000, MAX_BYTES, &img, &len));
  ASSERT_STREQ(fg_image_sniff(img, len), "PNG");
  fg_image im;
  ASSERT_OK(fg_image_decode(img, len, NULL, &im));
  printf("grabbed %zu bytes: a %d x %d PNG\n", len, im.w, im.h);
  ASSERT_EQ(im.w, 800);
  ASSERT_EQ(im.h, 800);
  fg_image_release(&im);
  free(img);

  /* more than max_bytes: refused, the child killed */
  ASSERT_ERR(fg_snapshot_fetch(grab_test, source, 10000, 1000, &img, &len), FG_EUNAVAIL,
             "more than 1000 bytes");
  ASSERT_STREQ(fg_error_reason(), "camera_unavailable");
  ASSERT(img == NULL && len == 0);

  /* a device that is not there, with the real grabber: its one line in the error */
  ASSERT_ERR(fg_snapshot_fetch(grab, FG_SOURCE_V4L2 "/dev/video-none", 10000, MAX_BYTES, &img,
                               &len), FG_EUNAVAIL, "cannot open /dev/video-none");
  ASSERT_STREQ(fg_error_reason(), "camera_unavailable");
  /* the real grabber takes no files for a camera */
  ASSERT_ERR(fg_snapshot_fetch(grab, source, 10000, MAX_BYTES, &img, &len), FG_EUNAVAIL,
             "cannot open");

  /* a grabber that never answers: killed at the timeout */
  const double t0 = fg_mono_s();
  ASSERT_ERR(fg_snapshot_fetch(grab_test, FG_SOURCE_V4L2 "hang", 300, MAX_BYTES, &img, &len),
             FG_ETIMEDOUT, "no frame within 300 ms");
  ASSERT_STREQ(fg_error_reason(), "camera_timeout");
  printf("a hung grabber ended after %.2f s\n", fg_mono_s() - t0);

  /* a grabber that is not there */
  ASSERT_ERR(fg_snapshot_fetch("/nonexistent/fieldgrip-grab", source, 1000, MAX_BYTES, &img,
                               &len), FG_EUNAVAIL, "cannot run");

  snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
  ASSERT_EQ(system(cmd), 0);
  printf("snapshot: ok\n");
  return 0;
}
