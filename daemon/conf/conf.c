/* fieldgripd's configuration file: see conf.h and SPEC.md "Configuration file".
 *
 * libinih does the INI lexing (trimming, inline "; comments", "key = value" / "key: value"),
 * but Debian builds it without line numbers in the handler. So we feed it through our own
 * reader that reads one physical line at a time and counts them; inih calls the handler right
 * after the line that holds the key, so the count is the key's line.
 *
 * The reader also classifies each line the same way inih will (comment, section header,
 * key, continuation) because inih does not tell the handler about section headers
 * (INI_CALL_HANDLER_ON_NEW_SECTION is off), truncates section names to 49 bytes, and treats
 * any indented line after a key as a continuation of that key's value (INI_ALLOW_MULTILINE).
 * Seeing headers lets us create empty [scene NAME] sections, remember header lines for the
 * checks made at the end, and report duplicate and unknown sections even when they hold no
 * keys. Continuation lines are refused with their own message (not "duplicate key"): no value
 * here spans lines, and an indented "key = value" silently swallowed into the previous value
 * would be a nasty surprise.
 *
 * Parsing stops at the first error: the reader returns end-of-file to inih once one has been
 * recorded, so the message is always about the earliest bad line. */
#include "conf_parse.h"
#include "secret.h"

#include "core/error.h"

#include <ini.h>

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>

/* ---------------------------------------------------------------- sections and keys */

static const char *const section_names[SEC_COUNT] = {
    [SEC_HTTP] = "http",       [SEC_STATE] = "state",  [SEC_CLIP] = "clip",
    [SEC_TRAIN] = "train",     [SEC_GRIPPER] = "gripper", [SEC_ROBOT] = "robot",
    [SEC_GRIPPER_MODBUS] = "gripper.modbus", [SEC_CALIBRATION] = "calibration",
};

enum {
  K_LISTEN, K_TOKEN, K_MAX_UPLOAD_MB, K_TOKEN_FILE, K_MAX_JSON_KB, K_MAX_CONNECTIONS,
  K_HEADER_TIMEOUT_S, K_IDLE_TIMEOUT_S, K_MIN_BODY_KB_PER_S, K_MAX_QUEUED_REQUESTS,
  K_VIEWER_DIR, K_THREE_JS, K_ALLOWED_HOSTS, K_ALLOWED_ORIGINS
};
enum { K_DIR, K_IMPORT_DIRS, K_MAX_SCENES, K_MAX_LOADED_FIELDS };
enum { K_WEIGHTS, K_VOCAB, K_CLIP_THREADS };
enum { K_STEPS, K_THREADS, K_MAX_IMAGE_SIDE, K_HALF_PRECISION, K_DEPTH_WEIGHT, K_DISTORTION_WEIGHT };
enum { K_MODEL };
/* Both Modbus sections take the first eight of these; K_BASE .. K_DONE_TIMEOUT_MS are
 * [robot] only, K_MOTION_TIMEOUT_MS [gripper.modbus] only (its ninth key, translated by
 * gripper_key). */
enum {
  K_TRANSPORT, K_HOST, K_PORT, K_DEVICE, K_BAUD, K_PARITY, K_UNIT_ID, K_TIMEOUT_MS,
  K_BASE, K_ENCODING, K_ACK_TIMEOUT_MS, K_DONE_TIMEOUT_MS, K_MOTION_TIMEOUT_MS
};
/* [robot]'s keys past the Modbus ones (robot_keys from index K_LIMIT_MIN on): the motion
 * limits and the path, then the audit log and the claim. */
enum {
  K_LIMIT_MIN = K_DONE_TIMEOUT_MS + 1, K_LIMIT_MAX, K_LIMIT_MARGIN, K_REACH_M, K_APPROACH_CONE_DEG,
  K_MAX_FORCE_N, K_MAX_SPEED_MPS, K_SPEED_MPS, K_APPROACH_M, K_RETREAT_M,
  K_AUDIT_MAX_MB, K_AUDIT_KEEP, K_LOCK_DIR, K_TCP_POSE_BASE
};
enum { K_WORKSPACE_MIN, K_WORKSPACE_MAX, K_VOXEL_SIZE, K_BACKGROUND, K_FIELD_SCALE,
       K_LEARN_BACKGROUND };


static const char *const http_keys[] = {"listen",           "token",
                                        "max_upload_mb",    "token_file",
                                        "max_json_kb",      "max_connections",
                                        "header_timeout_s", "idle_timeout_s",
                                        "min_body_kb_per_s", "max_queued_requests",
                                        "viewer_dir",       "three_js",
                                        "allowed_hosts",    "allowed_origins", NULL};
static const char *const state_keys[] = {"dir", "import_dirs", "max_scenes", "max_loaded_fields",
                                         NULL};
static const char *const clip_keys[] = {"weights", "vocab", "threads", NULL};
static const char *const train_keys[] = {"steps",          "threads",      "max_image_side",
                                         "half_precision", "depth_weight", "distortion_weight",
                                         NULL};
