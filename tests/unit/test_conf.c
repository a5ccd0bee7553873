/* Configuration file: defaults, the SPEC.md example verbatim, and every error class with the
 * line number it must name. */
#include "conf/conf.h"

#include "core/error.h"
#include "test.h"

#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmp_root[PATH_MAX]; /* realpath of the mkdtemp folder */

/* Writes text to tmp_root/name and returns the malloc'd path. */
static char *write_file(const char *name, const char *text) {
  char *path = malloc(strlen(tmp_root) + strlen(name) + 2);
  ASSERT(path != NULL);
  sprintf(path, "%s/%s", tmp_root, name);
  FILE *f = fopen(path, "w");
  ASSERT(f != NULL);
  ASSERT_EQ(fwrite(text, 1, strlen(text), f), strlen(text));
  ASSERT_EQ(fclose(f), 0);
  return path;
}

static fg_conf *load_ok(const char *text) {
  char *path = write_file("ok.conf", text);
  char err[1024] = "unset";
  fg_conf *c = NULL;
  int rc = fg_conf_load(path, &c, err, sizeof err);
  if (rc != 0) FG_TEST_FAIL("fg_conf_load failed: %d: %s\n--- file ---\n%s", rc, err, text);
  ASSERT_STREQ(err, "");
  ASSERT(c != NULL);
  free(path);
  return c;
}

/* Loads text and expects FG_EINVAL with "FILE:LINE: " followed (somewhere) by each of the
 * given substrings. */
static void expect_error_at(int src_line, const char *text, int line, const char *want1,
                            const char *want2) {
  char *path = write_file("bad.conf", text);
  char err[1024] = "";
  fg_conf *c = (fg_conf *)(uintptr_t)1;
  int rc = fg_conf_load(path, &c, err, sizeof err);
  char prefix[PATH_MAX + 32];
  snprintf(prefix, sizeof prefix, "%s:%d: ", path, line);
  if (rc != FG_EINVAL || c != NULL || strncmp(err, prefix, strlen(prefix)) != 0 ||
      (want1 && !strstr(err, want1)) || (want2 && !strstr(err, want2)))
    FG_TEST_FAIL("(from test line %d) rc %d, err \"%s\"; expected prefix \"%s\" and \"%s\", "
                 "\"%s\"\n--- file ---\n%s",
                 src_line, rc, err, prefix, want1 ? want1 : "", want2 ? want2 : "", text);
  if (getenv("FG_TEST_VERBOSE")) fprintf(stderr, "%s\n", err);
  /* the detail is also recorded for fg_error_detail() */
  ASSERT_STREQ(fg_error_detail(), err);
  free(path);
}
#define EXPECT_ERROR(text, line, w1, w2) expect_error_at(__LINE__, text, line, w1, w2)

/* ---------------------------------------------------------------- defaults */

static void check_defaults(const fg_conf *c) {
  ASSERT_STREQ(c->listen, "127.0.0.1:7070");
  ASSERT(c->token == NULL || c->token[0] == '\0');
  ASSERT_EQ(c->max_upload_bytes, 64u << 20);
  ASSERT_EQ(c->max_json_bytes, 1u << 20);
  ASSERT_EQ(c->max_scenes, 64);
  ASSERT_EQ(c->max_loaded_fields, 4);
  ASSERT_EQ(c->max_connections, 1024);
  ASSERT_EQ(c->header_timeout_s, 10);
  ASSERT_EQ(c->idle_timeout_s, 60);
  ASSERT_EQ(c->min_body_bytes_per_s, 8u << 10);
  ASSERT_EQ(c->max_queued_requests, 64);
  ASSERT(c->viewer_dir == NULL);
  ASSERT_STREQ(c->three_js, "/usr/share/javascript/three/three.min.js");
  ASSERT_STREQ(c->state_dir, "/var/lib/fieldgrip");
  ASSERT_EQ(c->n_import_dirs, 0);
  ASSERT(c->clip_weights == NULL);
  ASSERT(c->clip_vocab == NULL);
  ASSERT_EQ(c->train_steps, 2000);
  ASSERT_EQ(c->train_threads, 0);
  ASSERT_EQ(c->max_image_side, 400);
  ASSERT_EQ(c->half_precision, 0);
  ASSERT_NEAR(c->depth_weight, FG_TRAIN_DEPTH_WEIGHT, 0);
  ASSERT_NEAR(c->distortion_weight, FG_TRAIN_DISTORTION_WEIGHT, 0);
  ASSERT_EQ(c->gripper_model, FG_GRIPPER_PANDA);

  const fg_conf_modbus *r = &c->robot;
  ASSERT_EQ(r->transport, FG_TRANSPORT_NONE);
  ASSERT_STREQ(r->host, "127.0.0.1");
  ASSERT_EQ(r->port, 502);
  ASSERT_STREQ(r->device, "/dev/ttyUSB0");
  ASSERT_EQ(r->baud, 115200);
  ASSERT_EQ(r->parity, 'N');
  ASSERT_EQ(r->unit_id, 1);
  ASSERT_EQ(r->timeout_ms, 500);
  ASSERT_EQ(r->base, 128);
  ASSERT_EQ(r->encoding, FG_ENCODING_INT16);
  ASSERT_EQ(r->ack_timeout_ms, 2000);
  ASSERT_EQ(r->done_timeout_ms, 60000);

  const fg_conf_modbus *g = &c->gripper_modbus;
  ASSERT_EQ(g->motion_timeout_ms, 10000);
  ASSERT_EQ(g->transport, FG_TRANSPORT_NONE);
  ASSERT_STREQ(g->host, "127.0.0.1");
  ASSERT_EQ(g->port, 502);
  ASSERT_STREQ(g->device, "/dev/ttyUSB0");
  ASSERT_EQ(g->baud, 115200);
  ASSERT_EQ(g->parity, 'N');
  ASSERT_EQ(g->unit_id, 9);
  ASSERT_EQ(g->timeout_ms, 500);
}

static void test_defaults(void) {
  fg_conf *c = fg_conf_defaults();
  ASSERT(c != NULL);
  ASSERT(c->path == NULL);
  check_defaults(c);
  ASSERT_EQ(c->n_scenes, 0);
  ASSERT(fg_conf_find_scene(c, "tabletop") == NULL);
  fg_conf_free(c);
  fg_conf_free(NULL);

  /* an empty file, and one with only comments, change nothing */
  c = load_ok("");
  check_defaults(c);
  ASSERT(c->path != NULL && c->path[0] == '/');
  fg_conf_free(c);
  c = load_ok("; nothing here\n# nor here\n\n   \n");
  check_defaults(c);
  fg_conf_free(c);
}

static void check_scene_defaults(const fg_conf_scene *s) {
  ASSERT_NEAR(s->workspace_min[0], 0.10, 1e-12);
  ASSERT_NEAR(s->workspace_min[1], -0.45, 1e-12);
  ASSERT_NEAR(s->workspace_min[2], 0.005, 1e-12);
  ASSERT_NEAR(s->workspace_max[0], 0.80, 1e-12);
  ASSERT_NEAR(s->workspace_max[1], 0.45, 1e-12);
  ASSERT_NEAR(s->workspace_max[2], 0.35, 1e-12);
  ASSERT_NEAR(s->voxel_size, 0.01, 1e-12);
  for (int i = 0; i < 3; i++) ASSERT_NEAR(s->background[i], 1.0, 0);
  ASSERT(s->field_scale == 0);       /* auto */
  ASSERT_EQ(s->learn_background, -1); /* auto */
}

/* ---------------------------------------------------------------- the SPEC example */

