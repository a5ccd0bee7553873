/* CLIP over HTTP: POST /v1/embed/text and /v1/embed/image against the library run in this
 * process on the same files (which proves the routes compute, not just answer), their
 * errors, 409 without [clip], start-up errors for weights that do not load, and SIGHUP:
 * changed weights switch the model, broken ones keep the old. */
#include <math.h>
#include <stdio.h>
#include <unistd.h>

#include "clip_util.h"
#include "core/digest.h"
#include "core/error.h"
#include "io/npy.h"

static char *g_weights, *g_vocab;
static int g_E;

/* POST /v1/embed/text with a JSON body; the caller frees the reply. */
static h_resp *embed(const char *body) { return h_post_json("/v1/embed/text", body); }

/* The embeddings of one text over HTTP: out [E], and the reply's model fingerprint (static). */
static const char *embed_one(const char *text, float *out) {
  static char fp[FG_SHA256_HEX + 1];
  char *body = h_fmt("{\"text\": \"%s\"}", text);
  h_resp *r = embed(body);
  free(body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "dim"), g_E);
  ASSERT_EQ(json_array_size(JGET(r->json, "embeddings")), 1);
  float *v = c_floats(JGET(r->json, "embeddings.0"), g_E, NULL);
  memcpy(out, v, (size_t)g_E * sizeof *v);
  free(v);
  snprintf(fp, sizeof fp, "%s", JSTR(r->json, "model.fingerprint"));
  h_resp_free(r);
  return fp;
}

static h_resp *post_image(const char *query, const void *data, size_t len) {
  char *path = h_fmt("/v1/embed/image%s", query);
  h_req q = {.method = "POST", .path = path, .body = data, .body_len = len,
             .content_type = "image/png"};
  h_resp *r = h_request(&q);
  free(path);
  return r;
}

/* The daemon refuses to start with conf_text; its output names every string in needles. */
static void expect_refusal(const char *conf_text, const char *const *needles) {
  char *conf = h_fmt("%s/bad.conf", h_tmpdir());
  h_write_file(conf, conf_text, strlen(conf_text));
  char *state = h_fmt("%s/state-bad", h_tmpdir());
  const char *args[] = {"--config", conf, "--state-dir", state, "--listen", "127.0.0.1:0", NULL};
  char *out = NULL;
  int rc = h_run_daemon_capture(args, &out);
  if (rc == 0 || rc >= 128) FG_TEST_FAIL("exit %d, expected a failure exit; output: %s", rc, out);
  for (int i = 0; needles[i]; i++) ASSERT_STRCONTAINS(out, needles[i]);
  ASSERT(strstr(out, "listening on") == NULL);
  free(out);
  free(state);
  free(conf);
}

/* ---------------------------------------------------------------- without [clip] */

static void without_clip(void) {
  h_start();
  h_resp *r = embed("{\"text\": [\"a mug\"]}");
  ASSERT_HTTP_ERROR(r, 409, "clip_not_configured");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "[clip]");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "weights =");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "vocab =");
  h_resp_free(r);
  uint8_t *png;
  size_t len;
  h_png(32, 32, 3, 8, 1, 0, &png, &len);
  r = post_image("", png, len);
  ASSERT_HTTP_ERROR(r, 409, "clip_not_configured");
  h_resp_free(r);
  r = post_image("?output=pooled", png, len);
  ASSERT_HTTP_ERROR(r, 409, "clip_not_configured");
  h_resp_free(r);
  free(png);
  ASSERT_EQ(h_metric("fieldgrip_clip_model_loaded"), 0);
  h_stop();
}

/* ---------------------------------------------------------------- start-up errors */

