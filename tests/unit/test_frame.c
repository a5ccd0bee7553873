/* Unit tests of lib/io/frame: ingest (decode, composite, undistort, downscale, quantise,
 * feature checks) and the .fgf file format (round trip, CRC, truncation). */
#include "test.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "core/pose.h"
#include "io/frame.h"
#include "io/image.h"
#include "io/npy.h"

#include <stdint.h>
#include <zlib.h>

static char tmpdir[64];

static char *tmp_path(const char *name) {
  char *p = fg_path_join(tmpdir, name);
  ASSERT(p != NULL);
  return p;
}

enum { W = 800, H = 600, FH = 30, FW = 40, FD = 8 };

static uint8_t rgba[H][W][4];
static const float bg[3] = {0.25f, 0.5f, 1.0f};

/* An 800x600 RGBA PNG: colour gradients, alpha varying across the image. */
static void make_rgba_png(uint8_t **png, size_t *len) {
  for (int y = 0; y < H; y++)
    for (int x = 0; x < W; x++) {
      rgba[y][x][0] = (uint8_t)(x * 255 / (W - 1));
      rgba[y][x][1] = (uint8_t)(y * 255 / (H - 1));
      rgba[y][x][2] = (uint8_t)((x + y) % 256);
      rgba[y][x][3] = (uint8_t)(x < 100 ? 255 : x < 200 ? 0 : (x * 7 + y * 3) % 256);
    }
  ASSERT_OK(fg_image_encode_png(rgba, W, H, 4, 8, png, len));
}

static double composite(int y, int x, int c) {
  double a = rgba[y][x][3] / 255.0;
  return rgba[y][x][c] / 255.0 * a + bg[c] * (1 - a);
}

static void make_features_f16(uint8_t **npy, size_t *len, fg_npy *parsed) {
  static uint16_t f[FH][FW][FD];
  for (int i = 0; i < FH; i++)
    for (int j = 0; j < FW; j++)
      for (int k = 0; k < FD; k++) f[i][j][k] = fg_float_to_half(sinf((float)(i * 31 + j * 7 + k)));
  const size_t shape[3] = {FH, FW, FD};
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F16, 3, shape, f, npy, len));
  ASSERT_OK(fg_npy_parse(*npy, *len, parsed));
}

static const fg_camera cam800 = {.fl_x = 700, .fl_y = 700, .cx = 400.5, .cy = 299.5, .w = W,
                                 .h = H, .model = FG_CAMERA_PINHOLE};

static void make_pose(double T[16]) {
  const double n = sqrt(0.3 * 0.3 + 0.8 * 0.8 + 0.4 * 0.4 + 0.2 * 0.2);
  const double p[3] = {0.5, -0.1, 0.6}, q[4] = {0.3 / n, 0.8 / n, -0.4 / n, 0.2 / n};
  ASSERT_OK(fg_pose_from_quat(p, q, T));
}

static void write_bytes(const char *path, const void *buf, size_t len) {
  ASSERT_OK(fg_write_file_atomic(path, buf, len));
}

/* Rewrites the version 3 frame file raw[0..len) in place as the same frame in an earlier
 * version (1 or 2): the 512-byte header of those versions, then the same sections, its own
 * CRC. Returns the new length. */
static size_t downgrade(char *raw, size_t len, int version) {
  enum { OLD_HEADER = 512 };
  raw[8] = (char)version;
  raw[12] = (char)(OLD_HEADER & 0xff);
  raw[13] = (char)(OLD_HEADER >> 8);
  memmove(raw + OLD_HEADER, raw + FG_FRAME_HEADER_SIZE, len - FG_FRAME_HEADER_SIZE);
  len -= FG_FRAME_HEADER_SIZE - OLD_HEADER;
  const uint32_t crc = (uint32_t)crc32_z(crc32_z(0L, Z_NULL, 0), (const Bytef *)raw, len - 4);
  for (int i = 0; i < 4; i++) raw[len - 4 + i] = (char)(crc >> (8 * i));
  return len;
}

