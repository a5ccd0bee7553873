/* Random CLIP weights in safetensors format (see clipgen.h). */
#include "clipgen.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/error.h"
#include "core/fsutil.h"
#include "core/half.h"

/* ---- presets and checks ---------------------------------------------------------------- */

/* Fills cfg with a preset (clipgen.h). */
int clipgen_cfg_preset(clipgen_cfg *cfg, clipgen_preset preset) {
  if (!cfg) return fg_fail(FG_EINVAL, "clipgen_cfg_preset: cfg is NULL");
  memset(cfg, 0, sizeof *cfg);
  switch (preset) {
  case CLIPGEN_TINY:
    *cfg = (clipgen_cfg){.image_size = 32, .patch_size = 8, .vision_width = 48,
                         .vision_layers = 3, .vision_heads = 3, .text_width = 40,
                         .text_layers = 2, .text_heads = 5, .context_length = 77,
                         .vocab_size = 49408, .embed_dim = 24};
    break;
  case CLIPGEN_VIT_B_16:
    *cfg = (clipgen_cfg){.image_size = 224, .patch_size = 16, .vision_width = 768,
                         .vision_layers = 12, .vision_heads = 12, .text_width = 512,
                         .text_layers = 12, .text_heads = 8, .context_length = 77,
                         .vocab_size = 49408, .embed_dim = 512};
    break;
  default:
    return fg_fail(FG_EINVAL, "unknown CLIP preset %d", (int)preset);
  }
  cfg->naming = CLIPGEN_OPENAI;
  cfg->dtype = CLIPGEN_F32;
  cfg->seed = 0;
  cfg->write_metadata = 1;
  return 0;
}

/* Bounds every size so that shapes and byte counts cannot overflow. */
#define CLIPGEN_MAX_SIZE 65536

/* Validates cfg (clipgen.h). */
int clipgen_cfg_check(const clipgen_cfg *cfg) {
  if (!cfg) return fg_fail(FG_EINVAL, "clipgen: cfg is NULL");
  const struct {
    const char *name;
    int v;
  } f[] = {
      {"image_size", cfg->image_size},       {"patch_size", cfg->patch_size},
      {"vision_width", cfg->vision_width},   {"vision_layers", cfg->vision_layers},
      {"vision_heads", cfg->vision_heads},   {"text_width", cfg->text_width},
      {"text_layers", cfg->text_layers},     {"text_heads", cfg->text_heads},
      {"context_length", cfg->context_length}, {"vocab_size", cfg->vocab_size},
      {"embed_dim", cfg->embed_dim},
  };
  for (size_t i = 0; i < sizeof f / sizeof f[0]; i++)
    if (f[i].v <= 0 || f[i].v > CLIPGEN_MAX_SIZE)
      return fg_fail(FG_EINVAL, "clipgen: %s must be in [1, %d], got %d", f[i].name,
                     CLIPGEN_MAX_SIZE, f[i].v);
  if (cfg->image_size % cfg->patch_size)
    return fg_fail(FG_EINVAL, "clipgen: image_size %d is not a multiple of patch_size %d",
                   cfg->image_size, cfg->patch_size);
  if (cfg->vision_width % cfg->vision_heads)
    return fg_fail(FG_EINVAL, "clipgen: vision_width %d is not a multiple of vision_heads %d",
                   cfg->vision_width, cfg->vision_heads);
  if (cfg->text_width % cfg->text_heads)
    return fg_fail(FG_EINVAL, "clipgen: text_width %d is not a multiple of text_heads %d",
                   cfg->text_width, cfg->text_heads);
  if (!clipgen_naming_name(cfg->naming))
    return fg_fail(FG_EINVAL, "clipgen: unknown naming %d", (int)cfg->naming);
  if (!clipgen_dtype_name(cfg->dtype))
    return fg_fail(FG_EINVAL, "clipgen: unknown dtype %d", (int)cfg->dtype);
  return 0;
}

/* Names of the enums (clipgen.h). */
const char *clipgen_dtype_name(clipgen_dtype d) {
  switch (d) {
  case CLIPGEN_F32: return "F32";
  case CLIPGEN_F16: return "F16";
  case CLIPGEN_BF16: return "BF16";
  }
  return NULL;
}

