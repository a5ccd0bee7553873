/* Unit tests of lib/io/depth: depth read raw from 16-bit PNG and TIFF (value * scale) and
 * from float OpenEXR and TIFF (metres), from .npy arrays, every refusal with its code and a
 * detail a user can act on, the grid check against the image and the valid fraction. Files
 * are generated here (PNG through the encoder, EXR and float TIFF through
 * fg_image_write_file, integer TIFFs by hand), no fixtures. */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "io/depth.h"
#include "io/image.h"
#include "io/npy.h"

#include <stdint.h>

static char tmpdir[64];

enum { W = 5, H = 3 };

/* Millimetres as a RealSense saves them, with 0 (no reading) and the extremes. */
static const uint16_t mm[H][W] = {
    {0, 1, 999, 1000, 1234},
    {65535, 0, 4321, 500, 2},
    {7, 65534, 0, 32768, 1001},
};

static void read_file(const char *name, char **buf, size_t *len) {
  char *path = fg_path_join(tmpdir, name);
  ASSERT(path != NULL);
  ASSERT_OK(fg_read_file(path, 1u << 30, buf, len));
  free(path);
}

/* Writes float [h][w][channels] through fg_image_write_file and reads the file back. */
static void write_float_file(const char *name, const float *px, int w, int h, int channels,
                             char **buf, size_t *len) {
  char *path = fg_path_join(tmpdir, name);
  ASSERT(path != NULL);
  ASSERT_OK(fg_image_write_file(path, px, w, h, channels));
  free(path);
  read_file(name, buf, len);
}

static void put16(uint8_t *p, uint32_t v) {
  p[0] = (uint8_t)v;
  p[1] = (uint8_t)(v >> 8);
}

static void put32(uint8_t *p, uint32_t v) {
  put16(p, v);
  put16(p + 2, v >> 16);
}

/* A baseline little-endian TIFF of one channel, uncompressed, in one strip: bits 8, 16 or
 * 32 per sample, sample format 1 (unsigned), 2 (signed) or 3 (float); px is [h][w] in host
 * order (little-endian here). The caller frees the result. */
static uint8_t *make_tiff(const void *px, int w, int h, int bits, int format, size_t *len) {
  enum { NTAGS = 10 };
  const uint32_t data_len = (uint32_t)(w * h * bits / 8), data_off = 8 + 2 + NTAGS * 12 + 4;
  const uint32_t tags[NTAGS][3] = {
      /* tag, type (3 SHORT, 4 LONG), value; in ascending tag order as TIFF requires */
      {256, 4, (uint32_t)w},      {257, 4, (uint32_t)h},   {258, 3, (uint32_t)bits},
      {259, 3, 1 /* none */},     {262, 3, 1 /* black is zero */},
      {273, 4, data_off},         {277, 3, 1 /* samples per pixel */},
      {278, 4, (uint32_t)h},      {279, 4, data_len},      {339, 3, (uint32_t)format},
  };
  *len = data_off + data_len;
  uint8_t *b = calloc(1, *len);
  ASSERT(b != NULL);
  memcpy(b, "II*\0", 4);
  put32(b + 4, 8);
  put16(b + 8, NTAGS);
  for (int i = 0; i < NTAGS; i++) {
    uint8_t *e = b + 10 + 12 * i;
    put16(e, tags[i][0]);
    put16(e + 2, tags[i][1]);
    put32(e + 4, 1);
    put32(e + 8, tags[i][2]); /* a SHORT sits in the first two bytes, as little-endian does */
  }
  memcpy(b + data_off, px, data_len);
  return b;
}

/* The first n bytes of a PNG with a 16-bit grey w x h header and nothing else; enough for a
 * reader to learn the size. */
static void png16_header(uint32_t w, uint32_t h, uint8_t **png, size_t *len) {
  static const uint16_t one = 1000;
  ASSERT_OK(fg_image_encode_png(&one, 1, 1, 1, 16, png, len));
  /* IHDR's width and height sit at bytes 16..23; its CRC (29..32) must then be fixed, which
   * libpng checks. */
  uint8_t *p = *png;
  for (int i = 0; i < 4; i++) {
    p[16 + i] = (uint8_t)(w >> (24 - 8 * i));
    p[20 + i] = (uint8_t)(h >> (24 - 8 * i));
  }
  uint32_t crc = 0xffffffffu;
  for (int i = 12; i < 29; i++) { /* CRC-32 of "IHDR" and its 13 bytes */
    crc ^= p[i];
    for (int k = 0; k < 8; k++) crc = crc >> 1 ^ (0xedb88320u & (0u - (crc & 1)));
  }
  crc ^= 0xffffffffu;
  for (int i = 0; i < 4; i++) p[29 + i] = (uint8_t)(crc >> (24 - 8 * i));
}

