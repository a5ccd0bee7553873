/* Loading an instant-ngp / nerfstudio data set from disk straight into frames, in-process:
 * for benchmarks, tests and tools that train without the daemon. (The daemon imports through
 * its decoder processes instead; see daemon/api/api_frames.c.) */
#ifndef FG_IO_DATASET_H
#define FG_IO_DATASET_H

#include <stddef.h>

#include "io/frame.h"

/* Reads transforms_path and every frame it names whose image exists (frames whose image is
 * missing are skipped, as the import endpoint does), decoding images (alpha composited on
 * opts->background_rgb), reading each frame's optional features_path .npy and depth_file_path
 * depth map (a frame whose depth file is missing loads without depth), and preparing the
 * frames with fg_frame_prepare_image_depth (undistortion, downscaling to
 * opts->max_image_side).
 * Frames are decoded in parallel on n_threads (<= 0: the OpenMP default) and returned in
 * file order. On success the caller owns *frames (n entries; fg_dataset_free); on failure
 * nothing is left to free and the detail names the frame that failed. */
int fg_dataset_load(const char *transforms_path, const fg_ingest_opts *opts, int n_threads,
                    fg_frame **frames, size_t *n);

/* Frees n frames and the array. Accepts NULL. */
void fg_dataset_free(fg_frame *frames, size_t n);

#endif
