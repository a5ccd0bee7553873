/* Concurrency: 8 clients creating one scene at once get one 201 and seven 409; 8 clients uploading 4 frames each to one scene at once get 32 distinct frame
 * numbers 0..31, each listed with the pose its client sent; and while an import of the lego
 * data set runs, /v1/health and the scene list keep answering. */
#include <pthread.h>
#include <stdatomic.h>

#include "harness.h"

#define THREADS 8
#define PER_THREAD 4

typedef struct uploader {
  int id;
  int frames[PER_THREAD]; /* numbers the daemon gave */
} uploader;

/* The pose of upload (thread t, k-th): the translation encodes t and k. */
static void pose_of(int t, int k, double T[16]) {
  h_pose(T, 0.1 * t, 0.05 * k, -0.1, 0.01 * t, 0.1 * k, 0.5);
}

static void *upload_thread(void *arg) {
  uploader *u = arg;
  for (int k = 0; k < PER_THREAD; k++) {
    uint8_t *png, *npy;
    size_t png_len, npy_len;
    h_png(48, 36, 3, 8, (unsigned)(u->id * 10 + k), 0, &png, &png_len);
    static const int shape[3] = {3, 4, 8};
    h_npy("<f4", shape, 3, (unsigned)u->id, &npy, &npy_len);
    double T[16];
    pose_of(u->id, k, T);
    char *meta = h_meta(T, "opengl", 40, 24, 18, 48, 36);
    h_resp *r = h_upload("/v1/scenes/c/frames", png, png_len, meta, npy, npy_len);
    ASSERT_STATUS(r, 201);
    u->frames[k] = (int)JINT(r->json, "frame");
    h_resp_free(r);
    free(meta);
    free(png);
    free(npy);
  }
  return NULL;
}

static void test_parallel_uploads(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"c\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  pthread_t th[THREADS];
  uploader u[THREADS];
  for (int t = 0; t < THREADS; t++) {
    u[t].id = t;
    ASSERT_EQ(pthread_create(&th[t], NULL, upload_thread, &u[t]), 0);
  }
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_join(th[t], NULL), 0);

  int owner[THREADS * PER_THREAD];
  for (int i = 0; i < THREADS * PER_THREAD; i++) owner[i] = -1;
  for (int t = 0; t < THREADS; t++)
    for (int k = 0; k < PER_THREAD; k++) {
      int n = u[t].frames[k];
      ASSERT(n >= 0 && n < THREADS * PER_THREAD);
      if (owner[n] != -1) FG_TEST_FAIL("frame number %d given twice", n);
      owner[n] = t * PER_THREAD + k;
      if (k > 0) ASSERT(n > u[t].frames[k - 1]); /* one client's uploads are in order */
    }

  r = h_get("/v1/scenes/c/frames");
  ASSERT_STATUS(r, 200);
  json_t *frames = JGET(r->json, "frames");
  ASSERT_EQ(json_array_size(frames), THREADS * PER_THREAD);
  for (int i = 0; i < THREADS * PER_THREAD; i++) {
    json_t *f = json_array_get(frames, (size_t)i);
    ASSERT_EQ(JINT(f, "frame"), i);
    double T[16];
    pose_of(owner[i] / PER_THREAD, owner[i] % PER_THREAD, T);
    ASSERT_MATRIX(JGET(f, "transform_matrix"), T, 1e-6);
    ASSERT_EQ(JINT(f, "features.d"), 8);
  }
  h_resp_free(r);
  r = h_get("/v1/scenes/c");
  ASSERT_EQ(JINT(r->json, "frames"), THREADS * PER_THREAD);
  ASSERT_EQ(JINT(r->json, "feature_dim"), 8);
  h_resp_free(r);
}

typedef struct importer {
  char *body;
  atomic_int started, done;
  long status;
  long long imported;
} importer;

