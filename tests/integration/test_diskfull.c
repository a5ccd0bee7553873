/* A full disk: the state dir is a small tmpfs, mounted in a private mount namespace of this
 * test (so that it vanishes with the test, whatever happens). With the file system full, and
 * with just too little room so that writes fail half-way, every request that stores something
 * (upload, import, new scene, demo, a demo's deletion) answers 507 insufficient_storage with
 * a JSON error, a training ends failed saying why and the scene keeps its field, and nothing
 * stored before is touched. A kill -9 and a start on the full disk work and leave no temp
 * file. Once space is freed, every one of those requests succeeds, and a restart shows the
 * same state.
 *
 * Mounting needs CAP_SYS_ADMIN: as root the test unshares a mount namespace; otherwise it
 * tries an unprivileged user namespace. Where neither is allowed it exits 77 (skipped) with
 * the reason. A loop-mounted image would need the same privilege, so it is no fallback. */
#include <errno.h>
#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include "crash_util.h"
#include "grasp_util.h"

#define TMPFS_SIZE "80m" /* two half-precision checkpoints (about 30 MB each) and the frames */

static char g_why[512]; /* why the test cannot mount, for the skip message */

static int write_text(const char *path, const char *text) {
  int fd = open(path, O_WRONLY | O_CLOEXEC);
  if (fd < 0) return -1;
  ssize_t n = write(fd, text, strlen(text));
  close(fd);
  return n == (ssize_t)strlen(text) ? 0 : -1;
}

/* A private mount namespace for this process and its children (before any thread starts). */
static int isolate(void) {
  uid_t uid = geteuid();
  gid_t gid = getegid();
  if (uid == 0) {
    if (unshare(CLONE_NEWNS) != 0) {
      snprintf(g_why, sizeof g_why, "unshare(CLONE_NEWNS) as root: %s", strerror(errno));
      return -1;
    }
  } else {
    if (unshare(CLONE_NEWUSER | CLONE_NEWNS) != 0) {
      snprintf(g_why, sizeof g_why, "not root, and unprivileged user namespaces are not "
               "allowed: unshare(CLONE_NEWUSER | CLONE_NEWNS): %s", strerror(errno));
      return -1;
    }
    char map[64];
    snprintf(map, sizeof map, "0 %u 1\n", (unsigned)uid);
    if (write_text("/proc/self/setgroups", "deny") != 0 ||
        write_text("/proc/self/uid_map", map) != 0) {
      snprintf(g_why, sizeof g_why, "cannot map the user into a user namespace: %s",
               strerror(errno));
      return -1;
    }
    snprintf(map, sizeof map, "0 %u 1\n", (unsigned)gid);
    if (write_text("/proc/self/gid_map", map) != 0) {
      snprintf(g_why, sizeof g_why, "cannot map the group: %s", strerror(errno));
      return -1;
    }
  }
  if (mount(NULL, "/", NULL, MS_REC | MS_PRIVATE, NULL) != 0) {
    snprintf(g_why, sizeof g_why, "cannot make the mounts private: %s", strerror(errno));
    return -1;
  }
  return 0;
}

static void unmount_state(void) {
  if (h_pid() > 0) h_kill(); /* the daemon holds files there */
  umount2(h_state_dir(), MNT_DETACH);
}

/* ---------------------------------------------------------------------------------------- */
/* Filling the disk                                                                          */

static char *g_filler;

/* Fills the file system with one file, then gives back `room` bytes (rounded to pages by
 * tmpfs), so that a write larger than that fails half-way. */
static void fill(long long room) {
  int fd = open(g_filler, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) FG_TEST_FAIL("open %s: %s", g_filler, strerror(errno));
  static char block[1 << 20];
  memset(block, 0x5a, sizeof block);
  long long total = 0;
  for (size_t chunk = sizeof block; chunk >= 512;) {
    ssize_t n = write(fd, block, chunk);
    if (n > 0) {
      total += n;
      continue;
    }
    if (n < 0 && errno != ENOSPC) FG_TEST_FAIL("filling %s: %s", g_filler, strerror(errno));
    chunk /= 2;
  }
  if (room > 0 && ftruncate(fd, total > room ? total - room : 0) != 0)
    FG_TEST_FAIL("ftruncate %s: %s", g_filler, strerror(errno));
  close(fd);
  printf("filled the state dir (%lld bytes of filler), %lld bytes left\n", total - room, room);
}

static void unfill(void) {
  if (unlink(g_filler) != 0) FG_TEST_FAIL("unlink %s: %s", g_filler, strerror(errno));
}

/* ---------------------------------------------------------------------------------------- */
/* What was stored before the disk filled                                                    */