static void test_prepare_save_load(void) {
  uint8_t *png, *npy;
  size_t png_len, npy_len;
  fg_npy feats;
  make_rgba_png(&png, &png_len);
  make_features_f16(&npy, &npy_len, &feats);
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {bg[0], bg[1], bg[2]}, .max_image_side = 400};

  fg_frame f;
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &cam800, T, &feats, &opts));
  ASSERT_EQ(f.cam.w, 400);
  ASSERT_EQ(f.cam.h, 300);
  ASSERT_EQ(f.src_w, W);
  ASSERT_EQ(f.src_h, H);
  ASSERT_EQ(f.undistorted, 0);
  ASSERT_EQ(f.cam.model, FG_CAMERA_PINHOLE);
  ASSERT(f.cam.fl_x == 350 && f.cam.fl_y == 350); /* exact: the ratio is exactly 1/2 */
  ASSERT(f.cam.cx == 200.25 && f.cam.cy == 149.75);
  ASSERT(f.created_ms > 1600000000000LL);
  ASSERT_EQ(f.source[0], '\0');
  ASSERT_EQ(memcmp(f.T_world_cam, T, sizeof T), 0);
  ASSERT_EQ(f.feat_dtype, FG_DTYPE_F16);
  ASSERT_EQ(f.feat_h, FH);
  ASSERT_EQ(f.feat_w, FW);
  ASSERT_EQ(f.feat_d, FD);
  ASSERT_EQ(memcmp(f.feat, feats.data, (size_t)FH * FW * FD * 2), 0);
  /* Each stored pixel is the 2x2 mean of the composited source, quantised to 16 bits. */
  for (int y = 0; y < 300; y++)
    for (int x = 0; x < 400; x++)
      for (int c = 0; c < 3; c++) {
        double m = (composite(2 * y, 2 * x, c) + composite(2 * y, 2 * x + 1, c) +
                    composite(2 * y + 1, 2 * x, c) + composite(2 * y + 1, 2 * x + 1, c)) / 4;
        int got = f.rgb[((size_t)y * 400 + (size_t)x) * 3 + (size_t)c];
        if (abs(got - (int)lround(m * 65535)) > 2)
          FG_TEST_FAIL("pixel (%d,%d,%d): %d, expected %.1f", x, y, c, got, m * 65535);
      }

  snprintf(f.source, sizeof f.source, "%s", "upload-1.png");
  char *path = tmp_path("f.fgf");
  ASSERT_OK(fg_frame_save(&f, path));
  fg_frame distorted = f;
  distorted.cam.model = FG_CAMERA_OPENCV;
  distorted.cam.k1 = 0.1;
  ASSERT_ERR(fg_frame_save(&distorted, path), FG_EINVAL, "PINHOLE");
  distorted.feat_d = 5000;
  ASSERT_ERR(fg_frame_save(&distorted, path), FG_EINVAL, "feature grid");

  /* The layout as frame.h documents it. */
  char *raw;
  size_t raw_len;
  ASSERT_OK(fg_read_file(path, 1u << 30, &raw, &raw_len));
  ASSERT_EQ(raw_len, FG_FRAME_HEADER_SIZE + 400 * 300 * 3 * 2 + FH * FW * FD * 2 + 4);
  ASSERT_EQ(memcmp(raw, "FGFRAME\0", 8), 0);
  ASSERT_EQ((uint8_t)raw[8], FG_FRAME_VERSION);
  ASSERT_EQ(raw[9] | raw[10] | raw[11], 0);

  fg_frame g;
  ASSERT_OK(fg_frame_load(path, &g));
  ASSERT_EQ(memcmp(g.T_world_cam, f.T_world_cam, sizeof T), 0);
  ASSERT(g.cam.fl_x == f.cam.fl_x && g.cam.fl_y == f.cam.fl_y && g.cam.cx == f.cam.cx &&
         g.cam.cy == f.cam.cy);
  ASSERT_EQ(g.cam.w, 400);
  ASSERT_EQ(g.cam.h, 300);
  ASSERT_EQ(g.cam.model, FG_CAMERA_PINHOLE);
  ASSERT_EQ(g.src_w, W);
  ASSERT_EQ(g.src_h, H);
  ASSERT_EQ(g.undistorted, 0);
  ASSERT_EQ(g.created_ms, f.created_ms);
  ASSERT_STREQ(g.source, "upload-1.png");
  ASSERT_EQ(g.feat_dtype, FG_DTYPE_F16);
  ASSERT_EQ(g.feat_h, FH);
  ASSERT_EQ(g.feat_w, FW);
  ASSERT_EQ(g.feat_d, FD);
  ASSERT_EQ(memcmp(g.rgb, f.rgb, 400 * 300 * 3 * 2), 0);
  ASSERT_EQ(memcmp(g.feat, f.feat, FH * FW * FD * 2), 0);
  fg_frame_clear(&g);
  ASSERT(g.rgb == NULL && g.feat == NULL);

  fg_frame hdr;
  ASSERT_OK(fg_frame_load_header(path, &hdr));
  ASSERT_EQ(hdr.cam.w, 400);
  ASSERT_EQ(hdr.cam.h, 300);
  ASSERT_EQ(hdr.feat_d, FD);
  ASSERT_STREQ(hdr.source, "upload-1.png");
  ASSERT(hdr.rgb == NULL && hdr.feat == NULL);
  fg_frame_clear(&hdr);

  /* One flipped bit anywhere is caught by the CRC; the header-only read does not look. */
  char *bad = tmp_path("bad.fgf");
  raw[FG_FRAME_HEADER_SIZE + 12345] ^= 0x10;
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "CRC");
  ASSERT(g.rgb == NULL);
  ASSERT_OK(fg_frame_load_header(bad, &hdr));
  raw[FG_FRAME_HEADER_SIZE + 12345] ^= 0x10;
  raw[raw_len - 30] ^= 0x01; /* in the features */
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "CRC");
  raw[raw_len - 30] ^= 0x01;
  raw[300] ^= 0x01; /* in the source name */
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "CRC");
  raw[300] ^= 0x01;
  raw[0] = 'X';
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "magic");
  ASSERT_ERR(fg_frame_load_header(bad, &hdr), FG_EFORMAT, "magic");
  raw[0] = 'F';
  raw[8] = FG_FRAME_VERSION + 1;
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "version");
  raw[8] = FG_FRAME_VERSION;
  raw[179] = 0x7f; /* width becomes huge */
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load_header(bad, &hdr), FG_EFORMAT, "header");
  raw[179] = 0;

  /* Truncated, extended, too short for a header, missing. */
  write_bytes(bad, raw, raw_len - 10);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "truncated");
  ASSERT_ERR(fg_frame_load_header(bad, &hdr), FG_EFORMAT, "truncated");
  write_bytes(bad, raw, raw_len + 1);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "stray");
  write_bytes(bad, raw, 100);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "header");
  write_bytes(bad, raw, raw_len);
  ASSERT_OK(fg_frame_load(bad, &g)); /* restored byte for byte */
  fg_frame_clear(&g);
  char *missing = tmp_path("missing.fgf");
  ASSERT_ERR(fg_frame_load(missing, &g), FG_ENOENT, "missing.fgf");
  free(missing);
  free(bad);
  free(raw);

  /* A non-integer ratio: sizes rounded, intrinsics scaled by the exact size ratios. */
  fg_frame s;
  opts.max_image_side = 333;
  ASSERT_OK(fg_frame_prepare(&s, png, png_len, &cam800, T, NULL, &opts));
  ASSERT_EQ(s.cam.w, 333);
  ASSERT_EQ(s.cam.h, 250);
  ASSERT(s.cam.fl_x == 700 * (333.0 / 800) && s.cam.cx == 400.5 * (333.0 / 800));
  ASSERT(s.cam.fl_y == 700 * (250.0 / 600) && s.cam.cy == 299.5 * (250.0 / 600));
  ASSERT_EQ(s.feat_d, 0);
  ASSERT_EQ(s.feat_dtype, FG_DTYPE_NONE);
  ASSERT(s.feat == NULL);
  char *nf = tmp_path("nofeat.fgf");
  ASSERT_OK(fg_frame_save(&s, nf));
  fg_frame_clear(&s);
  ASSERT_OK(fg_frame_load(nf, &s));
  ASSERT_EQ(s.cam.w, 333);
  ASSERT(s.feat == NULL);
  fg_frame_clear(&s);
  free(nf);

  /* From an image decoded by the caller: the same frame, and the caller's image untouched. */
  fg_image img;
  ASSERT_OK(fg_image_decode(png, png_len, bg, &img));
  float first = img.rgb[0];
  opts.max_image_side = 400;
  ASSERT_OK(fg_frame_prepare_image(&s, &img, &cam800, T, &feats, &opts));
  ASSERT_EQ(s.cam.w, 400);
  ASSERT(s.cam.fl_x == f.cam.fl_x && s.cam.cy == f.cam.cy);
  ASSERT_EQ(memcmp(s.rgb, f.rgb, 400 * 300 * 3 * 2), 0);
  ASSERT_EQ(memcmp(s.feat, f.feat, FH * FW * FD * 2), 0);
  ASSERT(img.rgb[0] == first && img.w == W);
  fg_frame_clear(&s);
  fg_image bad_img = img;
  fg_camera c640 = cam800;
  c640.w = 640;
  ASSERT_ERR(fg_frame_prepare_image(&s, &img, &c640, T, NULL, &opts), FG_EINVAL, "camera says");
  ASSERT(s.rgb == NULL);
  bad_img.rgb = NULL;
  ASSERT_ERR(fg_frame_prepare_image(&s, &bad_img, &cam800, T, NULL, &opts), FG_EINVAL, "image");
  fg_image_release(&img);

  /* No downscale when the image is small enough or the limit is 0; w/h 0 take the image's. */
  fg_camera c0 = cam800;
  c0.w = c0.h = 0;
  opts.max_image_side = 0;
  ASSERT_OK(fg_frame_prepare(&s, png, png_len, &c0, T, NULL, &opts));
  ASSERT_EQ(s.cam.w, W);
  ASSERT_EQ(s.cam.h, H);
  ASSERT(s.cam.fl_x == 700);
  ASSERT_EQ(s.rgb[99 * 3], rgba[0][99][0] * 257); /* an opaque pixel keeps its exact value */
  fg_frame_clear(&s);

  fg_frame_clear(&f);
  free(path);
  free(png);
  free(npy);
}