static const char *const gripper_keys[] = {"model", NULL};
static const char *const robot_keys[] = {"transport", "host",     "port",           "device",
                                         "baud",      "parity",   "unit_id",        "timeout_ms",
                                         "base",      "encoding", "ack_timeout_ms", "done_timeout_ms",
                                         "limit_min", "limit_max", "limit_margin", "reach_m",
                                         "approach_cone_deg", "max_force_n", "max_speed_mps",
                                         "speed_mps", "approach_m", "retreat_m",
                                         "audit_max_mb", "audit_keep", "lock_dir",
                                         "tcp_pose_base", NULL};
_Static_assert(sizeof robot_keys / sizeof *robot_keys - 1 <= MAX_KEYS,
               "conf_parse.key_line holds a line per key of a section");
static const char *const gripper_modbus_keys[] = {"transport", "host",   "port",    "device",
                                                  "baud",      "parity", "unit_id", "timeout_ms",
                                                  "motion_timeout_ms", NULL};
static const char *const scene_keys[] = {"workspace_min", "workspace_max", "voxel_size",
                                         "background",    "field_scale",   "learn_background",
                                         NULL};

static const char *const *const section_keys[SEC_COUNT] = {
    [SEC_HTTP] = http_keys,       [SEC_STATE] = state_keys,   [SEC_CLIP] = clip_keys,
    [SEC_TRAIN] = train_keys,     [SEC_GRIPPER] = gripper_keys, [SEC_ROBOT] = robot_keys,
    [SEC_GRIPPER_MODBUS] = gripper_modbus_keys, [SEC_CALIBRATION] = conf_calibration_keys,
    [SEC_SCENE] = scene_keys, [SEC_CAMERA] = conf_camera_keys,
};

static const char *const transport_names[] = {"none", "tcp", "rtu", NULL};
static const char *const encoding_names[] = {"int16", "float32", NULL};
static const char *const gripper_model_names[] = {"panda", "robotiq-2f85", "robotiq-2f140",
                                                  NULL};
static const char *const bool_names[] = {"false", "true", NULL};



/* ---------------------------------------------------------------- sections */

static const char *skip_space(const char *s) {
  while (*s && isspace((unsigned char)*s)) s++;
  return s;
}

/* Handles a "[...]" line whose text between the brackets is text (untrimmed). */
static int enter_section(conf_parse *st, const char *text, size_t len) {
  while (len > 0 && isspace((unsigned char)*text)) text++, len--;
  while (len > 0 && isspace((unsigned char)text[len - 1])) len--;
  snprintf(st->sec_text, sizeof st->sec_text, "%.*s", (int)len, text);
  if (len >= sizeof st->sec_text)
    return conf_fail_at(st, st->line, NULL, NULL, "section name '%.40s...' is too long",
                        st->sec_text);

  for (int s = SEC_HTTP; s < SEC_SCENE; s++) {
    if (strcmp(st->sec_text, section_names[s]) != 0) continue;
    if (st->sec_line[s])
      return conf_fail_at(st, st->line, st->sec_text, NULL,
                          "duplicate section (first on line %d); merge the two", st->sec_line[s]);
    st->sec = (conf_section)s;
    st->sec_line[s] = st->line;
    return 1;
  }

  if (strncmp(st->sec_text, "scene", 5) == 0 &&
      (st->sec_text[5] == '\0' || isspace((unsigned char)st->sec_text[5]))) {
    const char *name = skip_space(st->sec_text + 5);
    if (*name == '\0')
      return conf_fail_at(st, st->line, st->sec_text, NULL,
                          "a scene section needs a name, e.g. [scene tabletop]");
    if (fg_scene_name_validate(name) < 0)
      return conf_fail_at(st, st->line, st->sec_text, NULL, "%s", fg_error_detail());
    fg_conf *c = st->conf;
    for (size_t i = 0; i < c->n_scenes; i++) {
      if (strcmp(c->scenes[i].name, name) == 0)
        return conf_fail_at(st, st->line, st->sec_text, NULL,
                            "duplicate scene section (first on line %d); merge the two",
                            st->scene_meta[i].header_line);
    }
    fg_conf_scene *scenes = realloc(c->scenes, (c->n_scenes + 1) * sizeof *scenes);
    if (!scenes) return conf_fail_nomem(st);
    c->scenes = scenes;
    scene_meta *meta = realloc(st->scene_meta, (c->n_scenes + 1) * sizeof *meta);
    if (!meta) return conf_fail_nomem(st);
    st->scene_meta = meta;
    fg_conf_scene_defaults(&scenes[c->n_scenes]);
    snprintf(scenes[c->n_scenes].name, sizeof scenes[c->n_scenes].name, "%s", name);
    memset(&meta[c->n_scenes], 0, sizeof *meta);
    meta[c->n_scenes].header_line = st->line;
    st->scene = c->n_scenes++;
    st->sec = SEC_SCENE;
    return 1;
  }

  if (strncmp(st->sec_text, "camera", 6) == 0 &&
      (st->sec_text[6] == '\0' || isspace((unsigned char)st->sec_text[6])))
    return conf_enter_camera(st, skip_space(st->sec_text + 6));

  return conf_fail_at(st, st->line, st->sec_text, NULL,
                      "unknown section; expected http, state, clip, train, gripper, robot, "
                      "gripper.modbus, calibration, scene NAME or camera NAME");
}