static void assert_scaled(const fg_depth_map *d, double scale) {
  ASSERT_EQ(d->w, W);
  ASSERT_EQ(d->h, H);
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      float m = d->m[y * W + x];
      /* One rounding, of the exact product, to float. */
      if (m != (float)((double)mm[y][x] * scale))
        FG_TEST_FAIL("[%d, %d]: %u * %g gave %.9g", y, x, mm[y][x], scale, (double)m);
      ASSERT_NEAR(m, mm[y][x] * scale, 1e-7 * (1 + mm[y][x] * scale));
      if (mm[y][x] == 0) ASSERT(m == 0 && !signbit(m));
    }
}

static void test_png16(void) {
  uint8_t *png;
  size_t len;
  ASSERT_OK(fg_image_encode_png(mm, W, H, 1, 16, &png, &len));
  fg_depth_map d;
  ASSERT_OK(fg_depth_decode(png, len, 0.001, &d));
  assert_scaled(&d, 0.001);
  ASSERT(d.m[0 * W + 3] == 1.0f);      /* 1000 mm */
  ASSERT(d.m[1 * W + 0] == 65.535f);   /* the largest value */
  ASSERT_NEAR(fg_depth_valid_fraction(d.m, W * H), 12.0 / 15.0, 1e-12);
  fg_depth_release(&d);
  ASSERT(d.m == NULL && d.w == 0);
  fg_depth_release(&d); /* twice is harmless */
  fg_depth_release(NULL);
  ASSERT_OK(fg_depth_decode(png, len, 0.0001, &d));
  assert_scaled(&d, 0.0001);
  ASSERT(d.m[0 * W + 3] == 0.1f);
  fg_depth_release(&d);
  ASSERT_OK(fg_depth_decode(png, len, FG_DEPTH_DEFAULT_SCALE, &d));
  assert_scaled(&d, 0.001);
  fg_depth_release(&d);
  /* fg_depth_read takes the image path for anything but .npy. */
  ASSERT_OK(fg_depth_read(png, len, 0.001, &d));
  assert_scaled(&d, 0.001);
  fg_depth_release(&d);
  free(png);
}

static void test_tiff16(void) {
  size_t len;
  uint8_t *tif = make_tiff(mm, W, H, 16, 1, &len);
  fg_depth_map d;
  ASSERT_OK(fg_depth_decode(tif, len, 0.001, &d));
  assert_scaled(&d, 0.001);
  fg_depth_release(&d);
  free(tif);
}

static void test_float(void) {
  /* Metres, with NaN (no reading) and -0, which must come back as +0. */
  float px[H][W];
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) px[y][x] = (float)(y * W + x) * 0.25f + 0.125f;
  px[0][1] = NAN;
  px[2][4] = NAN;
  px[1][1] = 0.0f;
  px[1][2] = -0.0f;
  px[2][0] = 1e6f;
  static const char *const names[2] = {"d.exr", "d.tif"};
  static const uint8_t magic[2] = {0x76, 'I'};
  for (int f = 0; f < 2; f++) {
    char *buf;
    size_t len;
    write_float_file(names[f], &px[0][0], W, H, 1, &buf, &len);
    ASSERT_EQ((uint8_t)buf[0], magic[f]);
    fg_depth_map d;
    ASSERT_OK(fg_depth_decode(buf, len, 0.001, &d)); /* scale ignored */
    ASSERT_EQ(d.w, W);
    ASSERT_EQ(d.h, H);
    for (int y = 0; y < H; y++)
      for (int x = 0; x < W; x++) {
        float m = d.m[y * W + x];
        if (isnan(px[y][x]) || px[y][x] == 0)
          ASSERT(m == 0 && !signbit(m));
        else if (m != px[y][x])
          FG_TEST_FAIL("%s [%d, %d]: %.9g, expected %.9g", names[f], y, x, (double)m,
                       (double)px[y][x]);
      }
    ASSERT_NEAR(fg_depth_valid_fraction(d.m, W * H), 11.0 / 15.0, 1e-12);
    fg_depth_release(&d);
    free(buf);
  }

  /* Negative and infinite metres name the first bad pixel and its value. */
  px[0][1] = 2.0f;
  px[2][4] = 3.0f;
  px[1][3] = -0.5f;
  px[2][1] = -7.0f;
  char *buf;
  size_t len;
  fg_depth_map d;
  write_float_file("neg.exr", &px[0][0], W, H, 1, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len, 0.001, &d), FG_EINVAL, "[row 1, col 3] is -0.5 metres");
  ASSERT(d.m == NULL);
  free(buf);
  px[1][3] = 1.0f;
  px[2][1] = INFINITY;
  write_float_file("inf.tif", &px[0][0], W, H, 1, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len, 0.001, &d), FG_EINVAL, "[row 2, col 1] is inf metres");
  ASSERT_STRCONTAINS(fg_error_detail(), "finite");
  free(buf);
}