static void test_prepare_refuse(void) {
  uint8_t *png, *npy;
  size_t png_len, npy_len;
  fg_npy feats;
  make_rgba_png(&png, &png_len);
  make_features_f16(&npy, &npy_len, &feats);
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {1, 1, 1}, .max_image_side = 400};
  fg_frame f;

  double Tn[16];
  memcpy(Tn, T, sizeof Tn);
  Tn[6] = NAN;
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, Tn, &feats, &opts), FG_EINVAL, "finite");
  ASSERT(f.rgb == NULL && f.feat == NULL);

  fg_npy two = feats;
  two.ndim = 2;
  two.shape[1] = FW * FD;
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, T, &two, &opts), FG_EINVAL,
             "features must have shape [h, w, D]; got 2 dimensions");

  float fv[2][3][4];
  for (int i = 0; i < 24; i++) (&fv[0][0][0])[i] = (float)i;
  fv[1][2][3] = NAN;
  const size_t shape[3] = {2, 3, 4};
  uint8_t *bad;
  size_t bad_len;
  fg_npy nanf;
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F32, 3, shape, fv, &bad, &bad_len));
  ASSERT_OK(fg_npy_parse(bad, bad_len, &nanf));
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, T, &nanf, &opts), FG_EINVAL,
             "[1, 2, 3]");
  free(bad);
  uint16_t hv[2][3][4] = {{{0}}};
  hv[0][1][2] = 0xfc00; /* -Inf */
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F16, 3, shape, hv, &bad, &bad_len));
  ASSERT_OK(fg_npy_parse(bad, bad_len, &nanf));
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, T, &nanf, &opts), FG_EINVAL, "NaN");
  free(bad);
  const size_t shape0[3] = {2, 3, 0};
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F16, 3, shape0, hv, &bad, &bad_len));
  ASSERT_OK(fg_npy_parse(bad, bad_len, &nanf));
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, T, &nanf, &opts), FG_EINVAL, "D = 0");
  free(bad);

  ASSERT_OK(fg_frame_check_features(&feats));
  ASSERT_ERR(fg_frame_check_features(&two), FG_EINVAL, "2 dimensions");

  fg_camera c = cam800;
  c.w = 640;
  c.h = 480;
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &c, T, &feats, &opts), FG_EINVAL,
             "camera says 640x480 but the image is 800x600");
  ASSERT(f.rgb == NULL && f.feat == NULL);
  c = cam800;
  c.fl_x = 0;
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &c, T, &feats, &opts), FG_EINVAL, "focal");
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len / 3, &cam800, T, &feats, &opts), FG_EFORMAT,
             "PNG");
  ASSERT_ERR(fg_frame_prepare(&f, "hello", 5, &cam800, T, &feats, &opts), FG_EFORMAT,
             "supported");
  opts.max_image_side = -1;
  ASSERT_ERR(fg_frame_prepare(&f, png, png_len, &cam800, T, &feats, &opts), FG_EINVAL,
             "max_image_side");
  free(png);
  free(npy);
}

