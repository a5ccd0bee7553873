/* The CLIP model against golden outputs of OpenAI's reference architecture (computed by
 * gen_clip_golden.py with PyTorch from the tiny model clipgen writes; CI needs no Python):
 * dense MaskCLIP features on a non-square grid with a remainder and on the square grid, the
 * pooled image embedding and text embeddings, for the tiny model in OpenAI's and Hugging
 * Face's naming and in F32, F16 and BF16 (which hold the same values, so all must agree
 * with the same tolerance), and without head-count metadata. Then batching, threads, the
 * preprocessing against PIL's, and malformed inputs. */
#include <pthread.h>
#include <unistd.h>

#include "clip/clip.h"
#include "clip/recipes.h"
#include "clip/tokenizer.h"
#include "clipgen.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/norm.h"
#include "io/image.h"
#include "io/npy.h"
#include "test.h"

#define TOL 1e-4

static char tmpdir[] = "/tmp/fg-test-clip-XXXXXX";

static char *data_path(const char *name) {
  const char *src = getenv("FG_SOURCE_DIR");
  char *p = malloc(1024);
  snprintf(p, 1024, "%s/tests/clip/data/%s", src ? src : ".", name);
  return p;
}

/* A golden array as float32 (from '<f4', '<i4' or '<f2' .npy), with its shape. */
typedef struct golden {
  int ndim;
  size_t shape[8], count;
  float *f;
  int32_t *i;
} golden;

static golden load_golden(const char *name) {
  char *path = data_path(name), *buf;
  size_t len;
  ASSERT_OK(fg_read_file(path, (size_t)1 << 28, &buf, &len));
  golden g = {0};
  /* The project's reader takes float arrays; int32 ids are read here by hand. */
  ASSERT(len > 12 && memcmp(buf, "\x93NUMPY", 6) == 0);
  const char *descr = memmem(buf, len < 256 ? len : 256, "'descr': '", 10);
  ASSERT(descr);
  if (strncmp(descr + 10, "<i4", 3) == 0) {
    const size_t hlen = buf[6] == 1 ? (size_t)(unsigned char)buf[8] |
                                          (size_t)(unsigned char)buf[9] << 8
                                    : (size_t)(unsigned char)buf[8] |
                                          (size_t)(unsigned char)buf[9] << 8 |
                                          (size_t)(unsigned char)buf[10] << 16;
    const size_t off = (buf[6] == 1 ? 10 : 12) + hlen;
    const char *sh = memmem(buf, off, "'shape': (", 10);
    ASSERT(sh);
    sh += 10;
    g.count = 1;
    while (*sh != ')') {
      char *end;
      g.shape[g.ndim] = strtoul(sh, &end, 10);
      g.count *= g.shape[g.ndim++];
      sh = end;
      while (*sh == ',' || *sh == ' ') sh++;
    }
    ASSERT_EQ(len - off, g.count * 4);
    g.i = malloc(g.count * 4);
    memcpy(g.i, buf + off, g.count * 4);
  } else {
    fg_npy a;
    ASSERT_OK(fg_npy_parse(buf, len, &a));
    ASSERT_EQ(a.dtype, FG_DTYPE_F32);
    g.ndim = a.ndim;
    g.count = a.count;
    memcpy(g.shape, a.shape, sizeof a.shape);
    g.f = malloc(g.count * sizeof(float));
    memcpy(g.f, a.data, g.count * sizeof(float));
  }
  free(buf);
  free(path);
  return g;
}

static void golden_free(golden *g) {
  free(g->f);
  free(g->i);
}

static double max_abs_diff(const float *a, const float *b, size_t n) {
  double m = 0.0;
  for (size_t i = 0; i < n; i++) {
    const double d = fabs((double)a[i] - b[i]);
    if (!(d <= m)) m = d; /* NaN propagates */
  }
  return m;
}

static double max_abs(const float *a, size_t n) {
  double m = 0.0;
  for (size_t i = 0; i < n; i++) m = fabs(a[i]) > m ? fabs(a[i]) : m;
  return m;
}

static golden g_dense, g_dense_in, g_sq, g_sq_in, g_pooled, g_pooled_in, g_ids, g_text;