static void startup_errors(void) {
  char *missing = h_fmt("%s/no-such-weights.safetensors", h_tmpdir());
  char *conf = c_config(missing, g_vocab, NULL);
  char *bad_conf = h_fmt("%s/bad.conf", h_tmpdir());
  char *where = h_fmt("%s:2: [clip] weights", bad_conf); /* "[clip]" is line 1 */
  const char *n1[] = {missing, where, "cannot load", NULL};
  expect_refusal(conf, n1);
  free(conf);
  free(where);

  /* not a safetensors file at all */
  char *junk = h_fmt("%s/junk.safetensors", h_tmpdir());
  h_write_file(junk, "this is not a weights file", 26);
  conf = c_config(junk, g_vocab, NULL);
  const char *n2[] = {junk, "[clip] weights", NULL};
  expect_refusal(conf, n2);
  free(conf);

  /* the vocabulary is checked as well */
  char *novocab = h_fmt("%s/no-such-vocab.txt.gz", h_tmpdir());
  conf = c_config(g_weights, novocab, NULL);
  const char *n3[] = {novocab, "[clip] vocab", NULL};
  expect_refusal(conf, n3);
  free(conf);

  /* [clip] without vocab is a configuration error */
  char *half = h_fmt("[clip]\nweights = %s\n", g_weights);
  const char *n4[] = {"[clip] vocab", "both", NULL};
  expect_refusal(half, n4);
  free(half);
  free(novocab);
  free(junk);
  free(bad_conf);
  free(missing);
}

/* ---------------------------------------------------------------- text */

static void text_endpoint(void) {
  float *mine = malloc((size_t)g_E * sizeof *mine);
  float *theirs = malloc((size_t)g_E * sizeof *theirs);
  ASSERT(mine && theirs);
  static const char *const texts[] = {"a mug", "a spoon", "a red apple on the table",
                                      "Ein Löffel, bitte!"};
  enum { N = 4 };
  float *single[N];
  for (int i = 0; i < N; i++) {
    single[i] = malloc((size_t)g_E * sizeof(float));
    ASSERT(single[i]);
    c_local_text(g_weights, g_vocab, texts[i], 0, mine);
    embed_one(texts[i], single[i]);
    C_ASSERT_CLOSE(single[i], mine, (size_t)g_E, 1e-5, texts[i]);
  }
  /* different texts, different embeddings */
  ASSERT(c_max_diff(single[0], single[1], (size_t)g_E) > 1e-3);
  ASSERT(c_max_diff(single[1], single[2], (size_t)g_E) > 1e-3);

  /* a batch is the singles */
  h_resp *r = embed("{\"text\": [\"a mug\", \"a spoon\", \"a red apple on the table\", "
                    "\"Ein L\\u00f6ffel, bitte!\"]}");
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "application/json");
  ASSERT_EQ(json_array_size(JGET(r->json, "embeddings")), N);
  ASSERT(json_is_false(JGET(r->json, "normalized")));
  for (int i = 0; i < N; i++) {
    char key[32];
    snprintf(key, sizeof key, "embeddings.%d", i);
    float *v = c_floats(JGET(r->json, key), g_E, NULL);
    C_ASSERT_CLOSE(v, single[i], (size_t)g_E, 1e-5, key);
    free(v);
  }
  /* the model object */
  ASSERT_EQ(JINT(r->json, "model.embed_dim"), g_E);
  ASSERT_STREQ(JSTR(r->json, "model.dtype"), "F32");
  ASSERT_STREQ(JSTR(r->json, "model.naming"), "openai");
  ASSERT_EQ(JINT(r->json, "model.image_size"), 32);
  ASSERT_EQ(JINT(r->json, "model.patch_size"), 8);
  ASSERT_EQ(JINT(r->json, "model.context_length"), 77);
  /* the weights file's SHA-256 in hex, as sha256sum prints it */
  const char *fp = JSTR(r->json, "model.fingerprint");
  ASSERT_EQ(strlen(fp), FG_SHA256_HEX);
  ASSERT_EQ(strspn(fp, "0123456789abcdef"), FG_SHA256_HEX);
  h_resp_free(r);

  /* normalize: unit rows in the same direction */
  r = embed("{\"text\": [\"a mug\"], \"normalize\": true}");
  ASSERT_STATUS(r, 200);
  ASSERT(json_is_true(JGET(r->json, "normalized")));
  float *v = c_floats(JGET(r->json, "embeddings.0"), g_E, NULL);
  double ss = 0, norm0 = 0;
  for (int k = 0; k < g_E; k++) {
    ss += (double)v[k] * v[k];
    norm0 += (double)single[0][k] * single[0][k];
  }
  ASSERT_NEAR(ss, 1.0, 1e-5);
  for (int k = 0; k < g_E; k++) theirs[k] = (float)(single[0][k] / sqrt(norm0));
  C_ASSERT_CLOSE(v, theirs, (size_t)g_E, 1e-5, "normalized");
  free(v);
  h_resp_free(r);

  /* too long: 100 words is more than 75 tokens; truncate embeds the first 75 */
  it_buf longtext = {0};
  for (int i = 0; i < 100; i++) it_buf_add(&longtext, "mug ", 4);
  char *body = h_fmt("{\"text\": [\"%s\"]}", longtext.p);
  r = embed(body);
  ASSERT_HTTP_ERROR(r, 400, "text_too_long");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "truncate");
  h_resp_free(r);
  free(body);
  body = h_fmt("{\"text\": [\"%s\"], \"truncate\": true}", longtext.p);
  r = embed(body);
  ASSERT_STATUS(r, 200);
  v = c_floats(JGET(r->json, "embeddings.0"), g_E, NULL);
  c_local_text(g_weights, g_vocab, longtext.p, 1, mine);
  C_ASSERT_CLOSE(v, mine, (size_t)g_E, 1e-5, "truncated");
  free(v);
  h_resp_free(r);
  free(body);
  free(longtext.p);

  /* refusals */
  static const struct {
    const char *body;
    long status;
    const char *code;
  } bad[] = {
      {"{\"text\": []}", 400, "invalid_request"},
      {"{\"text\": [1]}", 400, "invalid_request"},
      {"{\"text\": [\"a mug\", null]}", 400, "invalid_request"},
      {"{\"text\": 5}", 400, "invalid_request"},
      {"{}", 400, "invalid_request"},
      {"{\"text\": [\"a mug\"], \"colour\": 1}", 400, "invalid_request"},
      {"{\"text\": [\"a mug\"], \"truncate\": \"yes\"}", 400, "invalid_request"},
      {"{\"text\": \"\"}", 400, "invalid_text"},
      {"{\"text\": [\"a mug\", \"   \"]}", 400, "invalid_text"},
      {"{\"text\": [\"a mug\"", 400, "malformed_json"},
      {"[\"a mug\"]", 400, "invalid_request"},
      {"{\"text\": [\"\\ud800\"]}", 400, "malformed_json"}, /* a lone surrogate is not UTF-8 */
  };
  for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
    r = embed(bad[i].body);
    if (r->status != bad[i].status) fprintf(stderr, "case: %s\n", bad[i].body);
    ASSERT_HTTP_ERROR(r, bad[i].status, bad[i].code);
    h_resp_free(r);
  }
  /* too many texts */
  it_buf many = {0};
  it_buf_add(&many, "{\"text\": [", 10);
  for (int i = 0; i < 257; i++) it_buf_add(&many, i ? ", \"x\"" : "\"x\"", i ? 5 : 3);
  it_buf_add(&many, "]}", 2);
  r = embed(many.p);
  ASSERT_HTTP_ERROR(r, 400, "too_many_texts");
  h_resp_free(r);
  free(many.p);

  for (int i = 0; i < N; i++) free(single[i]);
  free(mine);
  free(theirs);
}