/* ---- undistortion on ingest --------------------------------------------------------- */

enum { UW = 320, UH = 240 };

static void test_prepare_opencv(void) {
  static uint8_t px[UH][UW][3];
  for (int y = 0; y < UH; y++)
    for (int x = 0; x < UW; x++) {
      px[y][x][0] = (uint8_t)x;
      px[y][x][1] = (uint8_t)y;
      px[y][x][2] = (uint8_t)((x / 16 + y / 16) % 2 * 255);
    }
  uint8_t *png;
  size_t png_len;
  ASSERT_OK(fg_image_encode_png(px, UW, UH, 3, 8, &png, &png_len));
  const fg_camera cam = {.fl_x = 250, .fl_y = 250, .cx = 161.3, .cy = 118.7, .w = UW, .h = UH,
                         .model = FG_CAMERA_OPENCV, .k1 = -0.25, .k2 = 0.08, .p1 = 0.001,
                         .p2 = -0.0015};
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {1, 1, 1}, .max_image_side = 0};

  /* A constant feature grid stays exactly constant, in both dtypes. */
  enum { GH = 15, GW = 20, GD = 4 };
  static float cf[GH][GW][GD];
  static uint16_t ch[GH][GW][GD];
  for (int i = 0; i < GH * GW; i++)
    for (int k = 0; k < GD; k++) {
      (&cf[0][0][0])[i * GD + k] = 0.37f + 0.1f * (float)k;
      (&ch[0][0][0])[i * GD + k] = fg_float_to_half(-0.61f + 0.2f * (float)k);
    }
  const size_t shape[3] = {GH, GW, GD};
  uint8_t *npy;
  size_t npy_len;
  fg_npy feats;
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F32, 3, shape, cf, &npy, &npy_len));
  ASSERT_OK(fg_npy_parse(npy, npy_len, &feats));
  fg_frame f;
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &cam, T, &feats, &opts));
  ASSERT_EQ(f.undistorted, 1);
  ASSERT_EQ(f.cam.model, FG_CAMERA_PINHOLE);
  ASSERT(f.cam.k1 == 0 && f.cam.k2 == 0 && f.cam.p1 == 0 && f.cam.p2 == 0 && f.cam.k3 == 0);
  ASSERT_EQ(f.cam.w, UW);
  ASSERT_EQ(f.cam.h, UH);
  ASSERT_EQ(f.src_w, UW);
  ASSERT_EQ(f.feat_dtype, FG_DTYPE_F32);
  ASSERT_EQ(memcmp(f.feat, cf, sizeof cf), 0);

  /* The stored image is fg_image_undistort's output, quantised. */
  fg_image img;
  ASSERT_OK(fg_image_decode(png, png_len, opts.background_rgb, &img));
  static float und[UH * UW * 3];
  fg_camera pin;
  ASSERT_OK(fg_image_undistort(img.rgb, &cam, und, &pin));
  ASSERT(pin.fl_x == f.cam.fl_x && pin.cx == f.cam.cx && pin.fl_y == f.cam.fl_y &&
         pin.cy == f.cam.cy);
  for (int i = 0; i < UW * UH * 3; i++)
    ASSERT(abs(f.rgb[i] - (int)lrintf(fminf(fmaxf(und[i], 0), 1) * 65535)) <= 1);
  fg_image_release(&img);
  fg_frame_clear(&f);
  free(npy);

  ASSERT_OK(fg_npy_encode(FG_DTYPE_F16, 3, shape, ch, &npy, &npy_len));
  ASSERT_OK(fg_npy_parse(npy, npy_len, &feats));
  opts.max_image_side = 160; /* undistort, then halve */
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &cam, T, &feats, &opts));
  ASSERT_EQ(f.undistorted, 1);
  ASSERT_EQ(f.cam.w, 160);
  ASSERT_EQ(f.cam.h, 120);
  ASSERT(f.cam.fl_x == pin.fl_x * 0.5 && f.cam.cy == pin.cy * 0.5);
  ASSERT_EQ(f.feat_dtype, FG_DTYPE_F16);
  ASSERT_EQ(memcmp(f.feat, ch, sizeof ch), 0);
  fg_frame_clear(&f);
  free(npy);

  /* Features that record their own pixel position (u, v) come out holding the distorted
   * position that each undistorted cell centre sees; OpenCV's undistortPoints must take it
   * back to the cell centre. Cells whose source lies in the clamped border are skipped. */
  static float pos[GH][GW][2];
  for (int i = 0; i < GH; i++)
    for (int j = 0; j < GW; j++) {
      pos[i][j][0] = (float)((j + 0.5) * UW / GW);
      pos[i][j][1] = (float)((i + 0.5) * UH / GH);
    }
  const size_t shape2[3] = {GH, GW, 2};
  ASSERT_OK(fg_npy_encode(FG_DTYPE_F32, 3, shape2, pos, &npy, &npy_len));
  ASSERT_OK(fg_npy_parse(npy, npy_len, &feats));
  opts.max_image_side = 0;
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &cam, T, &feats, &opts));
  const float *out = f.feat;
  int checked = 0;
  for (int i = 0; i < GH; i++)
    for (int j = 0; j < GW; j++) {
      double uv[2] = {out[(i * GW + j) * 2], out[(i * GW + j) * 2 + 1]};
      if (uv[0] <= pos[0][0][0] || uv[0] >= pos[0][GW - 1][0] || uv[1] <= pos[0][0][1] ||
          uv[1] >= pos[GH - 1][0][1])
        continue;
      ASSERT_OK(fg_camera_undistort_points(&cam, &f.cam, uv, 1));
      ASSERT_NEAR(uv[0], pos[i][j][0], 1e-3);
      ASSERT_NEAR(uv[1], pos[i][j][1], 1e-3);
      checked++;
    }
  ASSERT(checked > GH * GW / 2);
  fg_frame_clear(&f);
  free(npy);

  /* OPENCV without coefficients needs no undistortion. */
  fg_camera z = cam;
  z.k1 = z.k2 = z.p1 = z.p2 = 0;
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &z, T, NULL, &opts));
  ASSERT_EQ(f.undistorted, 0);
  ASSERT_EQ(f.cam.model, FG_CAMERA_PINHOLE);
  ASSERT(f.cam.fl_x == 250 && f.cam.cx == 161.3);
  ASSERT_EQ(f.rgb[3 * 5], 5 * 257); /* pixel (5, 0) red = 5/255 exactly */
  fg_frame_clear(&f);
  free(png);
}

