/* Unit tests of lib/io/image: decoding of every supported format (images are generated here,
 * no fixtures), compositing, linear-to-sRGB conversion, corrupt data, area resampling and
 * undistortion checked against OpenCV's own point undistortion. */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "io/depth.h"
#include "io/image.h"

#include <stdint.h>
#include <zlib.h>

static char tmpdir[64];

static char *tmp_path(const char *name) {
  char *p = fg_path_join(tmpdir, name);
  ASSERT(p != NULL);
  return p;
}

static void read_whole(const char *path, char **buf, size_t *len) {
  ASSERT_OK(fg_read_file(path, 1u << 30, buf, len));
}

static double srgb_encode(double v) {
  return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055;
}

static const float white[3] = {1, 1, 1};

static void test_png16_exact(void) {
  enum { W = 256, H = 4 };
  static uint16_t px[H][W][3];
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++)
      for (int c = 0; c < 3; c++) px[y][x][c] = (uint16_t)((x * 257 + y * 13 + c * 1000) % 65536);
  uint8_t *png;
  size_t len;
  ASSERT_OK(fg_image_encode_png(px, W, H, 3, 16, &png, &len));
  fg_image img;
  ASSERT_OK(fg_image_decode(png, len, white, &img));
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++)
      for (int c = 0; c < 3; c++) {
        float v = img.rgb[(y * W + x) * 3 + c];
        ASSERT_EQ(lrint(v * 65535.0), px[y][x][c]);
        ASSERT_NEAR(v, px[y][x][c] / 65535.0, 1e-7);
      }
  fg_image_release(&img);
  ASSERT(img.rgb == NULL);
  free(png);

  /* Grey 8-bit expands to RGB. */
  uint8_t grey[2 * 3] = {0, 51, 102, 153, 204, 255};
  ASSERT_OK(fg_image_encode_png(grey, 3, 2, 1, 8, &png, &len));
  ASSERT_OK(fg_image_decode(png, len, white, &img));
  ASSERT_EQ(img.w, 3);
  ASSERT_EQ(img.h, 2);
  for (int i = 0; i < 6; i++)
    for (int c = 0; c < 3; c++) ASSERT_NEAR(img.rgb[i * 3 + c], grey[i] / 255.0, 1e-6);
  fg_image_release(&img);
  free(png);
}

static void test_png_alpha(void) {
  /* Straight (unassociated) alpha 0, 0.5 and 1 on a coloured background. */
  enum { W = 3, H = 1 };
  const uint8_t px[W * 4] = {250, 10, 100, 0, 250, 10, 100, 128, 250, 10, 100, 255};
  const float bg[3] = {0.2f, 0.4f, 0.6f};
  uint8_t *png;
  size_t len;
  ASSERT_OK(fg_image_encode_png(px, W, H, 4, 8, &png, &len));
  fg_image img;
  ASSERT_OK(fg_image_decode(png, len, bg, &img));
  ASSERT_EQ(img.w, W);
  for (int i = 0; i < W; i++) {
    double a = px[i * 4 + 3] / 255.0;
    for (int c = 0; c < 3; c++) {
      double want = px[i * 4 + c] / 255.0 * a + bg[c] * (1 - a);
      ASSERT_NEAR(img.rgb[i * 3 + c], want, 1.0 / 255);
      ASSERT_NEAR(img.rgb[i * 3 + c], want, 1e-5); /* in fact exact up to float rounding */
    }
  }
  ASSERT_NEAR(img.rgb[0], 0.2, 1e-6); /* alpha 0 is the background */
  ASSERT_NEAR(img.rgb[6], 250 / 255.0, 1e-6); /* alpha 1 is the colour */
  fg_image_release(&img);
  free(png);

  /* Grey + alpha through a file written by OIIO. */
  const float ga[2 * 2] = {0.8f, 0.5f, 0.1f, 1.0f};
  char *path = tmp_path("ga.png");
  ASSERT_OK(fg_image_write_file(path, ga, 2, 1, 2));
  char *buf;
  read_whole(path, &buf, &len);
  ASSERT_OK(fg_image_decode(buf, len, bg, &img));
  for (int c = 0; c < 3; c++) {
    ASSERT_NEAR(img.rgb[c], 0.8 * 0.5 + bg[c] * 0.5, 1.0 / 255);
    ASSERT_NEAR(img.rgb[3 + c], 0.1, 1.0 / 255);
  }
  fg_image_release(&img);
  free(buf);
  free(path);
}