/* ---------------------------------------------------------------- the line reader */

/* inih's inline-comment rule: a ';' counts only after whitespace. Returns the first of chars
 * or of such a comment, or the end of s. */
static const char *find_chars_or_comment(const char *s, const char *chars) {
  int was_space = 0;
  while (*s && !(chars && strchr(chars, *s)) &&
         !(INI_ALLOW_INLINE_COMMENTS && was_space && strchr(INI_INLINE_COMMENT_PREFIXES, *s))) {
    was_space = isspace((unsigned char)*s);
    s++;
  }
  return s;
}

/* Classifies the line in st->raw as inih will and acts on section headers. Returns 1 to go on,
 * 0 after recording an error. */
static int classify_line(conf_parse *st) {
  const char *line = st->raw;
  if (INI_ALLOW_BOM && st->line == 1 && (unsigned char)line[0] == 0xEF &&
      (unsigned char)line[1] == 0xBB && (unsigned char)line[2] == 0xBF)
    line += 3;
  const char *start = skip_space(line);

  if (*start == '\0') {
    st->kind = LINE_BLANK;
    return 1;
  }
  if (strchr(INI_START_COMMENT_PREFIXES, *start)) {
    st->kind = LINE_COMMENT;
    return 1;
  }
  if (INI_ALLOW_MULTILINE && st->key_active && start > st->raw) {
    st->kind = LINE_CONTINUATION;
    return conf_fail_at(st, st->line, st->sec_text, st->last_key,
                        "this indented line would continue the value of '%s', and values "
                        "cannot span lines; remove the leading whitespace",
                        st->last_key);
  }
  if (*start == '[') {
    const char *end = find_chars_or_comment(start + 1, "]");
    if (*end != ']')
      return conf_fail_at(st, st->line, NULL, NULL,
                          "section header lacks its closing ']'; expected [NAME]");
    st->kind = LINE_HEADER;
    st->key_active = 0;
    return enter_section(st, start + 1, (size_t)(end - start - 1));
  }
  const char *end = find_chars_or_comment(start, "=:");
  if (*end != '=' && *end != ':')
    return conf_fail_at(st, st->line, st->sec == SEC_NONE ? NULL : st->sec_text, NULL,
                        "expected 'key = value', '[section]' or a comment, got '%.60s'", start);
  size_t klen = (size_t)(end - start);
  while (klen > 0 && isspace((unsigned char)start[klen - 1])) klen--;
  snprintf(st->last_key, sizeof st->last_key, "%.*s", (int)klen, start);
  st->kind = LINE_KEY;
  st->key_active = 1;
  return 1;
}

/* ini_reader: hands inih one physical line at a time so that st->line is the number of the
 * line inih is about to parse. Lines longer than inih's buffer are refused here instead of
 * being split (which would shift every later line number). Returns NULL at the end of the
 * file and after the first error, which ends the parse. */
static char *conf_reader(char *buf, int num, void *stream) {
  conf_parse *st = stream;
  if (st->failed) return NULL;
  ssize_t n = getline(&st->raw, &st->raw_cap, st->fp);
  if (n < 0) return NULL;
  st->line++;
  size_t len = (size_t)n;
  if (len > 0 && st->raw[len - 1] == '\n') st->raw[--len] = '\0';
  if (memchr(st->raw, '\0', len)) {
    conf_fail_at(st, st->line, NULL, NULL, "line holds a NUL byte; is this a text file?");
    return NULL;
  }
  /* inih wants room for the text, a newline and the terminator */
  if (num < 2 || len > (size_t)num - 2) {
    conf_fail_at(st, st->line, NULL, NULL,
                 "line is %zu characters long; the parser takes at most %d", 
                 len, num > 2 ? num - 2 : 0);
    return NULL;
  }
  if (!classify_line(st)) return NULL;
  memcpy(buf, st->raw, len);
  buf[len] = '\n';
  buf[len + 1] = '\0';
  return buf;
}

/* ---------------------------------------------------------------- the key handler */

static int find_key(const char *const *keys, const char *name) {
  for (int i = 0; keys[i]; i++)
    if (strcmp(keys[i], name) == 0) return i;
  return -1;
}

