/* Unit tests of lib/calib/charuco: dictionary names, the boards OpenCV cannot make, and the
 * printed board found again by the detector with every inner corner where the board frame
 * puts it. */
#include "test.h"

#include <math.h>

#include "calib/charuco.h"
#include "core/error.h"
#include "io/image.h"

static fg_charuco_board board(int sx, int sy, double square, double marker, const char *dict) {
  fg_charuco_board b = {sx, sy, square, marker, 0};
  ASSERT_EQ(fg_charuco_dictionary_parse(dict, &b.dictionary), 0);
  return b;
}

static void test_names(void) {
  int d = -1;
  ASSERT_EQ(fg_charuco_dictionary_parse("DICT_5X5_100", &d), 0);
  ASSERT_EQ(d, 5);
  ASSERT_STREQ(fg_charuco_dictionary_name(d), "DICT_5X5_100");
  ASSERT_EQ(fg_charuco_dictionary_parse("DICT_APRILTAG_36h11", &d), 0);
  ASSERT_EQ(d, 20);
  ASSERT_EQ(fg_charuco_dictionary_parse("DICT_5x5_100", &d), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "DICT_4X4_50"));
}

static void test_refusals(void) {
  fg_charuco_board b = board(2, 5, 0.04, 0.03, "DICT_5X5_100");
  ASSERT_EQ(fg_charuco_board_check(&b), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "2 x 5"));
  b = board(5, 7, 0.04, 0.04, "DICT_5X5_100");
  ASSERT_EQ(fg_charuco_board_check(&b), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "below square_m"));
  b = board(12, 12, 0.02, 0.015, "DICT_4X4_50"); /* 72 markers */
  ASSERT_EQ(fg_charuco_board_check(&b), FG_EINVAL);
  ASSERT(strstr(fg_error_detail(), "needs 72 markers; DICT_4X4_50 has 50"));
  b = board(5, 7, 0.04, 0.03, "DICT_5X5_100");
  ASSERT_EQ(fg_charuco_board_check(&b), 0);
  ASSERT_EQ(fg_charuco_corner_count(&b), 24);
  double c[3];
  fg_charuco_corner(&b, 4, c); /* the second row's first corner */
  ASSERT_NEAR(c[0], 0.04, 1e-12);
  ASSERT_NEAR(c[1], 0.08, 1e-12);
}

/* The print, as a PNG decoded and searched: every inner corner found, at the pixel the board frame and
 * the print's scale put it (a texel's centre is its pixel's integer coordinate). */
static void check_print(int sx, int sy, const char *dict) {
  fg_charuco_board b = board(sx, sy, 0.05, 0.037, dict);
  const int pps = 80, margin = 40;
  uint8_t *png, *print;
  size_t len;
  int pw, ph;
  ASSERT_EQ(fg_charuco_print(&b, pps, margin, &print, &pw, &ph), 0);
  ASSERT_EQ(fg_image_encode_png(print, pw, ph, 1, 8, &png, &len), 0); /* as the daemon does */
  free(print);
  const float bg[3] = {1, 1, 1};
  fg_image img;
  ASSERT_EQ(fg_image_decode(png, len, bg, &img), 0);
  free(png);
  ASSERT_EQ(img.w, sx * pps + 2 * margin);
  ASSERT_EQ(img.h, sy * pps + 2 * margin);
  uint8_t *gray = malloc((size_t)img.w * img.h);
  ASSERT(gray);
  for (int i = 0; i < img.w * img.h; i++) gray[i] = (uint8_t)lrintf(img.rgb[3 * i] * 255);
  const int n_max = fg_charuco_corner_count(&b);
  int *ids = malloc(sizeof *ids * n_max), n = 0;
  double *px = malloc(sizeof *px * 2 * n_max);
  ASSERT_EQ(fg_charuco_detect(&b, gray, img.w, img.h, ids, px, &n), 0);
  ASSERT_EQ(n, n_max);
  const double ppm = pps / b.square_m, H = sy * pps;
  const int flip = fg_charuco_face_z(&b) > 0;
  for (int k = 0; k < n; k++) {
    double c[3];
    fg_charuco_corner(&b, ids[k], c);
    const double u = margin + c[0] * ppm - 0.5;
    const double v = margin + (flip ? H - c[1] * ppm : c[1] * ppm) - 0.5;
    if (fabs(px[2 * k] - u) > 0.1 || fabs(px[2 * k + 1] - v) > 0.1)
      FG_TEST_FAIL("%dx%d: corner %d found at (%.2f, %.2f), expected (%.2f, %.2f)", sx, sy,
                   ids[k], px[2 * k], px[2 * k + 1], u, v);
  }
  /* a blank image: no board, no error */
  memset(gray, 200, (size_t)img.w * img.h);
  ASSERT_EQ(fg_charuco_detect(&b, gray, img.w, img.h, ids, px, &n), 0);
  ASSERT_EQ(n, 0);
  free(gray);
  free(ids);
  free(px);
  fg_image_release(&img);
}

static void test_print(void) {
  check_print(5, 7, "DICT_5X5_100");
  check_print(8, 6, "DICT_4X4_50"); /* an even number of rows */
}

int main(void) {
  test_names();
  test_refusals();
  test_print();
  printf("charuco: ok\n");
  return 0;
}