/* SPEC.md "Configuration file", copied verbatim. */
static const char spec_example[] =
    "[http]\n"
    "listen = 127.0.0.1:7070        ; host:port; [::1]:7070 for IPv6\n"
    "token =                        ; if set, every request but /v1/health needs \"Authorization: Bearer <token>\"\n"
    "max_upload_mb = 64\n"
    "\n"
    "[state]\n"
    "dir = /var/lib/fieldgrip\n"
    "import_dirs = /srv/scans       ; server-side folders that POST .../import may read (colon-separated)\n"
    "\n"
    "[clip]                         ; optional; without it, frames need uploaded features and queries need embeddings\n"
    "weights = /usr/share/fieldgrip/clip-vit-b-16.safetensors\n"
    "vocab = /usr/share/fieldgrip/bpe_simple_vocab_16e6.txt.gz\n"
    "\n"
    "[train]\n"
    "steps = 2000\n"
    "threads = 0                    ; 0 = all cores\n"
    "max_image_side = 400           ; frames are downscaled so that their long side is at most this\n"
    "\n"
    "[gripper]\n"
    "model = panda                  ; panda | robotiq-2f85: geometry for collision checks and widths\n"
    "\n"
    "[robot]                        ; Modbus peer that receives poses (profile pose-registers)\n"
    "transport = tcp                ; tcp | rtu | none\n"
    "host = 127.0.0.1\n"
    "port = 502\n"
    "unit_id = 1\n"
    "base = 128\n"
    "encoding = int16               ; int16 | float32\n"
    "ack_timeout_ms = 2000\n"
    "\n"
    "[gripper.modbus]               ; Modbus peer that actuates the gripper (profile robotiq-2f)\n"
    "transport = rtu                ; tcp | rtu | none\n"
    "device = /dev/ttyUSB0\n"
    "baud = 115200\n"
    "unit_id = 9\n"
    "\n"
    "[scene tabletop]               ; scenes named in the file exist at start-up\n"
    "workspace_min = 0.10 -0.45 0.005\n"
    "workspace_max = 0.80  0.45 0.35\n"
    "voxel_size = 0.01\n";

static void test_spec_example(void) {
  fg_conf *c = load_ok(spec_example);
  char expect_path[PATH_MAX + 16];
  snprintf(expect_path, sizeof expect_path, "%s/ok.conf", tmp_root);
  ASSERT_STREQ(c->path, expect_path);
  ASSERT_STREQ(c->listen, "127.0.0.1:7070");
  ASSERT(c->token == NULL || c->token[0] == '\0');
  ASSERT_EQ(c->max_upload_bytes, (size_t)64 * 1024 * 1024);
  ASSERT_STREQ(c->state_dir, "/var/lib/fieldgrip");
  ASSERT_EQ(c->n_import_dirs, 1);
  ASSERT_STREQ(c->import_dirs[0], "/srv/scans");
  ASSERT_STREQ(c->clip_weights, "/usr/share/fieldgrip/clip-vit-b-16.safetensors");
  ASSERT_STREQ(c->clip_vocab, "/usr/share/fieldgrip/bpe_simple_vocab_16e6.txt.gz");
  ASSERT_EQ(c->train_steps, 2000);
  ASSERT_EQ(c->train_threads, 0);
  ASSERT_EQ(c->max_image_side, 400);
  ASSERT_EQ(c->gripper_model, FG_GRIPPER_PANDA);

  ASSERT_EQ(c->robot.transport, FG_TRANSPORT_TCP);
  ASSERT_STREQ(c->robot.host, "127.0.0.1");
  ASSERT_EQ(c->robot.port, 502);
  ASSERT_EQ(c->robot.unit_id, 1);
  ASSERT_EQ(c->robot.base, 128);
  ASSERT_EQ(c->robot.encoding, FG_ENCODING_INT16);
  ASSERT_EQ(c->robot.ack_timeout_ms, 2000);
  ASSERT_EQ(c->robot.timeout_ms, 500);

  ASSERT_EQ(c->gripper_modbus.transport, FG_TRANSPORT_RTU);
  ASSERT_STREQ(c->gripper_modbus.device, "/dev/ttyUSB0");
  ASSERT_EQ(c->gripper_modbus.baud, 115200);
  ASSERT_EQ(c->gripper_modbus.unit_id, 9);
  ASSERT_EQ(c->gripper_modbus.parity, 'N');

  ASSERT_EQ(c->n_scenes, 1);
  const fg_conf_scene *s = fg_conf_find_scene(c, "tabletop");
  ASSERT(s != NULL);
  ASSERT_STREQ(s->name, "tabletop");
  check_scene_defaults(s); /* the example's values are the defaults */
  ASSERT(fg_conf_find_scene(c, "kitchen") == NULL);
  fg_conf_free(c);
}

/* ---------------------------------------------------------------- values */

/* [robot]'s audit log and claim keys: a fraction of a MiB, the kept files, a lock folder
 * taken from the file's folder, and an empty lock_dir meaning the default. */
static void test_audit_keys(void) {
  fg_conf *c = load_ok("[robot]\naudit_max_mb = 0.001\naudit_keep = 1000\nlock_dir = locks\n");
  ASSERT_EQ(c->audit_max_bytes, 1048);
  ASSERT_EQ(c->audit_keep, 1000);
  ASSERT(c->lock_dir && c->lock_dir[0] == '/');
  ASSERT_STRCONTAINS(c->lock_dir, "/locks");
  fg_conf_free(c);
  c = load_ok("[robot]\nlock_dir =\n");
  ASSERT(c->lock_dir == NULL);
  ASSERT_EQ(c->audit_max_bytes, (size_t)16 << 20);
  ASSERT_EQ(c->audit_keep, 8);
  fg_conf_free(c);
}

