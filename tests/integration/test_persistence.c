/* Persistence: scenes and frames survive a clean restart, a kill -9 after an import, and a
 * kill -9 in the middle of an upload (no half-written frame, no temp file left after start-up)
 * and while an import decodes (known to have begun and been cut off; whatever is listed
 * afterwards is whole);
 * deleted scenes stay deleted; scenes declared in the config come back empty. */
#include <curl/curl.h>
#include <dirent.h>
#include <pthread.h>
#include <stdatomic.h>
#include <unistd.h>

#include "harness.h"

static json_t *get_json(const char *path) {
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *j = json_incref(RJSON(r));
  h_resp_free(r);
  return j;
}

static int upload_frame(const char *scene, int w, int h, unsigned seed, int with_features) {
  uint8_t *png, *npy = NULL;
  size_t png_len, npy_len = 0;
  h_png(w, h, seed % 2 ? 4 : 3, 8, seed, 0, &png, &png_len);
  if (with_features) {
    static const int shape[3] = {4, 5, 8};
    h_npy(seed % 2 ? "<f2" : "<f4", shape, 3, seed, &npy, &npy_len);
  }
  double T[16];
  h_pose(T, 0.3 * seed, -0.2, 0.1 * seed, 0.1 * seed, 0.2, 0.5);
  char *meta = h_meta(T, seed % 3 == 2 ? "opencv" : "opengl", 40 + seed, w / 2.0, h / 2.0, w, h);
  char *path = h_fmt("/v1/scenes/%s/frames", scene);
  h_resp *r = h_upload(path, png, png_len, meta, npy, npy_len);
  ASSERT_STATUS(r, 201);
  int n = (int)JINT(r->json, "frame");
  h_resp_free(r);
  free(path);
  free(meta);
  free(png);
  free(npy);
  return n;
}

/* ---- an upload that stops half-way until released ---- */

typedef struct slow_upload {
  uint8_t *body;
  size_t len, pos;
  pthread_mutex_t lock;
  pthread_cond_t cond;
  int half_sent, release;
  long status; /* of the request, after the thread ends */
  int curl_rc;
} slow_upload;

static size_t slow_read(char *out, size_t size, size_t nmemb, void *ud) {
  slow_upload *s = ud;
  size_t n = size * nmemb;
  if (n > 16384) n = 16384;
  if (s->pos >= s->len / 2) {
    pthread_mutex_lock(&s->lock);
    s->half_sent = 1;
    pthread_cond_broadcast(&s->cond);
    while (!s->release) pthread_cond_wait(&s->cond, &s->lock);
    pthread_mutex_unlock(&s->lock);
    return CURL_READFUNC_ABORT;
  }
  if (n > s->len / 2 - s->pos) n = s->len / 2 - s->pos;
  memcpy(out, s->body + s->pos, n);
  s->pos += n;
  return n;
}

static void *slow_thread(void *arg) {
  slow_upload *s = arg;
  const char *hdrs[] = {"Content-Type: multipart/form-data; boundary=slowboundaryXYZ", "Expect:", NULL};
  h_req q = {.method = "POST", .path = "/v1/scenes/k/frames", .headers = hdrs, .read_cb = slow_read,
             .read_ud = s, .read_len = (long long)s->len};
  h_resp *r = h_request(&q);
  s->status = r->status;
  s->curl_rc = r->curl_rc;
  h_resp_free(r);
  return NULL;
}