static void test_jpeg(void) {
  enum { W = 64, H = 48 };
  static float px[H * W * 3];
  for (int i = 0; i < W * H; i++) px[i * 3] = 0.8f, px[i * 3 + 1] = 0.3f, px[i * 3 + 2] = 0.1f;
  char *path = tmp_path("c.jpg");
  ASSERT_OK(fg_image_write_file(path, px, W, H, 3));
  char *buf;
  size_t len;
  read_whole(path, &buf, &len);
  ASSERT_EQ((uint8_t)buf[0], 0xff);
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, white, &img));
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  const float *p = img.rgb + ((H / 2) * W + W / 2) * 3;
  ASSERT_NEAR(p[0], 0.8, 0.03);
  ASSERT_NEAR(p[1], 0.3, 0.03);
  ASSERT_NEAR(p[2], 0.1, 0.03);
  fg_image_release(&img);
  free(buf);
  free(path);
}

static void test_exr_linear(void) {
  enum { W = 8, H = 4 };
  static float px[H * W * 4];
  for (int i = 0; i < W * H * 3; i++) px[i] = 0.5f;
  char *path = tmp_path("lin.exr");
  ASSERT_OK(fg_image_write_file(path, px, W, H, 3));
  char *buf;
  size_t len;
  read_whole(path, &buf, &len);
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, white, &img));
  ASSERT_EQ(img.w, W);
  ASSERT_EQ(img.h, H);
  for (int i = 0; i < W * H * 3; i++) ASSERT_NEAR(img.rgb[i], 0.7354, 5e-4);
  fg_image_release(&img);
  /* A header attribute that declares more bytes than the file holds is refused before
   * OpenEXR allocates them (a fuzzed 513-byte file declared a 1.9 GB string), and so is a
   * file cut inside its header. */
  size_t at = 8 + strlen(buf + 8) + 1; /* past the signature and the first attribute's name */
  at += strlen(buf + at) + 1;          /* and its type: its 32-bit size */
  ASSERT(at + 4 < len);
  char saved[4];
  memcpy(saved, buf + at, 4);
  memcpy(buf + at, "\x13\x00\x00\x72", 4);
  ASSERT_ERR(fg_image_decode(buf, len, white, &img), FG_EFORMAT, "declares 1912602643 bytes");
  fg_depth_map dm;
  ASSERT_ERR(fg_depth_decode(buf, len, 1.0, &dm), FG_EFORMAT, "declares");
  memcpy(buf + at, saved, 4);
  ASSERT_ERR(fg_image_decode(buf, at + 2, white, &img), FG_EFORMAT, "truncated");
  free(buf);
  free(path);

  /* EXR alpha is associated; compositing happens in linear light: colour 0.25 (premultiplied
   * by 0.5) over a linear 0.5 grey background gives 0.25 + 0.5 * 0.5 = 0.5 linear. Values
   * above 1 are clamped. */
  for (int i = 0; i < W * H; i++) {
    float *q = px + i * 4;
    q[0] = q[1] = q[2] = 0.25f;
    q[3] = 0.5f;
  }
  px[0] = 7.0f; /* over-bright red of the first pixel */
  path = tmp_path("alpha.exr");
  ASSERT_OK(fg_image_write_file(path, px, W, H, 4));
  read_whole(path, &buf, &len);
  const float grey_bg[3] = {(float)srgb_encode(0.5), (float)srgb_encode(0.5),
                            (float)srgb_encode(0.5)};
  ASSERT_OK(fg_image_decode(buf, len, grey_bg, &img));
  ASSERT_NEAR(img.rgb[0], 1.0, 1e-6);
  for (int i = 1; i < W * H * 3; i++) ASSERT_NEAR(img.rgb[i], 0.7354, 1e-3);
  fg_image_release(&img);
  free(buf);
  free(path);

  /* A float TIFF is linear too. */
  for (int i = 0; i < W * H * 3; i++) px[i] = 0.5f;
  path = tmp_path("lin.tif");
  ASSERT_OK(fg_image_write_file(path, px, W, H, 3));
  read_whole(path, &buf, &len);
  ASSERT_OK(fg_image_decode(buf, len, white, &img));
  for (int i = 0; i < W * H * 3; i++) ASSERT_NEAR(img.rgb[i], 0.7354, 5e-4);
  fg_image_release(&img);
  free(buf);
  free(path);
}