const char *clipgen_naming_name(clipgen_naming n) {
  switch (n) {
  case CLIPGEN_OPENAI: return "openai";
  case CLIPGEN_HF: return "hf";
  }
  return NULL;
}

/* ---- the tensor list ------------------------------------------------------------------- */

/* A growing list of tensors; err keeps the first failure so that the builders stay flat. */
typedef struct tlist {
  clipgen_tensor *t;
  int n, cap;
  int err;
} tlist;

/* Appends a float tensor named name whose values are key's stream with the given mean and
 * std; the shape is ndim int64 arguments. Returns the entry, or NULL (l->err set). */
static clipgen_tensor *tl_add(tlist *l, const char *name, const char *key, double mean,
                              double std, int ndim, ...) {
  if (l->err) return NULL;
  if (l->n == l->cap) {
    int cap = l->cap ? 2 * l->cap : 64;
    clipgen_tensor *t = realloc(l->t, (size_t)cap * sizeof *t);
    if (!t) {
      l->err = fg_fail(FG_ENOMEM, "clipgen: out of memory for the tensor list");
      return NULL;
    }
    l->t = t;
    l->cap = cap;
  }
  clipgen_tensor *e = &l->t[l->n];
  memset(e, 0, sizeof *e);
  if ((size_t)snprintf(e->name, sizeof e->name, "%s", name) >= sizeof e->name ||
      (size_t)snprintf(e->key, sizeof e->key, "%s", key) >= sizeof e->key) {
    l->err = fg_fail(FG_EINVAL, "clipgen: tensor name too long: %s", name);
    return NULL;
  }
  e->ndim = ndim;
  e->count = 1;
  va_list ap;
  va_start(ap, ndim);
  for (int i = 0; i < ndim; i++) {
    e->shape[i] = va_arg(ap, int64_t);
    e->count *= (size_t)e->shape[i];
  }
  va_end(ap);
  e->mean = mean;
  e->std = std;
  l->n++;
  return e;
}

/* position_ids: I64 [1, n] holding 0..n-1 (Hugging Face files carry this buffer). */
static void tl_add_ids(tlist *l, const char *name, int64_t n) {
  clipgen_tensor *e = tl_add(l, name, "", 0, 0, 2, (int64_t)1, n);
  if (e) e->is_i64 = 1;
}

/* Initialisation scales of one transformer (OpenAI's CLIP.initialize_parameters). */
typedef struct scales {
  double attn, proj, fc;
} scales;

/* OpenAI's std for in_proj (attn), out_proj and c_proj (proj), and c_fc (fc). */
static scales scales_of(int width, int layers) {
  scales s;
  s.attn = pow(width, -0.5);
  s.proj = pow(width, -0.5) * pow(2.0 * layers, -0.5);
  s.fc = pow(2.0 * width, -0.5);
  return s;
}

#define LN_W_MEAN 1.0
#define LN_W_STD 0.1
#define LN_B_STD 0.05
#define BIAS_STD 0.02

/* The 12 tensors of OpenAI block b under prefix ("visual.transformer.resblocks" or
 * "transformer.resblocks"). */
static void add_block_openai(tlist *l, const char *prefix, int b, int w, scales s) {
  char n[CLIPGEN_NAME_MAX];
  const int64_t W = w;
#define K(suffix) (snprintf(n, sizeof n, "%s.%d.%s", prefix, b, suffix), n)
  tl_add(l, K("ln_1.weight"), n, LN_W_MEAN, LN_W_STD, 1, W);
  tl_add(l, K("ln_1.bias"), n, 0, LN_B_STD, 1, W);
  tl_add(l, K("attn.in_proj_weight"), n, 0, s.attn, 2, 3 * W, W);
  tl_add(l, K("attn.in_proj_bias"), n, 0, BIAS_STD, 1, 3 * W);
  tl_add(l, K("attn.out_proj.weight"), n, 0, s.proj, 2, W, W);
  tl_add(l, K("attn.out_proj.bias"), n, 0, BIAS_STD, 1, W);
  tl_add(l, K("ln_2.weight"), n, LN_W_MEAN, LN_W_STD, 1, W);
  tl_add(l, K("ln_2.bias"), n, 0, LN_B_STD, 1, W);
  tl_add(l, K("mlp.c_fc.weight"), n, 0, s.fc, 2, 4 * W, W);
  tl_add(l, K("mlp.c_fc.bias"), n, 0, BIAS_STD, 1, 4 * W);
  tl_add(l, K("mlp.c_proj.weight"), n, 0, s.proj, 2, W, 4 * W);
  tl_add(l, K("mlp.c_proj.bias"), n, 0, BIAS_STD, 1, W);
#undef K
}