static void test_clean_restart(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"p\", \"workspace\": {\"min\": [-0.5, -0.4, 0], "
                                        "\"max\": [0.5, 0.4, 0.6]}, \"voxel_size\": 0.004, "
                                        "\"background\": [0.2, 0.3, 0.4]}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  ASSERT_EQ(upload_frame("p", 64, 48, 1, 1), 0);
  ASSERT_EQ(upload_frame("p", 50, 40, 2, 1), 1);
  ASSERT_EQ(upload_frame("p", 64, 48, 3, 1), 2);
  ASSERT_EQ(upload_frame("decl", 32, 32, 4, 0), 0);
  r = h_post_json("/v1/scenes", "{\"name\": \"gone\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  ASSERT_EQ(upload_frame("gone", 32, 32, 5, 0), 0);
  r = h_delete("/v1/scenes/gone");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);

  /* The documented layout: <state>/scenes/<name>/scene.json and frames/<6 digits>.fgf; a
   * deleted scene's folder is gone. */
  static const char *const files[] = {"scenes/p/scene.json", "scenes/p/frames/000000.fgf",
                                      "scenes/p/frames/000001.fgf", "scenes/p/frames/000002.fgf",
                                      "scenes/decl/frames/000000.fgf"};
  for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
    char *f = h_fmt("%s/%s", h_state_dir(), files[i]);
    if (access(f, F_OK) != 0) FG_TEST_FAIL("%s is missing", f);
    free(f);
  }
  char *gone = h_fmt("%s/scenes/gone", h_state_dir());
  if (access(gone, F_OK) == 0) FG_TEST_FAIL("%s is still there after DELETE", gone);
  free(gone);

  json_t *scene = get_json("/v1/scenes/p");
  json_t *frames = get_json("/v1/scenes/p/frames");
  ASSERT_EQ(JINT(scene, "frames"), 3);
  ASSERT_EQ(JINT(scene, "feature_dim"), 8);
  ASSERT_EQ(json_array_size(JGET(frames, "frames")), 3);

  h_stop();
  h_start();

  json_t *scene2 = get_json("/v1/scenes/p");
  json_t *frames2 = get_json("/v1/scenes/p/frames");
  ASSERT_JSON_EQUAL(scene2, scene);
  ASSERT_JSON_EQUAL(frames2, frames);
  json_decref(scene2);
  json_decref(frames2);
  h_resp *g = h_get("/v1/scenes/gone");
  ASSERT_HTTP_ERROR(g, 404, "scene_not_found");
  h_resp_free(g);
  json_t *decl = get_json("/v1/scenes/decl");
  ASSERT_EQ(JINT(decl, "frames"), 1);
  ASSERT(json_is_true(JGET(decl, "declared_in_config")));
  json_decref(decl);
  json_t *list = get_json("/v1/scenes");
  ASSERT_EQ(json_array_size(JGET(list, "scenes")), 2);
  ASSERT_STREQ(JSTR(list, "scenes.0.name"), "decl");
  ASSERT_STREQ(JSTR(list, "scenes.1.name"), "p");
  json_decref(list);

  /* Numbering goes on after a restart. */
  ASSERT_EQ(upload_frame("p", 64, 48, 6, 1), 3);

  /* A scene declared in the config comes back, empty, at the next start. */
  r = h_delete("/v1/scenes/decl");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  h_stop();
  h_start();
  decl = get_json("/v1/scenes/decl");
  ASSERT_EQ(JINT(decl, "frames"), 0);
  ASSERT(json_is_true(JGET(decl, "declared_in_config")));
  static const double mn[3] = {0, 0, 0}, mx[3] = {1, 1, 1};
  ASSERT_VEC(JGET(decl, "workspace.min"), mn, 3, 1e-12);
  ASSERT_VEC(JGET(decl, "workspace.max"), mx, 3, 1e-12);
  ASSERT_NEAR(JNUM(decl, "voxel_size"), 0.02, 1e-12);
  json_decref(decl);
  json_t *p = get_json("/v1/scenes/p");
  ASSERT_EQ(JINT(p, "frames"), 4);
  json_decref(p);
  json_decref(scene);
  json_decref(frames);
}

static void test_kill_after_import(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"lego\", \"workspace\": {\"min\": [-1.5, -1.5, -1.5], "
                                        "\"max\": [1.5, 1.5, 1.5]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *shared = h_shared_data();
  char *body = h_fmt("{\"path\": \"%s/lego\", \"transforms\": \"transforms_train.json\"}", shared);
  r = h_post_json("/v1/scenes/lego/import", body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), 100);
  h_resp_free(r);
  free(body);
  free(shared);
  json_t *frames = get_json("/v1/scenes/lego/frames");
  ASSERT_EQ(json_array_size(JGET(frames, "frames")), 100);

  h_kill();
  h_start();

  json_t *scene = get_json("/v1/scenes/lego");
  ASSERT_EQ(JINT(scene, "frames"), 100);
  json_decref(scene);
  json_t *frames2 = get_json("/v1/scenes/lego/frames");
  ASSERT_JSON_EQUAL(frames2, frames);
  json_decref(frames2);
  json_decref(frames);
  ASSERT_EQ(h_count_files(h_state_dir(), ".tmp."), 0);
}