static void test_refusals(void) {
  fg_depth_map d;
  uint8_t *png;
  size_t len;
  ASSERT_OK(fg_image_encode_png(mm, W, H, 1, 16, &png, &len));

  /* The scale, whatever the encoding. */
  ASSERT_ERR(fg_depth_decode(png, len, 0, &d), FG_EINVAL, "depth scale is 0");
  ASSERT_ERR(fg_depth_decode(png, len, -0.001, &d), FG_EINVAL, "finite number > 0");
  ASSERT_ERR(fg_depth_decode(png, len, NAN, &d), FG_EINVAL, "depth scale is nan");
  ASSERT_ERR(fg_depth_decode(png, len, INFINITY, &d), FG_EINVAL, "depth scale is inf");
  ASSERT_ERR(fg_depth_decode(png, len, 1e300, &d), FG_EINVAL, "out of range for 16-bit");
  ASSERT_ERR(fg_depth_decode(png, len, 1e-50, &d), FG_EINVAL, "out of range for 16-bit");
  ASSERT(d.m == NULL);

  /* Truncated or corrupt data, nothing, and something else. */
  ASSERT_ERR(fg_depth_decode(png, len / 2, 0.001, &d), FG_EFORMAT, "truncated");
  ASSERT_ERR(fg_depth_decode(png, 0, 0.001, &d), FG_EFORMAT, "empty");
  ASSERT_ERR(fg_depth_decode(NULL, 0, 0.001, &d), FG_EFORMAT, "empty");
  ASSERT_ERR(fg_depth_decode("GIF89a and more", 15, 0.001, &d), FG_EFORMAT,
             "unrecognised depth format (data starts with 47 49 46 38)");
  ASSERT_STRCONTAINS(fg_error_detail(), "16-bit unsigned");
  free(png);

  /* 8-bit, and colour. */
  uint8_t grey8[H][W] = {{0}};
  ASSERT_OK(fg_image_encode_png(grey8, W, H, 1, 8, &png, &len));
  ASSERT_ERR(fg_depth_decode(png, len, 0.001, &d), FG_EINVAL, "depth PNG is 8-bit");
  ASSERT_STRCONTAINS(fg_error_detail(), "send 16-bit");
  free(png);
  static uint16_t rgb16[H][W][4];
  ASSERT_OK(fg_image_encode_png(rgb16, W, H, 3, 16, &png, &len));
  ASSERT_ERR(fg_depth_decode(png, len, 0.001, &d), FG_EINVAL, "has 3 channels");
  ASSERT_STRCONTAINS(fg_error_detail(), "looks like a colour image");
  free(png);
  ASSERT_OK(fg_image_encode_png(rgb16, W, H, 4, 16, &png, &len));
  ASSERT_ERR(fg_depth_decode(png, len, 0.001, &d), FG_EINVAL, "has 4 channels");
  free(png);
  float fpx[H][W][3] = {{{0}}};
  char *buf;
  write_float_file("rgb.exr", &fpx[0][0][0], W, H, 3, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len, 0.001, &d), FG_EINVAL,
             "depth OpenEXR has 3 channels, so it looks like a colour image");
  free(buf);

  /* JPEG: lossy, never depth. */
  write_float_file("d.jpg", &fpx[0][0][0], W, H, 1, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len, 0.001, &d), FG_EINVAL, "JPEG");
  ASSERT_STRCONTAINS(fg_error_detail(), "lossy");
  free(buf);

  /* Integer TIFFs other than 16-bit unsigned: never normalised into metres. */
  static const struct {
    int bits, format;
    const char *says;
  } tiffs[] = {
      {8, 1, "depth TIFF is 8-bit"},
      {16, 2, "16-bit signed integers"},
      {32, 1, "32-bit unsigned integers"},
  };
  static uint32_t raw[H][W];
  for (size_t i = 0; i < sizeof tiffs / sizeof tiffs[0]; i++) {
    uint8_t *tif = make_tiff(raw, W, H, tiffs[i].bits, tiffs[i].format, &len);
    ASSERT_ERR(fg_depth_decode(tif, len, 0.001, &d), FG_EINVAL, tiffs[i].says);
    free(tif);
  }
  /* The float TIFF of test_float cut short. */
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) fpx[y][x][0] = 1.0f;
  write_float_file("cut.tif", &fpx[0][0][0], W, H, 1, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len / 2, 0.001, &d), FG_EFORMAT, "TIFF");
  free(buf);
  write_float_file("cut.exr", &fpx[0][0][0], W, H, 1, &buf, &len);
  ASSERT_ERR(fg_depth_decode(buf, len / 2, 0.001, &d), FG_EFORMAT, "OpenEXR");
  free(buf);

  /* Sizes beyond the image limits, from the header alone. */
  png16_header(20000, 480, &png, &len);
  ASSERT_ERR(fg_depth_decode(png, len, 0.001, &d), FG_ERANGE, "20000x480");
  free(png);
  ASSERT(d.m == NULL);
}