/* The 16 tensors of Hugging Face layer b under hf_prefix ("vision_model.encoder.layers"),
 * with values from OpenAI block b under oa_prefix. */
static void add_block_hf(tlist *l, const char *hf_prefix, const char *oa_prefix, int b, int w,
                         scales s) {
  char n[CLIPGEN_NAME_MAX], k[CLIPGEN_NAME_MAX];
  const int64_t W = w;
#define N(suffix) (snprintf(n, sizeof n, "%s.%d.%s", hf_prefix, b, suffix), n)
#define K(suffix) (snprintf(k, sizeof k, "%s.%d.%s", oa_prefix, b, suffix), k)
  static const char *qkv[3] = {"q_proj", "k_proj", "v_proj"};
  char tmp[64];
  tl_add(l, N("layer_norm1.weight"), K("ln_1.weight"), LN_W_MEAN, LN_W_STD, 1, W);
  tl_add(l, N("layer_norm1.bias"), K("ln_1.bias"), 0, LN_B_STD, 1, W);
  for (int i = 0; i < 3; i++) {
    snprintf(tmp, sizeof tmp, "self_attn.%s.weight", qkv[i]);
    clipgen_tensor *e = tl_add(l, N(tmp), K("attn.in_proj_weight"), 0, s.attn, 2, W, W);
    if (e) e->key_offset = (size_t)i * (size_t)(W * W);
    snprintf(tmp, sizeof tmp, "self_attn.%s.bias", qkv[i]);
    e = tl_add(l, N(tmp), K("attn.in_proj_bias"), 0, BIAS_STD, 1, W);
    if (e) e->key_offset = (size_t)i * (size_t)W;
  }
  tl_add(l, N("self_attn.out_proj.weight"), K("attn.out_proj.weight"), 0, s.proj, 2, W, W);
  tl_add(l, N("self_attn.out_proj.bias"), K("attn.out_proj.bias"), 0, BIAS_STD, 1, W);
  tl_add(l, N("layer_norm2.weight"), K("ln_2.weight"), LN_W_MEAN, LN_W_STD, 1, W);
  tl_add(l, N("layer_norm2.bias"), K("ln_2.bias"), 0, LN_B_STD, 1, W);
  tl_add(l, N("mlp.fc1.weight"), K("mlp.c_fc.weight"), 0, s.fc, 2, 4 * W, W);
  tl_add(l, N("mlp.fc1.bias"), K("mlp.c_fc.bias"), 0, BIAS_STD, 1, 4 * W);
  tl_add(l, N("mlp.fc2.weight"), K("mlp.c_proj.weight"), 0, s.proj, 2, W, 4 * W);
  tl_add(l, N("mlp.fc2.bias"), K("mlp.c_proj.bias"), 0, BIAS_STD, 1, W);
#undef N
#undef K
}