static void *import_thread(void *arg) {
  importer *im = arg;
  atomic_store(&im->started, 1);
  h_resp *r = h_post_json("/v1/scenes/lego/import", im->body);
  im->status = r->status;
  if (r->status == 200) im->imported = JINT(r->json, "imported");
  else fprintf(stderr, "import: %ld %s\n", r->status, r->body);
  h_resp_free(r);
  atomic_store(&im->done, 1);
  return NULL;
}

static void test_health_during_import(void) {
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"lego\", \"workspace\": {\"min\": [-1.5, -1.5, -1.5], "
                                        "\"max\": [1.5, 1.5, 1.5]}}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  char *shared = h_shared_data();
  importer im = {0};
  im.body = h_fmt("{\"path\": \"%s/lego\", \"transforms\": \"transforms_train.json\"}", shared);
  free(shared);
  pthread_t th;
  ASSERT_EQ(pthread_create(&th, NULL, import_thread, &im), 0);
  while (!atomic_load(&im.started)) h_sleep_ms(1);
  h_sleep_ms(50); /* let the request reach the daemon; the assertions do not depend on it */

  int answered = 0, during = 0;
  do {
    r = h_get("/v1/health");
    ASSERT_STATUS(r, 200);
    ASSERT_STREQ(JSTR(r->json, "status"), "ok");
    h_resp_free(r);
    r = h_get("/v1/scenes/c");
    ASSERT_STATUS(r, 200);
    ASSERT_EQ(JINT(r->json, "frames"), THREADS * PER_THREAD);
    h_resp_free(r);
    answered++;
    if (!atomic_load(&im.done)) during++;
    h_sleep_ms(20);
  } while (!atomic_load(&im.done));
  ASSERT_EQ(pthread_join(th, NULL), 0);
  ASSERT_EQ(im.status, 200);
  ASSERT_EQ(im.imported, 100);
  ASSERT(answered >= 1);
  printf("health answered %d times, %d of them while the import was still running\n", answered,
         during);
  free(im.body);
  r = h_get("/v1/scenes/lego");
  ASSERT_EQ(JINT(r->json, "frames"), 100);
  h_resp_free(r);
}

/* ---- 8 clients create the same scene at once: one 201, seven 409 ---- */

typedef struct creator {
  long status;
  char code[64];
} creator;

static void *create_thread(void *arg) {
  creator *c = arg;
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"race\", \"voxel_size\": 0.02}");
  c->status = r->status;
  json_t *code = r->json ? h_jfind(r->json, "error.code") : NULL;
  snprintf(c->code, sizeof c->code, "%s", json_is_string(code) ? json_string_value(code) : "");
  h_resp_free(r);
  return NULL;
}

static void test_create_race(void) {
  pthread_t th[THREADS];
  creator c[THREADS];
  memset(c, 0, sizeof c);
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_create(&th[t], NULL, create_thread, &c[t]), 0);
  for (int t = 0; t < THREADS; t++) ASSERT_EQ(pthread_join(th[t], NULL), 0);
  int created = 0, exists = 0;
  for (int t = 0; t < THREADS; t++) {
    if (c[t].status == 201) created++;
    else if (c[t].status == 409 && strcmp(c[t].code, "scene_exists") == 0) exists++;
    else FG_TEST_FAIL("concurrent create: %ld %s", c[t].status, c[t].code);
  }
  ASSERT_EQ(created, 1);
  ASSERT_EQ(exists, THREADS - 1);
  h_resp *r = h_get("/v1/scenes");
  int n = 0;
  json_t *scenes = JGET(r->json, "scenes");
  for (size_t i = 0; i < json_array_size(scenes); i++)
    if (strcmp(JSTR(json_array_get(scenes, i), "name"), "race") == 0) n++;
  ASSERT_EQ(n, 1);
  h_resp_free(r);
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  char *shared = h_shared_data();
  char *conf = h_fmt("[state]\nimport_dirs = %s\n", shared);
  h_write_config(conf);
  free(conf);
  free(shared);
  h_start();
  test_create_race();
  test_parallel_uploads();
  test_health_during_import();
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
