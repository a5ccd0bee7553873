/* POST /v1/scenes/{s}/heatmap and renders with "output": "heatmap", black-box over HTTP on a
 * trained scenegen tabletop whose class embeddings (gt.json) serve as queries:
 *   - 409 not_trained on an untrained scene, 400 grid_too_large for a workspace over the limit;
 *   - json: the best point of each object's class embedding lies in that object's box, points
 *     come best first and agree with "best"; min_score and max_points bound the list; the same
 *     query gives the same bytes; negatives give scores in [0, 1];
 *   - npy: parses (fg_npy_parse) as float32 [nz, ny, nx], NaN exactly where free, its maximum
 *     the json's best; ply: a binary little-endian PLY with one vertex per json point;
 *   - the voxel cache is built once per field (scene JSON, /metrics), dropped by a new
 *     training and built again;
 *   - a heatmap answers while another scene trains;
 *   - every bad input gives its JSON error;
 *   - the heatmap render of a training view has the camera's size and its hottest pixels on
 *     the queried object (scenegen's mask), the score recovered per pixel against the plain
 *     render through the turbo table;
 *   - the geometry endpoint and normal renders of the same trained scene
 *     (geometry_checks.c).
 * The trained scene is the trained fixture's (trained.h: 250 steps at 1 cm), copied.
 *
 * argv[1]: fieldgripd, argv[2]: fieldgrip-scenegen. */
#include <math.h>
#include <pthread.h>
#include <unistd.h>

#include "core/error.h"
#include "io/image.h"
#include "io/npy.h"
#include "geometry_checks.h"
#include "query/colormap.h"
#include "trained.h"
#include "training.h"
#include "views.h"

#define VIEWS 30
#define W 160
#define H 120
#define DIM 32
#define PATCH 8 /* feature cells of 8 pixels: the ball covers a few of them in most views */

static json_t *g_gt;     /* gt.json */
static json_t *g_frames; /* transforms.json */
static char *g_dir;      /* the data set */

/* The embedding of class `name` of gt.json as a JSON array text; caller frees. */
static char *class_embedding(const char *name) {
  json_t *classes = JGET(g_gt, "classes");
  for (size_t i = 0; i < json_array_size(classes); i++) {
    json_t *c = json_array_get(classes, i);
    if (strcmp(JSTR(c, "name"), name) == 0) return json_dumps(JGET(c, "embedding"), JSON_COMPACT);
  }
  FG_TEST_FAIL("no class %s in gt.json", name);
}

static h_resp *heatmap(const char *scene, const char *body) {
  char *path = h_fmt("/v1/scenes/%s/heatmap", scene);
  h_resp *r = h_post_json(path, body);
  free(path);
  return r;
}

/* A json heatmap of class name's embedding with extra keys (may be ""); asserts 200. */
static h_resp *class_heatmap(const char *name, const char *extra) {
  char *e = class_embedding(name);
  char *body = h_fmt("{\"embedding\": %s%s%s}", e, extra[0] ? ", " : "", extra);
  h_resp *r = heatmap("sg", body);
  if (r->status != 200) fprintf(stderr, "heatmap %s: %s\n", body, r->body);
  ASSERT_STATUS(r, 200);
  free(body);
  free(e);
  return r;
}

static void expect_error(const char *scene, const char *body, long status, const char *code) {
  h_resp *r = heatmap(scene, body);
  if (r->status != status) fprintf(stderr, "heatmap %s -> %s\n", body, r->body);
  ASSERT_HTTP_ERROR(r, status, code);
  h_resp_free(r);
}

/* ---------------------------------------------------------------- json, npy, ply */