/* OpenAI's state_dict names, vision tower first. */
static void build_openai(tlist *l, const clipgen_cfg *c) {
  const int64_t w = c->vision_width, tw = c->text_width, E = c->embed_dim, p = c->patch_size;
  const int64_t g = c->image_size / c->patch_size;
  const double vs = pow((double)w, -0.5), ts = pow((double)tw, -0.5);
  tl_add(l, "visual.class_embedding", "visual.class_embedding", 0, vs, 1, w);
  tl_add(l, "visual.positional_embedding", "visual.positional_embedding", 0, vs, 2, g * g + 1, w);
  tl_add(l, "visual.proj", "visual.proj", 0, vs, 2, w, E);
  tl_add(l, "visual.conv1.weight", "visual.conv1.weight", 0, 0.02, 4, w, (int64_t)3, p, p);
  tl_add(l, "visual.ln_pre.weight", "visual.ln_pre.weight", LN_W_MEAN, LN_W_STD, 1, w);
  tl_add(l, "visual.ln_pre.bias", "visual.ln_pre.bias", 0, LN_B_STD, 1, w);
  scales sv = scales_of(c->vision_width, c->vision_layers);
  for (int b = 0; b < c->vision_layers; b++)
    add_block_openai(l, "visual.transformer.resblocks", b, c->vision_width, sv);
  tl_add(l, "visual.ln_post.weight", "visual.ln_post.weight", LN_W_MEAN, LN_W_STD, 1, w);
  tl_add(l, "visual.ln_post.bias", "visual.ln_post.bias", 0, LN_B_STD, 1, w);

  tl_add(l, "positional_embedding", "positional_embedding", 0, 0.01, 2,
         (int64_t)c->context_length, tw);
  tl_add(l, "text_projection", "text_projection", 0, ts, 2, tw, E);
  tl_add(l, "token_embedding.weight", "token_embedding.weight", 0, 0.02, 2,
         (int64_t)c->vocab_size, tw);
  scales st = scales_of(c->text_width, c->text_layers);
  for (int b = 0; b < c->text_layers; b++)
    add_block_openai(l, "transformer.resblocks", b, c->text_width, st);
  tl_add(l, "ln_final.weight", "ln_final.weight", LN_W_MEAN, LN_W_STD, 1, tw);
  tl_add(l, "ln_final.bias", "ln_final.bias", 0, LN_B_STD, 1, tw);
  tl_add(l, "logit_scale", "logit_scale", log(1 / 0.07), 0, 0);
}

/* Hugging Face CLIPModel names (transformers' convert_clip_original_pytorch_to_hf.py maps
 * OpenAI's tensors this way), vision tower first. */
static void build_hf(tlist *l, const clipgen_cfg *c) {
  const int64_t w = c->vision_width, tw = c->text_width, E = c->embed_dim, p = c->patch_size;
  const int64_t g = c->image_size / c->patch_size;
  const double vs = pow((double)w, -0.5), ts = pow((double)tw, -0.5);
  clipgen_tensor *e;
  tl_add(l, "vision_model.embeddings.class_embedding", "visual.class_embedding", 0, vs, 1, w);
  tl_add(l, "vision_model.embeddings.patch_embedding.weight", "visual.conv1.weight", 0, 0.02, 4,
         w, (int64_t)3, p, p);
  tl_add(l, "vision_model.embeddings.position_embedding.weight", "visual.positional_embedding",
         0, vs, 2, g * g + 1, w);
  tl_add_ids(l, "vision_model.embeddings.position_ids", g * g + 1);
  tl_add(l, "vision_model.pre_layrnorm.weight", "visual.ln_pre.weight", LN_W_MEAN, LN_W_STD, 1,
         w);
  tl_add(l, "vision_model.pre_layrnorm.bias", "visual.ln_pre.bias", 0, LN_B_STD, 1, w);
  scales sv = scales_of(c->vision_width, c->vision_layers);
  for (int b = 0; b < c->vision_layers; b++)
    add_block_hf(l, "vision_model.encoder.layers", "visual.transformer.resblocks", b,
                 c->vision_width, sv);
  tl_add(l, "vision_model.post_layernorm.weight", "visual.ln_post.weight", LN_W_MEAN, LN_W_STD,
         1, w);
  tl_add(l, "vision_model.post_layernorm.bias", "visual.ln_post.bias", 0, LN_B_STD, 1, w);
  e = tl_add(l, "visual_projection.weight", "visual.proj", 0, vs, 2, E, w);
  if (e) e->transpose_rows = w;

  tl_add(l, "text_model.embeddings.token_embedding.weight", "token_embedding.weight", 0, 0.02, 2,
         (int64_t)c->vocab_size, tw);
  tl_add(l, "text_model.embeddings.position_embedding.weight", "positional_embedding", 0, 0.01,
         2, (int64_t)c->context_length, tw);
  tl_add_ids(l, "text_model.embeddings.position_ids", c->context_length);
  scales st = scales_of(c->text_width, c->text_layers);
  for (int b = 0; b < c->text_layers; b++)
    add_block_hf(l, "text_model.encoder.layers", "transformer.resblocks", b, c->text_width, st);
  tl_add(l, "text_model.final_layer_norm.weight", "ln_final.weight", LN_W_MEAN, LN_W_STD, 1, tw);
  tl_add(l, "text_model.final_layer_norm.bias", "ln_final.bias", 0, LN_B_STD, 1, tw);
  e = tl_add(l, "text_projection.weight", "text_projection", 0, ts, 2, E, tw);
  if (e) e->transpose_rows = tw;
  tl_add(l, "logit_scale", "logit_scale", log(1 / 0.07), 0, 0);
}