/* Writes the tiny model in a naming and dtype; returns its path (caller frees). */
static char *write_model(clipgen_naming naming, clipgen_dtype dtype, int metadata) {
  clipgen_cfg cfg;
  ASSERT_OK(clipgen_cfg_preset(&cfg, CLIPGEN_TINY));
  cfg.naming = naming;
  cfg.dtype = dtype;
  cfg.write_metadata = metadata;
  char name[128];
  snprintf(name, sizeof name, "tiny_%s_%s%s.safetensors", clipgen_naming_name(naming),
           clipgen_dtype_name(dtype), metadata ? "" : "_nometa");
  char *path = fg_path_join(tmpdir, name);
  ASSERT_OK(clipgen_write(path, &cfg, NULL));
  return path;
}

/* The golden outputs were computed from the F32 OpenAI file of this generator: its
 * checksum must still be the one recorded beside them. */
static void check_generator_matches_goldens(const char *f32_openai) {
  char *path = data_path("golden_model.txt"), *buf;
  size_t len;
  ASSERT_OK(fg_read_file(path, 1 << 16, &buf, &len));
  uint64_t h;
  ASSERT_OK(clipgen_file_fnv1a64(f32_openai, &h));
  char hex[32];
  snprintf(hex, sizeof hex, "%016llx", (unsigned long long)h);
  if (!strstr(buf, hex))
    FG_TEST_FAIL("the generator's tiny model (fnv1a64 %s) is not the one the goldens were made "
                 "from; rerun tests/clip/gen_clip_golden.py (golden_model.txt:\n%s)", hex, buf);
  free(buf);
  free(path);
}

static void check_dense(fg_clip *c, const golden *in, const golden *want, const char *what) {
  const int H = (int)in->shape[2], W = (int)in->shape[3];
  int hp, wp;
  ASSERT_OK(fg_clip_dense_grid(c, H, W, &hp, &wp));
  ASSERT_EQ(want->ndim, 3);
  ASSERT_EQ(want->shape[0], (size_t)hp);
  ASSERT_EQ(want->shape[1], (size_t)wp);
  float *out = malloc(want->count * sizeof(float));
  ASSERT_OK(fg_clip_image_dense(c, in->f, 1, H, W, out));
  const double err = max_abs_diff(out, want->f, want->count);
  printf("  %s %dx%d px -> %dx%d: max abs error %.3g (values up to %.3g)\n", what, W, H, wp, hp,
         err, max_abs(want->f, want->count));
  ASSERT(err <= TOL);
  free(out);
}

static void check_model(const char *path) {
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, path));
  const fg_clip_info *in = fg_clip_get_info(c);
  printf("%s: %s, image %d patch %d width %d layers %d heads %d; text width %d layers %d "
         "heads %d ctx %d; E %d; %zu bytes\n", strrchr(path, '/') + 1, in->dtype,
         in->image_size, in->patch_size, in->vision_width, in->vision_layers, in->vision_heads,
         in->text_width, in->text_layers, in->text_heads, in->context_length, in->embed_dim,
         in->weights_bytes);
  ASSERT_EQ(in->image_size, 32);
  ASSERT_EQ(in->patch_size, 8);
  ASSERT_EQ(in->vision_layers, 3);
  ASSERT_EQ(in->vision_heads, 3);
  ASSERT_EQ(in->text_layers, 2);
  ASSERT_EQ(in->text_heads, 5);
  ASSERT_EQ(in->embed_dim, 24);
  ASSERT_EQ(in->context_length, 77);
  /* the fingerprint is the file's SHA-256, as the coreutils program computes it */
  char cmd[4200];
  snprintf(cmd, sizeof cmd, "sha256sum '%s'", path);
  FILE *p = popen(cmd, "r");
  char want[FG_SHA256_HEX + 1] = "";
  ASSERT(p && fscanf(p, "%64s", want) == 1);
  pclose(p);
  ASSERT_STREQ(in->fingerprint, want);
  const int E = in->embed_dim;
  check_dense(c, &g_dense_in, &g_dense, "dense");
  check_dense(c, &g_sq_in, &g_sq, "dense square");

  const int np = (int)g_pooled_in.shape[0];
  ASSERT_EQ(g_pooled.count, (size_t)np * E);
  float *emb = malloc(g_pooled.count * sizeof(float));
  ASSERT_OK(fg_clip_image_pooled(c, g_pooled_in.f, np, emb));
  double err = max_abs_diff(emb, g_pooled.f, g_pooled.count);
  printf("  pooled x%d: max abs error %.3g\n", np, err);
  ASSERT(err <= TOL);
  free(emb);

  const int n = (int)g_ids.shape[0];
  ASSERT_EQ(g_ids.shape[1], (size_t)in->context_length);
  ASSERT_EQ(g_text.count, (size_t)n * E);
  float *temb = malloc(g_text.count * sizeof(float));
  ASSERT_OK(fg_clip_text(c, g_ids.i, n, temb));
  err = max_abs_diff(temb, g_text.f, g_text.count);
  printf("  text x%d: max abs error %.3g\n", n, err);
  ASSERT(err <= TOL);
  free(temb);
  fg_clip_free(c);
}

