/* CLIP image and text encoders over weights mapped from a safetensors file (see clip.h).
 *
 * Weights stay where the file maps them. A float32 matrix that is 4-byte aligned is handed
 * to SGEMM in place; an F16 or BF16 one (or a misaligned F32 one) is converted into a
 * per-call scratch buffer just before its product, so memory stays near the file's size
 * plus one matrix and the activations. The small vectors (LayerNorm, biases, class token)
 * are converted once at load.
 *
 * Every call processes a batch layer by layer: the linear layers of all n inputs are one
 * SGEMM with n * T rows (which also converts each matrix once per batch), attention runs per
 * (input, head) on one thread each. */
#include "clip/clip.h"

#include <cblas.h>
#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core/blas.h"
#include "core/error.h"
#include "core/threads.h"
#include "io/safetensors.h"

#define LN_EPS 1e-5f
#define MAX_LAYERS 128
/* Tokens of one image (patches + class): a 224-px short side at patch 16 with an aspect of
 * up to 20:1 stays within this; attention holds T x T scores per running head. */
#define MAX_TOKENS 4097

/* ---- weights ---------------------------------------------------------------------------- */

/* A matrix [rows][cols] (row-major) as stored: direct when it is float32 and aligned. */
typedef struct mat {
  fg_st_tensor t;
  size_t rows, cols;
  const float *direct;
} mat;

/* One transformer block. The query/key/value projection is 1 piece (OpenAI's in_proj,
 * [3w][w]) or 3 (Hugging Face's q, k, v, [w][w] each). vec holds the small vectors. */
typedef struct block {
  mat qkv[3];
  int n_qkv;
  mat out, fc, pr; /* [w][w] [4w][w] [w][4w] */
  const float *ln1_w, *ln1_b, *qkv_b, *out_b, *ln2_w, *ln2_b, *fc_b, *pr_b;
} block;

typedef struct tower {
  int width, layers, heads;
  block blk[MAX_LAYERS];
} tower;

struct fg_clip {
  fg_st *st;
  fg_clip_info info;
  int threads;
  tower vis, txt;
  mat conv;     /* [w][3 p p] */
  mat vpos;     /* [n n + 1][w] */
  mat vproj;    /* OpenAI [w][E]; Hugging Face [E][w] */
  mat tok;      /* [vocab][tw] */
  mat tpos;     /* [ctx][tw] */
  mat tproj;    /* OpenAI [tw][E]; Hugging Face [E][tw] */
  const float *cls, *lnpre_w, *lnpre_b, *lnpost_w, *lnpost_b, *lnf_w, *lnf_b;
  float *vec; /* owns the small vectors above and the blocks' */
  size_t scratch_floats; /* the largest matrix converted at run time */
};

/* ---- tensor lookup, in either naming scheme --------------------------------------------- */

/* name = pattern with its "%d" (if any) replaced by the block number. */
static void tensor_name(char *name, size_t size, const char *pattern, int block_no) {
  if (!pattern) { /* the name tables hold NULL where one naming has no such tensor */
    name[0] = '\0';
    return;
  }
  const char *d = strstr(pattern, "%d");
  if (!d) {
    snprintf(name, size, "%s", pattern);
    return;
  }
  snprintf(name, size, "%.*s%d%s", (int)(d - pattern), pattern, block_no, d + 2);
}

/* Finds the tensor named by pattern fmt (with the block number where it has %d) and
 * checks that it holds floats of the expected shape: rows x cols for a matrix (cols 0: a
 * vector of rows). */
static int find_tensor(const fg_clip *c, const char *fmt, int block_no, fg_st_tensor *t) {
  char name[256];
  tensor_name(name, sizeof name, fmt, block_no);
  const int rc = fg_st_find(c->st, name, t);
  if (rc == FG_ENOENT)
    return fg_fail(FG_EFORMAT, "not a complete CLIP: the file has no tensor %s (OpenAI or Hugging "
                   "Face CLIPModel tensor names are expected)", name);
  if (rc != 0) return rc;
  if (t->dtype != FG_ST_F32 && t->dtype != FG_ST_F16 && t->dtype != FG_ST_BF16)
    return fg_fail(FG_EFORMAT, "tensor %s is %s; CLIP weights must be F32, F16 or BF16", name,
                   fg_st_dtype_name(t->dtype));
  return 0;
}

static int check_count(const fg_st_tensor *t, size_t want, const char *shape) {
  if (t->count != want)
    return fg_fail(FG_EFORMAT, "tensor %s has %zu values; the model needs %s = %zu", t->name,
                   t->count, shape, want);
  return 0;
}

static int mat_find(const fg_clip *c, const char *fmt, int block_no, size_t rows, size_t cols,
                    mat *m) {
  FG_TRY(find_tensor(c, fmt, block_no, &m->t));
  char shape[64];
  snprintf(shape, sizeof shape, "[%zu, %zu]", rows, cols);
  FG_TRY(check_count(&m->t, rows * cols, shape));
  m->rows = rows;
  m->cols = cols;
  m->direct = m->t.dtype == FG_ST_F32 && ((uintptr_t)m->t.data % sizeof(float)) == 0
                  ? (const float *)m->t.data
                  : NULL;
  return 0;
}

/* The matrix as float32: in place, or converted into scratch. */
static const float *mat_get(const mat *m, float *scratch) {
  if (m->direct) return m->direct;
  /* The shape and dtype were checked at load, so the conversion cannot fail. */
  fg_st_read_f32(&m->t, scratch, m->rows * m->cols);
  return scratch;
}