/* The tensor list (clipgen.h). */
int clipgen_tensors(const clipgen_cfg *cfg, clipgen_tensor **out, int *n) {
  if (!out || !n) return fg_fail(FG_EINVAL, "clipgen_tensors: NULL output");
  *out = NULL;
  *n = 0;
  FG_TRY(clipgen_cfg_check(cfg));
  tlist l = {0};
  if (cfg->naming == CLIPGEN_HF)
    build_hf(&l, cfg);
  else
    build_openai(&l, cfg);
  if (l.err) {
    free(l.t);
    return l.err;
  }
  *out = l.t;
  *n = l.n;
  return 0;
}

/* ---- values ---------------------------------------------------------------------------- */

#define GOLDEN_GAMMA 0x9e3779b97f4a7c15ULL

/* splitmix64's output function. */
static uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/* FNV-1a 64 (clipgen.h). */
uint64_t clipgen_fnv1a64(uint64_t h, const void *buf, size_t len) {
  const unsigned char *p = buf;
  for (size_t i = 0; i < len; i++) {
    h ^= p[i];
    h *= 0x100000001b3ULL;
  }
  return h;
}

/* The stream of a key: its k-th 64-bit draw is splitmix64's k-th output from state s. */
static uint64_t stream_of(uint64_t seed, const char *key) {
  uint64_t name_hash = clipgen_fnv1a64(CLIPGEN_FNV1A64_INIT, key, strlen(key));
  return mix64(name_hash ^ mix64(seed + GOLDEN_GAMMA));
}

/* Draw k of stream s: random access, so a tensor's values can be made in any order. */
static uint64_t draw(uint64_t s, uint64_t k) { return mix64(s + (k + 1) * GOLDEN_GAMMA); }

/* The standard normal pair p of stream s (Box-Muller on draws 2p and 2p+1): z[0] is element
 * 2p, z[1] element 2p+1. */
static void normal_pair(uint64_t s, uint64_t p, double z[2]) {
  double u1 = (double)((draw(s, 2 * p) >> 11) + 1) * 0x1p-53; /* (0, 1] */
  double u2 = (double)(draw(s, 2 * p + 1) >> 11) * 0x1p-53;   /* [0, 1) */
  double r = sqrt(-2.0 * log(u1));
  z[0] = r * cos(2.0 * M_PI * u2);
  z[1] = r * sin(2.0 * M_PI * u2);
}

/* Rounds to bfloat16 precision (nearest even) and flushes |v| < 2^-14 to +0. */
static float to_bf16_grid(double v) {
  float f = (float)v;
  uint32_t b;
  memcpy(&b, &f, sizeof b);
  b = (b + 0x7fffu + ((b >> 16) & 1u)) & 0xffff0000u;
  memcpy(&f, &b, sizeof f);
  if (fabsf(f) < 0x1p-14f) f = 0.0f;
  return f;
}

/* Elements [k0, k0 + n) of the key stream s as values: dst [n]. */
static void fill_stream(uint64_t s, double mean, double std, uint64_t k0, size_t n, float *dst) {
  double z[2];
  size_t i = 0;
  if (n == 0) return;
  if (k0 & 1) { /* odd start: second half of a pair */
    normal_pair(s, k0 >> 1, z);
    dst[i++] = to_bf16_grid(mean + std * z[1]);
  }
  for (; i + 1 < n; i += 2) {
    normal_pair(s, (k0 + i) >> 1, z);
    dst[i] = to_bf16_grid(mean + std * z[0]);
    dst[i + 1] = to_bf16_grid(mean + std * z[1]);
  }
  if (i < n) {
    normal_pair(s, (k0 + i) >> 1, z);
    dst[i] = to_bf16_grid(mean + std * z[0]);
  }
}