/* A batch gives each input what it gives alone, and so do other thread counts. */
static void check_batch_and_threads(const char *path) {
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, path));
  const fg_clip_info *in = fg_clip_get_info(c);
  const int E = in->embed_dim, H = (int)g_dense_in.shape[2], W = (int)g_dense_in.shape[3];
  const size_t px = (size_t)3 * H * W, per = g_dense.count;
  float *x2 = malloc(2 * px * sizeof(float)), *out2 = malloc(2 * per * sizeof(float));
  memcpy(x2, g_dense_in.f, px * sizeof(float));
  for (size_t i = 0; i < px; i++) x2[px + i] = -0.5f * g_dense_in.f[px - 1 - i];
  float *second = malloc(per * sizeof(float));
  ASSERT_OK(fg_clip_image_dense(c, x2 + px, 1, H, W, second));
  for (int threads = 1; threads <= 3; threads++) {
    fg_clip_set_threads(c, threads);
    ASSERT_OK(fg_clip_image_dense(c, x2, 2, H, W, out2));
    ASSERT(max_abs_diff(out2, g_dense.f, per) <= TOL);
    ASSERT(max_abs_diff(out2 + per, second, per) <= 1e-5);
    ASSERT(max_abs_diff(out2, out2 + per, per) > 1e-3); /* different inputs, different output */
  }
  /* Texts one at a time equal the batch (the batch runs on the longest one's length). */
  const int n = (int)g_ids.shape[0];
  float *one = malloc((size_t)E * sizeof(float));
  for (int q = 0; q < n; q++) {
    ASSERT_OK(fg_clip_text(c, g_ids.i + (size_t)q * in->context_length, 1, one));
    ASSERT(max_abs_diff(one, g_text.f + (size_t)q * E, (size_t)E) <= TOL);
  }
  free(one), free(x2), free(out2), free(second);

  /* More inputs than one internal batch takes (2048 tokens: 26 texts of 77, 56 images of
   * 36 tokens here): every one still gets its own answer. */
  const int many = 60, ctx = in->context_length;
  int32_t *ids = malloc((size_t)many * ctx * sizeof(int32_t));
  float *temb = malloc((size_t)many * E * sizeof(float));
  for (int q = 0; q < many; q++)
    memcpy(ids + (size_t)q * ctx, g_ids.i + (size_t)(q % n) * ctx, (size_t)ctx * sizeof(int32_t));
  ASSERT_OK(fg_clip_text(c, ids, many, temb));
  for (int q = 0; q < many; q++)
    ASSERT(max_abs_diff(temb + (size_t)q * E, g_text.f + (size_t)(q % n) * E, (size_t)E) <= TOL);
  float *xs = malloc((size_t)many * px * sizeof(float)), *dn = malloc((size_t)many * per * sizeof(float));
  for (int q = 0; q < many; q++) memcpy(xs + (size_t)q * px, g_dense_in.f, px * sizeof(float));
  ASSERT_OK(fg_clip_image_dense(c, xs, many, H, W, dn));
  for (int q = 0; q < many; q++) ASSERT(max_abs_diff(dn + (size_t)q * per, g_dense.f, per) <= TOL);
  free(ids), free(temb), free(xs), free(dn);
  fg_clip_free(c);
}