/* Converts a vector of n floats into *dst and advances it. */
static int vec_read(const fg_clip *c, const char *fmt, int block_no, size_t n, float **dst,
                    const float **out) {
  fg_st_tensor t;
  FG_TRY(find_tensor(c, fmt, block_no, &t));
  char shape[32];
  snprintf(shape, sizeof shape, "[%zu]", n);
  FG_TRY(check_count(&t, n, shape));
  FG_TRY(fg_st_read_f32(&t, *dst, n));
  *out = *dst;
  *dst += n;
  return 0;
}

/* ---- loading ---------------------------------------------------------------------------- */

typedef struct names {
  const char *ln1_w, *ln1_b, *out_w, *out_b, *ln2_w, *ln2_b, *fc_w, *fc_b, *pr_w, *pr_b;
  const char *in_w, *in_b;          /* OpenAI */
  const char *q_w, *k_w, *v_w;      /* Hugging Face */
  const char *q_b, *k_b, *v_b;
} names;

static const names OPENAI_VIS = {
    "visual.transformer.resblocks.%d.ln_1.weight", "visual.transformer.resblocks.%d.ln_1.bias",
    "visual.transformer.resblocks.%d.attn.out_proj.weight",
    "visual.transformer.resblocks.%d.attn.out_proj.bias",
    "visual.transformer.resblocks.%d.ln_2.weight", "visual.transformer.resblocks.%d.ln_2.bias",
    "visual.transformer.resblocks.%d.mlp.c_fc.weight",
    "visual.transformer.resblocks.%d.mlp.c_fc.bias",
    "visual.transformer.resblocks.%d.mlp.c_proj.weight",
    "visual.transformer.resblocks.%d.mlp.c_proj.bias",
    "visual.transformer.resblocks.%d.attn.in_proj_weight",
    "visual.transformer.resblocks.%d.attn.in_proj_bias", NULL, NULL, NULL, NULL, NULL, NULL};
static const names OPENAI_TXT = {
    "transformer.resblocks.%d.ln_1.weight", "transformer.resblocks.%d.ln_1.bias",
    "transformer.resblocks.%d.attn.out_proj.weight", "transformer.resblocks.%d.attn.out_proj.bias",
    "transformer.resblocks.%d.ln_2.weight", "transformer.resblocks.%d.ln_2.bias",
    "transformer.resblocks.%d.mlp.c_fc.weight", "transformer.resblocks.%d.mlp.c_fc.bias",
    "transformer.resblocks.%d.mlp.c_proj.weight", "transformer.resblocks.%d.mlp.c_proj.bias",
    "transformer.resblocks.%d.attn.in_proj_weight", "transformer.resblocks.%d.attn.in_proj_bias",
    NULL, NULL, NULL, NULL, NULL, NULL};
#define HF_BLOCK(tower)                                                                      \
  {                                                                                          \
    tower ".encoder.layers.%d.layer_norm1.weight", tower ".encoder.layers.%d.layer_norm1.bias", \
        tower ".encoder.layers.%d.self_attn.out_proj.weight",                                \
        tower ".encoder.layers.%d.self_attn.out_proj.bias",                                  \
        tower ".encoder.layers.%d.layer_norm2.weight",                                       \
        tower ".encoder.layers.%d.layer_norm2.bias", tower ".encoder.layers.%d.mlp.fc1.weight", \
        tower ".encoder.layers.%d.mlp.fc1.bias", tower ".encoder.layers.%d.mlp.fc2.weight",  \
        tower ".encoder.layers.%d.mlp.fc2.bias", NULL, NULL,                                 \
        tower ".encoder.layers.%d.self_attn.q_proj.weight",                                  \
        tower ".encoder.layers.%d.self_attn.k_proj.weight",                                  \
        tower ".encoder.layers.%d.self_attn.v_proj.weight",                                  \
        tower ".encoder.layers.%d.self_attn.q_proj.bias",                                    \
        tower ".encoder.layers.%d.self_attn.k_proj.bias",                                    \
        tower ".encoder.layers.%d.self_attn.v_proj.bias"                                     \
  }
static const names HF_VIS = HF_BLOCK("vision_model");
static const names HF_TXT = HF_BLOCK("text_model");

/* Floats of small vectors one block needs. */
static size_t block_vec_floats(int w) { return 13 * (size_t)w; }

static int block_find(fg_clip *c, const names *nm, int l, int w, block *b, float **vec) {
  const size_t W = (size_t)w;
  float *qkv_b = *vec;
  if (nm->in_w) {
    b->n_qkv = 1;
    FG_TRY(mat_find(c, nm->in_w, l, 3 * W, W, &b->qkv[0]));
    const float *unused;
    FG_TRY(vec_read(c, nm->in_b, l, 3 * W, vec, &unused));
  } else {
    b->n_qkv = 3;
    const char *wn[3] = {nm->q_w, nm->k_w, nm->v_w}, *bn[3] = {nm->q_b, nm->k_b, nm->v_b};
    for (int k = 0; k < 3; k++) {
      const float *unused;
      FG_TRY(mat_find(c, wn[k], l, W, W, &b->qkv[k]));
      FG_TRY(vec_read(c, bn[k], l, W, vec, &unused));
    }
  }
  b->qkv_b = qkv_b;
  FG_TRY(vec_read(c, nm->ln1_w, l, W, vec, &b->ln1_w));
  FG_TRY(vec_read(c, nm->ln1_b, l, W, vec, &b->ln1_b));
  FG_TRY(mat_find(c, nm->out_w, l, W, W, &b->out));
  FG_TRY(vec_read(c, nm->out_b, l, W, vec, &b->out_b));
  FG_TRY(vec_read(c, nm->ln2_w, l, W, vec, &b->ln2_w));
  FG_TRY(vec_read(c, nm->ln2_b, l, W, vec, &b->ln2_b));
  FG_TRY(mat_find(c, nm->fc_w, l, 4 * W, W, &b->fc));
  FG_TRY(vec_read(c, nm->fc_b, l, 4 * W, vec, &b->fc_b));
  FG_TRY(mat_find(c, nm->pr_w, l, W, 4 * W, &b->pr));
  FG_TRY(vec_read(c, nm->pr_b, l, W, vec, &b->pr_b));
  return 0;
}