static void test_values(void) {
  fg_conf *c = load_ok(
      "; a full-line comment\n"
      "# and another\n"
      "[http]\n"
      "listen = [::1]:0\n"
      "token = s3cret;not-a-comment   ; but this is one\n"
      "max_upload_mb: 4096\n"
      "[train]\n"
      "steps=10000000\n"
      "threads = 1024\n"
      "max_image_side = 16\n"
      "half_precision = true\n"
      "depth_weight = 0.25\n"
      "distortion_weight = 0.002\n"
      "[gripper]\n"
      "model = robotiq-2f140\n"
      "[robot]\n"
      "transport = rtu\n"
      "device = /dev/ttyS3\n"
      "baud = 9600\n"
      "parity = e\n"
      "unit_id = 247\n"
      "timeout_ms = 60000\n"
      "base = 65509\n"
      "encoding = float32\n"
      "ack_timeout_ms = 600000\n"
      "done_timeout_ms = 3600000\n"
      "[gripper.modbus]\n"
      "motion_timeout_ms = 1\n"
      "transport = tcp\n"
      "host = ::1\n"
      "port = 1502\n"
      "unit_id = 0\n"
      "[scene a]\n"
      "[scene b-2.x_Y]\n"
      "workspace_min = -1 -2 -3\n"
      "workspace_max = 1e0 2.5 +3\n"
      "voxel_size = 2\n"
      "background = 0 0.5 1\n"
      "field_scale = 4\n"
      "learn_background = true\n");
  ASSERT_STREQ(c->listen, "[::1]:0");
  ASSERT_STREQ(c->token, "s3cret;not-a-comment");
  ASSERT_EQ(c->max_upload_bytes, (size_t)4096 << 20);
  ASSERT_EQ(c->train_steps, 10000000);
  ASSERT_EQ(c->train_threads, 1024);
  ASSERT_EQ(c->max_image_side, 16);
  ASSERT_EQ(c->half_precision, 1);
  ASSERT_NEAR(c->depth_weight, 0.25, 0);
  ASSERT_NEAR(c->distortion_weight, 0.002, 0);
  ASSERT_EQ(c->gripper_model, FG_GRIPPER_ROBOTIQ_2F140);
  ASSERT_EQ(c->robot.done_timeout_ms, 3600000);
  ASSERT_EQ(c->gripper_modbus.motion_timeout_ms, 1);
  ASSERT_EQ(c->robot.transport, FG_TRANSPORT_RTU);
  ASSERT_STREQ(c->robot.device, "/dev/ttyS3");
  ASSERT_EQ(c->robot.baud, 9600);
  ASSERT_EQ(c->robot.parity, 'E');
  ASSERT_EQ(c->robot.unit_id, 247);
  ASSERT_EQ(c->robot.timeout_ms, 60000);
  ASSERT_EQ(c->robot.base, 65509);
  ASSERT_EQ(c->robot.encoding, FG_ENCODING_FLOAT32);
  ASSERT_EQ(c->robot.ack_timeout_ms, 600000);
  ASSERT_EQ(c->gripper_modbus.transport, FG_TRANSPORT_TCP);
  ASSERT_STREQ(c->gripper_modbus.host, "::1");
  ASSERT_EQ(c->gripper_modbus.port, 1502);
  ASSERT_EQ(c->gripper_modbus.unit_id, 0);
  ASSERT_EQ(c->n_scenes, 2);
  check_scene_defaults(fg_conf_find_scene(c, "a"));
  const fg_conf_scene *s = fg_conf_find_scene(c, "b-2.x_Y");
  ASSERT(s != NULL);
  ASSERT_NEAR(s->workspace_min[2], -3, 0);
  ASSERT_NEAR(s->workspace_max[1], 2.5, 0);
  ASSERT_NEAR(s->workspace_max[2], 3, 0);
  ASSERT_NEAR(s->voxel_size, 2, 0);
  ASSERT_NEAR(s->background[0], 0, 0);
  ASSERT_NEAR(s->background[1], 0.5, 0);
  ASSERT_NEAR(s->background[2], 1, 0);
  ASSERT_NEAR(s->field_scale, 4, 0);
  ASSERT_EQ(s->learn_background, 1);
  fg_conf_free(c);

  /* the connection and body limits of [http], each at a value other than its default */
  c = load_ok("[http]\nmax_json_kb = 64\nmax_connections = 16\nheader_timeout_s = 1\n"
              "idle_timeout_s = 86400\nmin_body_kb_per_s = 0\nmax_queued_requests = 1\n");
  ASSERT_EQ(c->max_json_bytes, 64u << 10);
  ASSERT_EQ(c->max_connections, 16);
  ASSERT_EQ(c->header_timeout_s, 1);
  ASSERT_EQ(c->idle_timeout_s, 86400);
  ASSERT_EQ(c->min_body_bytes_per_s, 0);
  ASSERT_EQ(c->max_queued_requests, 1);
  ASSERT_EQ(c->max_upload_bytes, 64u << 20);
  fg_conf_free(c);
  c = load_ok("[http]\nmax_json_kb = 1048576\nmax_connections = 1000000\n"
              "min_body_kb_per_s = 3\n");
  ASSERT_EQ(c->max_json_bytes, (size_t)1 << 30);
  ASSERT_EQ(c->max_connections, 1000000);
  ASSERT_EQ(c->min_body_bytes_per_s, 3u << 10);
  fg_conf_free(c);

  /* an empty token means no authentication */
  c = load_ok("[http]\ntoken =\n");
  ASSERT(c->token == NULL || c->token[0] == '\0');
  fg_conf_free(c);

  /* a UTF-8 byte order mark is not part of the first header */
  c = load_ok("\xEF\xBB\xBF[train]\nsteps = 5\n");
  ASSERT_EQ(c->train_steps, 5);
  fg_conf_free(c);

  /* CRLF line ends, and indentation right after a header (no value to continue yet) */
  c = load_ok("[train]\r\n  steps = 7\r\n");
  ASSERT_EQ(c->train_steps, 7);
  fg_conf_free(c);
}

/* Relative paths are taken from the configuration file's folder, not the working directory. */
static void test_paths(void) {
  char sub[PATH_MAX + 8];
  snprintf(sub, sizeof sub, "%s/etc", tmp_root);
  ASSERT_EQ(mkdir(sub, 0700), 0);
  char *path = write_file("etc/x.conf",
                          "[http]\n"
                          "viewer_dir = web/\n"
                          "three_js = ../js/three.min.js\n"
                          "[state]\n"
                          "dir = state/./here/\n"
                          "import_dirs = scans:/srv//abs/:../other::/missing/later/../mnt:\n"
                          "[clip]\n"
                          "weights = w.safetensors\n"
                          "vocab = ../share/vocab.txt.gz\n"
                          "threads = 3\n");
  /* load through a relative path from another working directory */
  char cwd[PATH_MAX];
  ASSERT(getcwd(cwd, sizeof cwd) != NULL);
  ASSERT_EQ(chdir(tmp_root), 0);
  fg_conf *c = NULL;
  char err[1024];
  int rc = fg_conf_load("etc/x.conf", &c, err, sizeof err);
  ASSERT_EQ(chdir(cwd), 0);
  if (rc) FG_TEST_FAIL("load failed: %s", err);

  char want[PATH_MAX + 64];
  snprintf(want, sizeof want, "%s/etc/x.conf", tmp_root);
  ASSERT_STREQ(c->path, want);
  snprintf(want, sizeof want, "%s/etc/state/here", tmp_root);
  ASSERT_STREQ(c->state_dir, want);
  ASSERT_EQ(c->n_import_dirs, 4);
  snprintf(want, sizeof want, "%s/etc/scans", tmp_root);
  ASSERT_STREQ(c->import_dirs[0], want);
  ASSERT_STREQ(c->import_dirs[1], "/srv/abs");
  snprintf(want, sizeof want, "%s/other", tmp_root);
  ASSERT_STREQ(c->import_dirs[2], want);
  ASSERT_STREQ(c->import_dirs[3], "/missing/mnt"); /* need not exist */
  snprintf(want, sizeof want, "%s/etc/w.safetensors", tmp_root);
  ASSERT_STREQ(c->clip_weights, want); /* existence is checked when CLIP loads, not here */
  snprintf(want, sizeof want, "%s/share/vocab.txt.gz", tmp_root);
  ASSERT_STREQ(c->clip_vocab, want);
  ASSERT_EQ(c->clip_threads, 3);
  snprintf(want, sizeof want, "%s/etc/web", tmp_root);
  ASSERT_STREQ(c->viewer_dir, want);
  snprintf(want, sizeof want, "%s/js/three.min.js", tmp_root);
  ASSERT_STREQ(c->three_js, want);
  fg_conf_free(c);
  free(path);

  /* empty viewer keys: the built-in places */
  c = load_ok("[http]\nviewer_dir =\nthree_js =\n");
  ASSERT(c->viewer_dir == NULL);
  ASSERT_STREQ(c->three_js, FG_CONF_DEFAULT_THREE_JS);
  fg_conf_free(c);

  /* a later import_dirs line would be a duplicate; an empty one means none */
  c = load_ok("[state]\nimport_dirs =\n");
  ASSERT_EQ(c->n_import_dirs, 0);
  fg_conf_free(c);
}

/* ---------------------------------------------------------------- token_file */

/* Writes a token file with the given mode; returns its malloc'd path. */
static char *write_secret(const char *name, const char *text, mode_t mode) {
  char *path = write_file(name, text);
  ASSERT_EQ(chmod(path, mode), 0);
  return path;
}

