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
#include "clip/recipes.h"
#include "clip/tokenizer.h"
#include "conf/conf.h"

typedef struct fg_clip_svc fg_clip_svc;
typedef struct fg_clip_model fg_clip_model;

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

/* An image's CLIP embedding: pooled, one vector (hp = wp = 0), or MaskCLIP's dense features
 * on the patch grid (hp, wp). data: (hp, wp, dim) or (dim), malloc'd. */
typedef struct fg_clip_image_embedding {
  float *data;
  int hp, wp, dim;
} fg_clip_image_embedding;

/* The embedding of an encoded image (PNG, JPEG, OpenEXR or TIFF, decoded by dec in a child
 * process; transparent pixels on white, the scenes' default background) by model m into
 * *out (free out->data), pooled or dense. Failures carry their reason: invalid_image (an
 * image that does not decode, or that the model cannot take), internal_error. */
struct fg_decoder;
int fg_clip_model_embed_image(fg_clip_model *m, struct fg_decoder *dec, const void *bytes,
                              size_t len, int pooled, fg_clip_image_embedding *out);

#endif