/* Blocks are numbered from 0 without gaps; the count is where the first ln_1 is missing. */
static int count_layers(const fg_clip *c, const char *ln1_fmt) {
  int n = 0;
  fg_st_tensor t;
  char name[256];
  for (;;) {
    tensor_name(name, sizeof name, ln1_fmt, n);
    if (n >= MAX_LAYERS || fg_st_find(c->st, name, &t) != 0) break;
    n++;
  }
  fg_error_clear();
  return n;
}

static int heads_from(const fg_clip *c, const char *key, int width, int *heads) {
  const char *v = fg_st_metadata(c->st, key);
  if (!v) {
    *heads = width >= 64 ? width / 64 : 1;
    if (width % *heads)
      return fg_fail(FG_EFORMAT, "width %d is not a multiple of 64; set the head count in the "
                     "file's __metadata__ key \"%s\"", width, key);
    return 0;
  }
  char *end;
  const long h = strtol(v, &end, 10);
  if (end == v || *end || h < 1 || h > width || width % h)
    return fg_fail(FG_EFORMAT, "__metadata__ \"%s\" = \"%s\" must be a head count dividing the "
                   "width %d", key, v, width);
  *heads = (int)h;
  return 0;
}

static size_t max_size(size_t a, size_t b) { return a > b ? a : b; }

/* Sizes from shapes, then every tensor found and checked. */
static int model_resolve(fg_clip *c) {
  fg_clip_info *in = &c->info;
  fg_st_tensor t;
  in->naming = fg_st_find(c->st, "visual.conv1.weight", &t) == 0 ? 0 : 1;
  fg_error_clear();
  const int hf = in->naming;
  FG_TRY(find_tensor(c, hf ? "vision_model.embeddings.patch_embedding.weight"
                           : "visual.conv1.weight", 0, &t));
  if (t.ndim != 4 || t.shape[1] != 3 || t.shape[2] != t.shape[3] || t.shape[2] < 1 ||
      t.shape[0] < 1)
    return fg_fail(FG_EFORMAT, "tensor %s must be [width, 3, patch, patch]", t.name);
  in->vision_width = (int)t.shape[0];
  in->patch_size = (int)t.shape[2];
  FG_TRY(find_tensor(c, hf ? "vision_model.embeddings.position_embedding.weight"
                           : "visual.positional_embedding", 0, &t));
  const int64_t n = t.ndim == 2 ? (int64_t)llround(sqrt((double)(t.shape[0] - 1))) : 0;
  if (t.ndim != 2 || n < 1 || n * n + 1 != t.shape[0] || t.shape[1] != in->vision_width)
    return fg_fail(FG_EFORMAT, "tensor %s must be [grid * grid + 1, %d]", t.name,
                   in->vision_width);
  in->image_size = (int)n * in->patch_size;
  FG_TRY(find_tensor(c, hf ? "visual_projection.weight" : "visual.proj", 0, &t));
  if (t.ndim != 2) return fg_fail(FG_EFORMAT, "tensor %s must be 2-D", t.name);
  in->embed_dim = (int)(hf ? t.shape[0] : t.shape[1]);
  FG_TRY(find_tensor(c, hf ? "text_model.embeddings.token_embedding.weight"
                           : "token_embedding.weight", 0, &t));
  if (t.ndim != 2 || t.shape[0] < 1 || t.shape[1] < 1)
    return fg_fail(FG_EFORMAT, "tensor %s must be [vocab, width]", t.name);
  in->vocab_size = (int)t.shape[0];
  in->text_width = (int)t.shape[1];
  FG_TRY(find_tensor(c, hf ? "text_model.embeddings.position_embedding.weight"
                           : "positional_embedding", 0, &t));
  if (t.ndim != 2 || t.shape[0] < 2 || t.shape[1] != in->text_width)
    return fg_fail(FG_EFORMAT, "tensor %s must be [context, %d]", t.name, in->text_width);
  in->context_length = (int)t.shape[0];

  const names *vn = hf ? &HF_VIS : &OPENAI_VIS, *tn = hf ? &HF_TXT : &OPENAI_TXT;
  in->vision_layers = count_layers(c, vn->ln1_w);
  in->text_layers = count_layers(c, tn->ln1_w);
  if (in->vision_layers < 1 || in->text_layers < 1)
    return fg_fail(FG_EFORMAT, "no transformer blocks found (%d vision, %d text); is this a "
                   "CLIP file with OpenAI or Hugging Face names?", in->vision_layers,
                   in->text_layers);
  FG_TRY(heads_from(c, "vision_heads", in->vision_width, &in->vision_heads));
  FG_TRY(heads_from(c, "text_heads", in->text_width, &in->text_heads));

  const size_t vw = (size_t)in->vision_width, tw = (size_t)in->text_width;
  const size_t E = (size_t)in->embed_dim, p = (size_t)in->patch_size;
  const size_t floats = 6 * vw + 2 * tw + block_vec_floats(in->vision_width) * in->vision_layers +
                        block_vec_floats(in->text_width) * in->text_layers;
  c->vec = malloc(floats * sizeof(float));
  if (!c->vec) return fg_fail(FG_ENOMEM, "cannot allocate the model's vectors");
  float *v = c->vec;
  c->vis = (tower){.width = in->vision_width, .layers = in->vision_layers,
                   .heads = in->vision_heads};
  c->txt = (tower){.width = in->text_width, .layers = in->text_layers, .heads = in->text_heads};
  for (int l = 0; l < in->vision_layers; l++)
    FG_TRY(block_find(c, vn, l, in->vision_width, &c->vis.blk[l], &v));
  for (int l = 0; l < in->text_layers; l++)
    FG_TRY(block_find(c, tn, l, in->text_width, &c->txt.blk[l], &v));

  FG_TRY(mat_find(c, hf ? "vision_model.embeddings.patch_embedding.weight" : "visual.conv1.weight",
                  0, vw, 3 * p * p, &c->conv));
  FG_TRY(mat_find(c, hf ? "vision_model.embeddings.position_embedding.weight"
                        : "visual.positional_embedding", 0, (size_t)(n * n + 1), vw, &c->vpos));
  FG_TRY(mat_find(c, hf ? "visual_projection.weight" : "visual.proj", 0, hf ? E : vw,
                  hf ? vw : E, &c->vproj));
  FG_TRY(mat_find(c, hf ? "text_model.embeddings.token_embedding.weight"
                        : "token_embedding.weight", 0, (size_t)in->vocab_size, tw, &c->tok));
  FG_TRY(mat_find(c, hf ? "text_model.embeddings.position_embedding.weight"
                        : "positional_embedding", 0, (size_t)in->context_length, tw, &c->tpos));
  FG_TRY(mat_find(c, hf ? "text_projection.weight" : "text_projection", 0, hf ? E : tw,
                  hf ? tw : E, &c->tproj));
  FG_TRY(vec_read(c, hf ? "vision_model.embeddings.class_embedding" : "visual.class_embedding",
                  0, vw, &v, &c->cls));
  FG_TRY(vec_read(c, hf ? "vision_model.pre_layrnorm.weight" : "visual.ln_pre.weight", 0, vw, &v,
                  &c->lnpre_w));
  FG_TRY(vec_read(c, hf ? "vision_model.pre_layrnorm.bias" : "visual.ln_pre.bias", 0, vw, &v,
                  &c->lnpre_b));
  FG_TRY(vec_read(c, hf ? "vision_model.post_layernorm.weight" : "visual.ln_post.weight", 0, vw,
                  &v, &c->lnpost_w));
  FG_TRY(vec_read(c, hf ? "vision_model.post_layernorm.bias" : "visual.ln_post.bias", 0, vw, &v,
                  &c->lnpost_b));
  FG_TRY(vec_read(c, hf ? "text_model.final_layer_norm.weight" : "ln_final.weight", 0, tw, &v,
                  &c->lnf_w));
  FG_TRY(vec_read(c, hf ? "text_model.final_layer_norm.bias" : "ln_final.bias", 0, tw, &v,
                  &c->lnf_b));

  /* The largest matrix that may need converting at run time (the token table is read by
   * rows), and what the file's tensors weigh. */
  const mat *singles[] = {&c->conv, &c->vpos, &c->vproj, &c->tpos, &c->tproj};
  size_t scratch = 4 * max_size(vw * vw, tw * tw), bytes = 0;
  for (size_t i = 0; i < sizeof singles / sizeof *singles; i++)
    scratch = max_size(scratch, singles[i]->rows * singles[i]->cols);
  for (int i = 0; i < fg_st_count(c->st); i++)
    if (fg_st_tensor_at(c->st, i, &t) == 0) bytes += t.nbytes;
  in->weights_bytes = bytes;
  c->scratch_floats = scratch;
  in->dtype = fg_st_dtype_name(c->vis.blk[0].fc.t.dtype);
  return 0;
}