static void test_token_file(void) {
  free(write_secret("tok", "s3cret-1\n", 0600));
  fg_conf *c = load_ok("[http]\ntoken_file = tok\n");
  ASSERT_STREQ(c->token, "s3cret-1"); /* the newline dropped */
  char want[PATH_MAX + 16];
  snprintf(want, sizeof want, "%s/tok", tmp_root);
  ASSERT_STREQ(c->token_file, want);
  fg_conf_free(c);
  /* CRLF, no newline at all, an empty token key beside it, an owner-only read bit */
  free(write_secret("tok", "s3cret-2\r\n", 0400));
  c = load_ok("[http]\ntoken =\ntoken_file = tok\n");
  ASSERT_STREQ(c->token, "s3cret-2");
  fg_conf_free(c);
  free(write_secret("tok", "s3cret-3", 0600));
  c = load_ok("[http]\ntoken_file = tok\n");
  ASSERT_STREQ(c->token, "s3cret-3");
  fg_conf_free(c);

  /* refused: readable by others, empty, two lines, missing, both keys */
  free(write_secret("tok", "s3cret\n", 0644));
  EXPECT_ERROR("[http]\ntoken_file = tok\n", 2, "[http] token_file", "chmod 600");
  free(write_secret("tok", "s3cret\n", 0640));
  EXPECT_ERROR("[http]\ntoken_file = tok\n", 2, "group or others (mode 0640)", NULL);
  free(write_secret("tok", "\n", 0600));
  EXPECT_ERROR("[http]\n\ntoken_file = tok\n", 3, "is empty", NULL);
  free(write_secret("tok", "", 0600));
  EXPECT_ERROR("[http]\ntoken_file = tok\n", 2, "is empty", NULL);
  free(write_secret("tok", "one\ntwo\n", 0600));
  EXPECT_ERROR("[http]\ntoken_file = tok\n", 2, "more than one line", NULL);
  EXPECT_ERROR("[http]\ntoken_file = nowhere\n", 2, "cannot open", "nowhere");
  free(write_secret("tok", "s3cret\n", 0600));
  EXPECT_ERROR("[http]\ntoken = abc\ntoken_file = tok\n", 3, "token is set too (line 2)",
               "keep one");
  c = load_ok("[http]\ntoken_file =\n"); /* empty: none, like token */
  ASSERT(!c->token && !c->token_file);
  fg_conf_free(c);

  /* ${CREDENTIALS_DIRECTORY}: systemd's LoadCredential= folder */
  unsetenv("CREDENTIALS_DIRECTORY");
  EXPECT_ERROR("[http]\ntoken_file = ${CREDENTIALS_DIRECTORY}/tok\n", 2,
               "${CREDENTIALS_DIRECTORY} is not set", "LoadCredential=");
  ASSERT_EQ(setenv("CREDENTIALS_DIRECTORY", tmp_root, 1), 0);
  c = load_ok("[http]\ntoken_file = ${CREDENTIALS_DIRECTORY}/tok\n");
  ASSERT_STREQ(c->token, "s3cret");
  ASSERT_STREQ(c->token_file, want);
  fg_conf_free(c);
  EXPECT_ERROR("[http]\ntoken_file = ${CREDENTIALS_DIRECTORY}\n", 2, "expected", "/NAME");
  unsetenv("CREDENTIALS_DIRECTORY");
}

/* ---------------------------------------------------------------- listen and scene names */

static void test_listen(void) {
  char *host = NULL;
  int port = -1;
  ASSERT_OK(fg_conf_parse_listen("127.0.0.1:7070", &host, &port));
  ASSERT_STREQ(host, "127.0.0.1");
  ASSERT_EQ(port, 7070);
  free(host);
  ASSERT_OK(fg_conf_parse_listen("[::1]:7070", &host, &port));
  ASSERT_STREQ(host, "::1");
  ASSERT_EQ(port, 7070);
  free(host);
  ASSERT_OK(fg_conf_parse_listen("[fe80::1%lo]:65535", &host, &port));
  ASSERT_STREQ(host, "fe80::1%lo");
  ASSERT_EQ(port, 65535);
  free(host);
  ASSERT_OK(fg_conf_parse_listen("localhost:0", &host, &port)); /* 0 = any free port */
  ASSERT_STREQ(host, "localhost");
  ASSERT_EQ(port, 0);
  free(host);

  ASSERT_ERR(fg_conf_parse_listen("::1:7070", &host, &port), FG_EINVAL, "brackets");
  ASSERT_ERR(fg_conf_parse_listen("[::1]7070", &host, &port), FG_EINVAL, "':PORT'");
  ASSERT_ERR(fg_conf_parse_listen("[::1:7070", &host, &port), FG_EINVAL, "']'");
  ASSERT_ERR(fg_conf_parse_listen("[]:7070", &host, &port), FG_EINVAL, "no host");
  ASSERT_ERR(fg_conf_parse_listen(":7070", &host, &port), FG_EINVAL, "no host");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1", &host, &port), FG_EINVAL, "no port");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1:", &host, &port), FG_EINVAL, "0 to 65535");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1:65536", &host, &port), FG_EINVAL, "0 to 65535");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1:7070x", &host, &port), FG_EINVAL, "bad port");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1:-1", &host, &port), FG_EINVAL, "bad port");
  ASSERT_ERR(fg_conf_parse_listen("127.0.0.1:0000070", &host, &port), FG_EINVAL, "bad port");
  ASSERT(host == NULL);

  /* IPv6 and port 0 through the file */
  fg_conf *c = load_ok("[http]\nlisten = [::1]:7070\n");
  ASSERT_STREQ(c->listen, "[::1]:7070");
  fg_conf_free(c);
  c = load_ok("[http]\nlisten = 127.0.0.1:0\n");
  ASSERT_STREQ(c->listen, "127.0.0.1:0");
  fg_conf_free(c);
}

/* [http] allowed_hosts and allowed_origins (lists at spaces and commas), and the refusal of a
 * robot on a network address without a token. */
static void test_cross_site(void) {
  fg_conf *c = load_ok("[http]\nallowed_hosts = robot.lab, Robot-PC.local ,,x_y\n"
                       "allowed_origins = http://panel.lab:8080 https://[::1]:7443\n");
  ASSERT_EQ(c->n_allowed_hosts, 3);
  ASSERT_STREQ(c->allowed_hosts[0], "robot.lab");
  ASSERT_STREQ(c->allowed_hosts[1], "Robot-PC.local");
  ASSERT_STREQ(c->allowed_hosts[2], "x_y");
  ASSERT_EQ(c->n_allowed_origins, 2);
  ASSERT_STREQ(c->allowed_origins[0], "http://panel.lab:8080");
  ASSERT_STREQ(c->allowed_origins[1], "https://[::1]:7443");
  fg_conf_free(c);
  c = load_ok("[http]\nallowed_hosts =\nallowed_origins =\n");
  ASSERT(c->n_allowed_hosts == 0 && c->allowed_hosts == NULL && c->n_allowed_origins == 0);
  fg_conf_free(c);
  EXPECT_ERROR("[http]\nallowed_hosts = robot.lab:7070\n", 2, "[http] allowed_hosts:",
               "without scheme or port");
  EXPECT_ERROR("[http]\nallowed_hosts = a b/c\n", 2, "'b/c'", NULL);
  EXPECT_ERROR("[http]\nallowed_hosts = ro*t\n", 2, "contains '*'", NULL);
  EXPECT_ERROR("[http]\nallowed_origins = http://panel.lab/\n", 2, "[http] allowed_origins:",
               "without a path");
  EXPECT_ERROR("[http]\nallowed_origins = null\n", 2, "is not a web origin", NULL);
  EXPECT_ERROR("[http]\nallowed_origins = *\n", 2, "is not a web origin", NULL);
  EXPECT_ERROR("[http]\nallowed_origins = ftp://x\n", 2, "is not a web origin", NULL);

  ASSERT(fg_conf_listen_is_loopback("127.0.0.1:7070"));
  ASSERT(fg_conf_listen_is_loopback("127.1.2.3:0"));
  ASSERT(fg_conf_listen_is_loopback("[::1]:7070"));
  ASSERT(fg_conf_listen_is_loopback("[::ffff:127.0.0.1]:7070"));
  ASSERT(fg_conf_listen_is_loopback("LocalHost:7070"));
  ASSERT(!fg_conf_listen_is_loopback("0.0.0.0:7070"));
  ASSERT(!fg_conf_listen_is_loopback("[::]:7070"));
  ASSERT(!fg_conf_listen_is_loopback("192.168.1.5:7070"));
  ASSERT(!fg_conf_listen_is_loopback("robot-pc:7070"));

  /* a robot or a gripper, a network address and no token: refused, naming the keys */
  c = load_ok("[http]\nlisten = 0.0.0.0:7070\n[robot]\ntransport = tcp\nhost = 10.0.0.2\n");
  ASSERT_ERR(fg_conf_check_exposure(c, NULL), FG_EINVAL, "[robot] transport");
  ASSERT_STRCONTAINS(fg_error_detail(), "[http] token_file");
  ASSERT_STRCONTAINS(fg_error_detail(), "127.0.0.1:PORT");
  fg_conf *loop = load_ok("[robot]\ntransport = tcp\nhost = 10.0.0.2\n");
  ASSERT_OK(fg_conf_check_exposure(loop, NULL));
  /* at a reload the running listen address counts: the file's changes only at a restart */
  ASSERT_OK(fg_conf_check_exposure(c, loop));
  ASSERT_ERR(fg_conf_check_exposure(loop, c), FG_EINVAL, "0.0.0.0:7070");
  fg_conf_free(loop);
  fg_conf_free(c);
  c = load_ok("[http]\nlisten = 0.0.0.0:7070\n[gripper.modbus]\ntransport = rtu\n");
  ASSERT_ERR(fg_conf_check_exposure(c, NULL), FG_EINVAL, "[gripper.modbus] transport");
  fg_conf_free(c);
  c = load_ok("[http]\nlisten = 0.0.0.0:7070\ntoken = s3cret\n[robot]\ntransport = tcp\n");
  ASSERT_OK(fg_conf_check_exposure(c, NULL));
  fg_conf_free(c);
  c = load_ok("[http]\nlisten = 0.0.0.0:7070\n"); /* nothing to move */
  ASSERT_OK(fg_conf_check_exposure(c, NULL));
  fg_conf_free(c);
}

