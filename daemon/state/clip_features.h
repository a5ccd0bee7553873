/* CLIP features at training time: when [clip] is configured, a training gives every frame
 * without uploaded features the dense MaskCLIP features of its stored image (F3RM's
 * preprocessing: short side to the model's image_size, no crop), a grid [H/p][W/p][E] that
 * covers the image as SPEC.md "Files" describes.
 *
 * They are cached in the scene's folder, one file per frame and model:
 *   <scene>/clip/000012.<fingerprint>.npy   float16 [h][w][E] (float32 where a value is
 *                                           beyond float16's range), written atomically
 * so that the next training of the scene reads instead of computing them. The fingerprint
 * (fg_clip_info: the SHA-256 of the weights file) changes with the file's bytes, so new
 * weights never meet old features: at the start of every features phase, files of another
 * fingerprint and of frames the scene no longer has are removed (a capture's deletion
 * removes its frames' files at once, so that a frame number used again never meets them).
 * A cache file that does not read back as the expected grid is logged and computed again.
 * The folder goes with its scene. Files named by the 16-digit checksum fingerprint of
 * earlier versions count as another model's: the first training after the upgrade computes
 * them again and removes them. */
#ifndef FG_DAEMON_CLIP_FEATURES_H
#define FG_DAEMON_CLIP_FEATURES_H

#include <stddef.h>

#include "clip_svc.h"
#include "io/frame.h"

typedef struct fg_clip_features_progress {
  size_t total;  /* frames that need CLIP features */
  size_t done;   /* of those, the ones that have them now */
  size_t cached; /* of done, the ones read from the cache */
} fg_clip_features_progress;

/* Number of frames of frames[0..n) without features. */
size_t fg_clip_features_needed(const fg_frame *frames, size_t n);

/* Gives every frame of frames[0..n) (frame numbers indices[0..n)) that has no features the
 * CLIP features of model m, read from scene_dir/clip or computed and cached; frames that
 * have features keep them, and their D must then be E (else FG_EINVAL, whose detail names
 * the frames and both dimensions; nothing is computed). stop (may be NULL) is asked before
 * each frame and ends the phase with FG_ECANCELED; progress (may be NULL) is told after
 * each frame. The features attached are the frames' own (freed by fg_frame_clear), also on
 * failure. Runs on the calling thread with m's threads. FG_ERANGE (an image with too many
 * patches), FG_ENOMEM, FG_EIO (the cache cannot be written). */
int fg_clip_features_attach(fg_clip_model *m, const char *scene_dir, fg_frame *frames,
                            const int *indices, size_t n, int (*stop)(void *ud),
                            void (*progress)(void *ud, const fg_clip_features_progress *p),
                            void *ud);

#endif