/* A depth map of the image as received (a k-times smaller grid): value per depth pixel, 0
 * and NaN for some, through the downscale by nearest sampling, stored and loaded again. */
static void test_depth(void) {
  uint8_t *png;
  size_t png_len;
  make_rgba_png(&png, &png_len);
  fg_image img;
  ASSERT_OK(fg_image_decode(png, png_len, bg, &img));
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {bg[0], bg[1], bg[2]}, .max_image_side = 400};
  enum { DW = W / 2, DH = H / 2 };
  static float dm[DH][DW];
  size_t valid = 0;
  for (int v = 0; v < DH; v++)
    for (int u = 0; u < DW; u++) {
      dm[v][u] = (u + v) % 11 == 0 ? 0.0f : (u + v) % 13 == 0 ? NAN : 0.4f + 0.001f * u + 0.01f * (v % 7);
      valid += dm[v][u] > 0.0f;
    }
  fg_depth_map d = {.w = DW, .h = DH, .m = &dm[0][0]};
  fg_frame f;
  ASSERT_OK(fg_frame_prepare_image_depth(&f, &img, &cam800, T, NULL, &d, &opts));
  ASSERT_EQ(f.cam.w, 400);
  ASSERT_EQ(f.depth_w, 400);
  ASSERT_EQ(f.depth_h, 300);
  /* stored pixel (u, v) is received pixel (2u + 1, 2v + 1): depth pixel (u, v), exactly */
  for (int v = 0; v < DH; v++)
    for (int u = 0; u < DW; u++) {
      const float want = dm[v][u] > 0.0f ? dm[v][u] : 0.0f;
      if (f.depth[v * DW + u] != want)
        FG_TEST_FAIL("depth (%d, %d): %g, want %g", u, v, (double)f.depth[v * DW + u], (double)want);
    }
  ASSERT_NEAR(f.depth_valid, (double)valid / (DW * DH), 1e-12);

  /* saved and loaded whole; the header alone names it */
  char *path = tmp_path("depth.fgf");
  ASSERT_OK(fg_frame_save(&f, path));
  fg_frame g, hdr;
  ASSERT_OK(fg_frame_load(path, &g));
  ASSERT(g.depth && g.depth_w == 400 && g.depth_h == 300 && g.depth_valid == f.depth_valid);
  ASSERT(memcmp(g.depth, f.depth, sizeof(float) * 400 * 300) == 0);
  ASSERT_OK(fg_frame_load_header(path, &hdr));
  ASSERT(!hdr.depth && hdr.depth_w == 400 && hdr.depth_valid == f.depth_valid);
  /* a flipped bit in the depth section fails the CRC */
  char *raw;
  size_t raw_len;
  ASSERT_OK(fg_read_file(path, 1u << 26, &raw, &raw_len));
  raw[raw_len - 40] ^= 0x01;
  char *bad = tmp_path("depth-bad.fgf");
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &hdr), FG_EFORMAT, "CRC");
  free(raw);
  fg_frame_clear(&g);

  /* a version 1 file (no depth fields) from an earlier build still loads */
  fg_frame plain;
  ASSERT_OK(fg_frame_prepare_image(&plain, &img, &cam800, T, NULL, &opts));
  ASSERT_OK(fg_frame_save(&plain, path));
  ASSERT_OK(fg_read_file(path, 1u << 26, &raw, &raw_len));
  size_t old_len = downgrade(raw, raw_len, 1);
  write_bytes(bad, raw, old_len);
  ASSERT_OK(fg_frame_load(bad, &g));
  ASSERT(!g.depth && g.depth_w == 0 && g.cam.w == 400);
  ASSERT_EQ(g.capture, 1);
  fg_frame_clear(&g);
  fg_frame_clear(&plain);
  free(raw);

  /* refused: off the image's grid, negative or infinite metres */
  fg_depth_map off = {.w = DW + 1, .h = DH, .m = &dm[0][0]};
  ASSERT_ERR(fg_frame_prepare_image_depth(&g, &img, &cam800, T, NULL, &off, &opts), FG_EINVAL,
             "800x600");
  const float keep = dm[5][7];
  dm[5][7] = -0.5f;
  ASSERT_ERR(fg_frame_prepare_image_depth(&g, &img, &cam800, T, NULL, &d, &opts), FG_EINVAL,
             "row 5, column 7");
  dm[5][7] = INFINITY;
  ASSERT_ERR(fg_frame_prepare_image_depth(&g, &img, &cam800, T, NULL, &d, &opts), FG_EINVAL,
             "finite");
  dm[5][7] = keep;
  fg_frame_clear(&f);
  fg_image_release(&img);
  free(path);
  free(bad);
  free(png);
}