static void test_scene_names(void) {
  ASSERT_OK(fg_scene_name_validate("tabletop"));
  ASSERT_OK(fg_scene_name_validate("A-b_c.9"));
  ASSERT_OK(fg_scene_name_validate("-x"));
  char name[FG_SCENE_NAME_MAX + 2];
  memset(name, 'a', FG_SCENE_NAME_MAX);
  name[FG_SCENE_NAME_MAX] = '\0';
  ASSERT_OK(fg_scene_name_validate(name));
  name[FG_SCENE_NAME_MAX] = 'a';
  name[FG_SCENE_NAME_MAX + 1] = '\0';
  ASSERT_ERR(fg_scene_name_validate(name), FG_EINVAL, "65 characters");
  ASSERT_ERR(fg_scene_name_validate(""), FG_EINVAL, "empty");
  ASSERT_ERR(fg_scene_name_validate(NULL), FG_EINVAL, "empty");
  ASSERT_ERR(fg_scene_name_validate(".hidden"), FG_EINVAL, "starts with '.'");
  ASSERT_ERR(fg_scene_name_validate(".."), FG_EINVAL, "starts with '.'");
  ASSERT_ERR(fg_scene_name_validate("a/b"), FG_EINVAL, "'/'");
  ASSERT_ERR(fg_scene_name_validate("a b"), FG_EINVAL, "' '");
  ASSERT_ERR(fg_scene_name_validate("caf\xc3\xa9"), FG_EINVAL, "0xc3");
}

/* ---------------------------------------------------------------- errors */