static int set_modbus(conf_parse *st, fg_conf_modbus *m, int k, const char *name, const char *v) {
  int x = 0;
  switch (k) {
  case K_TRANSPORT:
    if (!conf_parse_enum(st, name, v, transport_names, &x)) return 0;
    m->transport = (fg_transport)x;
    return 1;
  case K_HOST: return conf_set_string(st, &m->host, v);
  case K_PORT: return conf_parse_int(st, name, v, 1, 65535, &m->port);
  case K_DEVICE: return conf_set_string(st, &m->device, v);
  case K_BAUD: return conf_parse_int(st, name, v, 1, 4000000, &m->baud);
  case K_PARITY: {
    char c = (char)toupper((unsigned char)v[0]);
    if (v[0] == '\0' || v[1] != '\0' || (c != 'N' && c != 'E' && c != 'O'))
      return conf_fail_at(st, st->line, st->sec_text, name, "expected N, E or O, got '%s'", v);
    m->parity = c;
    return 1;
  }
  case K_UNIT_ID: return conf_parse_int(st, name, v, 0, 247, &m->unit_id);
  case K_TIMEOUT_MS: return conf_parse_int(st, name, v, 1, 60000, &m->timeout_ms);
  case K_BASE: return conf_parse_int(st, name, v, 0, 65535 - 26, &m->base); /* the float32 span */
  case K_ENCODING:
    if (!conf_parse_enum(st, name, v, encoding_names, &x)) return 0;
    m->encoding = (fg_encoding)x;
    return 1;
  case K_ACK_TIMEOUT_MS: return conf_parse_int(st, name, v, 1, 600000, &m->ack_timeout_ms);
  case K_DONE_TIMEOUT_MS: return conf_parse_int(st, name, v, 1, 3600000, &m->done_timeout_ms);
  case K_MOTION_TIMEOUT_MS: return conf_parse_int(st, name, v, 1, 600000, &m->motion_timeout_ms);
  }
  return 1;
}

/* A number from lo to hi (inclusive; lo_open excludes lo itself). */
static int parse_bounded(conf_parse *st, const char *key, const char *v, double lo, int lo_open,
                         double hi, double *out) {
  if (!conf_parse_double(st, key, v, out)) return 0;
  if (*out < lo || (lo_open && *out == lo) || *out > hi)
    return conf_fail_at(st, st->line, st->sec_text, key, "expected a number %s %g and at most %g, "
                        "got '%s'", lo_open ? "above" : "from", lo, hi, v);
  return 1;
}

static int set_motion(conf_parse *st, fg_conf_motion *m, int k, const char *name,
                      const char *v) {
  switch (k) {
  case K_LIMIT_MIN: return conf_parse_vec3(st, name, v, "x y z in metres", m->limit_min);
  case K_LIMIT_MAX: return conf_parse_vec3(st, name, v, "x y z in metres", m->limit_max);
  case K_LIMIT_MARGIN: return parse_bounded(st, name, v, 0, 0, 10, &m->limit_margin_m);
  case K_APPROACH_CONE_DEG: return parse_bounded(st, name, v, 0, 0, 180, &m->approach_cone_deg);
  case K_MAX_FORCE_N: return parse_bounded(st, name, v, 0, 0, 65535, &m->max_force_n);
  case K_MAX_SPEED_MPS: return parse_bounded(st, name, v, 0, 1, 10, &m->max_speed_mps);
  case K_SPEED_MPS: return parse_bounded(st, name, v, 0, 1, 10, &m->speed_mps);
  case K_APPROACH_M: return parse_bounded(st, name, v, 0, 0, 1, &m->approach_m);
  case K_RETREAT_M: return parse_bounded(st, name, v, 0, 0, 1, &m->retreat_m);
  case K_REACH_M: return parse_bounded(st, name, v, 0, 0, 10, &m->reach_m);
  }
  return 1;
}

/* [robot]'s audit_max_mb, audit_keep and lock_dir. A fraction of a MiB is allowed so that a
 * test can rotate after a few lines. */
static int set_robot_audit(conf_parse *st, fg_conf *c, int k, const char *name, const char *v) {
  if (k == K_AUDIT_KEEP) return conf_parse_int(st, name, v, 1, 1000, &c->audit_keep);
  if (k == K_LOCK_DIR) {
    if (v[0]) return conf_set_path(st, name, &c->lock_dir, v);
    free(c->lock_dir); /* empty: the default, so the example file can list the key */
    c->lock_dir = NULL;
    return 1;
  }
  double mb = 0;
  if (!conf_parse_double(st, name, v, &mb)) return 0;
  if (!(mb > 0) || mb > 1048576)
    return conf_fail_at(st, st->line, st->sec_text, name,
                        "expected a size in MiB above 0 and at most 1048576 (e.g. 16), "
                        "got '%s'", v);
  c->audit_max_bytes = (size_t)(mb * 1048576.0);
  if (c->audit_max_bytes == 0) c->audit_max_bytes = 1;
  return 1;
}