/* A PNG signature and an IHDR chunk declaring w x h, then IEND: enough for a reader to learn
 * the size and nothing more. */
static uint8_t *png_header_only(uint32_t w, uint32_t h, size_t *len) {
  static uint8_t b[80];
  size_t n = 0;
  memcpy(b, "\x89PNG\r\n\x1a\n", 8);
  n = 8;
  const uint8_t ihdr[17] = {'I', 'H', 'D', 'R', (uint8_t)(w >> 24), (uint8_t)(w >> 16),
                            (uint8_t)(w >> 8), (uint8_t)w, (uint8_t)(h >> 24), (uint8_t)(h >> 16),
                            (uint8_t)(h >> 8), (uint8_t)h, 8, 2, 0, 0, 0};
  b[n++] = 0, b[n++] = 0, b[n++] = 0, b[n++] = 13;
  memcpy(b + n, ihdr, 17);
  uint32_t crc = (uint32_t)crc32(0, ihdr, 17);
  n += 17;
  b[n++] = (uint8_t)(crc >> 24), b[n++] = (uint8_t)(crc >> 16), b[n++] = (uint8_t)(crc >> 8),
  b[n++] = (uint8_t)crc;
  /* An IDAT chunk (an empty zlib stream): readers stop reading the header at the first one. */
  const uint8_t idat[12] = {'I', 'D', 'A', 'T', 0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01};
  b[n++] = 0, b[n++] = 0, b[n++] = 0, b[n++] = 8;
  memcpy(b + n, idat, 12);
  n += 12;
  crc = (uint32_t)crc32(0, idat, 12);
  b[n++] = (uint8_t)(crc >> 24), b[n++] = (uint8_t)(crc >> 16), b[n++] = (uint8_t)(crc >> 8),
  b[n++] = (uint8_t)crc;
  memcpy(b + n, "\0\0\0\0IEND\xae\x42\x60\x82", 12);
  n += 12;
  *len = n;
  return b;
}

/* Appends an EXR attribute: name, type, size, value. The format is little-endian; the size is
 * written so, values are copied in host order (the tests run on little-endian machines). */
static size_t exr_attr(uint8_t *b, size_t n, const char *name, const char *type, const void *v,
                       uint32_t size) {
  memcpy(b + n, name, strlen(name) + 1), n += strlen(name) + 1;
  memcpy(b + n, type, strlen(type) + 1), n += strlen(type) + 1;
  for (int i = 0; i < 4; i++) b[n++] = (uint8_t)(size >> (8 * i));
  memcpy(b + n, v, size);
  return n + size;
}

/* An OpenEXR scan-line header declaring a w x h data window of half RGB, with no pixels: the
 * reader sizes its line buffers from the window as it opens the file. */