/* Values of a float tensor (clipgen.h). */
int clipgen_tensor_values(const clipgen_cfg *cfg, const clipgen_tensor *t, size_t off, size_t n,
                          float *dst) {
  if (!cfg || !t || (!dst && n)) return fg_fail(FG_EINVAL, "clipgen_tensor_values: NULL argument");
  if (t->is_i64) return fg_fail(FG_EINVAL, "clipgen: %s is an I64 tensor", t->name);
  if (off > t->count || n > t->count - off)
    return fg_fail(FG_EINVAL, "clipgen: elements [%zu, %zu) outside %s (%zu elements)", off,
                   off + n, t->name, t->count);
  if (t->std == 0) { /* a constant (logit_scale) */
    for (size_t i = 0; i < n; i++) dst[i] = to_bf16_grid(t->mean);
    return 0;
  }
  uint64_t s = stream_of(cfg->seed, t->key);
  if (t->transpose_rows <= 0) {
    fill_stream(s, t->mean, t->std, (uint64_t)(off + t->key_offset), n, dst);
    return 0;
  }
  /* this [C][R] is the key's [R][C] transposed: element (c, r) is key element r * C + c */
  const size_t R = (size_t)t->transpose_rows, C = t->count / R;
  for (size_t i = 0; i < n; i++) {
    size_t j = off + i, c = j / R, r = j % R;
    uint64_t k = (uint64_t)(r * C + c);
    double z[2];
    normal_pair(s, k >> 1, z);
    dst[i] = to_bf16_grid(t->mean + t->std * z[k & 1]);
  }
  return 0;
}

/* ---- the file -------------------------------------------------------------------------- */

/* A growing string for the JSON header. */
typedef struct sbuf {
  char *s;
  size_t len, cap;
  int err;
} sbuf;

/* Appends printf-style text to b, growing it; on failure b->err is set and later calls do
 * nothing. */
