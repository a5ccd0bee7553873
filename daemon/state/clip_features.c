/* CLIP features of a training's frames and their cache; see clip_features.h. */
#include "clip_features.h"

#include "metrics/metrics.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"
#include "core/log.h"
#include "io/npy.h"

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The largest cache file read back: far above any grid FG_CLIP_MAX_PATCHES allows. */
#define CACHE_MAX_BYTES ((size_t)256 << 20)
/* float16's largest finite value. */
#define HALF_MAX 65504.0f

size_t fg_clip_features_needed(const fg_frame *frames, size_t n) {
  size_t k = 0;
  for (size_t i = 0; i < n; i++) k += frames[i].feat_d == 0;
  return k;
}

/* "NNNNNN.FINGERPRINT.npy": 1 with the number and fingerprint, else 0. Files of the
 * 16-digit checksum fingerprints of earlier versions parse too, and so are swept as another
 * model's. */
static int parse_cache_name(const char *name, int *index, char fp[FG_SHA256_HEX + 1]) {
  const char *dot = strchr(name, '.');
  size_t len = strlen(name);
  if (!dot || dot == name || len < 4 || strcmp(name + len - 4, ".npy") != 0) return 0;
  long v = 0;
  for (const char *p = name; p < dot; p++) {
    if (*p < '0' || *p > '9' || v > 100000000) return 0;
    v = v * 10 + (*p - '0');
  }
  size_t fl = (size_t)(name + len - 4 - (dot + 1));
  if (fl == 0 || fl > FG_SHA256_HEX) return 0;
  memcpy(fp, dot + 1, fl);
  fp[fl] = '\0';
  *index = (int)v;
  return 1;
}

/* 1 when the scene in scene_dir still has frame number index (a training may use only
 * some of its frames: the others' features stay cached). */
static int frame_exists(const char *scene_dir, int index) {
  char name[48];
  snprintf(name, sizeof name, "frames/%06d.fgf", index);
  char *p = fg_path_join(scene_dir, name);
  const int yes = p && access(p, F_OK) == 0;
  free(p);
  return yes;
}

/* Removes what the current model and frames have no use for: files of other fingerprints,
 * of frames that are gone, and temp files of a writer that was killed. Only the training
 * worker writes here, one job at a time, so nothing in the folder is being written now. */