static void test_kill_mid_upload(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"k\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  int accepted = 0;
  ASSERT_EQ(upload_frame("k", 64, 48, 7, 1), 0);
  accepted++;
  ASSERT_EQ(upload_frame("k", 64, 48, 8, 1), 1);
  accepted++;
  json_t *frames = get_json("/v1/scenes/k/frames");

  /* A 2 MB frame upload that stops half-way. */
  slow_upload s = {0};
  pthread_mutex_init(&s.lock, NULL);
  pthread_cond_init(&s.cond, NULL);
  {
    uint8_t *png, *npy;
    size_t png_len, npy_len;
    h_png(820, 820, 3, 8, 9, 1, &png, &png_len);
    static const int shape[3] = {4, 5, 8};
    h_npy("<f4", shape, 3, 9, &npy, &npy_len);
    double T[16];
    h_pose(T, 0.1, 0.1, 0.1, 0, 0, 0.5);
    char *meta = h_meta(T, "opengl", 700, 410, 410, 820, 820);
    h_part parts[3] = {{"meta", meta, strlen(meta), NULL, "application/json"},
                       {"features", npy, npy_len, "features.npy", "application/octet-stream"},
                       {"image", png, png_len, "image.png", "image/png"}};
    h_multipart_build(parts, 3, "slowboundaryXYZ", &s.body, &s.len);
    free(meta);
    free(png);
    free(npy);
  }
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, slow_thread, &s), 0);
  pthread_mutex_lock(&s.lock);
  while (!s.half_sent) pthread_cond_wait(&s.cond, &s.lock);
  pthread_mutex_unlock(&s.lock);
  h_sleep_ms(300); /* let the daemon take in what was sent; correctness does not depend on it */

  h_kill();
  pthread_mutex_lock(&s.lock);
  s.release = 1;
  pthread_cond_broadcast(&s.cond);
  pthread_mutex_unlock(&s.lock);
  ASSERT_EQ(pthread_join(th, NULL), 0);
  ASSERT(s.status != 201); /* the cut-off upload was never accepted */
  free(s.body);
  pthread_mutex_destroy(&s.lock);
  pthread_cond_destroy(&s.cond);

  /* Leftovers a killed writer could have left (layout and names from the contract); the
   * start-up sweep must remove them, and they must not count as frames. */
  char *fdir = h_fmt("%s/scenes/k/frames", h_state_dir());
  char *t1 = h_fmt("%s/000002.fgf.tmp.4242", fdir);
  char *t2 = h_fmt("%s/scenes/k/scene.json.tmp.4242", h_state_dir());
  h_write_file(t1, "partial", 7);
  h_write_file(t2, "{\"partial", 9);
  free(t1);
  free(t2);
  free(fdir);

  h_start();
  json_t *list = get_json("/v1/scenes");
  int found = 0;
  for (size_t i = 0; i < json_array_size(JGET(list, "scenes")); i++)
    if (strcmp(json_string_value(json_object_get(json_array_get(JGET(list, "scenes"), i), "name")),
               "k") == 0) {
      found = 1;
      ASSERT_EQ(JINT(json_array_get(JGET(list, "scenes"), i), "frames"), accepted);
    }
  ASSERT(found);
  json_decref(list);
  json_t *frames2 = get_json("/v1/scenes/k/frames");
  ASSERT_JSON_EQUAL(frames2, frames);
  json_decref(frames2);
  json_decref(frames);
  ASSERT_EQ(h_count_files(h_state_dir(), ".tmp."), 0);
  /* The next upload takes the next number. */
  ASSERT_EQ(upload_frame("k", 64, 48, 10, 1), accepted);
}

/* ---- kill -9 while an import runs ---- */

typedef struct importer {
  char *body, *path;
  atomic_int started, done;
  long status; /* 0: no answer (cut off by the kill) */
} importer;

static void *import_thread(void *arg) {
  importer *im = arg;
  atomic_store(&im->started, 1);
  h_resp *r = h_post_json(im->path, im->body);
  im->status = r->status;
  if (r->status != 0 && r->status != 200)
    fprintf(stderr, "import during kill: %ld %s\n", r->status, r->body);
  h_resp_free(r);
  atomic_store(&im->done, 1);
  return NULL;
}

/* The daemon's image decoders (fieldgrip-decode children) running now, as pids in out[0 ..
 * max-1]; returns how many. */
static int decoder_pids(pid_t *out, int max) {
  DIR *d = opendir("/proc");
  ASSERT(d != NULL);
  int n = 0;
  struct dirent *e;
  while ((e = readdir(d)) != NULL) {
    if (e->d_name[0] < '1' || e->d_name[0] > '9') continue;
    char *path = h_fmt("/proc/%s/stat", e->d_name);
    char *stat = h_read_file(path, NULL);
    free(path);
    if (!stat) continue; /* gone meanwhile */
    /* "pid (comm) state ppid ...": comm may hold spaces, so parse after the last ')' */
    const char *close = strrchr(stat, ')');
    char state;
    int ppid;
    if (close && strstr(stat, "(fieldgrip-decod") && sscanf(close + 1, " %c %d", &state, &ppid) == 2 &&
        ppid == h_pid() && n < max)
      out[n++] = (pid_t)atoi(e->d_name);
    free(stat);
  }
  closedir(d);
  return n;
}