/* Two threads calling one model at once get the answers each gets alone. */
typedef struct worker {
  fg_clip *c;
  int ok;
} worker;

static void *worker_run(void *arg) {
  worker *wk = arg;
  const int H = (int)g_dense_in.shape[2], W = (int)g_dense_in.shape[3];
  float *out = malloc(g_dense.count * sizeof(float));
  wk->ok = 1;
  for (int r = 0; r < 20 && wk->ok; r++)
    wk->ok = fg_clip_image_dense(wk->c, g_dense_in.f, 1, H, W, out) == 0 &&
             max_abs_diff(out, g_dense.f, g_dense.count) <= TOL;
  free(out);
  return NULL;
}

static void check_concurrent(const char *path) {
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, path));
  fg_clip_set_threads(c, 1);
  worker w[2] = {{c, 0}, {c, 0}};
  pthread_t th[2];
  for (int i = 0; i < 2; i++) ASSERT_EQ(pthread_create(&th[i], NULL, worker_run, &w[i]), 0);
  for (int i = 0; i < 2; i++) pthread_join(th[i], NULL);
  ASSERT(w[0].ok && w[1].ok);
  fg_clip_free(c);
}

static void check_bad_inputs(const char *path) {
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, path));
  const fg_clip_info *in = fg_clip_get_info(c);
  float out[4096];
  int32_t ids[77] = {49406, 320, 49407};
  ids[1] = in->vocab_size;
  ASSERT_ERR(fg_clip_text(c, ids, 1, out), FG_EINVAL, "vocabulary");
  ids[1] = -1;
  ASSERT_ERR(fg_clip_text(c, ids, 1, out), FG_EINVAL, "vocabulary");
  ASSERT_ERR(fg_clip_text(c, ids, 0, out), FG_EINVAL, "");
  int hp, wp;
  ASSERT_ERR(fg_clip_dense_grid(c, 7, 64, &hp, &wp), FG_EINVAL, "patch");
  ASSERT_ERR(fg_clip_dense_grid(c, 8, 8 * 5000, &hp, &wp), FG_ERANGE, "patches");
  ASSERT_ERR(fg_clip_image_dense(c, g_dense_in.f, 1, 7, 64, out), FG_EINVAL, "patch");
  ASSERT_ERR(fg_clip_image_dense(c, g_dense_in.f, 0, 32, 32, out), FG_EINVAL, "");
  fg_clip_free(c);
  char *missing = fg_path_join(tmpdir, "no-such-file.safetensors");
  fg_clip *none = (fg_clip *)1;
  ASSERT_ERR(fg_clip_load(&none, missing), FG_ENOENT, "");
  ASSERT(none == NULL);
  free(missing);
}

/* A file that is valid safetensors but not a whole CLIP: one tensor missing, or of the wrong
 * shape or dtype, is refused with its name. */