static void test_objects(void) {
  json_t *objects = JGET(g_gt, "objects");
  for (size_t k = 0; k < json_array_size(objects); k++) {
    json_t *o = json_array_get(objects, k);
    const char *name = JSTR(o, "name");
    h_resp *r = class_heatmap(name, "\"max_points\": 1");
    json_t *best = JGET(r->json, "best.position");
    double vs = JNUM(r->json, "voxel_size");
    ASSERT_NEAR(vs, 0.01, 1e-12);
    printf("%s: best %.3f %.3f %.3f score %.3f, %lld occupied\n", name,
           JNUM(best, "0"), JNUM(best, "1"), JNUM(best, "2"), JNUM(r->json, "best.score"),
           JINT(r->json, "occupied"));
    /* Inside the object's box, give or take one voxel. */
    for (int a = 0; a < 3; a++) {
      char pa[16];
      snprintf(pa, sizeof pa, "%d", a);
      double p = JNUM(best, pa);
      double lo = JNUM(JGET(o, "aabb.min"), pa), hi = JNUM(JGET(o, "aabb.max"), pa);
      if (!(p >= lo - vs && p <= hi + vs))
        FG_TEST_FAIL("%s: best point axis %d at %.4f outside the object's box [%.4f, %.4f]", name,
                     a, p, lo, hi);
    }
    h_resp_free(r);
  }
}