static void test_errors(void) {
  /* unknown section, also when empty; unknown key; a key before any section */
  EXPECT_ERROR("[http]\n\n[htp]\n", 3, "[htp]: unknown section", "gripper.modbus");
  EXPECT_ERROR("[http]\nlisten = 127.0.0.1:1\nport = 80\n", 3, "[http] port: unknown key",
               "listen, token, max_upload_mb");
  EXPECT_ERROR("; top\nsteps = 3\n[train]\n", 2, "steps: key outside any section", NULL);
  EXPECT_ERROR("[Train]\nsteps = 3\n", 1, "[Train]: unknown section", NULL);

  /* integers: junk, range, empty, floats */
  EXPECT_ERROR("[train]\nsteps = many\n", 2,
               "[train] steps: expected an integer from 1 to 10000000, got 'many'", NULL);
  EXPECT_ERROR("[train]\n\nsteps = 12abc\n", 3, "[train] steps:", "got '12abc'");
  EXPECT_ERROR("[train]\nsteps = 0\n", 2, "[train] steps:", "from 1 to 10000000");
  EXPECT_ERROR("[train]\nsteps = 10000001\n", 2, "[train] steps:", "from 1 to 10000000");
  EXPECT_ERROR("[train]\nsteps = 99999999999999999999999\n", 2, "[train] steps:", NULL);
  EXPECT_ERROR("[train]\nsteps =\n", 2, "[train] steps:", "got ''");
  EXPECT_ERROR("[train]\nthreads = 1.5\n", 2, "[train] threads:", "from 0 to 1024");
  EXPECT_ERROR("[train]\nthreads = -1\n", 2, "[train] threads:", NULL);
  EXPECT_ERROR("[train]\nmax_image_side = 15\n", 2, "[train] max_image_side:", "16 to 16384");
  EXPECT_ERROR("[train]\nhalf_precision = yes\n", 2, "[train] half_precision:", "true");
  EXPECT_ERROR("[train]\ndepth_weight = -1\n", 2, "[train] depth_weight:", "0 to 1000");
  EXPECT_ERROR("[train]\ndistortion_weight = lots\n", 2, "[train] distortion_weight:", "number");
  EXPECT_ERROR("[http]\nmax_upload_mb = 0\n", 2, "[http] max_upload_mb:", "1 to 4096");
  EXPECT_ERROR("[state]\nmax_scenes = -1\n", 2, "[state] max_scenes:", "0 to 1000000");
  EXPECT_ERROR("[state]\nmax_loaded_fields = many\n", 2, "[state] max_loaded_fields:",
               "0 to 100000");
  /* the declared scenes alone would not fit: the key's line, else the first one too many */
  EXPECT_ERROR("[state]\nmax_scenes = 1\n[scene a]\n[scene b]\n", 2, "[state] max_scenes:",
               "declares 2 [scene NAME] sections");
  EXPECT_ERROR("[scene a]\n[scene b]\n[state]\nmax_scenes = 1\n", 4, "[state] max_scenes:",
               "raise max_scenes");
  {
    fg_conf *c = load_ok("[state]\nmax_scenes = 0\nmax_loaded_fields = 0\n[scene a]\n");
    ASSERT_EQ(c->max_scenes, 0);
    ASSERT_EQ(c->max_loaded_fields, 0);
    fg_conf_free(c);
    c = load_ok("[state]\nmax_scenes = 1\nmax_loaded_fields = 100000\n[scene a]\n");
    ASSERT_EQ(c->max_scenes, 1);
    ASSERT_EQ(c->max_loaded_fields, 100000);
    fg_conf_free(c);
  }
  EXPECT_ERROR("[http]\nmax_upload_mb = 4097\n", 2, "[http] max_upload_mb:", "1 to 4096");
  EXPECT_ERROR("[http]\nmax_json_kb = 0\n", 2, "[http] max_json_kb:", "1 to 1048576");
  EXPECT_ERROR("[http]\nmax_connections = 15\n", 2, "[http] max_connections:",
               "16 to 1000000");
  EXPECT_ERROR("[http]\nheader_timeout_s = 0\n", 2, "[http] header_timeout_s:", "1 to 3600");
  EXPECT_ERROR("[http]\nidle_timeout_s = 86401\n", 2, "[http] idle_timeout_s:", "1 to 86400");
  EXPECT_ERROR("[http]\nmin_body_kb_per_s = -1\n", 2, "[http] min_body_kb_per_s:",
               "0 to 1048576");
  EXPECT_ERROR("[http]\nmax_queued_requests = 0\n", 2, "[http] max_queued_requests:",
               "1 to 100000");
  EXPECT_ERROR("[http]\nheader_timeout_s = 1\nheader_timeout_s = 2\n", 3,
               "[http] header_timeout_s:", "duplicate key");
  EXPECT_ERROR("[robot]\nport = 0\n", 2, "[robot] port:", "1 to 65535");
  EXPECT_ERROR("[robot]\nunit_id = 248\n", 2, "[robot] unit_id:", "0 to 247");
  EXPECT_ERROR("[robot]\nbase = 65510\n", 2, "[robot] base:", "0 to 65509");
  EXPECT_ERROR("[robot]\nlimit_min = 0 0 0\n", 2, "[robot] limit_max:", "needs both");
  EXPECT_ERROR("[robot]\nlimit_min = 0 0 1\nlimit_max = 1 1 1\n", 2, "[robot] limit_min:",
               "below limit_max");
  EXPECT_ERROR("[robot]\napproach_cone_deg = 181\n", 2, "[robot] approach_cone_deg:",
               "at most 180");
  EXPECT_ERROR("[robot]\nreach_m = -1\n", 2, "[robot] reach_m:", "at most 10");
  EXPECT_ERROR("[camera c]\nsource = http://h/a.png\nfeatures_source = /dev/x\n", 3,
               "[camera c] features_source:", "serves the view's features as .npy");
  EXPECT_ERROR("[robot]\nmax_speed_mps = 0\n", 2, "[robot] max_speed_mps:", "above 0");
  EXPECT_ERROR("[robot]\nspeed_mps = 0.5\n", 2, "[robot] speed_mps:", "above max_speed_mps");
  EXPECT_ERROR("[robot]\napproach_m = 1.5\n", 2, "[robot] approach_m:", "at most 1");
  EXPECT_ERROR("[robot]\ntimeout_ms = 0\n", 2, "[robot] timeout_ms:", NULL);
  /* [calibration]: the board, checked as OpenCV would make it */
  {
    fg_conf *c = load_ok("[robot]\n");
    ASSERT_EQ(c->board.squares_x, 7);
    ASSERT_EQ(c->board.squares_y, 5);
    ASSERT_NEAR(c->board.square_m, 0.035, 1e-12);
    ASSERT_STREQ(fg_charuco_dictionary_name(c->board.dictionary), "DICT_5X5_100");
    fg_conf_free(c);
    c = load_ok("[calibration]\nsquares_x = 9\nsquares_y = 6\nsquare_m = 0.03\n"
                "marker_m = 0.022\ndictionary = DICT_4X4_50\n");
    ASSERT_EQ(c->board.squares_x, 9);
    ASSERT_STREQ(fg_charuco_dictionary_name(c->board.dictionary), "DICT_4X4_50");
    fg_conf_free(c);
  }
  EXPECT_ERROR("[calibration]\ndictionary = DICT_9X9\n", 2, "[calibration] dictionary:",
               "DICT_7X7_1000");
  EXPECT_ERROR("[calibration]\nsquares_x = 2\n", 2, "[calibration] squares_x:", "3 to 64");
  EXPECT_ERROR("[calibration]\nmarker_m = 0.04\n", 1, "[calibration]:", "below square_m");
  EXPECT_ERROR("[calibration]\nsquares_x = 12\nsquares_y = 12\ndictionary = DICT_4X4_50\n", 1,
               "[calibration]:", "needs 72 markers");
  /* [camera NAME] */
  {
    fg_conf *c = load_ok("[camera wrist]\nsource = http://127.0.0.1:8081/rgb.png\n"
                         "depth_source = http://127.0.0.1:8081/depth.png\n"
                         "[camera over]\nsource = http://10.0.0.5/snap.jpg\nmount = fixed\n"
                         "depth_scale = 0.0001\ntimeout_ms = 60000\n");
    ASSERT_EQ(c->n_cameras, 2);
    const fg_conf_camera *w = fg_conf_find_camera(c, "wrist"), *o = fg_conf_find_camera(c, "over");
    ASSERT(w && o && !fg_conf_find_camera(c, "none"));
    ASSERT_STREQ(w->source, "http://127.0.0.1:8081/rgb.png");
    ASSERT_STREQ(w->depth_source, "http://127.0.0.1:8081/depth.png");
    ASSERT_EQ(w->mount, FG_MOUNT_HAND);
    ASSERT_NEAR(w->depth_scale, 0.001, 1e-15);
    ASSERT_EQ(o->mount, FG_MOUNT_FIXED);
    ASSERT(o->depth_source == NULL);
    ASSERT_NEAR(o->depth_scale, 0.0001, 1e-15);
    ASSERT_EQ(w->timeout_ms, 5000);
    ASSERT_EQ(o->timeout_ms, 60000);
    fg_conf_free(c);
  }
  EXPECT_ERROR("[camera w]\nsource = http://h/a.png\ntimeout_ms = 50\n", 3,
               "[camera w] timeout_ms:", "from 100 to 600000");
  EXPECT_ERROR("[camera]\nsource = http://10.0.0.5/snap.jpg\n", 1, "[camera]:", "needs a name");
  EXPECT_ERROR("[camera a b]\n", 1, "[camera a b]:", "a camera's name");
  EXPECT_ERROR("[camera w]\nmount = hand\n", 1, "[camera w] source:", "missing");
  EXPECT_ERROR("[camera w]\nsource = ftp://x/y\n", 2, "[camera w] source:", "snapshot URL");
  {
    fg_conf *c = load_ok("[camera usb]\nsource = v4l2:/dev/video0\n");
    ASSERT_STREQ(fg_conf_find_camera(c, "usb")->source, "v4l2:/dev/video0");
    fg_conf_free(c);
  }
  EXPECT_ERROR("[camera w]\nsource = v4l2:video0\n", 2, "[camera w] source:",
               "v4l2:/dev/videoN");
  EXPECT_ERROR("[camera w]\nsource = v4l2:/dev/video0\ndepth_source = v4l2:/dev/video1\n", 3,
               "[camera w] depth_source:", "not depth");
  EXPECT_ERROR("[camera w]\nsource = http://10.0.0.5/snap.jpg\nmount = wrist\n", 3,
               "[camera w] mount:", "hand or fixed");
  EXPECT_ERROR("[camera w]\nsource = http://10.0.0.5/snap.jpg\n[camera w]\n", 3, "[camera w]:",
               "duplicate camera section");
  EXPECT_ERROR("[camera w]\nsource = http://10.0.0.5/snap.jpg\nlens = wide\n", 3, "[camera w] lens:",
               "[camera NAME] takes");
  /* the TCP pose registers: a register or none, never over the command block */
  EXPECT_ERROR("[robot]\ntcp_pose_base = 65530\n", 2, "[robot] tcp_pose_base:", "0 to 65529");
  EXPECT_ERROR("[robot]\ntcp_pose_base = 140\n", 2, "[robot] tcp_pose_base:",
               "140..145 overlap the command block 128..143");
  EXPECT_ERROR("[robot]\nencoding = float32\ntcp_pose_base = 150\n", 3,
               "[robot] tcp_pose_base:", "128..153");
  EXPECT_ERROR("[robot]\nbase = 395\n", 2, "[robot] tcp_pose_base:", "400..405 overlap");
  EXPECT_ERROR("[gripper.modbus]\ntcp_pose_base = 400\n", 2,
               "[gripper.modbus] tcp_pose_base: unknown key", "[robot] only");
  {
    fg_conf *c = load_ok("[robot]\ntcp_pose_base = none\n");
    ASSERT_EQ(c->robot.tcp_pose_base, -1);
    fg_conf_free(c);
    c = load_ok("[robot]\ntcp_pose_base = 122\n");
    ASSERT_EQ(c->robot.tcp_pose_base, 122);
    fg_conf_free(c);
    c = load_ok("[robot]\n");
    ASSERT_EQ(c->robot.tcp_pose_base, 400);
    fg_conf_free(c);
  }
  EXPECT_ERROR("[robot]\nack_timeout_ms = 600001\n", 2, "[robot] ack_timeout_ms:", NULL);
  EXPECT_ERROR("[gripper.modbus]\nbaud = fast\n", 2, "[gripper.modbus] baud:", NULL);

  /* enumerations */
  EXPECT_ERROR("[robot]\ntransport = udp\n", 2, "[robot] transport:",
               "expected none, tcp or rtu, got 'udp'");
  EXPECT_ERROR("[robot]\nencoding = int32\n", 2, "[robot] encoding:", "int16 or float32");
  EXPECT_ERROR("[robot]\nparity = X\n", 2, "[robot] parity:", "N, E or O");
  EXPECT_ERROR("[robot]\naudit_max_mb = 0\n", 2, "[robot] audit_max_mb:", "above 0");
  EXPECT_ERROR("[robot]\naudit_max_mb = -1\n", 2, "[robot] audit_max_mb:", "above 0");
  EXPECT_ERROR("[robot]\naudit_max_mb = lots\n", 2, "[robot] audit_max_mb:", NULL);
  EXPECT_ERROR("[robot]\naudit_keep = 0\n", 2, "[robot] audit_keep:", "1 to 1000");
  EXPECT_ERROR("[gripper.modbus]\naudit_keep = 2\n", 2, "[gripper.modbus] audit_keep: unknown key",
               "[robot] only");
  EXPECT_ERROR("[gripper]\nmodel = ur5\n", 2, "[gripper] model:",
               "panda, robotiq-2f85 or robotiq-2f140");

  /* robot-only keys in [gripper.modbus] */
  EXPECT_ERROR("[gripper.modbus]\ntransport = none\nbase = 128\n", 3,
               "[gripper.modbus] base: unknown key", "[robot] only");
  EXPECT_ERROR("[gripper.modbus]\nencoding = int16\n", 2, "[gripper.modbus] encoding:", NULL);
  EXPECT_ERROR("[gripper.modbus]\nack_timeout_ms = 5\n", 2, "[gripper.modbus] ack_timeout_ms:",
               NULL);
  EXPECT_ERROR("[gripper.modbus]\ndone_timeout_ms = 5\n", 2,
               "[gripper.modbus] done_timeout_ms: unknown key", "[robot] only");
  EXPECT_ERROR("[robot]\nmotion_timeout_ms = 5\n", 2, "[robot] motion_timeout_ms: unknown key",
               NULL);
  EXPECT_ERROR("[robot]\ndone_timeout_ms = 0\n", 2, "[robot] done_timeout_ms:", NULL);
  EXPECT_ERROR("[gripper.modbus]\nmotion_timeout_ms = 600001\n", 2,
               "[gripper.modbus] motion_timeout_ms:", NULL);

  /* floats and vectors */
  EXPECT_ERROR("[scene t]\nvoxel_size = nan\n", 2, "[scene t] voxel_size:", "finite number");
  EXPECT_ERROR("[scene t]\nvoxel_size = inf\n", 2, "[scene t] voxel_size:", "finite number");
  EXPECT_ERROR("[scene t]\nvoxel_size = 1e999\n", 2, "[scene t] voxel_size:", "finite number");
  EXPECT_ERROR("[scene t]\nvoxel_size = 0.01m\n", 2, "[scene t] voxel_size:", "got '0.01m'");
  EXPECT_ERROR("[scene t]\nvoxel_size = 0\n", 2, "[scene t] voxel_size:", "positive");
  EXPECT_ERROR("[scene t]\nvoxel_size = -0.01\n", 2, "[scene t] voxel_size:", "positive");
  EXPECT_ERROR("[scene t]\nfield_scale = 0.5\n", 2, "[scene t] field_scale:", "auto or a number from 1 to 64");
  EXPECT_ERROR("[scene t]\nfield_scale = 65\n", 2, "[scene t] field_scale:", "got '65'");
  EXPECT_ERROR("[scene t]\nfield_scale = big\n", 2, "[scene t] field_scale:", "got 'big'");
  EXPECT_ERROR("[scene t]\nlearn_background = yes\n", 2, "[scene t] learn_background:",
               "expected false, true or auto");
  EXPECT_ERROR("[scene t]\nworkspace_min = 0 0\n", 2, "[scene t] workspace_min:", "3");
  EXPECT_ERROR("[scene t]\nworkspace_max = 1 1 1 1\n", 2, "[scene t] workspace_max:",
               "exactly 3 numbers");
  EXPECT_ERROR("[scene t]\nworkspace_max = 1,1,1\n", 2, "[scene t] workspace_max:", NULL);
  EXPECT_ERROR("[scene t]\nworkspace_min = 0 nan 0\n", 2, "[scene t] workspace_min:", "finite");
  EXPECT_ERROR("[scene t]\nworkspace_min = 0 inf 0\n", 2, "[scene t] workspace_min:", NULL);
  EXPECT_ERROR("[scene t]\nbackground = 1 1\n", 2, "[scene t] background:", NULL);
  EXPECT_ERROR("[scene t]\nbackground = 1 1.5 1\n", 2, "[scene t] background:", "0 to 1");
  EXPECT_ERROR("[scene t]\nbackground = 0 0 -0.1\n", 2, "[scene t] background:", "0 to 1");

  /* workspace and voxel checks made at the end: the scene's header line */
  EXPECT_ERROR("[train]\n\n[scene box]\nworkspace_min = 0 0 1\nworkspace_max = 1 1 1\n"
               "[http]\n", 3, "[scene box] workspace_min:", "on z");
  EXPECT_ERROR("[scene box]\nworkspace_max = 0.1 0.1 0.1\n", 1, "[scene box] workspace_min:",
               "on x");
  EXPECT_ERROR("[scene ok]\n[scene box]\nworkspace_min = 0 0 0\nworkspace_max = 1 1 0.005\n", 2,
               "[scene box] voxel_size:", "smallest workspace extent");
  EXPECT_ERROR("[scene box]\nvoxel_size = 0.5\nworkspace_min = 0 0 0\nworkspace_max = 1 1 0.4\n",
               2, "[scene box] voxel_size:", "0.4 m");

  /* scene names and duplicates */
  EXPECT_ERROR("[scene]\n", 1, "[scene]:", "needs a name");
  EXPECT_ERROR("[scene .hidden]\n", 1, "[scene .hidden]:", "starts with '.'");
  EXPECT_ERROR("[scene a/b]\n", 1, "[scene a/b]:", "'/'");
  EXPECT_ERROR("[scene my table]\n", 1, "[scene my table]:", "' '");
  EXPECT_ERROR("[scene x]\nvoxel_size = 0.02\n[scene y]\n[scene x]\n", 4, "[scene x]:",
               "duplicate scene section (first on line 1)");
  EXPECT_ERROR("[http]\n[train]\n[http]\n", 3, "[http]:", "duplicate section (first on line 1)");

  /* duplicate keys and continuation lines */
  EXPECT_ERROR("[train]\nsteps = 1\nthreads = 2\nsteps = 3\n", 4, "[train] steps:",
               "duplicate key (first set on line 2)");
  EXPECT_ERROR("[scene a]\nvoxel_size = 0.02\n[scene b]\nvoxel_size = 0.02\nvoxel_size = 0.03\n",
               5, "[scene b] voxel_size:", "duplicate key (first set on line 4)");
  EXPECT_ERROR("[state]\nimport_dirs = /a\n   /b\n", 3, "[state] import_dirs:",
               "values cannot span lines");
  EXPECT_ERROR("[robot]\ntransport = tcp\n\n  host = 10.0.0.2\n", 4, "[robot] transport:",
               "remove the leading whitespace");

  /* listen */
  EXPECT_ERROR("[http]\nlisten = ::1:7070\n", 2, "[http] listen:", "brackets");
  EXPECT_ERROR("[http]\nlisten = 127.0.0.1:70000\n", 2, "[http] listen:", "0 to 65535");
  EXPECT_ERROR("[http]\nlisten = localhost\n", 2, "[http] listen:", "no port");

  /* [clip] needs both files: reported at its header */
  EXPECT_ERROR("[train]\n[clip]\nweights = /w\n[http]\n", 2, "[clip] vocab:", "both");
  EXPECT_ERROR("[clip] ; empty\n", 1, "[clip] weights:", "both");
  EXPECT_ERROR("[clip]\nweights =\n", 2, "[clip] weights:", "expected a path");
  EXPECT_ERROR("[clip]\nweights = /w\nvocab = /v\nthreads = -1\n", 4, "[clip] threads:", "0");
  EXPECT_ERROR("[clip]\nweights = /w\nvocab = /v\nthreads = two\n", 4, "[clip] threads:",
               "integer");
  EXPECT_ERROR("[clip]\nweights = /w\nvocab = /v\nmodel = b16\n", 4, "[clip] model:",
               "unknown key");

  /* transport needs */
  EXPECT_ERROR("[robot]\ntransport = tcp\nport = 502\nhost =\n", 4, "[robot] host:",
               "transport tcp needs a host");
  EXPECT_ERROR("[robot]\nhost =\n[gripper.modbus]\ndevice =\ntransport = rtu\n", 4,
               "[gripper.modbus] device:", "transport rtu needs");
  EXPECT_ERROR("[state]\ndir =\n", 2, "[state] dir:", "expected a path");

  /* syntax */
  EXPECT_ERROR("[train]\nsteps 5\n", 2, "expected 'key = value'", NULL);
  EXPECT_ERROR("[train\nsteps = 5\n", 1, "closing ']'", NULL);
  EXPECT_ERROR("[train ; comment]\n", 1, "closing ']'", NULL);

  /* a line longer than inih's buffer: refused, later line numbers stay right */
  char longtext[1024];
  char padding[400];
  memset(padding, 'x', sizeof padding - 1);
  padding[sizeof padding - 1] = '\0';
  snprintf(longtext, sizeof longtext, "[http]\n; %s\n", padding);
  EXPECT_ERROR(longtext, 2, "characters long", NULL);

  /* the first error wins, and nothing after it is parsed */
  EXPECT_ERROR("[train]\nsteps = x\n[nope]\n", 2, "[train] steps:", NULL);
}