/* Depth through an OPENCV camera's undistortion: nearest sampling keeps every value one of
 * the map's, never a blend across the step between two surfaces. */
static void test_depth_opencv(void) {
  static uint8_t px[UH][UW][3];
  memset(px, 128, sizeof px);
  uint8_t *png;
  size_t png_len;
  ASSERT_OK(fg_image_encode_png(px, UW, UH, 3, 8, &png, &png_len));
  fg_image img;
  const float white[3] = {1, 1, 1};
  ASSERT_OK(fg_image_decode(png, png_len, white, &img));
  const fg_camera cam = {.fl_x = 250, .fl_y = 250, .cx = 161.3, .cy = 118.7, .w = UW, .h = UH,
                         .model = FG_CAMERA_OPENCV, .k1 = -0.25, .k2 = 0.08, .p1 = 0.001,
                         .p2 = -0.0015};
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {1, 1, 1}, .max_image_side = 0};
  static float dm[UH][UW];
  for (int v = 0; v < UH; v++)
    for (int u = 0; u < UW; u++) dm[v][u] = u < UW / 2 ? 1.0f : 2.5f;
  fg_depth_map d = {.w = UW, .h = UH, .m = &dm[0][0]};
  fg_frame f;
  ASSERT_OK(fg_frame_prepare_image_depth(&f, &img, &cam, T, NULL, &d, &opts));
  ASSERT(f.undistorted && f.depth_w == f.cam.w && f.depth_h == f.cam.h);
  size_t near = 0, far = 0;
  for (int i = 0; i < f.depth_w * f.depth_h; i++) {
    /* 0 only where a pixel's centre maps outside the received image, at the border */
    ASSERT(f.depth[i] == 1.0f || f.depth[i] == 2.5f || f.depth[i] == 0.0f);
    near += f.depth[i] == 1.0f;
    far += f.depth[i] == 2.5f;
  }
  ASSERT(f.depth_valid > 0.99 && near > 1000 && far > 1000);
  /* the step stays where the lens puts it: the pixel whose centre maps to the received
   * image's left half has the near depth */
  for (int v = 0; v < f.cam.h; v += 17)
    for (int u = 0; u < f.cam.w; u += 13) {
      double x = (u + 0.5 - f.cam.cx) / f.cam.fl_x, y = (v + 0.5 - f.cam.cy) / f.cam.fl_y, xd, yd;
      fg_camera_distort_normalized(&cam, x, y, &xd, &yd);
      const double ud = cam.fl_x * xd + cam.cx, vd = cam.fl_y * yd + cam.cy;
      if (ud < 0 || vd < 0 || ud >= UW || vd >= UH) continue;
      ASSERT(f.depth[v * f.cam.w + u] == (ud < UW / 2 ? 1.0f : 2.5f));
    }
  fg_frame_clear(&f);
  fg_image_release(&img);
  free(png);
}