static void test_json_bounds(void) {
  h_resp *all = class_heatmap("mug", "");
  json_t *pts = JGET(all->json, "points");
  size_t n = json_array_size(pts);
  long long occupied = JINT(all->json, "occupied");
  ASSERT(n > 10);
  ASSERT_EQ((long long)n, JINT(all->json, "returned"));
  ASSERT_EQ((long long)n, occupied);
  ASSERT_EQ(JINT(all->json, "grid.shape.0"), 40); /* z: -0.05 .. 0.35 */
  ASSERT_EQ(JINT(all->json, "grid.shape.1"), 90);
  ASSERT_EQ(JINT(all->json, "grid.shape.2"), 70);
  /* Best first; the first is "best". */
  for (size_t i = 0; i < n; i++) {
    json_t *p = json_array_get(pts, i);
    ASSERT_EQ(json_array_size(p), 4);
    ASSERT(json_real_value(json_array_get(p, 3)) >= -1.0 - 1e-6);
    ASSERT(json_real_value(json_array_get(p, 3)) <= 1.0 + 1e-6);
    if (i) ASSERT(JNUM(p, "3") <= JNUM(json_array_get(pts, i - 1), "3"));
  }
  ASSERT_NEAR(JNUM(pts, "0.3"), JNUM(all->json, "best.score"), 1e-9);
  for (int a = 0; a < 3; a++) {
    char pa[16], pb[24];
    snprintf(pa, sizeof pa, "%d", a);
    snprintf(pb, sizeof pb, "0.%d", a);
    ASSERT_NEAR(JNUM(pts, pb), JNUM(JGET(all->json, "best.position"), pa), 1e-5);
  }

  /* min_score keeps exactly the points at or above it (scores in the reply are rounded to
   * 1e-6: points that close to the cut may go either way). */
  double cut = JNUM(json_array_get(pts, n / 3), "3");
  size_t surely = 0, maybe = 0;
  for (size_t i = 0; i < n; i++) {
    double sc = JNUM(json_array_get(pts, i), "3");
    surely += sc >= cut + 1.5e-6;
    maybe += sc >= cut - 1.5e-6;
  }
  char *extra = h_fmt("\"min_score\": %.9g", cut);
  h_resp *r = class_heatmap("mug", extra);
  free(extra);
  json_t *cp = JGET(r->json, "points");
  ASSERT(json_array_size(cp) >= surely && json_array_size(cp) <= maybe);
  for (size_t i = 0; i < json_array_size(cp); i++)
    ASSERT(JNUM(json_array_get(cp, i), "3") >= cut - 1e-6);
  ASSERT(json_array_size(cp) < n);
  ASSERT_EQ(JINT(r->json, "occupied"), occupied);
  h_resp_free(r);

  /* max_points keeps the best ones, in order. */
  r = class_heatmap("mug", "\"max_points\": 5");
  cp = JGET(r->json, "points");
  ASSERT_EQ(json_array_size(cp), 5);
  ASSERT_EQ(JINT(r->json, "returned"), 5);
  for (size_t i = 0; i < 5; i++) ASSERT_JSON_EQUAL(json_array_get(cp, i), json_array_get(pts, i));
  h_resp_free(r);

  /* The same query, the same bytes. */
  r = class_heatmap("mug", "");
  ASSERT_EQ(r->len, all->len);
  ASSERT(memcmp(r->body, all->body, r->len) == 0);
  h_resp_free(r);

  /* A higher alpha_threshold: fewer occupied voxels. */
  r = class_heatmap("mug", "\"alpha_threshold\": 0.5");
  ASSERT(JINT(r->json, "occupied") < occupied);
  h_resp_free(r);

  /* Negatives (the other classes): scores in [0, 1], the best still on the mug. */
  char *bowl = class_embedding("bowl"), *box = class_embedding("box");
  extra = h_fmt("\"negative_embeddings\": [%s, %s], \"temperature\": 0.1", bowl, box);
  r = class_heatmap("mug", extra);
  cp = JGET(r->json, "points");
  for (size_t i = 0; i < json_array_size(cp); i++) {
    double s = JNUM(json_array_get(cp, i), "3");
    ASSERT(s >= 0 && s <= 1);
  }
  json_t *mug = json_array_get(JGET(g_gt, "objects"), 0);
  ASSERT_STREQ(JSTR(mug, "name"), "mug");
  double px = JNUM(r->json, "best.position.0");
  ASSERT((px >= JNUM(mug, "aabb.min.0") - 0.01 && px <= JNUM(mug, "aabb.max.0") + 0.01));
  h_resp_free(r);
  free(extra);
  free(bowl);
  free(box);

  /* npy: the whole grid, NaN where free, its maximum the best score. */
  r = class_heatmap("mug", "\"format\": \"npy\"");
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "application/x-npy");
  fg_npy npy;
  ASSERT_OK(fg_npy_parse(r->body, r->len, &npy));
  ASSERT_EQ(npy.dtype, FG_DTYPE_F32);
  ASSERT_EQ(npy.ndim, 3);
  ASSERT_EQ(npy.shape[0], 40);
  ASSERT_EQ(npy.shape[1], 90);
  ASSERT_EQ(npy.shape[2], 70);
  const float *g = npy.data;
  size_t finite = 0, arg = 0;
  float mx = -INFINITY;
  for (size_t i = 0; i < npy.count; i++) {
    if (isnan(g[i])) continue;
    finite++;
    if (g[i] > mx) mx = g[i], arg = i;
  }
  ASSERT_EQ((long long)finite, occupied);
  ASSERT_NEAR(mx, JNUM(all->json, "best.score"), 1e-6);
  /* Voxel (ix, iy, iz) is centred at min + (i + 0.5) * voxel_size. */
  size_t ix = arg % 70, iy = arg / 70 % 90, iz = arg / 70 / 90;
  ASSERT_NEAR(0.1 + (ix + 0.5) * 0.01, JNUM(all->json, "best.position.0"), 1e-5);
  ASSERT_NEAR(-0.45 + (iy + 0.5) * 0.01, JNUM(all->json, "best.position.1"), 1e-5);
  ASSERT_NEAR(-0.05 + (iz + 0.5) * 0.01, JNUM(all->json, "best.position.2"), 1e-5);
  h_resp_free(r);

  /* ply: header, one vertex (x y z float, r g b uchar, score float) per json point. */
  r = class_heatmap("mug", "\"format\": \"ply\", \"max_points\": 100");
  ASSERT(r->len > 100);
  ASSERT(memcmp(r->body, "ply\nformat binary_little_endian 1.0\n", 36) == 0);
  ASSERT_STRCONTAINS(r->body, "element vertex 100\n");
  char *end = strstr(r->body, "end_header\n");
  ASSERT(end != NULL);
  size_t header = (size_t)(end - r->body) + strlen("end_header\n");
  ASSERT_EQ(r->len - header, (size_t)100 * (12 + 3 + 4));
  float xyz[3];
  memcpy(xyz, r->body + header, sizeof xyz);
  ASSERT_NEAR(xyz[0], JNUM(pts, "0.0"), 1e-5);
  ASSERT_NEAR(xyz[2], JNUM(pts, "0.2"), 1e-5);
  h_resp_free(r);
  h_resp_free(all);
}

/* ---------------------------------------------------------------- errors */