/* Starts the lego import into scene and SIGKILLs the daemon once the import is decoding (a
 * decoder child that was not there before has appeared). Returns 1 when the kill cut it off
 * (no answer came), 0 when the import answered first (a starved test thread; the caller tries
 * again). */
static int kill_during_import(const char *scene, const char *shared) {
  pid_t before[64], now[64];
  const int n_before = decoder_pids(before, 64);
  importer im = {0};
  im.path = h_fmt("/v1/scenes/%s/import", scene);
  im.body = h_fmt("{\"path\": \"%s/lego\", \"transforms\": \"transforms_train.json\"}", shared);
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, import_thread, &im), 0);
  const double deadline = h_now_s() + 60;
  int decoding = 0;
  while (!decoding && !atomic_load(&im.done)) {
    ASSERT(h_now_s() < deadline);
    const int n_now = decoder_pids(now, 64);
    for (int i = 0; i < n_now && !decoding; i++) {
      decoding = 1;
      for (int j = 0; j < n_before; j++)
        if (now[i] == before[j]) decoding = 0;
    }
    if (!decoding) h_sleep_ms(1);
  }
  h_kill();
  ASSERT_EQ(pthread_join(th, NULL), 0);
  free(im.path);
  free(im.body);
  if (im.status != 0) {
    ASSERT_EQ(im.status, 200);
    fprintf(stderr, "the import into %s answered before the kill; again\n", scene);
    return 0;
  }
  ASSERT(decoding); /* it had begun */
  return 1;
}

/* SIGKILL while an import decodes its frames: the import gets no answer, and after a restart
 * the scene lists whole frames only (none, or a prefix of the data set with its poses), and
 * no temp file is left. */
static void test_kill_mid_import(void) {
  char *shared = h_shared_data();
  char *tpath = h_fmt("%s/lego/transforms_train.json", shared);
  /* a fresh daemon: decoders left idle by earlier work would hide the import's own */
  h_stop();
  h_start();
  char scene[32];
  int cut = 0;
  for (int attempt = 0; attempt < 3 && !cut; attempt++) {
    snprintf(scene, sizeof scene, "lego%d", attempt + 2);
    char *body = h_fmt("{\"name\": \"%s\", \"workspace\": {\"min\": [-1.5, -1.5, -1.5], "
                       "\"max\": [1.5, 1.5, 1.5]}}", scene);
    h_resp *r = h_post_json("/v1/scenes", body);
    ASSERT_STATUS(r, 201);
    h_resp_free(r);
    free(body);
    cut = kill_during_import(scene, shared);
    h_start();
  }
  free(shared);
  if (!cut) FG_TEST_FAIL("three imports in a row answered before the kill reached them");

  ASSERT_EQ(h_count_files(h_state_dir(), ".tmp."), 0);
  char *path = h_fmt("/v1/scenes/%s", scene);
  json_t *sj = get_json(path);
  long long n = JINT(sj, "frames");
  json_decref(sj);
  free(path);
  printf("frames of %s after a kill -9 during its import: %lld\n", scene, n);
  ASSERT(n >= 0 && n <= 100);
  /* Whatever is listed is whole: frame i is transforms frame i, with its camera. */
  json_error_t jerr;
  json_t *tf = json_load_file(tpath, 0, &jerr);
  if (!tf) FG_TEST_FAIL("%s: %s", tpath, jerr.text);
  free(tpath);
  path = h_fmt("/v1/scenes/%s/frames", scene);
  json_t *frames = get_json(path);
  free(path);
  ASSERT_EQ(json_array_size(JGET(frames, "frames")), n);
  for (long long i = 0; i < n; i++) {
    json_t *f = json_array_get(JGET(frames, "frames"), (size_t)i);
    json_t *src = json_array_get(JGET(tf, "frames"), (size_t)i);
    double T[16];
    for (int k = 0; k < 16; k++) {
      char p[32];
      snprintf(p, sizeof p, "transform_matrix.%d.%d", k / 4, k % 4);
      T[k] = JNUM(src, p);
    }
    ASSERT_EQ(JINT(f, "frame"), i);
    ASSERT_MATRIX(JGET(f, "transform_matrix"), T, 1e-6);
    ASSERT_EQ(JINT(f, "camera.w"), 400);
  }
  json_decref(frames);
  json_decref(tf);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  char *shared = h_shared_data();
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[scene decl]\nworkspace_min = 0 0 0\n"
                     "workspace_max = 1 1 1\nvoxel_size = 0.02\n",
                     shared);
  h_write_config(conf);
  free(conf);
  free(shared);
  h_start();
  test_clean_restart();
  test_kill_mid_upload();
  test_kill_after_import();
  test_kill_mid_import();
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