/* ---------------------------------------------------------------- images */

/* torchvision's CenterCrop offset: int(round((size - crop) / 2.0)), round half to even. */
static int crop_offset(int size, int crop) {
  return (int)nearbyint((size - crop) / 2.0);
}

static void image_endpoint(void) {
  /* 40x30 RGB: the short side becomes 32, the long one int(32 * 40 / 30) = 42: a 4x5 grid */
  uint8_t *png;
  size_t len;
  h_png(40, 30, 3, 8, 7, 0, &png, &len);
  h_resp *r = post_image("", png, len);
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "application/x-npy");
  fg_npy npy;
  ASSERT_OK(fg_npy_parse(r->body, r->len, &npy));
  ASSERT_EQ(npy.dtype, FG_DTYPE_F32);
  ASSERT_EQ(npy.ndim, 3);
  int hp, wp;
  float *mine = c_local_dense(g_weights, png, len, &hp, &wp);
  ASSERT_EQ(hp, 4);
  ASSERT_EQ(wp, 5);
  ASSERT_EQ(npy.shape[0], hp);
  ASSERT_EQ(npy.shape[1], wp);
  ASSERT_EQ(npy.shape[2], g_E);
  C_ASSERT_CLOSE((const float *)npy.data, mine, npy.count, 1e-5, "dense features");
  free(mine);
  /* ?output=dense is the default */
  h_resp *r2 = post_image("?output=dense", png, len);
  ASSERT_STATUS(r2, 200);
  ASSERT_EQ(r2->len, r->len);
  ASSERT(memcmp(r2->body, r->body, r->len) == 0);
  h_resp_free(r2);
  h_resp_free(r);

  /* an RGBA image is composited on white, as here */
  uint8_t *rgba;
  size_t rgba_len;
  h_png(24, 48, 4, 8, 3, 0, &rgba, &rgba_len);
  r = post_image("", rgba, rgba_len);
  ASSERT_STATUS(r, 200);
  ASSERT_OK(fg_npy_parse(r->body, r->len, &npy));
  mine = c_local_dense(g_weights, rgba, rgba_len, &hp, &wp);
  ASSERT_EQ(npy.shape[0], hp);
  ASSERT_EQ(npy.shape[1], wp);
  C_ASSERT_CLOSE((const float *)npy.data, mine, npy.count, 1e-5, "RGBA dense features");
  free(mine);
  h_resp_free(r);

  /* pooled: CLIP's own preprocessing, i.e. the centre crop of the resized image; sizes whose
   * crop offsets are 5 (40x30 -> 42x32), 0 (33x32: 0.5 rounds to 0) and 2 (35x32: 1.5 -> 2) */
  static const int sizes[][2] = {{40, 30}, {33, 32}, {35, 32}, {30, 45}};
  float *pooled = malloc((size_t)g_E * sizeof *pooled);
  ASSERT(pooled);
  for (size_t i = 0; i < sizeof sizes / sizeof sizes[0]; i++) {
    int w = sizes[i][0], h = sizes[i][1];
    uint8_t *img;
    size_t img_len;
    h_png(w, h, 3, 8, 11 + (unsigned)i, 0, &img, &img_len);
    int W = w <= h ? 32 : (int)(32.0 * w / h), H = w <= h ? (int)(32.0 * h / w) : 32;
    c_local_pooled(g_weights, img, img_len, crop_offset(W, 32), crop_offset(H, 32), pooled);
    r = post_image("?output=pooled", img, img_len);
    ASSERT_STATUS(r, 200);
    ASSERT_EQ(JINT(r->json, "dim"), g_E);
    float *v = c_floats(JGET(r->json, "embedding"), g_E, NULL);
    C_ASSERT_CLOSE(v, pooled, (size_t)g_E, 1e-5, "pooled embedding");
    free(v);
    h_resp_free(r);
    free(img);
  }
  free(pooled);

  /* refusals */
  r = post_image("", "not an image at all", 19);
  ASSERT_HTTP_ERROR(r, 415, "unsupported_media_type");
  h_resp_free(r);
  r = post_image("", png, len / 2); /* a truncated PNG */
  ASSERT_HTTP_ERROR(r, 400, "invalid_image");
  h_resp_free(r);
  r = post_image("", NULL, 0);
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  r = post_image("?output=cls", png, len);
  ASSERT_HTTP_ERROR(r, 400, "invalid_request");
  h_resp_free(r);
  /* 1040x8 would be a 4x520 grid: more patches than the server computes */
  uint8_t *strip;
  size_t strip_len;
  h_png(1040, 8, 3, 8, 2, 0, &strip, &strip_len);
  r = post_image("", strip, strip_len);
  ASSERT_HTTP_ERROR(r, 400, "invalid_image");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "aspect ratio");
  h_resp_free(r);
  free(strip);
  /* a multipart form is not the image itself */
  h_part part = {"image", png, len, "x.png", "image/png"};
  h_req q = {.method = "POST", .path = "/v1/embed/image", .parts = &part, .n_parts = 1};
  r = h_request(&q);
  ASSERT_HTTP_ERROR(r, 415, "unsupported_media_type");
  h_resp_free(r);
  free(png);
  free(rgba);
}