static uint8_t *exr_header_only(int32_t w, int32_t h, size_t *len) {
  static uint8_t b[512];
  size_t n = 0;
  memcpy(b, "\x76\x2f\x31\x01\x02\0\0\0", 8), n = 8;
  uint8_t ch[3 * 18 + 1] = {0};
  for (int c = 0; c < 3; c++) {
    uint8_t *e = ch + 18 * c;
    e[0] = (uint8_t)"BGR"[c];       /* name, then its 0 */
    e[2] = 1;                       /* pixel type: half */
    e[10] = 1, e[14] = 1;           /* x and y sampling */
  }
  n = exr_attr(b, n, "channels", "chlist", ch, sizeof ch);
  n = exr_attr(b, n, "compression", "compression", "\0", 1);
  const int32_t win[4] = {0, 0, w - 1, h - 1};
  n = exr_attr(b, n, "dataWindow", "box2i", win, sizeof win);
  n = exr_attr(b, n, "displayWindow", "box2i", win, sizeof win);
  n = exr_attr(b, n, "lineOrder", "lineOrder", "\0", 1);
  const float one = 1.0f, centre[2] = {0.0f, 0.0f};
  n = exr_attr(b, n, "pixelAspectRatio", "float", &one, sizeof one);
  n = exr_attr(b, n, "screenWindowCenter", "v2f", centre, sizeof centre);
  n = exr_attr(b, n, "screenWindowWidth", "float", &one, sizeof one);
  b[n++] = 0;
  memset(b + n, 0, 64), n += 64; /* a zeroed offset table: no scan line is readable */
  *len = n;
  return b;
}

static void test_corrupt(void) {
  enum { W = 64, H = 64 };
  static uint8_t px[H * W * 3];
  for (size_t i = 0; i < sizeof px; i++) px[i] = (uint8_t)(i * 7919 % 251);
  uint8_t *png;
  size_t len;
  ASSERT_OK(fg_image_encode_png(px, W, H, 3, 8, &png, &len));
  fg_image img;
  ASSERT_ERR(fg_image_decode(png, len / 2, white, &img), FG_EFORMAT, "PNG");
  ASSERT(img.rgb == NULL);
  ASSERT_ERR(fg_image_decode(png, 20, white, &img), FG_EFORMAT, "truncated or corrupt");
  png[len / 2] ^= 0x55; /* a flipped byte inside the compressed data */
  int rc = fg_image_decode(png, len, white, &img);
  ASSERT_EQ(rc, FG_EFORMAT);
  free(png);

  /* The other formats cut in half. */
  static float fpx[H * W * 3];
  for (int i = 0; i < W * H * 3; i++) fpx[i] = (float)(i % 13) / 13.0f;
  static const char *const names[3] = {"t.jpg", "t.exr", "t.tif"};
  static const char *const formats[3] = {"JPEG", "OpenEXR", "TIFF"};
  for (int i = 0; i < 3; i++) {
    char *path = tmp_path(names[i]);
    ASSERT_OK(fg_image_write_file(path, fpx, W, H, 3));
    char *buf;
    read_whole(path, &buf, &len);
    ASSERT_OK(fg_image_decode(buf, len, white, &img));
    fg_image_release(&img);
    ASSERT_ERR(fg_image_decode(buf, len / 2, white, &img), FG_EFORMAT, formats[i]);
    ASSERT_STRCONTAINS(fg_error_detail(), "truncated or corrupt");
    free(buf);
    free(path);
  }

  uint8_t noise[1000];
  uint32_t s = 12345;
  for (size_t i = 0; i < sizeof noise; i++) {
    s = s * 1103515245u + 12345u;
    noise[i] = (uint8_t)(s >> 16);
  }
  noise[0] = 0x42;
  ASSERT(fg_image_sniff(noise, sizeof noise) == NULL);
  ASSERT(fg_image_sniff(NULL, 0) == NULL);
  ASSERT_ERR(fg_image_decode(noise, sizeof noise, white, &img), FG_EFORMAT, "supported");
  ASSERT_STRCONTAINS(fg_error_detail(), "PNG, JPEG, OpenEXR and TIFF");
  ASSERT_ERR(fg_image_decode(noise, 0, white, &img), FG_EFORMAT, "");
  /* JPEG, EXR and TIFF magic followed by garbage. */
  ASSERT(fg_image_sniff("\x89PNG\r\n", 6) != NULL);
  ASSERT_STREQ(fg_image_sniff("\x89PNG\r\n", 6), "PNG");
  ASSERT_STREQ(fg_image_sniff("\xff\xd8\xff\xe0", 4), "JPEG");
  ASSERT_STREQ(fg_image_sniff("\x76\x2f\x31\x01", 4), "OpenEXR");
  ASSERT_STREQ(fg_image_sniff("MM\0*", 4), "TIFF");
  ASSERT_STREQ(fg_image_sniff("II*\0", 4), "TIFF");
  ASSERT(fg_image_sniff("\x89PN", 3) == NULL);
  memcpy(noise, "\xff\xd8\xff", 3);
  ASSERT_ERR(fg_image_decode(noise, sizeof noise, white, &img), FG_EFORMAT, "JPEG");
  memcpy(noise, "\x76\x2f\x31\x01", 4);
  ASSERT_ERR(fg_image_decode(noise, sizeof noise, white, &img), FG_EFORMAT, "OpenEXR");
  memcpy(noise, "II*\0", 4);
  ASSERT_ERR(fg_image_decode(noise, sizeof noise, white, &img), FG_EFORMAT, "TIFF");

  /* Sizes beyond the limits are refused before any pixel memory is taken. */
  const uint8_t *hdr = png_header_only(20000, 20000, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_ERANGE, "20000x20000");
  hdr = png_header_only(16384, 8192, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_ERANGE, "downscale");
  /* OpenEXR refuses an oversized window itself, before it takes memory for line buffers
   * (a 9-million-pixel-wide header, found by fuzzing, cost seconds under AddressSanitizer). */
  hdr = exr_header_only(8978436, 3, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_ERANGE, "data window or tiles are larger");
  hdr = exr_header_only(3, FG_IMAGE_MAX_SIDE + 1, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_ERANGE, "data window or tiles are larger");
  /* At the limit, or small, the header passes and the missing pixels make it corrupt. */
  hdr = exr_header_only(FG_IMAGE_MAX_SIDE, 3, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_EFORMAT, "OpenEXR");
  hdr = exr_header_only(4, 3, &len);
  ASSERT_ERR(fg_image_decode(hdr, len, white, &img), FG_EFORMAT, "OpenEXR");
}

