/* Helpers for the training and rendering integration tests; see training.h. */
#include "training.h"

#include <errno.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

double t_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

void t_scenegen(const char *scenegen, const char *dir, int views, int w, int h, int dim,
                int patch) {
  t_scenegen_depth(scenegen, dir, views, w, h, dim, patch, NULL);
}

void t_scenegen_depth(const char *scenegen, const char *dir, int views, int w, int h, int dim,
                      int patch, const char *depth) {
  char sv[16], sw[16], sh[16], sd[16], sp[16];
  snprintf(sv, sizeof sv, "%d", views);
  snprintf(sw, sizeof sw, "%d", w);
  snprintf(sh, sizeof sh, "%d", h);
  snprintf(sd, sizeof sd, "%d", dim);
  snprintf(sp, sizeof sp, "%d", patch);
  const char *argv[] = {scenegen, "--out", dir, "--views", sv, "--width", sw, "--height", sh,
                        "--dim", sd, "--holdout", "0", NULL, NULL, NULL, NULL, NULL};
  int n = 13;
  if (patch > 0) argv[n++] = "--patch", argv[n++] = sp;
  if (depth) argv[n++] = "--depth", argv[n++] = depth;
  pid_t pid = fork();
  if (pid < 0) FG_TEST_FAIL("fork: %s", strerror(errno));
  if (pid == 0) {
    execv(scenegen, (char *const *)argv);
    _exit(127);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) != pid) FG_TEST_FAIL("waitpid: %s", strerror(errno));
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    FG_TEST_FAIL("%s --out %s failed (status %#x)", scenegen, dir, (unsigned)status);
}

json_t *t_scene_json(const char *name) {
  char *path = h_fmt("/v1/scenes/%s", name);
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *j = json_incref(RJSON(r));
  h_resp_free(r);
  free(path);
  return j;
}

void t_write_config(const char *imports) {
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nsteps = 20\n", imports);
  h_write_config(conf);
  free(conf);
}

char *t_dataset(const char *scenegen, int views, int w, int h, int dim, int patch) {
  char *imports = h_fmt("%s/imports", h_tmpdir());
  char *dir = h_fmt("%s/sg", imports);
  t_scenegen(scenegen, dir, views, w, h, dim, patch);
  t_write_config(imports);
  free(imports);
  return dir;
}

void t_scene_from_dataset(const char *name, const char *dir, int n) {
  /* scenegen's table top is z = 0 around (0.45, 0); the objects stand on it. */
  char *body = h_fmt("{\"name\": \"%s\", \"workspace\": {\"min\": [0.1, -0.45, -0.05], "
                     "\"max\": [0.8, 0.45, 0.35]}}", name);
  h_resp *r = h_post_json("/v1/scenes", body);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  free(body);
  char *path = h_fmt("/v1/scenes/%s/import", name);
  body = h_fmt("{\"path\": \"%s\"}", dir);
  r = h_post_json(path, body);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), n);
  h_resp_free(r);
  free(body);
  free(path);
}

char *t_train(const char *scene, const char *body) {
  char *path = h_fmt("/v1/scenes/%s/train", scene);
  h_resp *r = h_post_json(path, body);
  ASSERT_STATUS(r, 202);
  char *id = h_fmt("%s", JSTR(r->json, "job"));
  ASSERT_STREQ(JSTR(r->json, "state"), "queued");
  char *loc = h_fmt("/v1/jobs/%s", id);
  ASSERT_STREQ(h_resp_header(r, "Location"), loc);
  free(loc);
  h_resp_free(r);
  free(path);
  return id;
}

json_t *t_job(const char *id) {
  char *path = h_fmt("/v1/jobs/%s", id);
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *j = json_incref(RJSON(r));
  h_resp_free(r);
  free(path);
  return j;
}

void t_train_done(const char *scene, const char *body, double timeout_s) {
  char *id = t_train(scene, body);
  json_decref(t_wait_job(id, "done", timeout_s));
  free(id);
}

json_t *t_wait_job(const char *id, const char *state, double timeout_s) {
  double deadline = t_now() + timeout_s;
  for (;;) {
    json_t *j = t_job(id);
    const char *st = JSTR(j, "state");
    if (strcmp(st, "done") == 0 || strcmp(st, "failed") == 0 || strcmp(st, "cancelled") == 0) {
      if (strcmp(st, state) != 0) {
        char *s = json_dumps(j, JSON_COMPACT);
        FG_TEST_FAIL("job %s ended %s, expected %s: %s", id, st, state, s ? s : "?");
      }
      return j;
    }
    json_decref(j);
    if (t_now() > deadline) FG_TEST_FAIL("job %s did not finish within %g s", id, timeout_s);
    h_sleep_ms(50);
  }
}

void t_wait_running(const char *id, int min_step, double timeout_s) {
  double deadline = t_now() + timeout_s;
  for (;;) {
    json_t *j = t_job(id);
    const char *st = JSTR(j, "state");
    int ok = strcmp(st, "running") == 0 && JINT(j, "step") >= min_step;
    if (!ok && strcmp(st, "queued") != 0 && strcmp(st, "running") != 0) {
      char *s = json_dumps(j, JSON_COMPACT);
      FG_TEST_FAIL("job %s ended while waiting for it to run: %s", id, s ? s : "?");
    }
    json_decref(j);
    if (ok) return;
    if (t_now() > deadline)
      FG_TEST_FAIL("job %s did not reach step %d within %g s", id, min_step, timeout_s);
    h_sleep_ms(20);
  }
}

static void normalize(double v[3]) {
  double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int k = 0; k < 3; k++) v[k] /= n;
}

char *t_camera(const double eye[3], const double target[3], double fl, int w, int h) {
  double z[3] = {eye[0] - target[0], eye[1] - target[1], eye[2] - target[2]};
  normalize(z);
  double up[3] = {0, 0, 1};
  double x[3] = {up[1] * z[2] - up[2] * z[1], up[2] * z[0] - up[0] * z[2],
                 up[0] * z[1] - up[1] * z[0]};
  normalize(x);
  double y[3] = {z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]};
  double T[16] = {x[0], y[0], z[0], eye[0], x[1], y[1], z[1], eye[1],
                  x[2], y[2], z[2], eye[2], 0,    0,    0,    1};
  char *m = h_matrix_json(T);
  char *s = h_fmt("{\"transform_matrix\": %s, \"fl_x\": %.17g, \"fl_y\": %.17g, \"cx\": %.17g, "
                  "\"cy\": %.17g, \"w\": %d, \"h\": %d}", m, fl, fl, w / 2.0, h / 2.0, w, h);
  free(m);
  return s;
}

h_resp *t_render(const char *scene, const char *body) {
  char *path = h_fmt("/v1/scenes/%s/render", scene);
  h_resp *r = h_post_json(path, body);
  free(path);
  return r;
}

static uint32_t be32(const unsigned char *p) {
  return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

void t_png_header(const h_resp *r, int *w, int *h, int *bit_depth, int *colour_type) {
  ASSERT_STATUS(r, 200);
  ASSERT_STREQ(h_resp_header(r, "Content-Type"), "image/png");
  const unsigned char *b = (const unsigned char *)r->body;
  ASSERT(r->len > 33);
  ASSERT(memcmp(b, "\x89PNG\r\n\x1a\n", 8) == 0);
  ASSERT(memcmp(b + 12, "IHDR", 4) == 0);
  *w = (int)be32(b + 16);
  *h = (int)be32(b + 20);
  *bit_depth = b[24];
  *colour_type = b[25];
}
