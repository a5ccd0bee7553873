#include "io/dataset.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "core/threads.h"
#include "io/depth.h"
#include "io/image.h"
#include "io/npy.h"
#include "io/transforms.h"

#define MAX_FILE ((size_t)1 << 30)

static int load_one(fg_transforms_frame *tf, const fg_ingest_opts *opts, fg_frame *out) {
  char *bytes = NULL, *npy_bytes = NULL, *depth_bytes = NULL;
  size_t len = 0, npy_len = 0, depth_len = 0;
  fg_depth_map depth = {0};
  fg_image img = {0};
  fg_npy npy, *features = NULL;
  int rc = fg_read_file(tf->image_path, MAX_FILE, &bytes, &len);
  if (rc == 0) rc = fg_image_decode(bytes, len, opts->background_rgb, &img);
  if (rc == 0) rc = fg_transforms_complete_camera(tf, img.w, img.h);
  if (rc == 0 && tf->features_path) {
    rc = fg_read_file(tf->features_path, MAX_FILE, &npy_bytes, &npy_len);
    if (rc == 0) rc = fg_npy_parse(npy_bytes, npy_len, &npy);
    features = &npy;
  }
  if (rc == 0 && tf->depth_path) {
    rc = fg_read_file(tf->depth_path, MAX_FILE, &depth_bytes, &depth_len);
    if (rc == 0) rc = fg_depth_read(depth_bytes, depth_len, tf->depth_scale, &depth);
  }
  if (rc == 0)
    rc = fg_frame_prepare_image_depth(out, &img, &tf->cam, tf->T_world_cam, features,
                                      tf->depth_path ? &depth : NULL, opts);
  if (rc == 0) snprintf(out->source, sizeof out->source, "%s", tf->file_path);
  fg_image_release(&img);
  fg_depth_release(&depth);
  free(depth_bytes);
  free(npy_bytes);
  free(bytes);
  return rc;
}

int fg_dataset_load(const char *transforms_path, const fg_ingest_opts *opts, int n_threads,
                    fg_frame **frames, size_t *n) {
  *frames = NULL;
  *n = 0;
  fg_transforms tr;
  FG_TRY(fg_transforms_load(transforms_path, &tr));
  size_t m = 0;
  size_t *which = malloc((tr.n_frames ? tr.n_frames : 1) * sizeof *which);
  fg_frame *out = calloc(tr.n_frames ? tr.n_frames : 1, sizeof *out);
  if (!which || !out) {
    free(which);
    free(out);
    fg_transforms_free(&tr);
    return fg_fail(FG_ENOMEM, "cannot allocate %zu frames", tr.n_frames);
  }
  for (size_t i = 0; i < tr.n_frames; i++)
    if (tr.frames[i].image_path) which[m++] = i;
  int failed = 0, first_rc = 0;
  char detail[512] = "";
#pragma omp parallel for schedule(dynamic, 1) num_threads(fg_threads(n_threads))
  for (size_t k = 0; k < m; k++) {
    fg_transforms_frame *tf = &tr.frames[which[k]];
    const int rc = load_one(tf, opts, &out[k]);
    if (rc != 0) {
#pragma omp critical(fg_dataset_err)
      if (!failed) {
        failed = 1;
        first_rc = rc;
        snprintf(detail, sizeof detail, "%s: %s", tf->file_path, fg_error_detail());
      }
    }
  }
  fg_transforms_free(&tr);
  free(which);
  if (failed) {
    fg_dataset_free(out, m);
    return fg_fail(first_rc, "%s", detail);
  }
  *frames = out;
  *n = m;
  return 0;
}

void fg_dataset_free(fg_frame *frames, size_t n) {
  if (!frames) return;
  for (size_t i = 0; i < n; i++) fg_frame_clear(&frames[i]);
  free(frames);
}