/* ---------------------------------------------------------------- reloads */

static void reloads(void) {
  float *before = malloc((size_t)g_E * sizeof *before);
  float *after = malloc((size_t)g_E * sizeof *after);
  float *mine = malloc((size_t)g_E * sizeof *mine);
  ASSERT(before && after && mine);
  char fp0[FG_SHA256_HEX + 1], fp1[FG_SHA256_HEX + 1];
  snprintf(fp0, sizeof fp0, "%s", embed_one("a mug", before));
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"ok\"}"), 1);

  /* Each step waits for the end of its reload (h_reload), not for one of its signs: the
   * CLIP load is counted and the log written before the reload ends, and a count of log
   * lines taken while a reload is still running lets the next wait end on the wrong one. */

  /* a reload with nothing changed keeps the model */
  h_reload();
  ASSERT_EQ(h_log_count("configuration reloaded"), 1);
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"ok\"}"), 1);

  /* new weights (another seed, Hugging Face names, BF16), renamed over the configured file */
  c_write_model(g_weights, CLIPGEN_HF, CLIPGEN_BF16, 2);
  h_reload();
  ASSERT_EQ(h_log_count("configuration reloaded"), 2);
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"ok\"}"), 2);
  snprintf(fp1, sizeof fp1, "%s", embed_one("a mug", after));
  ASSERT(strcmp(fp0, fp1) != 0);
  ASSERT(c_max_diff(before, after, (size_t)g_E) > 1e-3);
  c_local_text(g_weights, g_vocab, "a mug", 0, mine);
  C_ASSERT_CLOSE(after, mine, (size_t)g_E, 1e-5, "embedding after the reload");
  h_resp *r = embed("{\"text\": \"a mug\"}");
  ASSERT_STREQ(JSTR(r->json, "model.dtype"), "BF16");
  ASSERT_STREQ(JSTR(r->json, "model.naming"), "hf");
  h_resp_free(r);

  /* broken weights: the reload logs why and the model stays */
  char *tmp = h_fmt("%s.new", g_weights);
  h_write_file(tmp, "\x10\0\0\0\0\0\0\0{\"a\": 1}", 16);
  ASSERT_EQ(rename(tmp, g_weights), 0);
  h_reload();
  ASSERT_EQ(h_log_count("configuration reloaded"), 3);
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"failed\"}"), 1);
  char *log = h_log();
  const char *line = strstr(log, "reload: ");
  ASSERT(line != NULL);
  ASSERT_STRCONTAINS(line, g_weights);
  ASSERT_STRCONTAINS(line, "stays in use");
  free(log);
  ASSERT(h_alive());
  float *still = malloc((size_t)g_E * sizeof *still);
  ASSERT(still);
  ASSERT_STREQ(embed_one("a mug", still), fp1);
  C_ASSERT_CLOSE(still, after, (size_t)g_E, 0, "embedding after a failed reload");
  ASSERT_EQ(h_metric("fieldgrip_clip_model_loaded"), 1);

  /* [clip] removed: 409 again */
  h_write_config("[train]\nthreads = 2\n");
  h_reload();
  r = embed("{\"text\": \"a mug\"}");
  ASSERT_HTTP_ERROR(r, 409, "clip_not_configured");
  h_resp_free(r);
  ASSERT_EQ(h_metric("fieldgrip_clip_model_loaded"), 0);

  /* [clip] back, but its weights are still the broken file: 409 says why */
  char *conf = c_config(g_weights, g_vocab, NULL);
  h_write_config(conf);
  free(conf);
  h_reload();
  ASSERT_EQ(h_metric("fieldgrip_clip_loads_total{result=\"failed\"}"), 2);
  r = embed("{\"text\": \"a mug\"}");
  ASSERT_HTTP_ERROR(r, 409, "clip_not_configured");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "did not load");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), g_weights);
  h_resp_free(r);
  free(still);
  free(tmp);
  free(before);
  free(after);
  free(mine);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  g_weights = h_fmt("%s/clip.safetensors", h_tmpdir());
  g_vocab = c_vocab_path();
  c_write_model(g_weights, CLIPGEN_OPENAI, CLIPGEN_F32, 1);
  g_E = c_embed_dim(g_weights);
  ASSERT_EQ(g_E, 24);

  without_clip();
  startup_errors();

  char *conf = c_config(g_weights, g_vocab, NULL);
  h_write_config(conf);
  free(conf);
  h_start();
  ASSERT_EQ(h_metric("fieldgrip_clip_model_loaded"), 1);
  text_endpoint();
  image_endpoint();
  ASSERT(h_metric("fieldgrip_clip_embeddings_total{kind=\"text\"}") >= 8);
  ASSERT(h_metric("fieldgrip_clip_embeddings_total{kind=\"image_dense\"}") >= 3);
  ASSERT_EQ(h_metric("fieldgrip_clip_embeddings_total{kind=\"image_pooled\"}"), 4);
  reloads();
  h_stop();
  free(g_weights);
  free(g_vocab);
  h_done();
  printf("ok\n");
  return 0;
}
