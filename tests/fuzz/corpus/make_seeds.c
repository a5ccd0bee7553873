/* Writes the binary seeds of the npy, depth, image, frame and checkpoint fuzz targets with the
 * library's own encoders, so the seeds are files the daemon really writes or accepts. Run
 * once from this folder (the output is committed; the tests never run this):
 *   cc -I../../../lib -I../../../build make_seeds.c ../../../build/lib/libfieldgrip.a \
 *     $(pkg-config --libs jansson OpenImageIO opencv4 zlib) -lopenblas -fopenmp -lm -lstdc++ \
 *     -o /tmp/make_seeds && /tmp/make_seeds */
#include "core/error.h"
#include "field/checkpoint.h"
#include "field/model.h"
#include "io/frame.h"
#include "io/image.h"
#include "io/npy.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void put(const char *path, const uint8_t *b, size_t n) {
  FILE *f = fopen(path, "wb");
  if (!f || fwrite(b, 1, n, f) != n || fclose(f) != 0) {
    fprintf(stderr, "cannot write %s\n", path);
    exit(1);
  }
}

static void npy(const char *path, fg_dtype t, int ndim, const size_t *shape, const void *data) {
  uint8_t *b;
  size_t n;
  if (fg_npy_encode(t, ndim, shape, data, &b, &n) != 0) exit(1);
  put(path, b, n);
  free(b);
}

static void png(const char *path, const void *px, int w, int h, int c, int bits) {
  uint8_t *b;
  size_t n;
  if (fg_image_encode_png(px, w, h, c, bits, &b, &n) != 0) exit(1);
  put(path, b, n);
  free(b);
}

int main(void) {
  float depth[12] = {0.5f, 0.6f, 0.7f, 0.f, 1.f, 1.5f, 2.f, 0.25f, 0.3f, 0.4f, 0.45f, 0.9f};
  uint16_t half[4] = {0x3c00, 0x4000, 0x0000, 0x7bff};
  size_t s2[2] = {3, 4}, s3[3] = {3, 4, 1}, s1[1] = {4}, s0[1] = {0};
  npy("npy/f32_3x4.npy", FG_DTYPE_F32, 2, s2, depth);
  npy("npy/f32_3x4x1.npy", FG_DTYPE_F32, 3, s3, depth);
  npy("npy/f16_4.npy", FG_DTYPE_F16, 1, s1, half);
  npy("npy/empty.npy", FG_DTYPE_F32, 1, s0, depth);
  npy("depth/f32_3x4.npy", FG_DTYPE_F32, 2, s2, depth);

  uint16_t mm[12] = {500, 600, 700, 0, 1000, 1500, 2000, 250, 300, 400, 450, 900};
  png("depth/u16_4x3.png", mm, 4, 3, 1, 16);
  uint8_t rgb[4 * 3 * 4];
  for (size_t i = 0; i < sizeof rgb; i++) rgb[i] = (uint8_t)(i * 37);
  png("image/rgb8_4x3.png", rgb, 4, 3, 3, 8);
  png("image/rgba8_4x3.png", rgb, 4, 3, 4, 8);
  png("image/grey8_4x3.png", rgb, 4, 3, 1, 8);
  png("image/grey16_4x3.png", mm, 4, 3, 1, 16);
  float frgb[4 * 3 * 3];
  for (size_t i = 0; i < sizeof frgb / sizeof frgb[0]; i++) frgb[i] = (float)(i % 7) / 7.0f;
  if (fg_image_write_file("image/rgb_4x3.jpg", frgb, 4, 3, 3) != 0) return 1;
  if (fg_image_write_file("image/rgb_4x3.tif", frgb, 4, 3, 3) != 0) return 1;
  if (fg_image_write_file("image/rgb_4x3.exr", frgb, 4, 3, 3) != 0) return 1;

  /* frames as the state dir keeps them: plain, with f16 features, with depth */
  fg_image img = {4, 3, frgb};
  fg_camera cam = {.fl_x = 5, .fl_y = 5, .cx = 2, .cy = 1.5, .w = 4, .h = 3};
  double T[16] = {1, 0, 0, 0.1, 0, 1, 0, 0.2, 0, 0, 1, 0.3, 0, 0, 0, 1};
  uint16_t fh[8] = {0x3c00, 0, 0x4000, 0xbc00, 0, 0x3c00, 0x3800, 0x3400};
  fg_npy feats = {FG_DTYPE_F16, 3, {2, 2, 2}, 8, fh};
  fg_depth_map dm = {4, 3, depth};
  fg_ingest_opts opts = {{1, 1, 1}, 0};
  fg_frame fr;
  if (fg_frame_prepare_image(&fr, &img, &cam, T, NULL, &opts) != 0 ||
      (strcpy(fr.source, "plain.png"), fg_frame_save(&fr, "frame/plain.fgf")) != 0)
    return 1;
  fg_frame_clear(&fr);
  if (fg_frame_prepare_image(&fr, &img, &cam, T, &feats, &opts) != 0 ||
      fg_frame_save(&fr, "frame/features.fgf") != 0)
    return 1;
  fg_frame_clear(&fr);
  if (fg_frame_prepare_image_depth(&fr, &img, &cam, T, NULL, &dm, &opts) != 0 ||
      fg_frame_save(&fr, "frame/depth.fgf") != 0) {
    fprintf(stderr, "frame: %s\n", fg_error_detail());
    return 1;
  }
  fg_frame_clear(&fr);

  /* the smallest field the checks allow, so the seed stays small */
  double lo[3] = {-0.1, -0.1, 0.0}, hi[3] = {0.1, 0.1, 0.2};
  fg_field_config cfg;
  if (fg_field_config_for_workspace(&cfg, lo, hi, 1.0, 0) != 0) return 1;
  fg_hashgrid_config g = {1, 1, 4, 2, 4};
  cfg.grid = g;
  cfg.feat_grid = g;
  cfg.occ_resolution = 8;
  fg_field *f;
  if (fg_field_new(&f, &cfg, 1) != 0) {
    fprintf(stderr, "field: %s\n", fg_error_detail());
    return 1;
  }
  if (fg_checkpoint_save(f, "checkpoint/small_f32.ckpt", 0) != 0 ||
      fg_checkpoint_save(f, "checkpoint/small_f16.ckpt", 1) != 0) {
    fprintf(stderr, "checkpoint: %s\n", fg_error_detail());
    return 1;
  }
  fg_field_free(f);
  return 0;
}