typedef struct snapshot {
  json_t *scenes;  /* GET /v1/scenes without the volatile voxel cache */
  json_t *frames[3];
  json_t *task;
} snapshot;

static const char *const scenes[3] = {"s", "up", "big"};

static json_t *get_json(const char *path) {
  h_resp *r = h_get(path);
  ASSERT_STATUS(r, 200);
  json_t *j = json_incref(RJSON(r));
  h_resp_free(r);
  return j;
}

static json_t *scene_list(void) {
  json_t *l = get_json("/v1/scenes");
  json_t *a = JGET(l, "scenes");
  for (size_t i = 0; i < json_array_size(a); i++) {
    json_object_del(json_array_get(a, i), "voxel_cache");
    json_object_del(json_array_get(a, i), "last_job");
  }
  return l;
}

static void take(snapshot *s) {
  s->scenes = scene_list();
  for (int i = 0; i < 3; i++) s->frames[i] = cu_check_scene_files(scenes[i]);
  s->task = get_json("/v1/tasks/t");
}

static void release(snapshot *s) {
  json_decref(s->scenes);
  for (int i = 0; i < 3; i++) json_decref(s->frames[i]);
  json_decref(s->task);
}

/* Everything stored before is as it was, and the state dir is consistent. */
static void check_intact(const snapshot *s, unsigned seed0) {
  json_t *l = scene_list();
  ASSERT_JSON_EQUAL(l, s->scenes);
  json_decref(l);
  for (int i = 0; i < 3; i++) {
    json_t *f = cu_check_scene_files(scenes[i]);
    ASSERT_JSON_EQUAL(f, s->frames[i]);
    json_decref(f);
  }
  for (unsigned k = 0; k < 2; k++)
    cu_check_upload("up", json_array_get(s->frames[1], k), seed0 + k);
  json_t *t = get_json("/v1/tasks/t");
  ASSERT_JSON_EQUAL(t, s->task);
  json_decref(t);
}

static h_resp *upload_big(unsigned seed) {
  uint8_t *png;
  size_t len;
  h_png(400, 300, 3, 16, seed, 1, &png, &len); /* noise: stored as 720 KB of pixels */
  double T[16];
  h_pose(T, 0.1, 0.2, 0.3, 0, 0, 0.5);
  char *meta = h_meta(T, "opengl", 300, 200, 150, 400, 300);
  h_resp *r = h_upload("/v1/scenes/big/frames", png, len, meta, NULL, 0);
  free(meta);
  free(png);
  return r;
}

static char *demo_body(void) {
  return g_demo_body_qp("s", "ball", "{\"n\": 16, \"std\": 0.02}", "");
}

/* Every storing request fails with 507 and stores nothing; a training fails and the scene
 * keeps its field. With `some_room`, only the requests that need more than that room: they
 * fail half-way through their writes. */
static void check_refusals(const snapshot *snap, unsigned seed0, long long steps,
                           int some_room) {
  h_resp *r;
  if (!some_room) {
    r = cu_upload("up", 900);
    ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
    h_resp_free(r);
  }
  r = upload_big(901);
  ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
  h_resp_free(r);
  r = g_import("s", NULL);
  ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
  h_resp_free(r);
  if (!some_room) {
    r = h_post_json("/v1/scenes", "{\"name\": \"new\"}");
    ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
    h_resp_free(r);
    char *body = demo_body();
    r = h_post_json("/v1/tasks/t/demos", body);
    ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
    h_resp_free(r);
    r = h_post_json("/v1/tasks/other/demos", body);
    ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
    h_resp_free(r);
    free(body);
    r = h_delete("/v1/tasks/t/demos/1");
    ASSERT_HTTP_ERROR(r, 507, "insufficient_storage");
    h_resp_free(r);
  }

  char *id = t_train("s", "{\"steps\": 1}");
  json_t *j = t_wait_job(id, "failed", 600);
  const char *err = JSTR(j, "error");
  if (!strstr(err, "No space left on device"))
    FG_TEST_FAIL("the training failed for another reason than the full disk: %s", err);
  json_decref(j);
  free(id);
  json_t *sc = t_scene_json("s");
  ASSERT_EQ(JINT(sc, "trained_steps"), steps);
  ASSERT(json_is_true(JGET(sc, "trained")));
  json_decref(sc);
  static const double eye[3] = {0.45, -0.6, 0.5}, target[3] = {0.45, 0, 0.05};
  char *cam = t_camera(eye, target, 30, 32, 24);
  char *rb = h_fmt("{\"camera\": %s}", cam);
  r = t_render("s", rb);
  int w, h, bits, type;
  t_png_header(r, &w, &h, &bits, &type);
  h_resp_free(r);
  free(rb);
  free(cam);

  r = h_get("/v1/health");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  check_intact(snap, seed0);
}