static void sb_printf(sbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

static void sb_printf(sbuf *b, const char *fmt, ...) {
  if (b->err) return;
  for (;;) {
    va_list ap;
    va_start(ap, fmt);
    size_t room = b->cap - b->len;
    int k = vsnprintf(b->s ? b->s + b->len : NULL, room, fmt, ap);
    va_end(ap);
    if (k < 0) {
      b->err = fg_fail(FG_EINVAL, "clipgen: header formatting failed");
      return;
    }
    if ((size_t)k < room) {
      b->len += (size_t)k;
      return;
    }
    size_t cap = b->cap ? b->cap : 4096;
    while (cap - b->len <= (size_t)k) cap *= 2;
    char *s = realloc(b->s, cap);
    if (!s) {
      b->err = fg_fail(FG_ENOMEM, "clipgen: out of memory for the header");
      return;
    }
    b->s = s;
    b->cap = cap;
  }
}

/* Bytes per element of t in the file. */
static size_t elem_size(const clipgen_cfg *cfg, const clipgen_tensor *t) {
  if (t->is_i64) return 8;
  return cfg->dtype == CLIPGEN_F32 ? 4 : 2;
}

/* The JSON header, padded with spaces to a multiple of 8: *hdr malloc'd, *data_bytes the
 * size of the data section. */
static int make_header(const clipgen_cfg *cfg, const clipgen_tensor *t, int n, char **hdr,
                       size_t *hdr_len, size_t *data_bytes) {
  sbuf b = {0};
  sb_printf(&b, "{");
  if (cfg->write_metadata)
    sb_printf(&b,
              "\"__metadata__\":{\"format\":\"pt\",\"vision_heads\":\"%d\","
              "\"text_heads\":\"%d\"},",
              cfg->vision_heads, cfg->text_heads);
  size_t off = 0;
  for (int i = 0; i < n; i++) {
    size_t nb = t[i].count * elem_size(cfg, &t[i]);
    sb_printf(&b, "%s\"%s\":{\"dtype\":\"%s\",\"shape\":[", i ? "," : "", t[i].name,
              t[i].is_i64 ? "I64" : clipgen_dtype_name(cfg->dtype));
    for (int d = 0; d < t[i].ndim; d++) sb_printf(&b, "%s%" PRId64, d ? "," : "", t[i].shape[d]);
    sb_printf(&b, "],\"data_offsets\":[%zu,%zu]}", off, off + nb);
    off += nb;
  }
  sb_printf(&b, "}");
  while (!b.err && b.len % 8) sb_printf(&b, " ");
  if (b.err) {
    free(b.s);
    return b.err;
  }
  *hdr = b.s;
  *hdr_len = b.len;
  *data_bytes = off;
  return 0;
}

/* The low nbytes of v, little-endian, at p. */
static void put_le(unsigned char *p, uint64_t v, int nbytes) {
  for (int i = 0; i < nbytes; i++) p[i] = (unsigned char)(v >> (8 * i));
}

/* Elements per chunk written at once. */
#define CHUNK 16384

/* Streams one tensor's data to fp through the scratch buffers vals [CHUNK] and bytes
 * [8 * CHUNK]. */
static int write_tensor(FILE *fp, const char *path, const clipgen_cfg *cfg,
                        const clipgen_tensor *t, float *vals, unsigned char *bytes) {
  const size_t es = elem_size(cfg, t);
  for (size_t off = 0; off < t->count; off += CHUNK) {
    size_t n = t->count - off < CHUNK ? t->count - off : CHUNK;
    if (t->is_i64) {
      for (size_t i = 0; i < n; i++) put_le(bytes + 8 * i, (uint64_t)(off + i), 8);
    } else {
      FG_TRY(clipgen_tensor_values(cfg, t, off, n, vals));
      for (size_t i = 0; i < n; i++) {
        uint32_t bits;
        memcpy(&bits, &vals[i], sizeof bits);
        if (cfg->dtype == CLIPGEN_F32)
          put_le(bytes + 4 * i, bits, 4);
        else if (cfg->dtype == CLIPGEN_BF16)
          put_le(bytes + 2 * i, bits >> 16, 2); /* exact: the value is on the bf16 grid */
        else
          put_le(bytes + 2 * i, fg_float_to_half(vals[i]), 2); /* exact as well */
      }
    }
    if (fwrite(bytes, es, n, fp) != n)
      return fg_fail(FG_EIO, "clipgen: writing %s: %s", path, strerror(errno));
  }
  return 0;
}

/* Writes the file (clipgen.h). */
int clipgen_write(const char *path, const clipgen_cfg *cfg, size_t *n_bytes) {
  if (!path) return fg_fail(FG_EINVAL, "clipgen_write: path is NULL");
  clipgen_tensor *t = NULL;
  int n = 0;
  FG_TRY(clipgen_tensors(cfg, &t, &n));
  char *hdr = NULL;
  size_t hdr_len = 0, data_bytes = 0;
  float *vals = malloc(CHUNK * sizeof *vals);
  unsigned char *bytes = malloc(8 * CHUNK);
  fg_atomic_file af = {0};
  int rc = (!vals || !bytes) ? fg_fail(FG_ENOMEM, "clipgen: out of memory") : 0;
  if (rc == 0) rc = make_header(cfg, t, n, &hdr, &hdr_len, &data_bytes);
  if (rc == 0) rc = fg_atomic_file_open(&af, path);
  if (rc == 0) {
    unsigned char len8[8];
    put_le(len8, hdr_len, 8);
    if (fwrite(len8, 1, 8, af.fp) != 8 || fwrite(hdr, 1, hdr_len, af.fp) != hdr_len)
      rc = fg_fail(FG_EIO, "clipgen: writing %s: %s", path, strerror(errno));
  }
  for (int i = 0; rc == 0 && i < n; i++) rc = write_tensor(af.fp, path, cfg, &t[i], vals, bytes);
  if (rc == 0)
    rc = fg_atomic_file_commit(&af);
  else
    fg_atomic_file_abort(&af);
  if (rc == 0 && n_bytes) *n_bytes = 8 + hdr_len + data_bytes;
  free(hdr);
  free(vals);
  free(bytes);
  free(t);
  return rc;
}

/* FNV-1a 64 of a file (clipgen.h). */
int clipgen_file_fnv1a64(const char *path, uint64_t *out) {
  FILE *fp = fopen(path, "rb");
  if (!fp)
    return fg_fail(errno == ENOENT ? FG_ENOENT : FG_EIO, "cannot open %s: %s", path,
                   strerror(errno));
  unsigned char buf[65536];
  uint64_t h = CLIPGEN_FNV1A64_INIT;
  size_t k;
  while ((k = fread(buf, 1, sizeof buf, fp)) > 0) h = clipgen_fnv1a64(h, buf, k);
  int bad = ferror(fp);
  fclose(fp);
  if (bad) return fg_fail(FG_EIO, "reading %s failed", path);
  *out = h;
  return 0;
}