static void sweep(const char *scene_dir, const char *dir, const char *fingerprint) {
  DIR *d = opendir(dir);
  if (!d) return;
  struct dirent *e;
  int removed = 0;
  while ((e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') continue;
    int index;
    char fp[FG_SHA256_HEX + 1];
    int keep = !strstr(e->d_name, ".tmp.") && parse_cache_name(e->d_name, &index, fp) &&
               strcmp(fp, fingerprint) == 0 && frame_exists(scene_dir, index);
    if (keep) continue;
    char *p = fg_path_join(dir, e->d_name);
    if (p && unlink(p) == 0) removed++;
    free(p);
  }
  closedir(d);
  if (removed)
    fg_info("%s: removed %d cached feature files of other CLIP weights or of frames that are "
            "gone", dir, removed);
}

/* Reads the cache file at path into f's features when it holds a grid [hp][wp][E] of finite
 * values. 1 when it did, 0 when there is no usable file (a bad one is logged). */
static int cache_read(const char *path, fg_frame *f, int hp, int wp, int E) {
  if (access(path, F_OK) != 0) return 0;
  char *buf = NULL;
  size_t len = 0;
  fg_npy npy;
  int ok = fg_read_file(path, CACHE_MAX_BYTES, &buf, &len) == 0 &&
           fg_npy_parse(buf, len, &npy) == 0 && fg_frame_check_features(&npy) == 0;
  if (ok && (npy.shape[0] != (size_t)hp || npy.shape[1] != (size_t)wp ||
             npy.shape[2] != (size_t)E)) {
    fg_fail(FG_EFORMAT, "it holds a [%zu, %zu, %zu] grid where [%d, %d, %d] was expected",
            npy.shape[0], npy.shape[1], npy.shape[2], hp, wp, E);
    ok = 0;
  }
  if (!ok) {
    fg_warn("cached CLIP features %s are unusable and are computed again: %s", path,
            fg_error_detail());
    free(buf);
    return 0;
  }
  size_t bytes = npy.count * fg_dtype_size(npy.dtype);
  void *feat = malloc(bytes);
  if (!feat) {
    free(buf);
    return 0;
  }
  memcpy(feat, npy.data, bytes);
  free(buf);
  f->feat = feat;
  f->feat_h = hp;
  f->feat_w = wp;
  f->feat_d = E;
  f->feat_dtype = npy.dtype;
  return 1;
}

/* Computes f's features with m and writes them to path. */
static int compute(fg_clip_model *m, fg_frame *f, const char *path) {
  const int w = f->cam.w, h = f->cam.h, E = fg_clip_model_info(m)->embed_dim;
  /* rgb [h][w][3] in [0, 1] from the stored 16-bit sRGB */
  size_t np = (size_t)w * (size_t)h * 3;
  float *rgb = malloc(np * sizeof *rgb);
  if (!rgb) return fg_fail(FG_ENOMEM, "out of memory");
  for (size_t i = 0; i < np; i++) rgb[i] = (float)f->rgb[i] / 65535.0f;
  float *dense = NULL;
  int hp = 0, wp = 0;
  int rc = fg_clip_dense_features(fg_clip_model_clip(m), rgb, w, h, &dense, &hp, &wp);
  free(rgb);
  if (rc != 0) return rc;
  size_t count = (size_t)hp * (size_t)wp * (size_t)E;
  int fits = 1;
  for (size_t i = 0; i < count && fits; i++) fits = fabsf(dense[i]) <= HALF_MAX;
  void *feat = dense;
  fg_dtype dtype = FG_DTYPE_F32;
  if (fits) {
    uint16_t *half = malloc(count * sizeof *half);
    if (!half) {
      free(dense);
      return fg_fail(FG_ENOMEM, "out of memory");
    }
    fg_float_to_half_n(dense, half, count);
    free(dense);
    feat = half;
    dtype = FG_DTYPE_F16;
  }
  f->feat = feat;
  f->feat_h = hp;
  f->feat_w = wp;
  f->feat_d = E;
  f->feat_dtype = dtype;
  const size_t shape[3] = {(size_t)hp, (size_t)wp, (size_t)E};
  uint8_t *npy = NULL;
  size_t npy_len = 0;
  rc = fg_npy_encode(dtype, 3, shape, feat, &npy, &npy_len);
  if (rc == 0) rc = fg_write_file_atomic(path, npy, npy_len);
  free(npy);
  return rc;
}

/* The check that precedes any work: uploaded features must have D = E. */
static int check_dims(const fg_frame *frames, const int *indices, size_t n, int E,
                      size_t need) {
  size_t wrong = 0;
  int first = -1, d = 0;
  for (size_t i = 0; i < n; i++) {
    if (frames[i].feat_d == 0 || frames[i].feat_d == E) continue;
    if (!wrong++) {
      first = indices[i];
      d = frames[i].feat_d;
    }
  }
  if (!wrong) return 0;
  return fg_fail(FG_EINVAL, "%zu frame%s (frame %d first) %s uploaded features of D = %d, but "
                 "the CLIP model of [clip] makes E = %d for the %zu frame%s without; a scene's "
                 "features need one D: upload features for every frame (or for none, or of "
                 "D = %d)", wrong, wrong == 1 ? "" : "s", first, wrong == 1 ? "has" : "have", d,
                 E, need, need == 1 ? "" : "s", E);
}

int fg_clip_features_attach(fg_clip_model *m, const char *scene_dir, fg_frame *frames,
                            const int *indices, size_t n, int (*stop)(void *ud),
                            void (*progress)(void *ud, const fg_clip_features_progress *p),
                            void *ud) {
  const fg_clip_info *info = fg_clip_model_info(m);
  const int E = info->embed_dim;
  fg_clip_features_progress pr = {fg_clip_features_needed(frames, n), 0, 0};
  if (pr.total == 0) return 0;
  FG_TRY(check_dims(frames, indices, n, E, pr.total));
  char *dir = fg_path_join(scene_dir, "clip");
  if (!dir) return fg_fail(FG_ENOMEM, "out of memory");
  int rc = fg_mkdir_p(dir);
  if (rc == 0) sweep(scene_dir, dir, info->fingerprint);
  for (size_t i = 0; rc == 0 && i < n; i++) {
    fg_frame *f = &frames[i];
    if (f->feat_d) continue;
    if (stop && stop(ud)) {
      rc = fg_fail(FG_ECANCELED, "stopped while computing CLIP features");
      break;
    }
    char name[32 + FG_SHA256_HEX];
    snprintf(name, sizeof name, "%06d.%s.npy", indices[i], info->fingerprint);
    char *path = fg_path_join(dir, name);
    if (!path) {
      rc = fg_fail(FG_ENOMEM, "out of memory");
      break;
    }
    int hp, wp;
    rc = fg_clip_image_grid(fg_clip_model_clip(m), f->cam.w, f->cam.h, &hp, &wp);
    if (rc == 0 && cache_read(path, f, hp, wp, E)) {
      pr.cached++;
      fg_metrics_add_clip_feature_frames(0, 1);
    } else if (rc == 0) {
      rc = compute(m, f, path);
      if (rc == 0) fg_metrics_add_clip_feature_frames(1, 0);
    }
    if (rc != 0) {
      char detail[768];
      snprintf(detail, sizeof detail, "%s", fg_error_detail());
      rc = fg_fail(rc, "frame %d: %s", indices[i], detail);
    }
    free(path);
    if (rc == 0) {
      pr.done++;
      if (progress) progress(ud, &pr);
    }
  }
  free(dir);
  return rc;
}