/* A .npy of the given dtype and shape from float values. The caller frees *out. */
static void make_npy(fg_dtype dtype, int ndim, const size_t *shape, const float *v, uint8_t **out,
                     size_t *len) {
  size_t n = 1;
  for (int i = 0; i < ndim; i++) n *= shape[i];
  uint16_t *half = NULL;
  const void *data = v;
  if (dtype == FG_DTYPE_F16) {
    half = malloc((n ? n : 1) * sizeof *half);
    ASSERT(half != NULL);
    fg_float_to_half_n(v, half, n);
    data = half;
  }
  ASSERT_OK(fg_npy_encode(dtype, ndim, shape, data, out, len));
  free(half);
}

static void test_npy(void) {
  float v[H * W];
  for (int i = 0; i < H * W; i++) v[i] = 0.5f + 0.25f * (float)i;
  v[3] = NAN;
  v[4] = 0.0f;
  v[7] = -0.0f;
  static const size_t hw[2] = {H, W}, hw1[3] = {H, W, 1};
  static const struct {
    fg_dtype dtype;
    int ndim;
    const size_t *shape;
  } ok[] = {{FG_DTYPE_F32, 2, hw}, {FG_DTYPE_F32, 3, hw1}, {FG_DTYPE_F16, 2, hw}};
  for (size_t k = 0; k < sizeof ok / sizeof ok[0]; k++) {
    uint8_t *buf;
    size_t len;
    make_npy(ok[k].dtype, ok[k].ndim, ok[k].shape, v, &buf, &len);
    fg_npy npy;
    ASSERT_OK(fg_npy_parse(buf, len, &npy));
    fg_depth_map d, r;
    ASSERT_OK(fg_depth_from_npy(&npy, &d));
    ASSERT_EQ(d.w, W);
    ASSERT_EQ(d.h, H);
    for (int i = 0; i < H * W; i++) {
      if (i == 3 || i == 4 || i == 7)
        ASSERT(d.m[i] == 0 && !signbit(d.m[i]));
      else
        ASSERT(d.m[i] == v[i]); /* exact in float16 too: quarters up to 4 */
    }
    /* fg_depth_read knows .npy by its magic; the scale does not apply to it. */
    ASSERT_OK(fg_depth_read(buf, len, 0.001, &r));
    ASSERT_EQ(r.w, W);
    ASSERT(memcmp(r.m, d.m, sizeof v) == 0);
    fg_depth_release(&r);
    ASSERT_ERR(fg_depth_read(buf, len, 0, &r), FG_EINVAL, "depth scale");
    fg_depth_release(&d);
    free(buf);
  }

  /* Negative and infinite values, and shapes that are not one value per pixel. */
  uint8_t *buf;
  size_t len;
  fg_npy npy;
  fg_depth_map d;
  v[3] = 1.0f;
  v[2 * W + 1] = -0.5f;
  v[2 * W + 3] = -2.0f;
  make_npy(FG_DTYPE_F32, 2, hw, v, &buf, &len);
  ASSERT_OK(fg_npy_parse(buf, len, &npy));
  ASSERT_ERR(fg_depth_from_npy(&npy, &d), FG_EINVAL, "depth pixel [row 2, col 1] is -0.5 metres");
  ASSERT(d.m == NULL);
  ASSERT_ERR(fg_depth_read(buf, len, 0.001, &d), FG_EINVAL, "[row 2, col 1]");
  free(buf);
  v[2 * W + 1] = 1.0f;
  v[2 * W + 3] = 1.0f;
  v[W + 2] = -INFINITY;
  make_npy(FG_DTYPE_F32, 3, hw1, v, &buf, &len);
  ASSERT_OK(fg_npy_parse(buf, len, &npy));
  ASSERT_ERR(fg_depth_from_npy(&npy, &d), FG_EINVAL, "[row 1, col 2] is -inf metres");
  free(buf);
  v[W + 2] = INFINITY;
  make_npy(FG_DTYPE_F16, 2, hw, v, &buf, &len);
  ASSERT_OK(fg_npy_parse(buf, len, &npy));
  ASSERT_ERR(fg_depth_from_npy(&npy, &d), FG_EINVAL, "[row 1, col 2] is inf metres");
  free(buf);

  static float zeros[3 * 20000];
  static const struct {
    int ndim;
    size_t shape[3];
    int code;
    const char *says;
  } bad[] = {
      {3, {3, 5, 3}, FG_EINVAL, "shape (3, 5, 3)"},
      {1, {15}, FG_EINVAL, "shape (15,); depth takes one value per pixel"},
      {3, {1, 3, 5}, FG_EINVAL, "shape (1, 3, 5)"},
      {2, {0, 5}, FG_EINVAL, "the depth .npy is empty (5x0 pixels)"},
      {2, {2, 20000}, FG_ERANGE, "the depth .npy is 20000x2"},
  };
  for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
    make_npy(FG_DTYPE_F32, bad[k].ndim, bad[k].shape, zeros, &buf, &len);
    ASSERT_OK(fg_npy_parse(buf, len, &npy));
    ASSERT_ERR(fg_depth_from_npy(&npy, &d), bad[k].code, bad[k].says);
    free(buf);
  }
  ASSERT_ERR(fg_depth_from_npy(NULL, &d), FG_EINVAL, "no array");
  /* A .npy magic on garbage is the parser's FG_EFORMAT. */
  ASSERT_ERR(fg_depth_read("\x93NUMPY\x01\x00garbage", 15, 0.001, &d), FG_EFORMAT, "");
}

