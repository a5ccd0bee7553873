/* The CLIP model the daemon serves ([clip] of the configuration): the weights (clip/clip.h)
 * and the tokenizer (clip/tokenizer.h), loaded once at start-up or at a reload, never per
 * request.
 *
 * A loaded model is shared by reference count: the service holds one reference, every
 * request or training that uses the model another, so a reload that brings new weights
 * never frees a model in use; the old one goes when its last user releases it.
 *
 * At a reload the model is kept when [clip] names the same files, neither of them changed
 * (device, inode, size and modification time are compared) and the thread count is the same;
 * otherwise the files are loaded again, and only once they load does the new model replace
 * the old one. Replace a weights file by renaming a new file over it (mv, or a copy to a
 * temporary name first): the running model maps the file, and overwriting it in place would
 * change the weights under requests in flight. */
#ifndef FG_DAEMON_CLIP_SVC_H
#define FG_DAEMON_CLIP_SVC_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

#include "clip/clip.h"
#include "clip/tokenizer.h"
#include "conf/conf.h"

typedef struct fg_clip_svc fg_clip_svc;
typedef struct fg_clip_model fg_clip_model;

/* Most texts one call of fg_clip_model_embed_texts (and one POST /v1/embed/text) takes, and
 * the longest text in bytes (the tokenizer's cost grows with the length of a word; 75 tokens
 * are far fewer bytes than this). */
#define FG_CLIP_MAX_TEXTS 256
#define FG_CLIP_MAX_TEXT_BYTES 4096

/* Most patch tokens of one image: an image whose preprocessed grid (short side image_size)
 * has more patches than this has too extreme an aspect ratio (attention grows with the square
 * of the token count). ViT-B/16 takes up to about 10:1. */
#define FG_CLIP_MAX_PATCHES 2048

/* Creates a service with no model. On success the caller owns *out (fg_clip_svc_free). */
int fg_clip_svc_new(fg_clip_svc **out);

/* Drops the service's reference to its model (users still holding one keep it). Accepts NULL. */
void fg_clip_svc_free(fg_clip_svc *svc);

/* Brings the service in line with conf's [clip] section (see above). Without [clip] the
 * model is dropped. On failure the model the service had stays, the failure is remembered
 * for fg_clip_svc_unavailable, and the detail reads
 * "FILE:LINE: [clip] weights: cannot load PATH: why" (or vocab). *changed (may be NULL)
 * is set to 1 when the service now serves another model or none where it had one. Called
 * from one thread at a time (start-up, then the signal loop). */
int fg_clip_svc_configure(fg_clip_svc *svc, const fg_conf *conf, int *changed);

/* The current model with a reference the caller drops with fg_clip_model_release; NULL when
 * there is none. */
fg_clip_model *fg_clip_svc_acquire(fg_clip_svc *svc);
void fg_clip_model_release(fg_clip_model *m);

/* Why there is no model, for messages: writes into msg (size n) "" when [clip] was never
 * configured or was removed, else the last load failure. */
void fg_clip_svc_unavailable(fg_clip_svc *svc, char *msg, size_t n);

/* fg_clip_svc_acquire for callers that answer a client: svc may be NULL (no service). When
 * there is no model it returns NULL and writes into msg (size n) a message for the client
 * that says why (no [clip] section, or the files that did not load) and how to fix it; the
 * HTTP handlers send it as 409 clip_not_configured. On success the caller owns a reference
 * (fg_clip_model_release) and msg is untouched. */
fg_clip_model *fg_clip_svc_acquire_explained(fg_clip_svc *svc, char *msg, size_t n);

/* The model's parts; they live as long as the reference. The fg_clip is safe to call from
 * several threads at once (clip.h). */
fg_clip *fg_clip_model_clip(const fg_clip_model *m);
const fg_tokenizer *fg_clip_model_tokenizer(const fg_clip_model *m);
const fg_clip_info *fg_clip_model_info(const fg_clip_model *m);
/* Threads every call of this model uses (>= 1). */
int fg_clip_model_threads(const fg_clip_model *m);

/* The model object of the API: {"fingerprint", "dtype", "embed_dim", "image_size",
 * "patch_size", "context_length", "naming"}. New reference, NULL on allocation failure. */
json_t *fg_clip_model_json(const fg_clip_model *m);

/* Text embeddings (CLIP's encode_text) of n texts (1..FG_CLIP_MAX_TEXTS) into out [n][E]
 * (caller-owned). truncate cuts texts longer than the context to it instead of failing;
 * normalize scales each row to unit L2 norm. On failure *bad (may be NULL) is the index of
 * the text at fault, or -1: FG_EINVAL (empty, longer than FG_CLIP_MAX_TEXT_BYTES, invalid
 * UTF-8), FG_ERANGE (more tokens than the context takes, without truncate), FG_ENOMEM. */
int fg_clip_model_embed_texts(fg_clip_model *m, const char *const *texts, int n, int truncate,
                              int normalize, float *out, int *bad);

/* The grid [*hp][*wp] of the dense features of a w x h image: F3RM's resize (short side
 * image_size, long side int(image_size * long / short)), then whole patches. FG_ERANGE when
 * it has more than FG_CLIP_MAX_PATCHES patches, FG_EINVAL for a size below 1. */
int fg_clip_model_grid(const fg_clip_model *m, int w, int h, int *hp, int *wp);

/* Dense MaskCLIP features of an RGB image rgb [h][w][3] in [0, 1] (sRGB), preprocessed as
 * F3RM does (short side to image_size, no crop, 8-bit rounding as PIL on 8-bit images): on
 * success *out is a malloc'd [*hp][*wp][E] the caller frees. FG_ERANGE when the grid has
 * more than FG_CLIP_MAX_PATCHES patches (checked before any work); FG_EINVAL, FG_ENOMEM. */
int fg_clip_model_dense(fg_clip_model *m, const float *rgb, int w, int h, float **out, int *hp,
                        int *wp);

/* The pooled image embedding (CLIP's encode_image) of rgb [h][w][3] as CLIP's own
 * preprocessing gives it: the F3RM preprocessing above, then the centre image_size x
 * image_size crop (offsets rounded half to even, as torchvision's CenterCrop). out [E]
 * (caller-owned). FG_ERANGE when the resized image would exceed FG_IMAGE_MAX_PIXELS;
 * FG_EINVAL, FG_ENOMEM. */
int fg_clip_model_pooled(fg_clip_model *m, const float *rgb, int w, int h, float *out);

/* Scales v [n] to unit L2 norm (in double). FG_EINVAL when its norm is 0 or not finite. */
int fg_l2_normalize(float *v, int n);

#endif