/* SHA-256 of every byte of the file: a weights file that changes in any byte changes its
 * fingerprint, and nobody can make two files share one (cached features are keyed by it), as
 * they could with a checksum. It equals `sha256sum weights.safetensors`, so a user can tell
 * which file a daemon runs. */
static void fingerprint(const fg_st *st, char out[FG_SHA256_HEX + 1]) {
  fg_span whole;
  fg_st_bytes(st, &whole.data, &whole.len);
  fg_sha256_hex(&whole, 1, out);
}

int fg_clip_load(fg_clip **out, const char *path) {
  *out = NULL;
  fg_clip *c = calloc(1, sizeof *c);
  if (!c) return fg_fail(FG_ENOMEM, "cannot allocate a CLIP model");
  int rc = fg_st_open(&c->st, path);
  if (rc == 0) rc = model_resolve(c);
  if (rc != 0) {
    fg_clip_free(c);
    return rc;
  }
  fingerprint(c->st, c->info.fingerprint);
  *out = c;
  return 0;
}

void fg_clip_free(fg_clip *c) {
  if (!c) return;
  fg_st_close(c->st);
  free(c->vec);
  free(c);
}

const fg_clip_info *fg_clip_get_info(const fg_clip *c) { return &c->info; }

void fg_clip_set_threads(fg_clip *c, int n_threads) { c->threads = n_threads > 0 ? n_threads : 0; }

/* ---- kernels ---------------------------------------------------------------------------- */

/* The element-wise kernels below are compiled for AVX-512, AVX2 and the baseline, chosen at
 * load time by the CPU (GCC's function multi-versioning): at the baseline's 4 lanes, the
 * exponentials of QuickGELU alone took a tenth of a ViT's time. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define FG_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define FG_CLONES
#endif

/* e^x, accurate to a few ulp over the float range: x = k ln2 + r with |r| <= ln2/2 (k by
 * the add-and-subtract rounding trick), a degree-6 polynomial for e^r, 2^k through the
 * exponent bits. Plain arithmetic only, so that the loops calling it vectorise. */
