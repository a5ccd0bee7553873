/* Random CLIP weights in safetensors format, for tests and benchmarks (never installed).
 *
 * clipgen_write() writes a ViT CLIP with either OpenAI's tensor names (visual.conv1.weight,
 * visual.transformer.resblocks.N.attn.in_proj_weight, ...) or Hugging Face CLIPModel's
 * (vision_model.encoder.layers.N.self_attn.q_proj.weight, ...), as F32, F16 or BF16.
 *
 * Values: every tensor is derived from its OpenAI name (its "key") and the seed only, by a
 * counter-based generator (splitmix64 outputs at element index k, Box-Muller pairs), so a
 * tensor's values do not depend on the order tensors are written in nor on the naming: a
 * Hugging Face q_proj is the first row block of the OpenAI in_proj_weight of the same seed,
 * visual_projection.weight the transpose of visual.proj. Scales follow OpenAI's
 * initialisation (std width^-0.5 for embeddings, projections and in_proj, (2 width)^-0.5 for
 * c_fc, width^-0.5 (2 layers)^-0.5 for out_proj and c_proj, 0.02 for token embeddings and
 * the patch convolution, 0.01 for the text positional embedding); LayerNorm weights are
 * 1 + 0.1 N(0,1) and biases 0.05 N(0,1) so that the affine part matters; linear biases are
 * 0.02 N(0,1); logit_scale is ln(1/0.07).
 *
 * Every value is rounded to bfloat16 (round to nearest even) and values with |v| < 2^-14 are
 * flushed to +0, so each is exactly representable in F32, F16 and BF16: the three dtypes of
 * one seed hold the same numbers.
 *
 * File layout: the JSON header lists __metadata__ first (when written: "format": "pt",
 * "vision_heads", "text_heads", decimal strings), then the tensors in data order; it is
 * padded with spaces to a multiple of 8 bytes and the data section is contiguous. The file
 * is written tensor by tensor through a small buffer (ViT-B/16 in F32 is about 600 MB). */
#ifndef CLIPGEN_H
#define CLIPGEN_H

#include <stddef.h>
#include <stdint.h>

typedef enum { CLIPGEN_OPENAI = 0, CLIPGEN_HF = 1 } clipgen_naming;
typedef enum { CLIPGEN_F32 = 0, CLIPGEN_F16 = 1, CLIPGEN_BF16 = 2 } clipgen_dtype;

/* CLIPGEN_TINY: image 32, patch 8 (a 4x4 grid), vision 48 wide, 3 layers, 3 heads; text 40
 * wide, 2 layers, 5 heads, context 77, vocabulary 49408; embedding 24. Head widths (16, 8)
 * are not 64, so a reader must take the head counts from the metadata.
 * CLIPGEN_VIT_B_16: OpenAI's ViT-B/16 sizes (224/16, 768 x 12 layers x 12 heads; text 512 x
 * 12 x 8, 77, 49408; embedding 512). */
typedef enum { CLIPGEN_TINY = 0, CLIPGEN_VIT_B_16 = 1 } clipgen_preset;

typedef struct clipgen_cfg {
  int image_size, patch_size, vision_width, vision_layers, vision_heads;
  int text_width, text_layers, text_heads, context_length, vocab_size;
  int embed_dim;
  clipgen_naming naming;
  clipgen_dtype dtype;
  uint64_t seed;
  int write_metadata; /* nonzero: __metadata__ with the head counts */
} clipgen_cfg;

#define CLIPGEN_NAME_MAX 96
#define CLIPGEN_MAX_DIMS 4

/* One tensor of the file a cfg describes. */
typedef struct clipgen_tensor {
  char name[CLIPGEN_NAME_MAX]; /* as written in the file */
  char key[CLIPGEN_NAME_MAX];  /* the OpenAI tensor its values come from ("" for position_ids) */
  int is_i64;                  /* position_ids: I64 0, 1, ..., n-1; else cfg->dtype */
  int ndim;                    /* 0 for logit_scale */
  int64_t shape[CLIPGEN_MAX_DIMS];
  size_t count; /* product of shape (1 for a scalar) */
  /* How the values are made: element j is element k of the key's stream, value
   * bf16(mean + std z_k) with z_k ~ N(0,1) (std 0: the constant mean), where
   * k = j + key_offset (Hugging Face q/k/v: row blocks of in_proj), or, when transpose_rows
   * R > 0, this tensor [C][R] is the transpose of the key's [R][C]. */
  double mean, std;
  size_t key_offset;
  int64_t transpose_rows;
} clipgen_tensor;

/* Fills *cfg with a preset's sizes, OpenAI naming, F32, seed 0 and metadata on.
 * FG_EINVAL for an unknown preset. */
int clipgen_cfg_preset(clipgen_cfg *cfg, clipgen_preset preset);

/* Checks the sizes: all positive, image_size a multiple of patch_size, widths multiples of
 * their head counts. FG_EINVAL with a detail naming the field otherwise. */
int clipgen_cfg_check(const clipgen_cfg *cfg);

/* The tensors of the file for cfg, in file order: on success *out is a malloc'd array of *n
 * entries the caller frees; on failure *out is NULL. FG_EINVAL (bad cfg), FG_ENOMEM. */
int clipgen_tensors(const clipgen_cfg *cfg, clipgen_tensor **out, int *n);

/* Elements [off, off + n) (C order of t's shape) of a float tensor t of the list for cfg,
 * as float32 (what the file holds, decoded), into dst (caller-owned, n floats). FG_EINVAL
 * for an I64 tensor or a range outside the tensor. */
int clipgen_tensor_values(const clipgen_cfg *cfg, const clipgen_tensor *t, size_t off, size_t n,
                          float *dst);

/* Writes the file for cfg to path (a temp file renamed over path, so a reader never sees a
 * torn file). *n_bytes (may be NULL) receives the file size. 0, FG_EINVAL (bad cfg),
 * FG_EIO (with the path and errno), FG_ENOMEM. */
int clipgen_write(const char *path, const clipgen_cfg *cfg, size_t *n_bytes);

/* FNV-1a 64 of len bytes continuing from h (start with CLIPGEN_FNV1A64_INIT). */
#define CLIPGEN_FNV1A64_INIT 0xcbf29ce484222325ULL
uint64_t clipgen_fnv1a64(uint64_t h, const void *buf, size_t len);

/* FNV-1a 64 of a whole file's bytes. FG_ENOENT / FG_EIO. */
int clipgen_file_fnv1a64(const char *path, uint64_t *out);

/* "F32", "F16", "BF16"; "openai", "hf"; NULL when out of range. */
const char *clipgen_dtype_name(clipgen_dtype d);
const char *clipgen_naming_name(clipgen_naming n);

#endif