static void check_incomplete_models(void) {
  clipgen_cfg cfg;
  ASSERT_OK(clipgen_cfg_preset(&cfg, CLIPGEN_TINY));
  clipgen_tensor *ts;
  int n;
  ASSERT_OK(clipgen_tensors(&cfg, &ts, &n));
  /* Rebuild the tiny file by hand with one change at a time: drop, reshape, retype. */
  const char *victims[] = {"visual.transformer.resblocks.1.mlp.c_fc.bias", "ln_final.weight",
                           "visual.proj"};
  for (int v = 0; v < 3; v++)
    for (int mode = 0; mode < 3; mode++) {
      char *path = fg_path_join(tmpdir, "broken.safetensors");
      FILE *f = fopen(path, "wb");
      ASSERT(f);
      static char hdr[1 << 20];
      size_t hl = 0, off = 0;
      hl += (size_t)snprintf(hdr + hl, sizeof hdr - hl, "{");
      for (int i = 0; i < n; i++) {
        const clipgen_tensor *t = &ts[i];
        const int hit = strcmp(t->name, victims[v]) == 0;
        if (hit && mode == 0) continue;
        const char *dt = t->is_i64 ? "I64" : (hit && mode == 2 ? "I32" : "F32");
        size_t count = t->count;
        hl += (size_t)snprintf(hdr + hl, sizeof hdr - hl,
                               "%s\"%s\":{\"dtype\":\"%s\",\"shape\":[", hl > 1 ? "," : "",
                               t->name, dt);
        for (int d = 0; d < t->ndim; d++)
          hl += (size_t)snprintf(hdr + hl, sizeof hdr - hl, "%s%lld", d ? "," : "",
                                 (long long)(hit && mode == 1 && d == 0 ? t->shape[d] + 1
                                                                        : t->shape[d]));
        if (hit && mode == 1) count = count / (size_t)t->shape[0] * (size_t)(t->shape[0] + 1);
        const size_t nb = count * (t->is_i64 ? 8 : 4);
        hl += (size_t)snprintf(hdr + hl, sizeof hdr - hl, "],\"data_offsets\":[%zu,%zu]}", off,
                               off + nb);
        off += nb;
      }
      hl += (size_t)snprintf(hdr + hl, sizeof hdr - hl, "}");
      while (hl % 8) hdr[hl++] = ' ';
      const uint64_t hl64 = hl;
      fwrite(&hl64, 8, 1, f);
      fwrite(hdr, 1, hl, f);
      char zero[4096] = {0};
      for (size_t k = 0; k < off; k += sizeof zero)
        fwrite(zero, 1, off - k < sizeof zero ? off - k : sizeof zero, f);
      fclose(f);
      fg_clip *c = (fg_clip *)1;
      const int rc = fg_clip_load(&c, path);
      printf("  %s %s: %s\n", mode == 0 ? "without" : (mode == 1 ? "reshaped" : "retyped"),
             victims[v], fg_error_detail());
      ASSERT_EQ(rc, FG_EFORMAT);
      ASSERT(c == NULL);
      ASSERT_STRCONTAINS(fg_error_detail(), victims[v]);
      unlink(path);
      free(path);
    }
  free(ts);
}

/* fg_clip_preprocess against PIL's resize + ToTensor + Normalize (preprocess_*.npy). */
static void check_preprocess(const char *model, const char *png, const char *want_name) {
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, model));
  char *path = data_path(png), *buf;
  size_t len;
  ASSERT_OK(fg_read_file(path, 1 << 24, &buf, &len));
  const float bg[3] = {1, 1, 1};
  fg_image img;
  ASSERT_OK(fg_image_decode(buf, len, bg, &img));
  golden want = load_golden(want_name);
  float *x;
  int H, W;
  ASSERT_OK(fg_clip_preprocess(c, img.rgb, img.w, img.h, 1, &x, &H, &W));
  ASSERT_EQ(want.ndim, 3);
  ASSERT_EQ(want.shape[0], 3);
  ASSERT_EQ(want.shape[1], (size_t)H);
  ASSERT_EQ(want.shape[2], (size_t)W);
  double err = max_abs_diff(x, want.f, want.count);
  printf("  preprocess %s %dx%d -> %dx%d: max abs error %.3g\n", png, img.w, img.h, W, H, err);
  ASSERT(err <= 1e-6); /* PIL's integer arithmetic, reproduced exactly */
  free(x);
  /* In floating point (no 8-bit rounding) it stays within a couple of levels of PIL. */
  ASSERT_OK(fg_clip_preprocess(c, img.rgb, img.w, img.h, 0, &x, &H, &W));
  err = max_abs_diff(x, want.f, want.count);
  printf("  ... in floating point: max abs error %.3g (%.2f levels)\n", err, err * 0.26 * 255);
  ASSERT(err <= 2.5 / 255 / 0.26);
  free(x);
  golden_free(&want);
  fg_image_release(&img);
  free(buf);
  free(path);
  ASSERT_ERR(fg_clip_preprocess(c, NULL, 0, 10, 1, &x, &H, &W), FG_EINVAL, "");
  fg_clip_free(c);
}

/* The recipes (recipes.h) against the model's own calls: texts tokenised, encoded and
 * normalised; the grid of an image and its limits; dense features and the pooled embedding of
 * an image as its preprocessing and the encoder give them; and the refusals. */