static void test_errors(void) {
  char *e = class_embedding("mug");
  char *b;
#define BAD(status, code, ...)                                                                 \
  do {                                                                                         \
    b = h_fmt(__VA_ARGS__);                                                                    \
    expect_error("sg", b, status, code);                                                       \
    free(b);                                                                                   \
  } while (0)
  BAD(400, "invalid_query", "{\"embedding\": [1, 0, 0]}");
  BAD(400, "invalid_query", "{}");
  BAD(400, "invalid_query", "{\"negative_embeddings\": [%s]}", e);
  BAD(400, "invalid_query", "{\"embedding\": %s, \"negative_embeddings\": [%s], "
      "\"temperature\": 0}", e, e);
  BAD(400, "invalid_query", "{\"embedding\": %s, \"negative_embeddings\": [%s], "
      "\"temperature\": -1}", e, e);
  BAD(400, "invalid_query", "{\"embedding\": %s, \"negative_embeddings\": [[1, 2]]}", e);
  BAD(409, "clip_not_configured", "{\"text\": \"a mug\"}");
  BAD(409, "clip_not_configured", "{\"text\": [\"a mug\", \"a cup\"]}");
  BAD(400, "invalid_query", "{\"text\": []}");
  BAD(400, "invalid_request", "{\"embedding\": %s, \"format\": \"obj\"}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"alpha_threshold\": 0}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"alpha_threshold\": 1.5}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"max_points\": 0}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"max_points\": 2.5}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"min_score\": \"high\"}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"format\": \"npy\", \"max_points\": 3}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"voxel_size\": 0.02}", e);
  BAD(400, "invalid_request", "{\"embedding\": %s, \"colour\": \"red\"}", e);
  BAD(400, "malformed_json", "{\"embedding\": ");
#undef BAD
  /* voxel_size equal to the scene's is fine. */
  h_resp *r = class_heatmap("mug", "\"voxel_size\": 0.01, \"max_points\": 1");
  h_resp_free(r);
  b = h_fmt("{\"embedding\": %s}", e);
  expect_error("nope", b, 404, "scene_not_found");
  free(b);
  free(e);
}

/* ---------------------------------------------------------------- the render */

static uint8_t *decode(const h_resp *r, int w, int h) {
  int pw, ph, bits, type;
  t_png_header(r, &pw, &ph, &bits, &type);
  ASSERT_EQ(pw, w);
  ASSERT_EQ(ph, h);
  fg_image img;
  const float bg[3] = {0, 0, 0};
  ASSERT_OK(fg_image_decode(r->body, r->len, bg, &img));
  uint8_t *px = malloc((size_t)w * h * 3);
  for (size_t i = 0; i < (size_t)w * h * 3; i++) px[i] = (uint8_t)lrintf(img.rgb[i] * 255.0f);
  fg_image_release(&img);
  return px;
}

/* The turbo level t (0..255) that best explains heat pixel hp as the blend of fg_heatmap_blend
 * over plain pixel rp: (1 - a) rp + a turbo(t), a = 0.25 + 0.6 t / 255. */
static int turbo_level(const uint8_t hp[3], const uint8_t rp[3]) {
  int best = -1;
  double best_err = INFINITY;
  for (int t = 0; t < 256; t++) {
    double a = 0.25 + 0.6 * t / 255.0, err = 0;
    for (int k = 0; k < 3; k++) {
      double v = (1 - a) * rp[k] + a * fg_turbo_rgb[t][k] - hp[k];
      err += v * v;
    }
    if (err < best_err) best_err = err, best = t;
  }
  return best;
}