static inline float fast_expf(float x) {
  x = x < -87.0f ? -87.0f : (x > 88.0f ? 88.0f : x);
  const float k = (x * 1.44269504f + 12582912.0f) - 12582912.0f;
  const float r = x - k * 0.693145752f - k * 1.42860677e-6f;
  float p = 1.38888889e-3f;
  p = p * r + 8.33333333e-3f;
  p = p * r + 4.16666667e-2f;
  p = p * r + 1.66666667e-1f;
  p = p * r + 0.5f;
  p = p * r + 1.0f;
  p = p * r + 1.0f;
  union { float f; int32_t i; } s = {.i = ((int32_t)k + 127) * (1 << 23)};
  return p * s.f;
}

/* QuickGELU of n values in place: x * sigmoid(1.702 x). */
FG_CLONES static void quick_gelu_span(float *x, size_t n) {
  for (size_t i = 0; i < n; i++) x[i] = x[i] / (1.0f + fast_expf(-1.702f * x[i]));
}

/* Softmax of r over its first n entries; entries n..total are zeroed (the causal mask). */
FG_CLONES static void softmax_row(float *r, int n, int total) {
  float mx = r[0];
  for (int j = 1; j < n; j++) mx = r[j] > mx ? r[j] : mx;
  float sum = 0.0f;
  for (int j = 0; j < n; j++) {
    r[j] = fast_expf(r[j] - mx);
    sum += r[j];
  }
  const float inv = 1.0f / sum;
  for (int j = 0; j < n; j++) r[j] *= inv;
  for (int j = n; j < total; j++) r[j] = 0.0f;
}

/* out [T][w] = LayerNorm(x [T][w]) * g + b (out may be x). */
static void layer_norm(const float *x, int T, int w, const float *g, const float *b, float *out,
                       int nt) {
#pragma omp parallel for schedule(static) num_threads(nt) if (T >= 64)
  for (int t = 0; t < T; t++) {
    const float *r = x + (size_t)t * w;
    float *o = out + (size_t)t * w;
    float mean = 0.0f, var = 0.0f;
    for (int i = 0; i < w; i++) mean += r[i];
    mean /= (float)w;
    for (int i = 0; i < w; i++) var += (r[i] - mean) * (r[i] - mean);
    var /= (float)w;
    const float inv = 1.0f / sqrtf(var + LN_EPS);
    for (int i = 0; i < w; i++) o[i] = (r[i] - mean) * inv * g[i] + b[i];
  }
}

/* C [M][ldc] (columns 0..N) = A [M][K] @ op(B) (+ bias [N]; with accumulate, C += instead
 * of =). op(B) = B^T for B [N][ldb] (trans_b) or B for B [K][ldb].
 *
 * All parallelism here is OpenMP's: each thread runs a single-threaded SGEMM on its own
 * slice of the N columns (a slice of the weight matrix, so no weights are packed twice).
 * Letting OpenBLAS's own threads run beside OpenMP's spinning ones costs a factor of two or
 * more on a machine with few cores. */
static void gemm(int M, int N, int K, const float *A, int lda, const float *B, int ldb,
                 int trans_b, const float *bias, float *C, int ldc, int accumulate, int nt) {
  const int chunk = 64;
  int parts = (N + chunk - 1) / chunk;
  if (parts > nt) parts = nt;
  if ((double)M * N * K < 4e6) parts = 1;
#pragma omp parallel num_threads(parts) if (parts > 1)
  {
    const int t = omp_get_thread_num(), P = omp_get_num_threads();
    /* Slices of whole chunks, as even as they can be. */
    const int chunks = (N + chunk - 1) / chunk;
    const int j0 = (int)((long)chunks * t / P) * chunk;
    int j1 = (int)((long)chunks * (t + 1) / P) * chunk;
    if (j1 > N) j1 = N;
    if (j1 > j0) {
      if (bias)
        for (int i = 0; i < M; i++) {
          float *r = C + (size_t)i * ldc;
          if (accumulate)
            for (int j = j0; j < j1; j++) r[j] += bias[j];
          else
            memcpy(r + j0, bias + j0, (size_t)(j1 - j0) * sizeof(float));
        }
      const float beta = bias || accumulate ? 1.0f : 0.0f;
      const float *Bs = trans_b ? B + (size_t)j0 * ldb : B + j0;
      cblas_sgemm(CblasRowMajor, CblasNoTrans, trans_b ? CblasTrans : CblasNoTrans, M, j1 - j0,
                  K, 1.0f, A, lda, Bs, ldb, beta, C + j0, ldc);
    }
  }
}

/* y [T][ldy] (columns 0..n) = x [T][k] @ W^T + bias, W [n][k]; with accumulate, y += ... */
static void linear(const float *x, int T, int k, const float *W, const float *bias, int n,
                   float *y, int ldy, int accumulate, int nt) {
  gemm(T, n, k, x, k, W, k, 1, bias, y, ldy, accumulate, nt);
}

/* QuickGELU in place over n values, in spans per thread. */
static void quick_gelu(float *x, size_t n, int nt) {
  const size_t span = 16384, spans = (n + span - 1) / span;
#pragma omp parallel for schedule(static) num_threads(nt)
  for (size_t k = 0; k < spans; k++)
    quick_gelu_span(x + k * span, k + 1 < spans ? span : n - k * span);
}

/* Softmax of each row of s [T][ld] over its first t + 1 entries when causal, else all T. */
static void softmax_rows(float *s, int T, int ld, int causal) {
  for (int t = 0; t < T; t++) softmax_row(s + (size_t)t * ld, causal ? t + 1 : T, T);
}

/* ---- one transformer block over a batch ------------------------------------------------- */

/* Activations of a batch of n sequences of T tokens, width w. */
typedef struct acts {
  float *h;      /* [n T][w]   LayerNorm output */
  float *qkv;    /* [n T][3w]  */
  float *att;    /* [n T][w]   attention output before out_proj */
  float *mlp;    /* [n T][4w]  */
  float *scores; /* [threads][T][T] */
  float *wbuf;   /* converted matrix scratch */
} acts;

