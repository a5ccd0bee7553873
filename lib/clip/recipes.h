/* CLIP's recipes as F3RM and the API use them, over a loaded model (clip.h) and tokenizer
 * (tokenizer.h): texts to (normalised) embeddings; an image to its dense MaskCLIP features on
 * F3RM's grid, or to CLIP's pooled embedding with CLIP's own centre crop. */
#ifndef FG_CLIP_RECIPES_H
#define FG_CLIP_RECIPES_H

#include "clip/clip.h"
#include "clip/tokenizer.h"

/* Most texts one call of fg_clip_embed_texts (and one POST /v1/embed/text) takes, and
 * the longest text in bytes (the tokenizer's cost grows with the length of a word; 75 tokens
 * are far fewer bytes than this). */
#define FG_CLIP_MAX_TEXTS 256
#define FG_CLIP_MAX_TEXT_BYTES 4096

/* Most patch tokens of one image: an image whose preprocessed grid (short side image_size)
 * has more patches than this has too extreme an aspect ratio (attention grows with the square
 * of the token count). ViT-B/16 takes up to about 10:1. */
#define FG_CLIP_MAX_PATCHES 2048

/* Text embeddings (CLIP's encode_text) of n texts (1..FG_CLIP_MAX_TEXTS) into out [n][E]
 * (caller-owned). truncate cuts texts longer than the context to it instead of failing;
 * normalize scales each row to unit L2 norm. On failure *bad (may be NULL) is the index of
 * the text at fault, or -1: FG_EINVAL (empty, longer than FG_CLIP_MAX_TEXT_BYTES, invalid
 * UTF-8), FG_ERANGE (more tokens than the context takes, without truncate), FG_ENOMEM. */
int fg_clip_embed_texts(fg_clip *clip, const fg_tokenizer *tok, const char *const *texts, int n,
                        int truncate, int normalize, float *out, int *bad);

/* The grid [*hp][*wp] of the dense features of a w x h image: F3RM's resize (short side
 * image_size, long side int(image_size * long / short)), then whole patches. FG_ERANGE when
 * it has more than FG_CLIP_MAX_PATCHES patches, FG_EINVAL for a size below 1. */
int fg_clip_image_grid(const fg_clip *clip, int w, int h, int *hp, int *wp);

/* Dense MaskCLIP features of an RGB image rgb [h][w][3] in [0, 1] (sRGB), preprocessed as
 * F3RM does (short side to image_size, no crop, 8-bit rounding as PIL on 8-bit images): on
 * success *out is a malloc'd [*hp][*wp][E] the caller frees. FG_ERANGE when the grid has
 * more than FG_CLIP_MAX_PATCHES patches (checked before any work); FG_EINVAL, FG_ENOMEM. */
int fg_clip_dense_features(fg_clip *clip, const float *rgb, int w, int h, float **out, int *hp,
                           int *wp);

/* The pooled image embedding (CLIP's encode_image) of rgb [h][w][3] as CLIP's own
 * preprocessing gives it: the F3RM preprocessing above, then the centre image_size x
 * image_size crop (offsets rounded half to even, as torchvision's CenterCrop). out [E]
 * (caller-owned). FG_ERANGE when the resized image would exceed FG_IMAGE_MAX_PIXELS;
 * FG_EINVAL, FG_ENOMEM. */
int fg_clip_pooled_embedding(fg_clip *clip, const float *rgb, int w, int h, float *out);

#endif