static void check_recipes(const char *path) {
  const char *shared = getenv("FG_SHARED_DATA");
  if (!shared) FG_TEST_FAIL("FG_SHARED_DATA is not set (run through meson test)");
  char *vocab = fg_path_join(shared, "clip/bpe_simple_vocab_16e6.txt.gz");
  fg_tokenizer *tok;
  ASSERT_OK(fg_tokenizer_load(&tok, vocab));
  free(vocab);
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, path));
  const fg_clip_info *in = fg_clip_get_info(c);
  const int E = in->embed_dim, ctx = in->context_length, S = in->image_size;

  /* texts: the embeddings of their ids, each scaled to unit length */
  const char *const texts[] = {"a mug", "a photo of a cat on a table"};
  float *got = malloc(2 * (size_t)E * sizeof *got), *want = malloc(2 * (size_t)E * sizeof *want);
  int32_t *ids = malloc(2 * (size_t)ctx * sizeof *ids);
  int bad = 7;
  ASSERT_OK(fg_clip_embed_texts(c, tok, texts, 2, 0, 1, got, &bad));
  for (int i = 0; i < 2; i++)
    ASSERT_OK(fg_tokenizer_encode(tok, texts[i], ctx, 0, ids + (size_t)i * ctx, NULL));
  ASSERT_OK(fg_clip_text(c, ids, 2, want));
  for (int i = 0; i < 2; i++) {
    ASSERT_OK(fg_l2_normalize(want + (size_t)i * E, E));
    double n2 = 0;
    for (int k = 0; k < E; k++) n2 += (double)got[(size_t)i * E + k] * got[(size_t)i * E + k];
    ASSERT_NEAR(n2, 1.0, 1e-5);
  }
  ASSERT(max_abs_diff(got, want, 2 * (size_t)E) <= 1e-6);
  /* refusals, naming the text at fault */
  const char *const blank[] = {"a mug", " \t\n"};
  ASSERT_ERR(fg_clip_embed_texts(c, tok, blank, 2, 0, 1, got, &bad), FG_EINVAL, "empty");
  ASSERT_EQ(bad, 1);
  char *long_text = malloc(FG_CLIP_MAX_TEXT_BYTES + 2);
  memset(long_text, 'a', FG_CLIP_MAX_TEXT_BYTES + 1);
  long_text[FG_CLIP_MAX_TEXT_BYTES + 1] = '\0';
  const char *const too_long[] = {long_text};
  ASSERT_ERR(fg_clip_embed_texts(c, tok, too_long, 1, 1, 1, got, &bad), FG_EINVAL, "limit");
  ASSERT_EQ(bad, 0);
  free(long_text);
  ASSERT_ERR(fg_clip_embed_texts(c, tok, texts, 0, 0, 1, got, &bad), FG_EINVAL, "texts");
  free(ids);
  free(want);
  free(got);

  /* the grid: whole patches of the image resized to a short side of S, within the limit */
  int hp, wp;
  ASSERT_OK(fg_clip_image_grid(c, 3 * S, S, &hp, &wp));
  ASSERT_EQ(hp, S / in->patch_size);
  ASSERT_EQ(wp, 3 * S / in->patch_size);
  ASSERT_ERR(fg_clip_image_grid(c, 0, 10, &hp, &wp), FG_EINVAL, "pixels");
  ASSERT_ERR(fg_clip_image_grid(c, 20000, 1, &hp, &wp), FG_ERANGE, "patches");

  /* an image: dense features and the pooled embedding as the encoder gives them */
  const int w = S + 5, h = S;
  float *rgb = malloc((size_t)w * h * 3 * sizeof *rgb);
  for (size_t i = 0; i < (size_t)w * h * 3; i++) rgb[i] = (float)((i * 37) % 101) / 100.0f;
  float *dense = NULL, *x = NULL;
  ASSERT_OK(fg_clip_dense_features(c, rgb, w, h, &dense, &hp, &wp));
  int H, W;
  ASSERT_OK(fg_clip_preprocess(c, rgb, w, h, 1, &x, &H, &W));
  float *dense_want = malloc((size_t)hp * wp * E * sizeof *dense_want);
  ASSERT_OK(fg_clip_image_dense(c, x, 1, H, W, dense_want));
  ASSERT(max_abs_diff(dense, dense_want, (size_t)hp * wp * E) == 0.0);
  /* pooled: the centre S x S crop of the preprocessed image, its offset W - S = 5 halved and
   * rounded to even: 2 */
  ASSERT_EQ(H, S);
  ASSERT_EQ(W, S + 5);
  float *crop = malloc((size_t)3 * S * S * sizeof *crop);
  for (int ch = 0; ch < 3; ch++)
    for (int y = 0; y < S; y++)
      memcpy(crop + ((size_t)ch * S + y) * S, x + ((size_t)ch * H + y) * W + 2,
             (size_t)S * sizeof *crop);
  float *pooled = malloc((size_t)E * sizeof *pooled);
  float *pooled_want = malloc((size_t)E * sizeof *pooled_want);
  ASSERT_OK(fg_clip_pooled_embedding(c, rgb, w, h, pooled));
  ASSERT_OK(fg_clip_image_pooled(c, crop, 1, pooled_want));
  ASSERT(max_abs_diff(pooled, pooled_want, (size_t)E) == 0.0);
  ASSERT_ERR(fg_clip_pooled_embedding(c, rgb, 0, h, pooled), FG_EINVAL, "pixels");
  free(pooled_want);
  free(pooled);
  free(crop);
  free(dense_want);
  free(x);
  free(dense);
  free(rgb);
  fg_clip_free(c);
  fg_tokenizer_free(tok);
}

