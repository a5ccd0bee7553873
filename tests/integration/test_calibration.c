/* The calibration endpoints over HTTP: the board of [calibration] as a printable PNG, found
 * again by the detector with every corner where a print at 300 dpi puts it; a board the
 * configuration describes differently prints differently.
 * argv[1]: fieldgripd. */
#include "harness.h"

#include <math.h>

#include "calib/charuco.h"
#include "io/image.h"

/* GET /v1/calibration/board.png, every corner found at square_m x 300 dpi. */
static void check_board(int sx, int sy, double square, double marker, const char *dict) {
  char conf[256];
  snprintf(conf, sizeof conf, "[calibration]\nsquares_x = %d\nsquares_y = %d\nsquare_m = %g\n"
           "marker_m = %g\ndictionary = %s\n", sx, sy, square, marker, dict);
  h_write_config(conf);
  h_start();
  h_resp *r = h_get("/v1/calibration/board.png");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "image/png");
  const float bg[3] = {1, 1, 1};
  fg_image img;
  ASSERT_EQ(fg_image_decode(r->body, r->len, bg, &img), 0);
  h_resp_free(r);
  const int px = (int)lround(square / 0.0254 * 300);
  ASSERT_EQ(img.w, sx * px + 2 * (px / 2));
  ASSERT_EQ(img.h, sy * px + 2 * (px / 2));
  uint8_t *gray = malloc((size_t)img.w * img.h);
  ASSERT(gray);
  for (int i = 0; i < img.w * img.h; i++) gray[i] = (uint8_t)lrintf(img.rgb[3 * i] * 255);
  fg_charuco_board b = {sx, sy, square, marker, 0};
  ASSERT_EQ(fg_charuco_dictionary_parse(dict, &b.dictionary), 0);
  int ids[64 * 64], n = 0;
  static double xy[2 * 64 * 64];
  ASSERT_EQ(fg_charuco_detect(&b, gray, img.w, img.h, ids, xy, &n), 0);
  ASSERT_EQ(n, fg_charuco_corner_count(&b));
  free(gray);
  fg_image_release(&img);
  h_stop();
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  check_board(7, 5, 0.035, 0.026, "DICT_5X5_100"); /* the default, as the example file sets it */
  check_board(5, 4, 0.02, 0.015, "DICT_4X4_50");
  h_done();
  printf("ok\n");
  return 0;
}