static void acts_free(acts *a) {
  free(a->h), free(a->qkv), free(a->att), free(a->mlp), free(a->scores), free(a->wbuf);
  memset(a, 0, sizeof *a);
}

static int acts_alloc(acts *a, const fg_clip *c, int n, int T, int w, int nt) {
  const size_t rows = (size_t)n * T, W = (size_t)w;
  a->h = malloc(rows * W * sizeof(float));
  a->qkv = malloc(rows * 3 * W * sizeof(float));
  a->att = malloc(rows * W * sizeof(float));
  a->mlp = malloc(rows * 4 * W * sizeof(float));
  a->scores = malloc((size_t)nt * T * T * sizeof(float));
  a->wbuf = malloc(c->scratch_floats * sizeof(float));
  if (!a->h || !a->qkv || !a->att || !a->mlp || !a->scores || !a->wbuf) {
    acts_free(a);
    return fg_fail(FG_ENOMEM, "cannot allocate activations for %d x %d tokens", n, T);
  }
  return 0;
}

/* Multi-head attention of n sequences: att [n T][w] from qkv [n T][3w]; each (sequence,
 * head) pair runs on one thread. */
static void attention(acts *a, int n, int T, int w, int heads, int causal, int nt) {
  const int hd = w / heads;
  const float scale = 1.0f / sqrtf((float)hd);
#pragma omp parallel for schedule(dynamic) num_threads(nt)
  for (int job = 0; job < n * heads; job++) {
    const int q = job / heads, hh = job % heads;
    float *s = a->scores + (size_t)omp_get_thread_num() * T * T;
    const float *base = a->qkv + (size_t)q * T * 3 * w;
    const float *Q = base + hh * hd, *K = base + w + hh * hd, *V = base + 2 * w + hh * hd;
    /* s [T][T] = Q K^T / sqrt(hd); causal rows only need their first t + 1 columns, which
     * SGEMM computes anyway: the mask is applied by the softmax. */
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, T, T, hd, scale, Q, 3 * w, K, 3 * w,
                0.0f, s, T);
    softmax_rows(s, T, T, causal);
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, T, hd, T, 1.0f, s, T, V, 3 * w, 0.0f,
                a->att + (size_t)q * T * w + hh * hd, w);
  }
}

/* The query/key/value projections of h [rows][w] into qkv [rows][3w]. */
static void qkv_project(const block *b, acts *a, int rows, int w, int nt) {
  int col = 0;
  for (int k = 0; k < b->n_qkv; k++) {
    const mat *m = &b->qkv[k];
    linear(a->h, rows, w, mat_get(m, a->wbuf), b->qkv_b + col, (int)m->rows, a->qkv + col,
           3 * w, 0, nt);
    col += (int)m->rows;
  }
}

/* x [n T][w] += attn(ln_1 x); x += mlp(ln_2 x). */
static void block_forward(const block *b, float *x, int n, int T, int w, int heads, int causal,
                          acts *a, int nt) {
  const int rows = n * T;
  layer_norm(x, rows, w, b->ln1_w, b->ln1_b, a->h, nt);
  qkv_project(b, a, rows, w, nt);
  attention(a, n, T, w, heads, causal, nt);
  linear(a->att, rows, w, mat_get(&b->out, a->wbuf), b->out_b, w, x, w, 1, nt);
  layer_norm(x, rows, w, b->ln2_w, b->ln2_b, a->h, nt);
  linear(a->h, rows, w, mat_get(&b->fc, a->wbuf), b->fc_b, 4 * w, a->mlp, 4 * w, 0, nt);
  quick_gelu(a->mlp, (size_t)rows * 4 * w, nt);
  linear(a->mlp, rows, 4 * w, mat_get(&b->pr, a->wbuf), b->pr_b, w, x, w, 1, nt);
}

/* ---- image encoder ---------------------------------------------------------------------- */

/* PyTorch's bicubic convolution weights (A = -0.75) for a fraction t in [0, 1). */
static void cubic_weights(float t, float wt[4]) {
  const float A = -0.75f;
  float x = t + 1.0f;
  wt[0] = ((A * x - 5 * A) * x + 8 * A) * x - 4 * A;
  x = t;
  wt[1] = ((A + 2) * x - (A + 3)) * x * x + 1;
  x = 1.0f - t;
  wt[2] = ((A + 2) * x - (A + 3)) * x * x + 1;
  x = 2.0f - t;
  wt[3] = ((A * x - 5 * A) * x + 8 * A) * x - 4 * A;
}

/* out [hp][wp][w] = the patch part of the positional embedding, pos [g g][w], resampled as
 * F3RM does: F.interpolate(bicubic, align_corners=False, scale_factor=((hp + 0.1) / g,
 * (wp + 0.1) / g), recompute_scale_factor=False), i.e. source coordinate
 * (dst + 0.5) * g / (hp + 0.1) - 0.5, neighbours clamped at the borders. */
static void interp_pos(const float *pos, int g, int w, int hp, int wp, float *out) {
  for (int y = 0; y < hp; y++) {
    const float sy = (float)((y + 0.5) * g / (hp + 0.1) - 0.5);
    const int iy = (int)floorf(sy);
    float wy[4];
    cubic_weights(sy - (float)iy, wy);
    for (int x = 0; x < wp; x++) {
      const float sx = (float)((x + 0.5) * g / (wp + 0.1) - 0.5);
      const int ix = (int)floorf(sx);
      float wx[4];
      cubic_weights(sx - (float)ix, wx);
      float *o = out + ((size_t)y * wp + x) * w;
      memset(o, 0, (size_t)w * sizeof(float));
      for (int a = 0; a < 4; a++) {
        const int yy = iy - 1 + a < 0 ? 0 : (iy - 1 + a >= g ? g - 1 : iy - 1 + a);
        for (int bb = 0; bb < 4; bb++) {
          const int xx = ix - 1 + bb < 0 ? 0 : (ix - 1 + bb >= g ? g - 1 : ix - 1 + bb);
          const float k = wy[a] * wx[bb];
          const float *p = pos + ((size_t)yy * g + xx) * w;
          for (int i = 0; i < w; i++) o[i] += k * p[i];
        }
      }
    }
  }
}