static int set_scene(conf_parse *st, fg_conf_scene *s, int k, const char *name, const char *v) {
  switch (k) {
  case K_WORKSPACE_MIN: return conf_parse_vec3(st, name, v, "x y z in metres", s->workspace_min);
  case K_WORKSPACE_MAX: return conf_parse_vec3(st, name, v, "x y z in metres", s->workspace_max);
  case K_VOXEL_SIZE:
    if (!conf_parse_double(st, name, v, &s->voxel_size)) return 0;
    if (s->voxel_size <= 0)
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected a positive size in metres (e.g. 0.01), got '%s'", v);
    return 1;
  case K_BACKGROUND:
    if (!conf_parse_vec3(st, name, v, "R G B from 0 to 1", s->background)) return 0;
    for (int i = 0; i < 3; i++) {
      if (s->background[i] < 0 || s->background[i] > 1)
        return conf_fail_at(st, st->line, st->sec_text, name,
                            "expected 3 numbers from 0 to 1 (R G B), got '%s'", v);
    }
    return 1;
  case K_FIELD_SCALE:
    if (strcmp(v, "auto") == 0) {
      s->field_scale = 0;
      return 1;
    }
    if (!conf_parse_double(st, name, v, &s->field_scale)) return 0;
    if (!(s->field_scale >= 1 && s->field_scale <= 64))
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected auto or a number from 1 to 64 (the field's cube over the "
                          "workspace's largest extent), got '%s'", v);
    return 1;
  case K_LEARN_BACKGROUND: {
    static const char *const names[] = {"false", "true", "auto", NULL};
    int i;
    if (!conf_parse_enum(st, name, v, names, &i)) return 0;
    s->learn_background = i == 2 ? -1 : i;
    return 1;
  }
  }
  return 1;
}

/* Lists a section's keys for the "unknown key" message. */
static void list_keys(const char *const *keys, char *buf, size_t size) {
  buf[0] = '\0';
  for (int i = 0; keys[i]; i++) {
    size_t n = strlen(buf);
    snprintf(buf + n, size - n, "%s%s", i ? ", " : "", keys[i]);
  }
}

/* inih's handler: one "key = value" line, st->line being its number. Returns 1 to go on, 0 on
 * error (inih then remembers the line; our reader ends the parse). */