static void test_resize(void) {
  float src[4 * 4], dst[2 * 2];
  for (int i = 0; i < 16; i++) src[i] = (float)(i * i % 11) / 10.0f;
  ASSERT_OK(fg_image_resize_area(src, 4, 4, 1, dst, 2, 2));
  for (int y = 0; y < 2; y++)
    for (int x = 0; x < 2; x++) {
      double m = (src[(2 * y) * 4 + 2 * x] + src[(2 * y) * 4 + 2 * x + 1] +
                  src[(2 * y + 1) * 4 + 2 * x] + src[(2 * y + 1) * 4 + 2 * x + 1]) / 4.0;
      ASSERT_NEAR(dst[y * 2 + x], m, 1e-6);
    }
  /* Many channels (feature grids) and a non-integer ratio keep a constant constant. */
  enum { C = 8 };
  static float s8[30 * 40 * C], d8[11 * 17 * C];
  for (int i = 0; i < 30 * 40; i++)
    for (int c = 0; c < C; c++) s8[i * C + c] = (float)c * 0.125f;
  ASSERT_OK(fg_image_resize_area(s8, 40, 30, C, d8, 17, 11));
  for (int i = 0; i < 11 * 17; i++)
    for (int c = 0; c < C; c++) ASSERT_NEAR(d8[i * C + c], c * 0.125, 1e-6);
  ASSERT_ERR(fg_image_resize_area(src, 4, 4, 1, dst, 0, 2), FG_EINVAL, "");
}

/* ---- undistortion ------------------------------------------------------------------- */