static int threads_of(const fg_clip *c) { return fg_threads(c->threads); }

int fg_clip_dense_grid(const fg_clip *c, int H, int W, int *hp, int *wp) {
  const int p = c->info.patch_size;
  if (H < p || W < p)
    return fg_fail(FG_EINVAL, "an image of %dx%d pixels holds no whole %d-pixel patch", W, H, p);
  if ((int64_t)(H / p) * (W / p) + 1 > MAX_TOKENS)
    return fg_fail(FG_ERANGE, "an image of %dx%d pixels is %d patches; at most %d fit", W, H,
                   (H / p) * (W / p), MAX_TOKENS - 1);
  *hp = H / p;
  *wp = W / p;
  return 0;
}

/* The vision tower on n images x [n][3][H][W]: dense (out [n][hp wp][E]) or pooled
 * (out [n][E]). */
static int vision(fg_clip *c, const float *x, int n, int H, int W, int dense, float *out) {
  const fg_clip_info *in = &c->info;
  const int p = in->patch_size, w = in->vision_width, E = in->embed_dim;
  const int g = in->image_size / p, K = 3 * p * p;
  int hp, wp;
  FG_TRY(fg_clip_dense_grid(c, H, W, &hp, &wp));
  const int np = hp * wp, T = np + 1, rows = n * T, nt = threads_of(c);
  const int prev = fg_blas_single_begin();
  acts a = {0};
  float *xs = malloc((size_t)rows * w * sizeof(float));
  float *cols = malloc((size_t)n * np * K * sizeof(float));
  float *pos = malloc((size_t)T * w * sizeof(float));
  int rc = xs && cols && pos ? acts_alloc(&a, c, n, T, w, nt)
                             : fg_fail(FG_ENOMEM, "cannot allocate activations for %d images", n);
  if (rc != 0) goto out;

  /* Positional embedding for this grid: [class; patches]. */
  const float *vpos = mat_get(&c->vpos, a.wbuf);
  memcpy(pos, vpos, (size_t)w * sizeof(float));
  if (hp == g && wp == g)
    memcpy(pos + w, vpos + w, (size_t)np * w * sizeof(float));
  else
    interp_pos(vpos + w, g, w, hp, wp, pos + w);

  /* Patch embedding: one GEMM over im2col rows ordered (channel, ky, kx) as conv1's weight. */
#pragma omp parallel for schedule(static) num_threads(nt)
  for (int r = 0; r < n * np; r++) {
    const int img = r / np, py = (r % np) / wp, px = r % wp;
    const float *src = x + (size_t)img * 3 * H * W;
    float *dst = cols + (size_t)r * K;
    for (int ch = 0; ch < 3; ch++)
      for (int ky = 0; ky < p; ky++)
        memcpy(dst + (ch * p + ky) * p, src + ((size_t)ch * H + py * p + ky) * W + px * p,
               (size_t)p * sizeof(float));
  }
  for (int img = 0; img < n; img++) {
    float *t0 = xs + (size_t)img * T * w;
    for (int i = 0; i < w; i++) t0[i] = c->cls[i] + pos[i];
    for (int r = 1; r < T; r++) memcpy(t0 + (size_t)r * w, pos + (size_t)r * w, w * sizeof(float));
  }
  const float *conv = mat_get(&c->conv, a.wbuf);
  for (int img = 0; img < n; img++)
    gemm(np, w, K, cols + (size_t)img * np * K, K, conv, K, 1, NULL,
         xs + ((size_t)img * T + 1) * w, w, 1, nt);
  layer_norm(xs, rows, w, c->lnpre_w, c->lnpre_b, xs, nt);

  const int L = c->vis.layers;
  for (int l = 0; l < L - (dense ? 1 : 0); l++)
    block_forward(&c->vis.blk[l], xs, n, T, w, c->vis.heads, 0, &a, nt);

  if (dense) {
    /* MaskCLIP: the last block's value path, out_proj(v_proj(ln_1 x)), for every token (the
     * class token's row is computed and dropped). */
    const block *b = &c->vis.blk[L - 1];
    layer_norm(xs, rows, w, b->ln1_w, b->ln1_b, a.h, nt);
    const mat *vm = b->n_qkv == 1 ? &b->qkv[0] : &b->qkv[2];
    const float *Wv = mat_get(vm, a.wbuf) + (b->n_qkv == 1 ? 2 * (size_t)w * w : 0);
    linear(a.h, rows, w, Wv, b->qkv_b + 2 * w, w, a.att, w, 0, nt);
    linear(a.att, rows, w, mat_get(&b->out, a.wbuf), b->out_b, w, a.h, w, 0, nt);
    layer_norm(a.h, rows, w, c->lnpost_w, c->lnpost_b, a.h, nt);
  } else {
    for (int img = 0; img < n; img++)
      memcpy(a.h + (size_t)img * w, xs + (size_t)img * T * w, (size_t)w * sizeof(float));
    layer_norm(a.h, n, w, c->lnpost_w, c->lnpost_b, a.h, nt);
  }
  /* Projection: OpenAI's proj is [w][E] (x @ proj); Hugging Face's is [E][w] (x @ W^T). */
  const float *proj = mat_get(&c->vproj, a.wbuf);
  const int hf = in->naming, ldp = hf ? w : E;
  if (dense)
    for (int img = 0; img < n; img++)
      gemm(np, E, w, a.h + ((size_t)img * T + 1) * w, w, proj, ldp, hf, NULL,
           out + (size_t)img * np * E, E, 0, nt);
  else
    gemm(n, E, w, a.h, w, proj, ldp, hf, NULL, out, E, 0, nt);
out:
  acts_free(&a);
  free(xs), free(cols), free(pos);
  fg_blas_single_end(prev);
  return rc;
}