int main(void) {
  ASSERT(mkdtemp(tmpdir));
  g_dense_in = load_golden("golden_dense_input.npy");
  g_dense = load_golden("golden_dense.npy");
  g_sq_in = load_golden("golden_dense_square_input.npy");
  g_sq = load_golden("golden_dense_square.npy");
  g_pooled_in = load_golden("golden_pooled_input.npy");
  g_pooled = load_golden("golden_pooled.npy");
  g_ids = load_golden("golden_text_ids.npy");
  g_text = load_golden("golden_text.npy");

  char *f32 = write_model(CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  check_generator_matches_goldens(f32);
  for (int naming = 0; naming < 2; naming++)
    for (int dtype = 0; dtype < 3; dtype++) {
      if (naming == CLIPGEN_OPENAI && dtype == CLIPGEN_F32) {
        check_model(f32);
        continue;
      }
      char *p = write_model((clipgen_naming)naming, (clipgen_dtype)dtype, 1);
      check_model(p);
      unlink(p);
      free(p);
    }
  check_batch_and_threads(f32);
  check_concurrent(f32);
  check_bad_inputs(f32);
  check_recipes(f32);
  check_incomplete_models();
  check_preprocess(f32, "preprocess_in.png", "preprocess_golden.npy");
  check_preprocess(f32, "preprocess_in_20x14.png", "preprocess_golden_20x14.npy");

  /* Without metadata the head counts default to width / 64 (1 for these widths): the model
   * loads and runs, and its outputs differ from the 3- and 5-head goldens. */
  char *nometa = write_model(CLIPGEN_OPENAI, CLIPGEN_F32, 0);
  fg_clip *c;
  ASSERT_OK(fg_clip_load(&c, nometa));
  ASSERT_EQ(fg_clip_get_info(c)->vision_heads, 1);
  ASSERT_EQ(fg_clip_get_info(c)->text_heads, 1);
  float *t1 = malloc(g_text.count * sizeof(float));
  ASSERT_OK(fg_clip_text(c, g_ids.i, (int)g_ids.shape[0], t1));
  ASSERT(max_abs_diff(t1, g_text.f, g_text.count) > 1e-3);
  free(t1);
  fg_clip_free(c);
  unlink(nometa);
  free(nometa);

  unlink(f32);
  free(f32);
  golden *all[] = {&g_dense_in, &g_dense, &g_sq_in, &g_sq, &g_pooled_in, &g_pooled, &g_ids,
                   &g_text};
  for (size_t i = 0; i < sizeof all / sizeof *all; i++) golden_free(all[i]);
  ASSERT_OK(fg_rmtree(tmpdir));
  printf("ok\n");
  return 0;
}