int main(int argc, char **argv) {
  if (isolate() != 0) {
    printf("SKIP: the disk-full test needs a mount namespace for its tmpfs: %s\n", g_why);
    return 77;
  }
  h_init(argc, argv);
  if (argc < 3) FG_TEST_FAIL("usage: %s FIELDGRIPD FIELDGRIP-SCENEGEN", argv[0]);
  h_mkdirs(h_state_dir());
  if (mount("tmpfs", h_state_dir(), "tmpfs", MS_NOSUID | MS_NODEV, "size=" TMPFS_SIZE) != 0) {
    printf("SKIP: cannot mount a tmpfs on %s: %s\n", h_state_dir(), strerror(errno));
    h_done();
    return 77;
  }
  atexit(unmount_state);
  g_filler = h_fmt("%s/filler", h_state_dir());

  char *imports = g_dataset(argv[2]); /* outside the tmpfs */
  char *conf = h_fmt("[state]\nimport_dirs = %s\n\n[train]\nthreads = 2\nhalf_precision = "
                     "true\n", imports);
  h_write_config(conf);
  free(conf);
  free(imports);
  h_start();

  /* What is stored before the disk fills. */
  g_scene("s", NULL);
  g_train("s", 2);
  const long long steps = 2;
  h_resp *r = h_post_json("/v1/scenes", "{\"name\": \"up\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"big\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  const unsigned seed0 = 100;
  for (unsigned k = 0; k < 2; k++) {
    r = cu_upload("up", seed0 + k);
    ASSERT_STATUS(r, 201);
    h_resp_free(r);
  }
  char *body = demo_body();
  for (int k = 0; k < 2; k++) {
    r = h_post_json("/v1/tasks/t/demos", body);
    ASSERT_STATUS(r, 201);
    h_resp_free(r);
  }
  snapshot snap;
  take(&snap);

  /* Full to the last page. */
  fill(0);
  check_refusals(&snap, seed0, steps, 0);
  /* Room for a little: the frame, the import and the checkpoint fail half-way. */
  unfill();
  fill(256 << 10);
  check_refusals(&snap, seed0, steps, 1);

  /* Killed and started again on the full disk. */
  size_t from = cu_log_size();
  h_kill();
  h_start();
  cu_check_clean_start(from);
  cu_check_no_leftovers();
  check_intact(&snap, seed0);
  release(&snap);

  /* Space again: everything works. */
  unfill();
  r = cu_upload("up", 902);
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "frame"), 2);
  h_resp_free(r);
  r = upload_big(903);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = g_import("s", NULL);
  ASSERT_STATUS(r, 200);
  ASSERT_EQ(JINT(r->json, "imported"), G_VIEWS);
  h_resp_free(r);
  r = h_post_json("/v1/scenes", "{\"name\": \"new\"}");
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  r = h_post_json("/v1/tasks/t/demos", body);
  ASSERT_STATUS(r, 201);
  ASSERT_EQ(JINT(r->json, "demo.id"), 3);
  h_resp_free(r);
  r = h_delete("/v1/tasks/t/demos/1");
  ASSERT_STATUS(r, 200);
  h_resp_free(r);
  free(body);
  g_train("s", 3);

  /* A restart shows the same state. */
  json_t *before = scene_list(), *task = get_json("/v1/tasks/t");
  json_t *frames[3];
  for (int i = 0; i < 3; i++) frames[i] = cu_check_scene_files(scenes[i]);
  from = cu_log_size();
  h_stop();
  h_start();
  cu_check_clean_start(from);
  cu_check_no_leftovers();
  json_t *after = scene_list();
  ASSERT_JSON_EQUAL(after, before);
  json_t *task2 = get_json("/v1/tasks/t");
  ASSERT_JSON_EQUAL(task2, task);
  for (int i = 0; i < 3; i++) {
    json_t *f = cu_check_scene_files(scenes[i]);
    ASSERT_JSON_EQUAL(f, frames[i]);
    json_decref(f);
    json_decref(frames[i]);
  }
  ASSERT_EQ(json_array_size(JGET(task2, "demos")), 2);
  json_t *sc = t_scene_json("s");
  ASSERT_EQ(JINT(sc, "trained_steps"), 3);
  json_decref(sc);
  json_decref(before);
  json_decref(after);
  json_decref(task);
  json_decref(task2);
  h_stop();
  h_done();
  printf("ok\n");
  return 0;
}