static int conf_handler(void *user, const char *section, const char *name, const char *v) {
  conf_parse *st = user;
  fg_conf *c = st->conf;
  (void)section; /* inih truncates long section names; ours comes from the reader */
  if (st->kind != LINE_KEY)
    return conf_fail_at(st, st->line, NULL, name, "the parser saw a value on a line that is not "
                        "'key = value'; check the indentation");
  if (st->sec == SEC_NONE)
    return conf_fail_at(st, st->line, NULL, name, "key outside any section; put it under its "
                        "[section] header");

  const char *const *keys = section_keys[st->sec];
  int k = find_key(keys, name);
  if (k < 0) {
    char list[256];
    list_keys(keys, list, sizeof list);
    if (st->sec == SEC_GRIPPER_MODBUS && find_key(robot_keys, name) >= 0)
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "unknown key: this one belongs to [robot] only; [gripper.modbus] "
                          "takes %s", list);
    return conf_fail_at(st, st->line, st->sec_text, name, "unknown key; [%s] takes %s",
                        st->sec == SEC_SCENE    ? "scene NAME"
                        : st->sec == SEC_CAMERA ? "camera NAME"
                                                : st->sec_text,
                        list);
  }
  int *seen = st->sec == SEC_SCENE    ? &st->scene_meta[st->scene].key_line[k]
              : st->sec == SEC_CAMERA ? &st->camera_meta[st->camera].key_line[k]
                                      : &st->key_line[st->sec][k];
  if (*seen)
    return conf_fail_at(st, st->line, st->sec_text, name,
                        "duplicate key (first set on line %d); keep "
                        "one", *seen);
  *seen = st->line;

  int x = 0;
  switch (st->sec) {
  case SEC_HTTP:
    if (k == K_LISTEN) {
      char *host;
      int port;
      if (fg_conf_parse_listen(v, &host, &port) < 0)
        return conf_fail_at(st, st->line, st->sec_text, name, "%s", fg_error_detail());
      free(host);
      return conf_set_string(st, &c->listen, v);
    }
    if (k == K_TOKEN) {
      fg_secret_free(c->token);
      c->token = NULL;
      return v[0] ? conf_set_string(st, &c->token, v) : 1;
    }
    switch (k) {
    case K_TOKEN_FILE: return conf_set_token_file(st, name, v);
    /* Empty: the built-in place, so the example file can list the keys without values. */
    case K_VIEWER_DIR:
      if (v[0]) return conf_set_path(st, name, &c->viewer_dir, v);
      free(c->viewer_dir);
      c->viewer_dir = NULL;
      return 1;
    case K_THREE_JS:
      return conf_set_path(st, name, &c->three_js, v[0] ? v : FG_CONF_DEFAULT_THREE_JS);
    case K_ALLOWED_HOSTS:
    case K_ALLOWED_ORIGINS: {
      const int hosts = k == K_ALLOWED_HOSTS;
      int rc = fg_conf_split_list(v, hosts ? fg_conf_check_host_name : fg_conf_check_origin,
                                  hosts ? &c->allowed_hosts : &c->allowed_origins,
                                  hosts ? &c->n_allowed_hosts : &c->n_allowed_origins);
      if (rc == FG_ENOMEM) return conf_fail_nomem(st);
      return rc == 0 ? 1 : conf_fail_at(st, st->line, st->sec_text, name, "%s", fg_error_detail());
    }
    case K_MAX_UPLOAD_MB:
      if (!conf_parse_int(st, name, v, 1, 4096, &x)) return 0;
      c->max_upload_bytes = (size_t)x << 20;
      return 1;
    case K_MAX_JSON_KB:
      if (!conf_parse_int(st, name, v, 1, 1048576, &x)) return 0;
      c->max_json_bytes = (size_t)x << 10;
      return 1;
    case K_MAX_CONNECTIONS: return conf_parse_int(st, name, v, 16, 1000000, &c->max_connections);
    case K_HEADER_TIMEOUT_S: return conf_parse_int(st, name, v, 1, 3600, &c->header_timeout_s);
    case K_IDLE_TIMEOUT_S: return conf_parse_int(st, name, v, 1, 86400, &c->idle_timeout_s);
    case K_MIN_BODY_KB_PER_S:
      if (!conf_parse_int(st, name, v, 0, 1048576, &x)) return 0;
      c->min_body_bytes_per_s = (size_t)x << 10;
      return 1;
    default: return conf_parse_int(st, name, v, 1, 100000, &c->max_queued_requests);
    }
  case SEC_STATE:
    if (k == K_DIR) return conf_set_path(st, name, &c->state_dir, v);
    if (k == K_MAX_SCENES) return conf_parse_int(st, name, v, 0, 1000000, &c->max_scenes);
    if (k == K_MAX_LOADED_FIELDS)
      return conf_parse_int(st, name, v, 0, 100000, &c->max_loaded_fields);
    return conf_set_import_dirs(st, name, v);
  case SEC_CLIP:
    if (k == K_CLIP_THREADS) return conf_parse_int(st, name, v, 0, 1024, &c->clip_threads);
    return conf_set_path(st, name, k == K_WEIGHTS ? &c->clip_weights : &c->clip_vocab, v);
  case SEC_TRAIN:
    if (k == K_STEPS) return conf_parse_int(st, name, v, 1, 10000000, &c->train_steps);
    if (k == K_THREADS) return conf_parse_int(st, name, v, 0, 1024, &c->train_threads);
    if (k == K_HALF_PRECISION) return conf_parse_enum(st, name, v, bool_names, &c->half_precision);
    if (k == K_DEPTH_WEIGHT || k == K_DISTORTION_WEIGHT) {
      double *w = k == K_DEPTH_WEIGHT ? &c->depth_weight : &c->distortion_weight;
      if (!conf_parse_double(st, name, v, w)) return 0;
      if (*w < 0.0 || *w > FG_TRAIN_MAX_LOSS_WEIGHT)
        return conf_fail_at(st, st->line, st->sec_text, name, "must be from 0 to %g, got '%s'",
                            (double)FG_TRAIN_MAX_LOSS_WEIGHT, v);
      return 1;
    }
    return conf_parse_int(st, name, v, 16, 16384, &c->max_image_side);
  case SEC_GRIPPER:
    if (!conf_parse_enum(st, name, v, gripper_model_names, &x)) return 0;
    c->gripper_model = (fg_gripper_model)x;
    return 1;
  case SEC_ROBOT:
    if (k == K_TCP_POSE_BASE) {
      if (strcmp(v, "none") == 0) {
        c->robot.tcp_pose_base = -1;
        return 1;
      }
      return conf_parse_int(st, name, v, 0, 65535 - 6, &c->robot.tcp_pose_base);
    }
    if (k >= K_AUDIT_MAX_MB) return set_robot_audit(st, c, k, name, v);
    if (k >= K_LIMIT_MIN) return set_motion(st, &c->motion, k, name, v);
    return set_modbus(st, &c->robot, k, name, v);
  case SEC_GRIPPER_MODBUS:
    return set_modbus(st, &c->gripper_modbus, k > K_TIMEOUT_MS ? K_MOTION_TIMEOUT_MS : k, name,
                      v);
  case SEC_SCENE: return set_scene(st, &c->scenes[st->scene], k, name, v);
  case SEC_CALIBRATION: return conf_set_calibration(st, k, name, v);
  case SEC_CAMERA: return conf_set_camera(st, k, name, v);
  case SEC_NONE:
  case SEC_COUNT: break;
  }
  return 1;
}

/* ---------------------------------------------------------------- checks at the end */