/* Inputs run in batches of at most this many tokens (rows of every activation), which bounds
 * the activations' memory (about 40 KB per token at width 768) whatever n a caller passes;
 * the weights are converted once per batch. */
#define BATCH_TOKENS 2048

/* The number of inputs of T tokens each that one batch takes. */
static int batch_of(int T) { return T >= BATCH_TOKENS ? 1 : BATCH_TOKENS / T; }

int fg_clip_image_dense(fg_clip *c, const float *x, int n, int H, int W, float *out) {
  int hp, wp;
  FG_TRY(fg_clip_dense_grid(c, H, W, &hp, &wp));
  if (n < 1) return fg_fail(FG_EINVAL, "no images given");
  const int b = batch_of(hp * wp + 1);
  for (int i = 0; i < n; i += b)
    FG_TRY(vision(c, x + (size_t)i * 3 * H * W, n - i < b ? n - i : b, H, W, 1,
                  out + (size_t)i * hp * wp * c->info.embed_dim));
  return 0;
}

int fg_clip_image_pooled(fg_clip *c, const float *x, int n, float *out) {
  const int S = c->info.image_size, p = c->info.patch_size;
  if (n < 1) return fg_fail(FG_EINVAL, "no images given");
  const int b = batch_of((S / p) * (S / p) + 1);
  for (int i = 0; i < n; i += b)
    FG_TRY(vision(c, x + (size_t)i * 3 * S * S, n - i < b ? n - i : b, S, S, 0,
                  out + (size_t)i * c->info.embed_dim));
  return 0;
}

/* ---- text encoder ----------------------------------------------------------------------- */

/* Text embeddings of a batch of n sequences whose ids were checked. */
static int text_batch(fg_clip *c, const int32_t *ids, int n, float *out) {
  const fg_clip_info *in = &c->info;
  const int ctx = in->context_length, w = in->text_width, E = in->embed_dim;
  /* The end-of-text row of each sequence (OpenAI: argmax of the ids, the first maximum). With
   * causal attention no token sees a later one, so only the first max(eot) + 1 positions
   * affect the result: the batch runs on that many. */
  int *eot = malloc((size_t)n * sizeof(int));
  if (!eot) return fg_fail(FG_ENOMEM, "out of memory");
  int T = 1;
  for (int q = 0; q < n; q++) {
    const int32_t *r = ids + (size_t)q * ctx;
    eot[q] = 0;
    for (int t = 0; t < ctx; t++)
      if (r[t] > r[eot[q]]) eot[q] = t;
    if (eot[q] + 1 > T) T = eot[q] + 1;
  }
  const int rows = n * T, nt = threads_of(c);
  const int prev = fg_blas_single_begin();
  acts a = {0};
  float *xs = malloc((size_t)rows * w * sizeof(float));
  int rc = xs ? acts_alloc(&a, c, n, T, w, nt) : fg_fail(FG_ENOMEM, "out of memory");
  if (rc != 0) goto out;
  /* Token rows are read one at a time: the table is vocab x w and most of it is unused. */
  const float *tpos = mat_get(&c->tpos, a.wbuf);
  for (int q = 0; q < n && rc == 0; q++)
    for (int t = 0; t < T && rc == 0; t++) {
      float *r = xs + ((size_t)q * T + t) * w;
      rc = fg_st_read_rows_f32(&c->tok.t, (size_t)ids[(size_t)q * ctx + t], 1, r);
      for (int k = 0; k < w; k++) r[k] += tpos[(size_t)t * w + k];
    }
  if (rc != 0) goto out;
  for (int l = 0; l < c->txt.layers; l++)
    block_forward(&c->txt.blk[l], xs, n, T, w, c->txt.heads, 1, &a, nt);
  for (int q = 0; q < n; q++)
    memcpy(a.h + (size_t)q * w, xs + ((size_t)q * T + eot[q]) * w, (size_t)w * sizeof(float));
  layer_norm(a.h, n, w, c->lnf_w, c->lnf_b, a.h, nt);
  const float *proj = mat_get(&c->tproj, a.wbuf);
  gemm(n, E, w, a.h, w, proj, in->naming ? w : E, in->naming, NULL, out, E, 0, nt);
out:
  acts_free(&a);
  free(xs);
  free(eot);
  fg_blas_single_end(prev);
  return rc;
}

int fg_clip_text(fg_clip *c, const int32_t *ids, int n, float *out) {
  if (n < 1) return fg_fail(FG_EINVAL, "no texts given");
  const int ctx = c->info.context_length, V = c->info.vocab_size, b = batch_of(ctx);
  for (size_t k = 0; k < (size_t)n * ctx; k++)
    if (ids[k] < 0 || ids[k] >= V)
      return fg_fail(FG_EINVAL, "token id %d at position %d of text %d is outside the "
                     "vocabulary (0..%d)", ids[k], (int)(k % ctx), (int)(k / ctx), V - 1);
  for (int i = 0; i < n; i += b)
    FG_TRY(text_batch(c, ids + (size_t)i * ctx, n - i < b ? n - i : b,
                      out + (size_t)i * c->info.embed_dim));
  return 0;
}