static void test_render(void) {
  /* The training view that sees most of the mug (mask value 2 = the mug). */
  uint8_t *best_mask;
  size_t best_count;
  const int best_view = v_best_view(g_dir, VIEWS, W, H, 2, &best_mask, &best_count);
  ASSERT(best_count > 200);
  const int rw = W, rh = H;
  char *cam = v_frame_camera(g_frames, best_view, rw, rh);
  char *e = class_embedding("mug");
  char *body = h_fmt("{\"camera\": %s, \"output\": \"heatmap\", \"embedding\": %s}", cam, e);
  h_resp *hr = t_render("sg", body);
  if (hr->status != 200) fprintf(stderr, "render: %s\n", hr->body);
  uint8_t *heat = decode(hr, rw, rh);
  h_resp *again = t_render("sg", body);
  ASSERT_EQ(again->len, hr->len);
  ASSERT(memcmp(again->body, hr->body, hr->len) == 0);
  h_resp_free(again);
  free(body);
  body = h_fmt("{\"camera\": %s}", cam);
  h_resp *rr = t_render("sg", body);
  uint8_t *plain = decode(rr, rw, rh);

  /* Pixels in the top tenth of the image's score range lie mostly on the mug. */
  size_t hot = 0, hot_on_mug = 0, changed = 0;
  for (size_t i = 0; i < (size_t)rw * rh; i++) {
    int t = turbo_level(heat + 3 * i, plain + 3 * i);
    changed += memcmp(heat + 3 * i, plain + 3 * i, 3) != 0;
    if (t >= 230) {
      hot++;
      hot_on_mug += best_mask[i] == 2;
    }
  }
  printf("render of view %d: %zu mug pixels, %zu hot, %zu of them on the mug\n", best_view,
         best_count, hot, hot_on_mug);
  ASSERT(changed > (size_t)rw * rh / 4);
  ASSERT(hot >= 5);
  ASSERT(hot_on_mug * 10 >= hot * 7);

  /* The errors of a query render. */
  free(body);
  body = h_fmt("{\"camera\": %s, \"output\": \"heatmap\", \"embedding\": [1, 2]}", cam);
  h_resp *er = t_render("sg", body);
  ASSERT_HTTP_ERROR(er, 400, "invalid_query");
  h_resp_free(er);

  h_resp_free(hr);
  h_resp_free(rr);
  free(heat);
  free(plain);
  free(best_mask);
  free(body);
  free(e);
  free(cam);
}

/* ---------------------------------------------------------------- concurrent first heatmaps */

#define CONCURRENT 4

typedef struct {
  const char *body;
  h_resp *r;
} heat_job;

static void *heat_thread(void *arg) {
  heat_job *j = arg;
  j->r = heatmap("sg", j->body);
  return NULL;
}

/* CONCURRENT heatmaps of a field without voxel features yet: one build, shared, and the same
 * bytes for all. */
static void concurrent_first(const char *body) {
  double builds = h_metric("fieldgrip_voxel_cache_builds_total");
  pthread_t th[CONCURRENT];
  heat_job jobs[CONCURRENT];
  for (int i = 0; i < CONCURRENT; i++) {
    jobs[i].body = body;
    ASSERT_EQ(pthread_create(&th[i], NULL, heat_thread, &jobs[i]), 0);
  }
  for (int i = 0; i < CONCURRENT; i++) ASSERT_EQ(pthread_join(th[i], NULL), 0);
  for (int i = 0; i < CONCURRENT; i++) {
    ASSERT_STATUS(jobs[i].r, 200);
    ASSERT_EQ(jobs[i].r->len, jobs[0].r->len);
    ASSERT(memcmp(jobs[i].r->body, jobs[0].r->body, jobs[0].r->len) == 0);
  }
  for (int i = 0; i < CONCURRENT; i++) h_resp_free(jobs[i].r);
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_builds_total"), builds + 1);
}

/* ---------------------------------------------------------------- main */