/* A transport's needs, which depend on keys that may come in any order. */
static void check_modbus(conf_parse *st, conf_section sec, const fg_conf_modbus *m) {
  const int *lines = st->key_line[sec];
  const char *name = section_names[sec];
  int where = lines[K_TRANSPORT];
  if (m->transport == FG_TRANSPORT_TCP && (!m->host || !m->host[0]))
    conf_fail_at(st, lines[K_HOST] ? lines[K_HOST] : where, name, "host",
                 "transport tcp needs a host; set host = ADDRESS (name or IP address)");
  if (m->transport == FG_TRANSPORT_RTU && (!m->device || !m->device[0]))
    conf_fail_at(st, lines[K_DEVICE] ? lines[K_DEVICE] : where, name, "device",
                 "transport rtu needs a serial device; set device = /dev/ttyUSB0 or similar");
}

/* The TCP pose registers must not overlap the command block (its whole float32 or int16
 * span: ack, status and stop too). */
static void check_tcp_pose(conf_parse *st, const fg_conf_modbus *m) {
  const int t = m->tcp_pose_base, end = m->base + (m->encoding == FG_ENCODING_FLOAT32 ? 26 : 16);
  if (t >= 0 && t < end && m->base < t + 6) {
    const int *lines = st->key_line[SEC_ROBOT];
    conf_fail_at(st, lines[K_TCP_POSE_BASE] ? lines[K_TCP_POSE_BASE] : lines[K_BASE], "robot",
                 "tcp_pose_base", "the TCP pose registers %d..%d overlap the command block "
                 "%d..%d (base = %d, encoding %s)", t, t + 5, m->base, end - 1, m->base,
                 m->encoding == FG_ENCODING_FLOAT32 ? "float32" : "int16");
  }
}

/* limit_min and limit_max come together and make a box; the default speed is one the limit
 * allows. */
static void check_motion(conf_parse *st, fg_conf_motion *m) {
  const int *lines = st->key_line[SEC_ROBOT];
  const int lmin = lines[K_LIMIT_MIN], lmax = lines[K_LIMIT_MAX];
  if (lmin || lmax) {
    if (!lmin || !lmax) {
      conf_fail_at(st, lmin ? lmin : lmax, "robot", lmin ? "limit_max" : "limit_min",
                   "missing; the position box needs both limit_min and limit_max (or neither: then "
                   "it is the scenes' workspaces grown by limit_margin)");
      return;
    }
    static const char axis[3] = {'x', 'y', 'z'};
    for (int i = 0; i < 3; i++)
      if (!(m->limit_min[i] < m->limit_max[i])) {
        conf_fail_at(st, lmin, "robot", "limit_min",
                     "must be below limit_max on every axis, but on "
                     "%c it is %g and limit_max is %g", axis[i], m->limit_min[i], m->limit_max[i]);
        return;
      }
    m->has_box = 1;
  }
  if (m->speed_mps > m->max_speed_mps)
    conf_fail_at(st, lines[K_SPEED_MPS] ? lines[K_SPEED_MPS] : lines[K_MAX_SPEED_MPS], "robot",
                 "speed_mps", "the default speed %g m/s is above max_speed_mps = %g m/s",
                 m->speed_mps, m->max_speed_mps);
}

/* A scene's workspace must be a box, and a voxel must fit into it. Reported at the scene's
 * header (the box is two keys; neither alone is wrong). */
static void check_scene(conf_parse *st, const fg_conf_scene *s, const scene_meta *meta) {
  char sec[96];
  snprintf(sec, sizeof sec, "scene %s", s->name);
  static const char axis[3] = {'x', 'y', 'z'};
  double smallest = INFINITY;
  for (int i = 0; i < 3; i++) {
    double extent = s->workspace_max[i] - s->workspace_min[i];
    if (!(extent > 0)) {
      conf_fail_at(st, meta->header_line, sec, "workspace_min",
                   "must be below workspace_max on every axis, but on %c it is %g and "
                   "workspace_max is %g", axis[i], s->workspace_min[i], s->workspace_max[i]);
      return;
    }
    if (extent < smallest) smallest = extent;
  }
  if (s->voxel_size > smallest)
    conf_fail_at(st,
                 meta->key_line[K_VOXEL_SIZE] ? meta->key_line[K_VOXEL_SIZE] : meta->header_line, 
                 sec, "voxel_size",
                 "%g m is larger than the smallest workspace extent (%g m); expected at most that",
                 s->voxel_size, smallest);
}

/* The token from token_file; both keys at once would leave one of them ignored. */
static void check_token_file(conf_parse *st) {
  fg_conf *c = st->conf;
  const int line = st->key_line[SEC_HTTP][K_TOKEN_FILE];
  if (!c->token_file) return;
  if (c->token && c->token[0]) {
    conf_fail_at(st, line, "http", "token_file",
                 "token is set too (line %d); keep one of them, token_file for a token that "
                 "others may not read", st->key_line[SEC_HTTP][K_TOKEN]);
    return;
  }
  char *secret;
  if (fg_secret_read(c->token_file, &secret) != 0) {
    conf_fail_at(st, line, "http", "token_file", "%s", fg_error_detail());
    return;
  }
  fg_secret_free(c->token);
  c->token = secret;
}

