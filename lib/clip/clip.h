/* CLIP (Radford et al. 2021) in C, numerically OpenAI's reference model: the image encoder
 * (ViT) with F3RM's MaskCLIP dense output, and the text encoder, from a user's safetensors
 * file with OpenAI or Hugging Face CLIPModel tensor names.
 *
 * Image encoder, for an input [3][H][W] already preprocessed (fg_clip_preprocess):
 *   patches (stride-p convolution without bias; a remainder of H or W beyond a whole patch
 *   is ignored, as the convolution does) -> [class; patches] + positional embedding (the
 *   patch part interpolated bicubically to the input's grid as F3RM does) -> ln_pre ->
 *   blocks x = x + attn(ln_1 x); x = x + mlp(ln_2 x) (QuickGELU)
 * dense (MaskCLIP): the last block keeps only the value path for the patch tokens,
 *   y = out_proj(v_proj(ln_1 x)), with no attention mixing, residual or MLP, then ln_post and
 *   the projection for every patch token -> [h][w][E];
 * pooled: the ordinary last block, ln_post of the class token and the projection -> [E].
 * Text encoder: token + positional embedding, causal blocks, ln_final, the row of the
 * end-of-text token (the largest id, as OpenAI's argmax), text projection -> [E].
 *
 * A loaded model is read-only: calls may run on several threads at once, each with its own
 * scratch memory. */
#ifndef FG_CLIP_CLIP_H
#define FG_CLIP_CLIP_H

#include <stddef.h>
#include <stdint.h>

#include "core/digest.h"

typedef struct fg_clip fg_clip;

typedef struct fg_clip_info {
  int image_size, patch_size, vision_width, vision_layers, vision_heads;
  int text_width, text_layers, text_heads, context_length, vocab_size;
  int embed_dim;         /* E */
  int naming;            /* 0 OpenAI, 1 Hugging Face */
  const char *dtype;     /* "F32", "F16" or "BF16": how the weights are stored and kept */
  size_t weights_bytes;  /* the tensors the model uses, as stored */
  /* SHA-256 of the whole weights file in lowercase hex, as sha256sum prints it: changes
   * when any byte of the weights does */
  char fingerprint[FG_SHA256_HEX + 1];
} fg_clip_info;

/* Opens a weights file and checks that every tensor the model needs is there with a
 * consistent shape and a float dtype (FG_EFORMAT naming the tensor otherwise). On success
 * the caller owns *out (fg_clip_free) and the file stays mapped until then; on failure *out
 * is NULL. */
int fg_clip_load(fg_clip **out, const char *path);
void fg_clip_free(fg_clip *c);
const fg_clip_info *fg_clip_get_info(const fg_clip *c);

/* Sets the thread count of later calls (0: all cores). */
void fg_clip_set_threads(fg_clip *c, int n_threads);

/* F3RM's preprocessing (CLIP's without the centre crop): rgb [h][w][3] in [0, 1] (sRGB) is
 * resized so that its short side is image_size and the long side int(image_size * long /
 * short), with PIL's antialiased bicubic filter; with quantize set each pass rounds to 8 bits
 * as PIL does on 8-bit images. Then it is normalised with CLIP's mean and std into *out, a
 * malloc'd [3][*H][*W] the caller frees. */
int fg_clip_preprocess(const fg_clip *c, const float *rgb, int w, int h, int quantize,
                       float **out, int *H, int *W);

/* The dense grid of an input of H x W pixels: *hp = H / p, *wp = W / p (FG_EINVAL if either
 * is 0). */
int fg_clip_dense_grid(const fg_clip *c, int H, int W, int *hp, int *wp);

/* Dense MaskCLIP features of n preprocessed images x [n][3][H][W]: out [n][H/p][W/p][E]
 * (caller-owned). 0, FG_EINVAL, FG_ENOMEM. */
int fg_clip_image_dense(fg_clip *c, const float *x, int n, int H, int W, float *out);

/* The pooled image embedding (encode_image) of n images x [n][3][image_size][image_size]:
 * out [n][E]. */
int fg_clip_image_pooled(fg_clip *c, const float *x, int n, float *out);

/* Text embeddings of n token sequences ids [n][context_length] (start, tokens, end, zeros,
 * as fg_tokenizer_encode writes them): out [n][E]. FG_EINVAL for an id outside the
 * vocabulary. */
int fg_clip_text(fg_clip *c, const int32_t *ids, int n, float *out);

#endif
