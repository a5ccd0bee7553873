/* The random-CLIP generator (clipgen.h, gen_clip): the tiny model in both namings and all
 * three dtypes, read back with the safetensors reader.
 *
 * Checks: every file opens; it holds exactly the tensors of OpenAI's state_dict or of
 * Hugging Face's CLIPModel (names, shapes, dtypes transcribed here from the two layouts, not
 * taken from the generator); the header is space-padded to 8 bytes and the data follows it
 * contiguously in header order; the metadata carries the head counts (and is absent with
 * write_metadata off); F32, F16 and BF16 decode to bit-identical float32; the Hugging Face
 * tensors are the OpenAI ones renamed (q/k/v the row blocks of in_proj, the projections
 * transposed); every value is on the bfloat16 grid; the scales are the documented ones; the
 * seed changes the values and the same seed the bytes never; the OpenAI F32 file's FNV-1a
 * matches tests/clip/data/golden_model.txt (so the golden outputs still describe these
 * weights); gen_clip (argv[1]) writes what the library writes. */
#include "test.h"

#include <spawn.h>
#include <stdarg.h>
#include <stdint.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "clipgen.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "io/safetensors.h"

extern char **environ;

/* ---- utilities -------------------------------------------------------------------------- */

static char *tmpdir;

/* dir/name, malloc'd. */
static char *path_in(const char *name) {
  char *p = fg_path_join(tmpdir, name);
  ASSERT(p != NULL);
  return p;
}

/* The tiny preset with the given naming, dtype and metadata flag, seed 0. */
static clipgen_cfg tiny(clipgen_naming naming, clipgen_dtype dtype, int metadata) {
  clipgen_cfg c;
  ASSERT_OK(clipgen_cfg_preset(&c, CLIPGEN_TINY));
  c.naming = naming;
  c.dtype = dtype;
  c.write_metadata = metadata;
  return c;
}

/* A whole float tensor decoded to float32 (malloc'd); fails the test when absent. */
static float *read_tensor(const fg_st *st, const char *name, size_t *count) {
  fg_st_tensor t;
  ASSERT_OK(fg_st_find(st, name, &t));
  float *v = malloc((t.count ? t.count : 1) * sizeof *v);
  ASSERT(v != NULL);
  ASSERT_OK(fg_st_read_f32(&t, v, t.count));
  if (count) *count = t.count;
  return v;
}

/* Mean and standard deviation of n floats. */
static void stats(const float *v, size_t n, double *mean, double *std) {
  double s = 0, s2 = 0;
  for (size_t i = 0; i < n; i++) s += v[i];
  double m = s / (double)n;
  for (size_t i = 0; i < n; i++) s2 += (v[i] - m) * (v[i] - m);
  *mean = m;
  *std = sqrt(s2 / (double)n);
}