/* Version 3: the capture and the robot's TCP pose go with the frame; a version 2 file is a
 * frame of capture 1 without a robot pose; a bad pose is refused on save and on load. */
static void test_capture_robot_pose(void) {
  uint8_t *png;
  size_t png_len;
  make_rgba_png(&png, &png_len);
  double T[16];
  make_pose(T);
  fg_ingest_opts opts = {.background_rgb = {bg[0], bg[1], bg[2]}, .max_image_side = 200};
  fg_frame f;
  ASSERT_OK(fg_frame_prepare(&f, png, png_len, &cam800, T, NULL, &opts));
  ASSERT_EQ(f.capture, 0); /* the store gives it one */
  ASSERT_EQ(f.has_robot_pose, 0);
  f.capture = 7;
  f.has_robot_pose = 1;
  const double tcp[16] = {0, -1, 0, 0.40, 1, 0, 0, -0.15, 0, 0, 1, 0.62, 0, 0, 0, 1};
  memcpy(f.T_world_tcp, tcp, sizeof tcp);
  char *path = tmp_path("capture.fgf");
  ASSERT_OK(fg_frame_save(&f, path));
  fg_frame g;
  ASSERT_OK(fg_frame_load(path, &g));
  ASSERT_EQ(g.capture, 7);
  ASSERT_EQ(g.has_robot_pose, 1);
  ASSERT_EQ(memcmp(g.T_world_tcp, tcp, sizeof tcp), 0);
  ASSERT_EQ(memcmp(g.rgb, f.rgb, (size_t)f.cam.w * (size_t)f.cam.h * 6), 0);
  fg_frame_clear(&g);
  ASSERT_OK(fg_frame_load_header(path, &g));
  ASSERT(g.capture == 7 && g.has_robot_pose && g.T_world_tcp[3] == 0.40);
  fg_frame_clear(&g);

  /* the header's new fields are under the CRC */
  char *raw;
  size_t raw_len;
  ASSERT_OK(fg_read_file(path, 1u << 26, &raw, &raw_len));
  ASSERT_EQ(raw_len, FG_FRAME_HEADER_SIZE + (size_t)f.cam.w * (size_t)f.cam.h * 6 + 4);
  char *bad = tmp_path("capture-bad.fgf");
  raw[496] ^= 0x02; /* capture 7 -> 5 */
  write_bytes(bad, raw, raw_len);
  ASSERT_ERR(fg_frame_load(bad, &g), FG_EFORMAT, "CRC");
  raw[496] ^= 0x02;
  /* a version 2 file of the same frame: capture 1, no robot pose, same pixels */
  size_t old_len = downgrade(raw, raw_len, 2);
  write_bytes(bad, raw, old_len);
  ASSERT_OK(fg_frame_load(bad, &g));
  ASSERT_EQ(g.capture, 1);
  ASSERT_EQ(g.has_robot_pose, 0);
  ASSERT_EQ(memcmp(g.rgb, f.rgb, (size_t)f.cam.w * (size_t)f.cam.h * 6), 0);
  fg_frame_clear(&g);
  /* a version 2 header that claims the version 3 size is refused */
  raw[8] = 2;
  raw[13] = 4; /* header_size 1024 */
  write_bytes(bad, raw, old_len);
  ASSERT_ERR(fg_frame_load_header(bad, &g), FG_EFORMAT, "version 2");
  free(raw);

  /* refused: a negative capture, a robot pose that is not a rigid motion */
  f.capture = -1;
  ASSERT_ERR(fg_frame_save(&f, path), FG_EINVAL, "capture");
  f.capture = 7;
  f.T_world_tcp[0] = 2.0;
  ASSERT_ERR(fg_frame_save(&f, path), FG_EINVAL, "robot pose");
  f.has_robot_pose = 0; /* without the flag the pose is not written */
  ASSERT_OK(fg_frame_save(&f, path));
  ASSERT_OK(fg_frame_load_header(path, &g));
  ASSERT(g.has_robot_pose == 0 && g.T_world_tcp[0] == 0.0);
  fg_frame_clear(&g);
  fg_frame_clear(&f);
  free(path);
  free(bad);
  free(png);
}

int main(void) {
  snprintf(tmpdir, sizeof tmpdir, "/tmp/fg_test_frame_XXXXXX");
  ASSERT(mkdtemp(tmpdir) != NULL);
  test_prepare_save_load();
  test_prepare_refuse();
  test_prepare_opencv();
  test_depth();
  test_depth_opencv();
  test_capture_robot_pose();
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("frame: ok\n");
  return 0;
}