static void check_final(conf_parse *st) {
  fg_conf *c = st->conf;
  check_token_file(st);
  if (st->sec_line[SEC_CLIP]) {
    c->clip_weights_line = st->key_line[SEC_CLIP][K_WEIGHTS];
    c->clip_vocab_line = st->key_line[SEC_CLIP][K_VOCAB];
    if (!c->clip_weights)
      conf_fail_at(st, st->sec_line[SEC_CLIP], "clip", "weights",
                   "missing; [clip] needs both weights and vocab (or remove the section)");
    else if (!c->clip_vocab)
      conf_fail_at(st, st->sec_line[SEC_CLIP], "clip", "vocab",
                   "missing; [clip] needs both weights and vocab (or remove the section)");
  }
  check_modbus(st, SEC_ROBOT, &c->robot);
  check_tcp_pose(st, &c->robot);
  check_motion(st, &c->motion);
  check_modbus(st, SEC_GRIPPER_MODBUS, &c->gripper_modbus);
  for (size_t i = 0; i < c->n_scenes; i++) check_scene(st, &c->scenes[i], &st->scene_meta[i]);
  conf_check_cell(st);
  /* The declared scenes alone would not fit: the file contradicts itself. */
  if (c->max_scenes > 0 && c->n_scenes > (size_t)c->max_scenes)
    conf_fail_at(st, st->key_line[SEC_STATE][K_MAX_SCENES]
                         ? st->key_line[SEC_STATE][K_MAX_SCENES]
                         : st->scene_meta[c->max_scenes].header_line,
                 "state", "max_scenes", "the file declares %zu [scene NAME] sections, more than "
                 "max_scenes (%d); raise max_scenes or declare fewer scenes", c->n_scenes,
                 c->max_scenes);
}

/* ---------------------------------------------------------------- load and free */

static void copy_err(char *err, size_t errlen, const char *msg) {
  if (err && errlen) snprintf(err, errlen, "%s", msg);
}

int fg_conf_load(const char *path, fg_conf **out, char *err, size_t errlen) {
  if (out) *out = NULL;
  copy_err(err, errlen, "");
  if (!path || !out) {
    copy_err(err, errlen, "fg_conf_load: no path or output given");
    return fg_fail(FG_EINVAL, "fg_conf_load: no path or output given");
  }

  conf_parse st;
  memset(&st, 0, sizeof st);
  st.path = path;
  st.fp = fopen(path, "r");
  if (!st.fp) {
    int e = errno;
    int rc = fg_fail(e == ENOENT ? FG_ENOENT : FG_EIO, "%s: cannot open: %s", path, strerror(e));
    copy_err(err, errlen, fg_error_detail());
    return rc;
  }
  st.base_dir = conf_folder_of(path);
  if (!st.base_dir) {
    st.failed = 1;
    st.err_code = errno == ENOMEM ? FG_ENOMEM : FG_EIO;
    snprintf(st.err, sizeof st.err, "%s: cannot resolve its folder: %s", path, strerror(errno));
  } else {
    const char *slash = strrchr(path, '/');
    st.conf = fg_conf_defaults();
    if (st.conf) st.conf->path = conf_path_absolute(st.base_dir, slash ? slash + 1 : path);
    if (!st.conf || !st.conf->path) {
      st.failed = 1;
      st.err_code = FG_ENOMEM;
      snprintf(st.err, sizeof st.err, "%s: out of memory", path);
    }
  }
  if (!st.failed) {
    int rc = ini_parse_stream(conf_reader, &st, conf_handler, &st);
    if (ferror(st.fp)) {
      st.failed = 1;
      st.err_code = FG_EIO;
      snprintf(st.err, sizeof st.err, "%s: cannot read: %s", path, strerror(errno));
    } else if (rc < 0 && !st.failed) {
      st.failed = 1;
      st.err_code = FG_ENOMEM;
      snprintf(st.err, sizeof st.err, "%s: out of memory while parsing", path);
    } else if (rc > 0 && !st.failed) {
      /* inih saw something our classification let through; should not happen */
      conf_fail_at(&st, rc, NULL, NULL, "malformed line; expected 'key = value', '[section]' or a "
                   "comment");
    }
    if (!st.failed) check_final(&st);
  }

  fclose(st.fp);
  free(st.raw);
  free(st.base_dir);
  free(st.scene_meta);
  free(st.camera_meta);
  if (st.failed) {
    fg_conf_free(st.conf);
    copy_err(err, errlen, st.err);
    return fg_fail(st.err_code, "%s", st.err);
  }
  *out = st.conf;
  return 0;
}