/* Runs program with args (NULL-terminated, without argv[0]) and returns its exit status. */
static int run(const char *program, const char *const *args) {
  const char *argv[16];
  int n = 0;
  argv[n++] = program;
  while (*args && n < 15) argv[n++] = *args++;
  argv[n] = NULL;
  pid_t pid;
  int rc = posix_spawn(&pid, program, NULL, NULL, (char *const *)argv, environ);
  if (rc != 0) FG_TEST_FAIL("cannot start %s: %s", program, strerror(rc));
  int status;
  ASSERT(waitpid(pid, &status, 0) == pid);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* ---- the two layouts, transcribed ------------------------------------------------------- */

typedef struct expect {
  char name[CLIPGEN_NAME_MAX];
  int ndim;
  int64_t shape[4];
  int i64;
} expect;

typedef struct expect_list {
  expect e[256];
  int n;
} expect_list;

static void ex(expect_list *l, int i64, int ndim, int64_t d0, int64_t d1, int64_t d2, int64_t d3,
               const char *fmt, ...) __attribute__((format(printf, 8, 9)));

static void ex(expect_list *l, int i64, int ndim, int64_t d0, int64_t d1, int64_t d2, int64_t d3,
               const char *fmt, ...) {
  ASSERT(l->n < 256);
  expect *e = &l->e[l->n++];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(e->name, sizeof e->name, fmt, ap);
  va_end(ap);
  e->ndim = ndim;
  e->shape[0] = d0;
  e->shape[1] = d1;
  e->shape[2] = d2;
  e->shape[3] = d3;
  e->i64 = i64;
}

/* OpenAI's CLIP state_dict for the tiny sizes: w 48 x 3 layers, tw 40 x 2, E 24, grid 4. */
static void openai_layout(expect_list *l) {
  const int64_t w = 48, tw = 40, E = 24, n_pos = 4 * 4 + 1;
  l->n = 0;
  ex(l, 0, 4, w, 3, 8, 8, "visual.conv1.weight");
  ex(l, 0, 1, w, 0, 0, 0, "visual.class_embedding");
  ex(l, 0, 2, n_pos, w, 0, 0, "visual.positional_embedding");
  ex(l, 0, 1, w, 0, 0, 0, "visual.ln_pre.weight");
  ex(l, 0, 1, w, 0, 0, 0, "visual.ln_pre.bias");
  for (int t = 0; t < 2; t++) {
    const char *pre = t ? "transformer.resblocks" : "visual.transformer.resblocks";
    const int64_t d = t ? tw : w;
    for (int b = 0; b < (t ? 2 : 3); b++) {
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.ln_1.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.ln_1.bias", pre, b);
      ex(l, 0, 2, 3 * d, d, 0, 0, "%s.%d.attn.in_proj_weight", pre, b);
      ex(l, 0, 1, 3 * d, 0, 0, 0, "%s.%d.attn.in_proj_bias", pre, b);
      ex(l, 0, 2, d, d, 0, 0, "%s.%d.attn.out_proj.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.attn.out_proj.bias", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.ln_2.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.ln_2.bias", pre, b);
      ex(l, 0, 2, 4 * d, d, 0, 0, "%s.%d.mlp.c_fc.weight", pre, b);
      ex(l, 0, 1, 4 * d, 0, 0, 0, "%s.%d.mlp.c_fc.bias", pre, b);
      ex(l, 0, 2, d, 4 * d, 0, 0, "%s.%d.mlp.c_proj.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.mlp.c_proj.bias", pre, b);
    }
  }
  ex(l, 0, 1, w, 0, 0, 0, "visual.ln_post.weight");
  ex(l, 0, 1, w, 0, 0, 0, "visual.ln_post.bias");
  ex(l, 0, 2, w, E, 0, 0, "visual.proj");
  ex(l, 0, 2, 49408, tw, 0, 0, "token_embedding.weight");
  ex(l, 0, 2, 77, tw, 0, 0, "positional_embedding");
  ex(l, 0, 1, tw, 0, 0, 0, "ln_final.weight");
  ex(l, 0, 1, tw, 0, 0, 0, "ln_final.bias");
  ex(l, 0, 2, tw, E, 0, 0, "text_projection");
  ex(l, 0, 0, 0, 0, 0, 0, "logit_scale");
}

/* Hugging Face CLIPModel for the same sizes. */
static void hf_layout(expect_list *l) {
  const int64_t w = 48, tw = 40, E = 24, n_pos = 4 * 4 + 1;
  l->n = 0;
  ex(l, 0, 4, w, 3, 8, 8, "vision_model.embeddings.patch_embedding.weight");
  ex(l, 0, 1, w, 0, 0, 0, "vision_model.embeddings.class_embedding");
  ex(l, 0, 2, n_pos, w, 0, 0, "vision_model.embeddings.position_embedding.weight");
  ex(l, 1, 2, 1, n_pos, 0, 0, "vision_model.embeddings.position_ids");
  ex(l, 0, 1, w, 0, 0, 0, "vision_model.pre_layrnorm.weight");
  ex(l, 0, 1, w, 0, 0, 0, "vision_model.pre_layrnorm.bias");
  for (int t = 0; t < 2; t++) {
    const char *pre = t ? "text_model.encoder.layers" : "vision_model.encoder.layers";
    const int64_t d = t ? tw : w;
    for (int b = 0; b < (t ? 2 : 3); b++) {
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.layer_norm1.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.layer_norm1.bias", pre, b);
      static const char *p[4] = {"q_proj", "k_proj", "v_proj", "out_proj"};
      for (int k = 0; k < 4; k++) {
        ex(l, 0, 2, d, d, 0, 0, "%s.%d.self_attn.%s.weight", pre, b, p[k]);
        ex(l, 0, 1, d, 0, 0, 0, "%s.%d.self_attn.%s.bias", pre, b, p[k]);
      }
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.layer_norm2.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.layer_norm2.bias", pre, b);
      ex(l, 0, 2, 4 * d, d, 0, 0, "%s.%d.mlp.fc1.weight", pre, b);
      ex(l, 0, 1, 4 * d, 0, 0, 0, "%s.%d.mlp.fc1.bias", pre, b);
      ex(l, 0, 2, d, 4 * d, 0, 0, "%s.%d.mlp.fc2.weight", pre, b);
      ex(l, 0, 1, d, 0, 0, 0, "%s.%d.mlp.fc2.bias", pre, b);
    }
  }
  ex(l, 0, 1, w, 0, 0, 0, "vision_model.post_layernorm.weight");
  ex(l, 0, 1, w, 0, 0, 0, "vision_model.post_layernorm.bias");
  ex(l, 0, 2, E, w, 0, 0, "visual_projection.weight");
  ex(l, 0, 2, 49408, tw, 0, 0, "text_model.embeddings.token_embedding.weight");
  ex(l, 0, 2, 77, tw, 0, 0, "text_model.embeddings.position_embedding.weight");
  ex(l, 1, 2, 1, 77, 0, 0, "text_model.embeddings.position_ids");
  ex(l, 0, 1, tw, 0, 0, 0, "text_model.final_layer_norm.weight");
  ex(l, 0, 1, tw, 0, 0, 0, "text_model.final_layer_norm.bias");
  ex(l, 0, 2, E, tw, 0, 0, "text_projection.weight");
  ex(l, 0, 0, 0, 0, 0, 0, "logit_scale");
}

/* ---- per-file checks -------------------------------------------------------------------- */

/* The header length field, the padding and the contiguous data section of the file. */
static void check_framing(const char *path, const fg_st *st) {
  FILE *fp = fopen(path, "rb");
  ASSERT(fp != NULL);
  unsigned char len8[8];
  ASSERT_EQ(fread(len8, 1, 8, fp), 8);
  uint64_t hlen = 0;
  for (int i = 7; i >= 0; i--) hlen = hlen << 8 | len8[i];
  ASSERT_EQ(hlen % 8, 0);
  char *hdr = malloc(hlen + 1);
  ASSERT(hdr != NULL);
  ASSERT_EQ(fread(hdr, 1, hlen, fp), hlen);
  hdr[hlen] = '\0';
  fclose(fp);
  ASSERT_EQ(hdr[0], '{');
  size_t end = hlen;
  while (end > 0 && hdr[end - 1] == ' ') end--;
  ASSERT(end > 0 && hdr[end - 1] == '}');
  ASSERT(hlen - end < 8); /* padding only, and at most 7 bytes of it */
  free(hdr);

  /* tensors in header order sit back to back from the first byte of the data section */
  struct stat sb;
  ASSERT_EQ(stat(path, &sb), 0);
  const unsigned char *base = NULL, *next = NULL;
  size_t total = 0;
  for (int i = 0; i < fg_st_count(st); i++) {
    fg_st_tensor t;
    ASSERT_OK(fg_st_tensor_at(st, i, &t));
    if (i == 0) base = next = t.data;
    if ((const unsigned char *)t.data != next)
      FG_TEST_FAIL("%s: tensor %d (%s) does not follow the previous one", path, i, t.name);
    next += t.nbytes;
    total += t.nbytes;
  }
  ASSERT(base != NULL);
  ASSERT_EQ((uint64_t)sb.st_size, 8 + hlen + total);
}

/* Names, shapes and dtypes against the transcribed layout. */
static void check_layout(const fg_st *st, const expect_list *l, const char *dtype) {
  ASSERT_EQ(fg_st_count(st), l->n);
  for (int i = 0; i < l->n; i++) {
    const expect *e = &l->e[i];
    fg_st_tensor t;
    int rc = fg_st_find(st, e->name, &t);
    if (rc != 0) FG_TEST_FAIL("tensor %s missing: %s", e->name, fg_error_detail());
    ASSERT_EQ(t.ndim, e->ndim);
    for (int d = 0; d < e->ndim; d++)
      if (t.shape[d] != e->shape[d])
        FG_TEST_FAIL("%s: dimension %d is %" PRId64 ", expected %" PRId64, e->name, d,
                     t.shape[d], e->shape[d]);
    ASSERT_STREQ(fg_st_dtype_name(t.dtype), e->i64 ? "I64" : dtype);
    if (e->i64) { /* position_ids: 0, 1, ..., n-1 */
      const unsigned char *p = t.data;
      for (size_t k = 0; k < t.count; k++) {
        int64_t v = 0;
        for (int b = 7; b >= 0; b--) v = (int64_t)((uint64_t)v << 8 | p[8 * k + (size_t)b]);
        ASSERT_EQ(v, (int64_t)k);
      }
    }
  }
}

/* Every float of the file is on the bfloat16 grid and either 0 or at least 2^-14 in
 * magnitude; the whole file's tensors are also what clipgen_tensor_values says. */
static void check_values(const fg_st *st, const clipgen_cfg *cfg) {
  clipgen_tensor *t = NULL;
  int n = 0;
  ASSERT_OK(clipgen_tensors(cfg, &t, &n));
  ASSERT_EQ(n, fg_st_count(st));
  for (int i = 0; i < n; i++) {
    fg_st_tensor ft;
    ASSERT_OK(fg_st_tensor_at(st, i, &ft));
    ASSERT_STREQ(ft.name, t[i].name);
    if (t[i].is_i64) continue;
    size_t count;
    float *v = read_tensor(st, t[i].name, &count);
    float *g = malloc(count * sizeof *g);
    ASSERT(g != NULL);
    ASSERT_OK(clipgen_tensor_values(cfg, &t[i], 0, count, g));
    if (memcmp(v, g, count * sizeof *v) != 0)
      FG_TEST_FAIL("%s: file values differ from clipgen_tensor_values", t[i].name);
    /* a slice starting at an odd element (the second half of a Box-Muller pair) */
    if (count > 3) {
      float s[2];
      ASSERT_OK(clipgen_tensor_values(cfg, &t[i], 1, 2, s));
      ASSERT(memcmp(s, v + 1, sizeof s) == 0);
    }
    for (size_t k = 0; k < count; k++) {
      uint32_t bits;
      memcpy(&bits, &v[k], sizeof bits);
      if ((bits & 0xffffu) != 0 || (v[k] != 0 && fabsf(v[k]) < 0x1p-14f) || !isfinite(v[k]))
        FG_TEST_FAIL("%s[%zu] = %a is not on the bf16 grid", t[i].name, k, (double)v[k]);
    }
    free(g);
    free(v);
  }
  free(t);
}

/* ---- cross-file checks ------------------------------------------------------------------ */

/* Every float tensor of a and b (same names) decodes to the same bits. */
static void check_same_floats(const fg_st *a, const fg_st *b, const char *what) {
  ASSERT_EQ(fg_st_count(a), fg_st_count(b));
  for (int i = 0; i < fg_st_count(a); i++) {
    fg_st_tensor t;
    ASSERT_OK(fg_st_tensor_at(a, i, &t));
    if (t.dtype == FG_ST_I64) continue;
    size_t na, nb;
    float *va = read_tensor(a, t.name, &na), *vb = read_tensor(b, t.name, &nb);
    ASSERT_EQ(na, nb);
    if (memcmp(va, vb, na * sizeof *va) != 0)
      FG_TEST_FAIL("%s: %s decodes to different values", what, t.name);
    free(va);
    free(vb);
  }
}

/* hf[i] == oa[i + off] for n elements, or hf [C][R] == transpose of oa [R][C]. */
static void same_as(const fg_st *hf, const char *hf_name, const fg_st *oa, const char *oa_name,
                    size_t off, int transpose) {
  size_t nh, no;
  float *h = read_tensor(hf, hf_name, &nh), *o = read_tensor(oa, oa_name, &no);
  if (transpose) {
    fg_st_tensor t;
    ASSERT_OK(fg_st_find(oa, oa_name, &t));
    const size_t R = (size_t)t.shape[0], C = (size_t)t.shape[1];
    ASSERT_EQ(nh, no);
    for (size_t r = 0; r < R; r++)
      for (size_t c = 0; c < C; c++)
        if (h[c * R + r] != o[r * C + c])
          FG_TEST_FAIL("%s[%zu][%zu] != %s[%zu][%zu]", hf_name, c, r, oa_name, r, c);
  } else {
    ASSERT(off + nh <= no);
    if (memcmp(h, o + off, nh * sizeof *h) != 0)
      FG_TEST_FAIL("%s differs from %s at element offset %zu", hf_name, oa_name, off);
  }
  free(h);
  free(o);
}

/* The Hugging Face file is the OpenAI one renamed (convert_clip_original_pytorch_to_hf.py). */
static void check_hf_is_openai(const fg_st *hf, const fg_st *oa) {
  same_as(hf, "vision_model.embeddings.patch_embedding.weight", oa, "visual.conv1.weight", 0, 0);
  same_as(hf, "vision_model.embeddings.class_embedding", oa, "visual.class_embedding", 0, 0);
  same_as(hf, "vision_model.embeddings.position_embedding.weight", oa,
          "visual.positional_embedding", 0, 0);
  same_as(hf, "vision_model.pre_layrnorm.weight", oa, "visual.ln_pre.weight", 0, 0);
  same_as(hf, "vision_model.pre_layrnorm.bias", oa, "visual.ln_pre.bias", 0, 0);
  same_as(hf, "vision_model.post_layernorm.weight", oa, "visual.ln_post.weight", 0, 0);
  same_as(hf, "vision_model.post_layernorm.bias", oa, "visual.ln_post.bias", 0, 0);
  same_as(hf, "visual_projection.weight", oa, "visual.proj", 0, 1);
  same_as(hf, "text_model.embeddings.token_embedding.weight", oa, "token_embedding.weight", 0, 0);
  same_as(hf, "text_model.embeddings.position_embedding.weight", oa, "positional_embedding", 0, 0);
  same_as(hf, "text_model.final_layer_norm.weight", oa, "ln_final.weight", 0, 0);
  same_as(hf, "text_model.final_layer_norm.bias", oa, "ln_final.bias", 0, 0);
  same_as(hf, "text_projection.weight", oa, "text_projection", 0, 1);
  same_as(hf, "logit_scale", oa, "logit_scale", 0, 0);
  static const char *pairs[][2] = {
      {"layer_norm1.weight", "ln_1.weight"},           {"layer_norm1.bias", "ln_1.bias"},
      {"self_attn.out_proj.weight", "attn.out_proj.weight"},
      {"self_attn.out_proj.bias", "attn.out_proj.bias"},
      {"layer_norm2.weight", "ln_2.weight"},           {"layer_norm2.bias", "ln_2.bias"},
      {"mlp.fc1.weight", "mlp.c_fc.weight"},           {"mlp.fc1.bias", "mlp.c_fc.bias"},
      {"mlp.fc2.weight", "mlp.c_proj.weight"},         {"mlp.fc2.bias", "mlp.c_proj.bias"},
  };
  static const char *qkv[3] = {"q_proj", "k_proj", "v_proj"};
  char hn[128], on[128];
  for (int t = 0; t < 2; t++) {
    const char *hp = t ? "text_model.encoder.layers" : "vision_model.encoder.layers";
    const char *op = t ? "transformer.resblocks" : "visual.transformer.resblocks";
    const size_t d = t ? 40 : 48;
    for (int b = 0; b < (t ? 2 : 3); b++) {
      for (size_t k = 0; k < sizeof pairs / sizeof pairs[0]; k++) {
        snprintf(hn, sizeof hn, "%s.%d.%s", hp, b, pairs[k][0]);
        snprintf(on, sizeof on, "%s.%d.%s", op, b, pairs[k][1]);
        same_as(hf, hn, oa, on, 0, 0);
      }
      for (int k = 0; k < 3; k++) { /* row block k of in_proj */
        snprintf(hn, sizeof hn, "%s.%d.self_attn.%s.weight", hp, b, qkv[k]);
        snprintf(on, sizeof on, "%s.%d.attn.in_proj_weight", op, b);
        same_as(hf, hn, oa, on, (size_t)k * d * d, 0);
        snprintf(hn, sizeof hn, "%s.%d.self_attn.%s.bias", hp, b, qkv[k]);
        snprintf(on, sizeof on, "%s.%d.attn.in_proj_bias", op, b);
        same_as(hf, hn, oa, on, (size_t)k * d, 0);
      }
    }
  }
}

/* std of a tensor within rel of want, and its mean within tol of mean. */
static void check_scale(const fg_st *st, const char *name, double mean, double tol, double want,
                        double rel) {
  size_t n;
  float *v = read_tensor(st, name, &n);
  double m, s;
  stats(v, n, &m, &s);
  if (fabs(m - mean) > tol || fabs(s - want) > rel * want)
    FG_TEST_FAIL("%s: mean %.5f std %.5f, expected mean %.5f (+-%g) std %.5f (+-%g%%)", name, m,
                 s, mean, tol, want, rel * 100);
  free(v);
}

/* OpenAI's initialisation scales, and LayerNorm parameters that are not the identity. */
static void check_scales(const fg_st *oa) {
  const double w = 48, tw = 40;
  check_scale(oa, "visual.class_embedding", 0, 0.08, pow(w, -0.5), 0.3);
  check_scale(oa, "visual.positional_embedding", 0, 0.02, pow(w, -0.5), 0.1);
  check_scale(oa, "visual.proj", 0, 0.02, pow(w, -0.5), 0.1);
  check_scale(oa, "visual.conv1.weight", 0, 0.002, 0.02, 0.05);
  check_scale(oa, "visual.transformer.resblocks.0.attn.in_proj_weight", 0, 0.005, pow(w, -0.5),
              0.05);
  check_scale(oa, "visual.transformer.resblocks.2.attn.out_proj.weight", 0, 0.005,
              pow(w, -0.5) * pow(6, -0.5), 0.05);
  check_scale(oa, "visual.transformer.resblocks.1.mlp.c_fc.weight", 0, 0.005, pow(2 * w, -0.5),
              0.05);
  check_scale(oa, "visual.transformer.resblocks.1.mlp.c_proj.weight", 0, 0.005,
              pow(w, -0.5) * pow(6, -0.5), 0.05);
  check_scale(oa, "transformer.resblocks.1.attn.in_proj_weight", 0, 0.005, pow(tw, -0.5), 0.05);
  check_scale(oa, "transformer.resblocks.0.mlp.c_proj.weight", 0, 0.005,
              pow(tw, -0.5) * pow(4, -0.5), 0.05);
  check_scale(oa, "token_embedding.weight", 0, 0.0005, 0.02, 0.01);
  check_scale(oa, "positional_embedding", 0, 0.001, 0.01, 0.05);
  check_scale(oa, "text_projection", 0, 0.02, pow(tw, -0.5), 0.1);
  check_scale(oa, "visual.transformer.resblocks.0.ln_1.weight", 1, 0.05, 0.1, 0.35);
  check_scale(oa, "visual.transformer.resblocks.0.ln_1.bias", 0, 0.025, 0.05, 0.35);
  check_scale(oa, "transformer.resblocks.1.ln_2.weight", 1, 0.05, 0.1, 0.35);
  check_scale(oa, "ln_final.bias", 0, 0.025, 0.05, 0.35);
  check_scale(oa, "visual.transformer.resblocks.0.mlp.c_fc.bias", 0, 0.005, 0.02, 0.15);
  check_scale(oa, "transformer.resblocks.0.attn.in_proj_bias", 0, 0.007, 0.02, 0.2);

  size_t n;
  float *ls = read_tensor(oa, "logit_scale", &n);
  ASSERT_EQ(n, 1);
  ASSERT_NEAR(ls[0], log(1 / 0.07), 0.008); /* bf16 of ln(1/0.07) = 2.65625 */
  free(ls);

  /* different tensors draw different streams */
  float *a = read_tensor(oa, "visual.transformer.resblocks.0.ln_1.weight", &n);
  float *b = read_tensor(oa, "visual.transformer.resblocks.1.ln_1.weight", NULL);
  float *c = read_tensor(oa, "visual.transformer.resblocks.0.ln_2.weight", NULL);
  ASSERT(memcmp(a, b, n * sizeof *a) != 0);
  ASSERT(memcmp(a, c, n * sizeof *a) != 0);
  free(a);
  free(b);
  free(c);
}

/* The golden outputs' weights: size and FNV-1a of the OpenAI F32 file, seed 0. */
static void check_golden(const char *path) {
  const char *src = getenv("FG_SOURCE_DIR");
  if (!src) FG_TEST_FAIL("FG_SOURCE_DIR is not set (run through meson test)");
  char gpath[4096];
  snprintf(gpath, sizeof gpath, "%s/tests/clip/data/golden_model.txt", src);
  char *buf = NULL;
  size_t len = 0;
  ASSERT_OK(fg_read_file(gpath, 1 << 16, &buf, &len));
  ASSERT_STRCONTAINS(buf, "--preset tiny --naming openai --dtype f32 --seed 0\n");
  const char *s = strstr(buf, "\nsize=");
  const char *h = strstr(buf, "\nfnv1a64=");
  ASSERT(s && h);
  unsigned long long want_size = strtoull(s + 6, NULL, 10);
  unsigned long long want_hash = strtoull(h + 9, NULL, 16);
  struct stat sb;
  ASSERT_EQ(stat(path, &sb), 0);
  ASSERT_EQ((unsigned long long)sb.st_size, want_size);
  uint64_t got;
  ASSERT_OK(clipgen_file_fnv1a64(path, &got));
  if (got != want_hash)
    FG_TEST_FAIL("%s: fnv1a64 %016" PRIx64 ", golden_model.txt has %016llx: the generator no "
                 "longer writes the weights the golden outputs were computed from (rerun "
                 "tests/clip/gen_clip_golden.py if that is intended)",
                 path, got, want_hash);
  free(buf);
}

/* ---- main ------------------------------------------------------------------------------- */

int main(int argc, char **argv) {
  const char *gen_clip = argc > 1 ? argv[1] : NULL;
  char tmpl[512];
  const char *base = getenv("TMPDIR");
  snprintf(tmpl, sizeof tmpl, "%s/fg-clipgen-XXXXXX", base && *base ? base : "/tmp");
  ASSERT(mkdtemp(tmpl) != NULL);
  tmpdir = tmpl;

  static const clipgen_dtype dtypes[3] = {CLIPGEN_F32, CLIPGEN_F16, CLIPGEN_BF16};
  expect_list *layout = malloc(sizeof *layout);
  ASSERT(layout != NULL);
  fg_st *files[2][3];
  char *paths[2][3];
  for (int nm = 0; nm < 2; nm++) {
    if (nm == 0)
      openai_layout(layout);
    else
      hf_layout(layout);
    for (int d = 0; d < 3; d++) {
      clipgen_cfg cfg = tiny(nm ? CLIPGEN_HF : CLIPGEN_OPENAI, dtypes[d], 1);
      char name[64];
      snprintf(name, sizeof name, "tiny-%s-%s.safetensors", clipgen_naming_name(cfg.naming),
               clipgen_dtype_name(cfg.dtype));
      paths[nm][d] = path_in(name);
      size_t bytes = 0;
      ASSERT_OK(clipgen_write(paths[nm][d], &cfg, &bytes));
      struct stat sb;
      ASSERT_EQ(stat(paths[nm][d], &sb), 0);
      ASSERT_EQ((size_t)sb.st_size, bytes);
      ASSERT_OK(fg_st_open(&files[nm][d], paths[nm][d]));
      check_framing(paths[nm][d], files[nm][d]);
      check_layout(files[nm][d], layout, clipgen_dtype_name(cfg.dtype));
      ASSERT_STREQ(fg_st_metadata(files[nm][d], "vision_heads"), "3");
      ASSERT_STREQ(fg_st_metadata(files[nm][d], "text_heads"), "5");
      if (d == 0) check_values(files[nm][d], &cfg);
      if (d > 0) check_same_floats(files[nm][0], files[nm][d], name);
    }
  }
  check_hf_is_openai(files[1][0], files[0][0]);
  check_hf_is_openai(files[1][2], files[0][1]); /* BF16 HF against F16 OpenAI */
  check_scales(files[0][0]);
  check_golden(paths[0][0]);

  /* without metadata: no __metadata__ at all, same tensors */
  clipgen_cfg nometa = tiny(CLIPGEN_OPENAI, CLIPGEN_BF16, 0);
  char *p_nometa = path_in("tiny-nometa.safetensors");
  ASSERT_OK(clipgen_write(p_nometa, &nometa, NULL));
  fg_st *st;
  ASSERT_OK(fg_st_open(&st, p_nometa));
  ASSERT(fg_st_metadata(st, "vision_heads") == NULL);
  ASSERT(fg_st_metadata(st, "text_heads") == NULL);
  ASSERT(fg_st_metadata(st, "format") == NULL);
  check_framing(p_nometa, st);
  openai_layout(layout);
  check_layout(st, layout, "BF16");
  check_same_floats(files[0][0], st, "no metadata");
  fg_st_close(st);

  /* the same config writes the same bytes; another seed other values */
  uint64_t h0, h1, h2;
  clipgen_cfg c0 = tiny(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  char *p_again = path_in("again.safetensors"), *p_seed = path_in("seed7.safetensors");
  ASSERT_OK(clipgen_write(p_again, &c0, NULL));
  c0.seed = 7;
  ASSERT_OK(clipgen_write(p_seed, &c0, NULL));
  ASSERT_OK(clipgen_file_fnv1a64(paths[0][0], &h0));
  ASSERT_OK(clipgen_file_fnv1a64(p_again, &h1));
  ASSERT_OK(clipgen_file_fnv1a64(p_seed, &h2));
  ASSERT(h0 == h1);
  ASSERT(h0 != h2);
  ASSERT_OK(fg_st_open(&st, p_seed));
  float *a = read_tensor(files[0][0], "visual.proj", NULL);
  float *b = read_tensor(st, "visual.proj", NULL);
  size_t same = 0;
  for (size_t i = 0; i < 48 * 24; i++) same += a[i] == b[i];
  ASSERT(same < 48 * 24 / 20);
  free(a);
  free(b);
  fg_st_close(st);

  /* bad configurations are refused with a reason, and nothing is written */
  clipgen_cfg bad = tiny(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  bad.vision_heads = 5;
  char *p_bad = path_in("bad.safetensors");
  ASSERT_ERR(clipgen_write(p_bad, &bad, NULL), FG_EINVAL, "vision_heads");
  bad = tiny(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  bad.image_size = 36;
  ASSERT_ERR(clipgen_write(p_bad, &bad, NULL), FG_EINVAL, "patch_size");
  bad = tiny(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  bad.embed_dim = 0;
  ASSERT_ERR(clipgen_write(p_bad, &bad, NULL), FG_EINVAL, "embed_dim");
  ASSERT(access(p_bad, F_OK) != 0);
  clipgen_cfg ok = tiny(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  char *p_nodir = path_in("no/such/dir.safetensors");
  ASSERT(clipgen_write(p_nodir, &ok, NULL) < 0);

  /* gen_clip writes what the library writes */
  if (gen_clip) {
    char *p_cli = path_in("cli.safetensors");
    const char *args[] = {p_cli, "--naming", "hf", "--dtype", "bf16", "--seed", "0",
                          "--no-metadata", NULL};
    ASSERT_EQ(run(gen_clip, args), 0);
    clipgen_cfg cc = tiny(CLIPGEN_HF, CLIPGEN_BF16, 0);
    char *p_lib = path_in("lib.safetensors");
    ASSERT_OK(clipgen_write(p_lib, &cc, NULL));
    ASSERT_OK(clipgen_file_fnv1a64(p_cli, &h1));
    ASSERT_OK(clipgen_file_fnv1a64(p_lib, &h2));
    ASSERT(h1 == h2);
    const char *defaults[] = {p_cli, NULL}; /* tiny, openai, f32, seed 0, metadata */
    ASSERT_EQ(run(gen_clip, defaults), 0);
    ASSERT_OK(clipgen_file_fnv1a64(p_cli, &h1));
    ASSERT(h1 == h0);
    const char *bad_dtype[] = {p_cli, "--dtype", "f64", NULL};
    ASSERT_EQ(run(gen_clip, bad_dtype), 2);
    const char *bad_seed[] = {p_cli, "--seed", "-1", NULL};
    ASSERT_EQ(run(gen_clip, bad_seed), 2);
    const char *no_out[] = {"--preset", "tiny", NULL};
    ASSERT_EQ(run(gen_clip, no_out), 2);
    free(p_cli);
    free(p_lib);
  }

  for (int nm = 0; nm < 2; nm++)
    for (int d = 0; d < 3; d++) {
      fg_st_close(files[nm][d]);
      free(paths[nm][d]);
    }
  free(layout);
  free(p_nometa);
  free(p_again);
  free(p_seed);
  free(p_bad);
  free(p_nodir);
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("clip_gen: ok\n");
  return 0;
}