static void test_missing_file(void) {
  char path[PATH_MAX + 32];
  snprintf(path, sizeof path, "%s/no-such.conf", tmp_root);
  char err[1024] = "";
  fg_conf *c = (fg_conf *)(uintptr_t)1;
  int rc = fg_conf_load(path, &c, err, sizeof err);
  ASSERT_EQ(rc, FG_ENOENT);
  ASSERT(c == NULL);
  char want[PATH_MAX + 64];
  snprintf(want, sizeof want, "%s: cannot open: %s", path, strerror(ENOENT));
  ASSERT_STREQ(err, want);
  ASSERT_STREQ(fg_error_detail(), want);

  /* a folder is not a configuration file */
  rc = fg_conf_load(tmp_root, &c, err, sizeof err);
  ASSERT(rc < 0);
  ASSERT(c == NULL);
  ASSERT_STRCONTAINS(err, tmp_root);

  /* a tiny error buffer is truncated, not overrun */
  char small[8];
  rc = fg_conf_load(path, &c, small, sizeof small);
  ASSERT_EQ(rc, FG_ENOENT);
  ASSERT_EQ(strlen(small), sizeof small - 1);
}

/* The files shipped in config/ load as they are: the documented example holds every key
 * with its default, the demo a robot and a gripper on the simulator's port. */