enum { UW = 320, UH = 240, NDOTS = 13 };

static void test_undistort(void) {
  const fg_camera cam = {.fl_x = 250, .fl_y = 250, .cx = 161.3, .cy = 118.7, .w = UW, .h = UH,
                         .model = FG_CAMERA_OPENCV, .k1 = -0.25, .k2 = 0.08, .p1 = 0.001,
                         .p2 = -0.0015, .k3 = 0};
  /* Distorted pixel positions (continuous convention) of the dots: the centre, the corners
   * inset by 20 px, the middles of the edges and a few in between. */
  const double dots[NDOTS][2] = {
    {160, 120}, {20, 20},   {300, 20},  {20, 220}, {300, 220}, {160, 20}, {160, 220},
    {20, 120},  {300, 120}, {90, 70},   {240, 70}, {90, 175},  {240, 175},
  };
  const double sigma = 1.2;
  static float src[UH * UW * 3], dst[UH * UW * 3];
  for (int y = 0; y < UH; y++)
    for (int x = 0; x < UW; x++) {
      double v = 0;
      for (int d = 0; d < NDOTS; d++) {
        double dx = x + 0.5 - dots[d][0], dy = y + 0.5 - dots[d][1];
        v += exp(-(dx * dx + dy * dy) / (2 * sigma * sigma));
      }
      for (int c = 0; c < 3; c++) src[(y * UW + x) * 3 + c] = (float)v;
    }
  fg_camera pin;
  ASSERT_OK(fg_image_undistort(src, &cam, dst, &pin));
  ASSERT_EQ(pin.model, FG_CAMERA_PINHOLE);
  ASSERT_EQ(pin.w, UW);
  ASSERT_EQ(pin.h, UH);
  ASSERT(pin.k1 == 0 && pin.k2 == 0 && pin.k3 == 0 && pin.p1 == 0 && pin.p2 == 0);
  /* Barrel distortion squeezes a wider view into the frame: undistorted, even the inscribed
   * rectangle that alpha 0 keeps needs shorter focal lengths to fit. */
  ASSERT(pin.fl_x < 250 && pin.fl_y < 250);
  ASSERT_OK(fg_camera_validate(&pin));

  double xy[NDOTS * 2];
  memcpy(xy, dots, sizeof xy);
  ASSERT_OK(fg_camera_undistort_points(&cam, &pin, xy, NDOTS));
  int seen_corners = 0;
  for (int d = 0; d < NDOTS; d++) {
    double ex = xy[2 * d], ey = xy[2 * d + 1];
    /* A dot the crop cut away cannot be measured; the corner ones must all be inside. */
    if (ex < 10 || ey < 10 || ex > UW - 10 || ey > UH - 10) {
      ASSERT(!(d >= 1 && d <= 4));
      continue;
    }
    if (d >= 1 && d <= 4) seen_corners++;
    double sw = 0, sx = 0, sy = 0;
    for (int y = (int)ey - 9; y <= (int)ey + 9; y++)
      for (int x = (int)ex - 9; x <= (int)ex + 9; x++) {
        if (x < 0 || y < 0 || x >= UW || y >= UH) continue;
        double v = dst[(y * UW + x) * 3 + 1];
        sw += v;
        sx += v * (x + 0.5);
        sy += v * (y + 0.5);
      }
    ASSERT(sw > 1.0);
    double cxm = sx / sw, cym = sy / sw;
    if (fabs(cxm - ex) > 0.5 || fabs(cym - ey) > 0.5)
      FG_TEST_FAIL("dot %d at (%.1f, %.1f): centroid (%.3f, %.3f), undistortPoints (%.3f, %.3f)",
                   d, dots[d][0], dots[d][1], cxm, cym, ex, ey);
  }
  ASSERT_EQ(seen_corners, 4);

  /* The forward model inverts undistortPoints: distorting the undistorted positions through
   * pin's normalised coordinates lands back on the dots. */
  for (int d = 0; d < NDOTS; d++) {
    double x = (xy[2 * d] - pin.cx) / pin.fl_x, y = (xy[2 * d + 1] - pin.cy) / pin.fl_y, xd, yd;
    fg_camera_distort_normalized(&cam, x, y, &xd, &yd);
    ASSERT_NEAR(cam.fl_x * xd + cam.cx, dots[d][0], 1e-6);
    ASSERT_NEAR(cam.fl_y * yd + cam.cy, dots[d][1], 1e-6);
  }

  /* A pinhole camera passes through unchanged. */
  fg_camera ph = cam;
  ph.model = FG_CAMERA_PINHOLE;
  ph.k1 = ph.k2 = ph.p1 = ph.p2 = 0;
  ASSERT_OK(fg_image_undistort(src, &ph, dst, &pin));
  ASSERT_EQ(memcmp(src, dst, sizeof src), 0);
  ASSERT(pin.fl_x == 250 && pin.cx == 161.3);
  /* PINHOLE with coefficients is a mistake worth reporting. */
  ph.k1 = 0.1;
  ASSERT_ERR(fg_image_undistort(src, &ph, dst, &pin), FG_EINVAL, "OPENCV");
}