static void test_grid(void) {
  ASSERT_OK(fg_depth_check_grid(640, 480, 1280, 960));
  ASSERT_OK(fg_depth_check_grid(640, 480, 640, 480));
  ASSERT_OK(fg_depth_check_grid(320, 240, 1280, 960));
  ASSERT_OK(fg_depth_check_grid(1, 1, 7, 7));
  ASSERT_ERR(fg_depth_check_grid(641, 480, 1280, 960), FG_EINVAL,
             "the depth map is 641x480 but its image is 1280x960");
  ASSERT_STRCONTAINS(fg_error_detail(), "1280x960 or 640x480");
  ASSERT_ERR(fg_depth_check_grid(640, 360, 1280, 960), FG_EINVAL, "640x360");
  ASSERT_STRCONTAINS(fg_error_detail(), "1280x960");
  ASSERT_ERR(fg_depth_check_grid(320, 480, 1280, 960), FG_EINVAL, "320x480"); /* 4 and 2 */
  ASSERT_ERR(fg_depth_check_grid(1280, 960, 640, 480), FG_EINVAL, "1280x960"); /* larger */
  ASSERT_ERR(fg_depth_check_grid(0, 480, 640, 480), FG_EINVAL, "positive");
  ASSERT_ERR(fg_depth_check_grid(640, 480, 640, -1), FG_EINVAL, "positive");
}

static void test_valid_fraction(void) {
  const float m[4] = {0, 1.5f, 0, 2};
  ASSERT_NEAR(fg_depth_valid_fraction(m, 4), 0.5, 0);
  ASSERT_NEAR(fg_depth_valid_fraction(m, 0), 0, 0);
  ASSERT_NEAR(fg_depth_valid_fraction(NULL, 4), 0, 0);
  ASSERT_NEAR(fg_depth_valid_fraction(m + 1, 1), 1, 0);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/fg_test_depth_XXXXXX");
  ASSERT(mkdtemp(tmpdir) != NULL);
  test_png16();
  test_tiff16();
  test_float();
  test_refusals();
  test_npy();
  test_grid();
  test_valid_fraction();
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("depth: ok\n");
  return 0;
}