static void test_shipped(void) {
  const char *src = getenv("FG_SOURCE_DIR");
  ASSERT(src);
  char path[PATH_MAX], err[1024];
  fg_conf *c = NULL;
  snprintf(path, sizeof path, "%s/config/fieldgripd.conf", src);
  /* its token comes from the credential systemd/fieldgripd.service loads */
  ASSERT(fg_conf_load(path, &c, err, sizeof err) != 0);
  ASSERT_STRCONTAINS(err, "${CREDENTIALS_DIRECTORY} is not set");
  free(write_secret("token", "from-systemd\n", 0400));
  ASSERT_EQ(setenv("CREDENTIALS_DIRECTORY", tmp_root, 1), 0);
  if (fg_conf_load(path, &c, err, sizeof err) != 0) FG_TEST_FAIL("%s", err);
  unsetenv("CREDENTIALS_DIRECTORY");
  ASSERT_STREQ(c->token, "from-systemd");
  fg_conf *d = fg_conf_defaults();
  ASSERT(d);
  ASSERT_EQ(c->robot.transport, FG_TRANSPORT_NONE);
  ASSERT_EQ(c->robot.done_timeout_ms, d->robot.done_timeout_ms);
  ASSERT_EQ(c->gripper_modbus.motion_timeout_ms, d->gripper_modbus.motion_timeout_ms);
  ASSERT_EQ(c->gripper_model, d->gripper_model);
  ASSERT(c->depth_weight == d->depth_weight && c->distortion_weight == d->distortion_weight);
  ASSERT_EQ(c->max_json_bytes, d->max_json_bytes);
  ASSERT_EQ(c->max_connections, d->max_connections);
  ASSERT_EQ(c->header_timeout_s, d->header_timeout_s);
  ASSERT_EQ(c->idle_timeout_s, d->idle_timeout_s);
  ASSERT_EQ(c->min_body_bytes_per_s, d->min_body_bytes_per_s);
  ASSERT_EQ(c->max_queued_requests, d->max_queued_requests);
  ASSERT_EQ(c->max_scenes, d->max_scenes);
  ASSERT_EQ(c->max_loaded_fields, d->max_loaded_fields);
  ASSERT(c->viewer_dir == NULL && d->viewer_dir == NULL);
  ASSERT_STREQ(c->three_js, d->three_js);
  ASSERT_EQ(c->audit_max_bytes, d->audit_max_bytes);
  ASSERT_EQ(c->audit_keep, d->audit_keep);
  ASSERT(c->lock_dir == NULL && d->lock_dir == NULL);
  ASSERT_EQ(c->motion.has_box, 0);
  ASSERT(c->motion.limit_margin_m == d->motion.limit_margin_m &&
         c->motion.reach_m == d->motion.reach_m && d->motion.reach_m == 0 &&
         c->motion.approach_cone_deg == d->motion.approach_cone_deg &&
         c->motion.max_force_n == d->motion.max_force_n &&
         c->motion.max_speed_mps == d->motion.max_speed_mps &&
         c->motion.speed_mps == d->motion.speed_mps &&
         c->motion.approach_m == d->motion.approach_m &&
         c->motion.retreat_m == d->motion.retreat_m);
  fg_conf_free(c);
  fg_conf_free(d);
  snprintf(path, sizeof path, "%s/config/demo.conf", src);
  if (fg_conf_load(path, &c, err, sizeof err) != 0) FG_TEST_FAIL("%s", err);
  ASSERT_EQ(c->robot.transport, FG_TRANSPORT_TCP);
  ASSERT_EQ(c->robot.port, 1502);
  ASSERT_EQ(c->gripper_modbus.transport, FG_TRANSPORT_TCP);
  ASSERT_EQ(c->gripper_model, FG_GRIPPER_ROBOTIQ_2F85);
  fg_conf_free(c);
}

int main(void) {
  char tmpl[] = "/tmp/fg_test_conf.XXXXXX";
  ASSERT(mkdtemp(tmpl) != NULL);
  ASSERT(realpath(tmpl, tmp_root) != NULL);

  test_defaults();
  test_spec_example();
  test_values();
  test_audit_keys();
  test_paths();
  test_token_file();
  test_listen();
  test_cross_site();
  test_scene_names();
  test_errors();
  test_missing_file();
  test_shipped();

  char cmd[PATH_MAX + 16];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmp_root);
  ASSERT_EQ(system(cmd), 0);
  printf("conf: ok\n");
  return 0;
}