int main(int argc, char **argv) {
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  double t0 = t_now();
  /* the fixture's data set is scenegen's with these parameters (grasp_util.h: G_*) */
  char *imports = f_dataset(argv[2]);
  t_write_config(imports);
  g_dir = h_fmt("%s/sg", imports);
  free(imports);
  char *gt_path = h_fmt("%s/gt.json", g_dir), *tf_path = h_fmt("%s/transforms.json", g_dir);
  json_error_t jerr;
  g_gt = json_load_file(gt_path, 0, &jerr);
  g_frames = json_load_file(tf_path, 0, &jerr);
  ASSERT(g_gt && g_frames);
  f_scene("t250", "sg");    /* trained {"steps": 250} */
  f_scene("raw1", "other"); /* the same frames, untrained */
  h_start();

  /* Untrained: 409 saying how; a grid over the limit: 400 whatever the state. */
  char *e = class_embedding("mug");
  char *body = h_fmt("{\"embedding\": %s}", e);
  h_resp *r = heatmap("other", body);
  ASSERT_HTTP_ERROR(r, 409, "not_trained");
  ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), "POST /v1/scenes/other/train");
  h_resp_free(r);
  geometry_checks_untrained("other");
  r = h_post_json("/v1/scenes", "{\"name\": \"huge\", \"workspace\": {\"min\": [-2, -2, -2], "
                  "\"max\": [2, 2, 2]}, \"voxel_size\": 0.01}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  expect_error("huge", body, 400, "grid_too_large");

  double t_ready = t_now();
  json_t *sj = t_scene_json("sg");
  ASSERT(json_is_false(JGET(sj, "voxel_cache.built")));
  ASSERT_EQ(JINT(sj, "voxel_cache.bytes"), 0);
  json_decref(sj);
  double builds0 = h_metric("fieldgrip_voxel_cache_builds_total");

  test_objects();
  sj = t_scene_json("sg");
  ASSERT(json_is_true(JGET(sj, "voxel_cache.built")));
  ASSERT_EQ(JINT(sj, "voxel_cache.voxels"), 70 * 90 * 40);
  long long bytes = JINT(sj, "voxel_cache.bytes");
  ASSERT(bytes > 0);
  ASSERT(JINT(sj, "voxel_cache.kept") > 0);
  ASSERT(JINT(sj, "voxel_cache.kept") <= 70 * 90 * 40);
  json_decref(sj);
  test_json_bounds();
  test_errors();
  test_render();
  /* Every heatmap so far shared one build. */
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_builds_total"), builds0 + 1);
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_bytes"), (double)bytes);
  ASSERT(h_metric("fieldgrip_heatmaps_total{format=\"json\"}") >= 8);
  ASSERT(h_metric("fieldgrip_heatmaps_total{format=\"npy\"}") >= 1);
  ASSERT(h_metric("fieldgrip_heatmaps_total{format=\"ply\"}") >= 1);
  ASSERT(h_metric("fieldgrip_heatmaps_total{format=\"render\"}") >= 2);
  double t_queried = t_now();
  const geometry_data_set ds = {g_dir, g_frames, VIEWS, W, H, DIM};
  geometry_checks(&ds);

  /* While another scene trains, heatmaps and health answer. */
  char *id = t_train("other", "{\"steps\": 1000000}");
  t_wait_running(id, 1, 600);
  double ta = t_now();
  r = heatmap("sg", body);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  printf("heatmap while training: %.3f s\n", t_now() - ta);
  json_t *j = t_job(id);
  ASSERT_STREQ(JSTR(j, "state"), "running");
  json_decref(j);
  char *path = h_fmt("/v1/jobs/%s", id);
  r = h_delete(path);
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  char *needle = h_fmt("job %s: stopped (cancelled)", id);
  ASSERT(h_wait_log(needle, 1, 600));
  free(needle);
  free(path);
  free(id);

  /* A new field drops the cache; the next heatmap builds it again. */
  t_train_done("sg", "{\"steps\": 2}", 600);
  sj = t_scene_json("sg");
  ASSERT(json_is_false(JGET(sj, "voxel_cache.built")));
  json_decref(sj);
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_bytes"), 0);
  concurrent_first(body);
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_builds_total"), builds0 + 2);
  /* The scene deleted: its cache goes with it. */
  r = h_delete("/v1/scenes/sg");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  ASSERT_EQ(h_metric("fieldgrip_voxel_cache_bytes"), 0);
  expect_error("sg", body, 404, "scene_not_found");
  printf("setup %.1f s, queries %.1f s, total %.1f s\n", t_ready - t0,
         t_queried - t_ready, t_now() - t0);

  h_stop();
  free(body);
  free(e);
  json_decref(g_gt);
  json_decref(g_frames);
  free(gt_path);
  free(tf_path);
  free(g_dir);
  h_done();
  return 0;
}