static void test_camera(void) {
  fg_camera_model m;
  ASSERT_OK(fg_camera_model_parse("OPENCV", &m));
  ASSERT_EQ(m, FG_CAMERA_OPENCV);
  ASSERT_OK(fg_camera_model_parse("PINHOLE", &m));
  ASSERT_EQ(m, FG_CAMERA_PINHOLE);
  ASSERT_ERR(fg_camera_model_parse("FISHEYE", &m), FG_EINVAL, "PINHOLE and OPENCV");
  ASSERT_STREQ(fg_camera_model_name(FG_CAMERA_OPENCV), "OPENCV");
  fg_camera c = {.fl_x = 100, .fl_y = 100, .cx = 50, .cy = 40, .w = 100, .h = 80};
  ASSERT_OK(fg_camera_validate(&c));
  ASSERT(!fg_camera_is_distorted(&c));
  c.fl_y = -1;
  ASSERT_ERR(fg_camera_validate(&c), FG_EINVAL, "focal");
  c.fl_y = 100;
  c.w = 0;
  ASSERT_ERR(fg_camera_validate(&c), FG_EINVAL, "size");
  c.w = 100;
  c.cx = NAN;
  ASSERT_ERR(fg_camera_validate(&c), FG_EINVAL, "principal");
  c.cx = 50;
  c.model = FG_CAMERA_OPENCV;
  c.p2 = INFINITY;
  ASSERT_ERR(fg_camera_validate(&c), FG_EINVAL, "p2");
  c.p2 = 0.01;
  ASSERT_OK(fg_camera_validate(&c));
  ASSERT(fg_camera_is_distorted(&c));
  double xd, yd;
  c.k1 = 0.1, c.k2 = 0.01, c.k3 = 0.001, c.p1 = 0.002, c.p2 = 0.003;
  fg_camera_distort_normalized(&c, 0.3, -0.2, &xd, &yd);
  double r2 = 0.13, rad = 1 + 0.1 * r2 + 0.01 * r2 * r2 + 0.001 * r2 * r2 * r2;
  ASSERT_NEAR(xd, 0.3 * rad + 2 * 0.002 * 0.3 * -0.2 + 0.003 * (r2 + 2 * 0.09), 1e-15);
  ASSERT_NEAR(yd, -0.2 * rad + 0.002 * (r2 + 2 * 0.04) + 2 * 0.003 * 0.3 * -0.2, 1e-15);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/fg_test_image_XXXXXX");
  ASSERT(mkdtemp(tmpdir) != NULL);
  test_camera();
  test_png16_exact();
  test_png_alpha();
  test_jpeg();
  test_exr_linear();
  test_corrupt();
  test_resize();
  test_undistort();
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("image: ok\n");
  return 0;
}
