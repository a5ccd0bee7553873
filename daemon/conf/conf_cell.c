/* [calibration] and [camera NAME] (conf_parse.h): the ChArUco board and the cameras. */
#include "conf_parse.h"

#include "core/error.h"

#include <ctype.h>
#include <stdlib.h>
#include <string.h>

const char *const conf_calibration_keys[] = {"squares_x", "squares_y", "square_m", "marker_m",
                                             "dictionary", NULL};
enum { K_SQUARES_X, K_SQUARES_Y, K_SQUARE_M, K_MARKER_M, K_DICTIONARY };

const char *const conf_camera_keys[] = {"source", "depth_source", "depth_scale", "mount",
                                        "features_source", "timeout_ms", NULL};
enum { K_SOURCE, K_DEPTH_SOURCE, K_DEPTH_SCALE, K_MOUNT, K_FEATURES_SOURCE, K_TIMEOUT_MS };
_Static_assert(sizeof conf_camera_keys / sizeof *conf_camera_keys - 1 <= MAX_KEYS,
               "camera_meta.key_line holds a line per camera key");

static const char *const mount_names[] = {"hand", "fixed", NULL};

int conf_enter_camera(conf_parse *st, const char *name) {
  if (*name == '\0')
    return conf_fail_at(st, st->line, st->sec_text, NULL,
                        "a camera section needs a name, e.g. [camera wrist]");
  if (strlen(name) > FG_CAMERA_NAME_MAX || fg_scene_name_validate(name) < 0)
    return conf_fail_at(st, st->line, st->sec_text, NULL, "a camera's name is 1 to %d letters, "
                        "digits, '-' or '_', starting with a letter or digit",
                        FG_CAMERA_NAME_MAX);
  fg_conf *c = st->conf;
  for (size_t i = 0; i < c->n_cameras; i++)
    if (strcmp(c->cameras[i].name, name) == 0)
      return conf_fail_at(st, st->line, st->sec_text, NULL,
                          "duplicate camera section (first on line %d); merge the two",
                          st->camera_meta[i].header_line);
  fg_conf_camera *cams = realloc(c->cameras, (c->n_cameras + 1) * sizeof *cams);
  if (!cams) return conf_fail_nomem(st);
  c->cameras = cams;
  camera_meta *meta = realloc(st->camera_meta, (c->n_cameras + 1) * sizeof *meta);
  if (!meta) return conf_fail_nomem(st);
  st->camera_meta = meta;
  fg_conf_camera *cam = &cams[c->n_cameras];
  memset(cam, 0, sizeof *cam);
  snprintf(cam->name, sizeof cam->name, "%s", name);
  cam->depth_scale = 0.001;
  cam->mount = FG_MOUNT_HAND;
  cam->timeout_ms = FG_CAMERA_TIMEOUT_MS;
  memset(&meta[c->n_cameras], 0, sizeof *meta);
  meta[c->n_cameras].header_line = st->line;
  st->camera = c->n_cameras++;
  st->sec = SEC_CAMERA;
  return 1;
}

int conf_set_calibration(conf_parse *st, int k, const char *name, const char *v) {
  fg_charuco_board *b = &st->conf->board;
  switch (k) {
  case K_SQUARES_X: return conf_parse_int(st, name, v, 3, 64, &b->squares_x);
  case K_SQUARES_Y: return conf_parse_int(st, name, v, 3, 64, &b->squares_y);
  case K_SQUARE_M:
  case K_MARKER_M: {
    double x;
    if (!conf_parse_double(st, name, v, &x)) return 0;
    if (!(x > 0 && x <= 1))
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected a size in metres above 0 and at most 1, got '%s'", v);
    *(k == K_SQUARE_M ? &b->square_m : &b->marker_m) = x;
    return 1;
  }
  case K_DICTIONARY:
    if (fg_charuco_dictionary_parse(v, &b->dictionary) != 0)
      return conf_fail_at(st, st->line, st->sec_text, name, "%s", fg_error_detail());
    return 1;
  }
  return 1;
}

/* A source: an http(s):// URL without spaces. */
static int source_ok(const char *v) {
  if (strncmp(v, "http://", 7) != 0 && strncmp(v, "https://", 8) != 0) return 0;
  for (const char *p = v; *p; p++)
    if (isspace((unsigned char)*p) || !isprint((unsigned char)*p)) return 0;
  return strlen(v) > 8;
}

/* A device path: /dev/ and a name of printable characters without spaces. */
static int device_ok(const char *v) {
  if (strncmp(v, "/dev/", 5) != 0 || strlen(v) < 6 || strstr(v, "/../")) return 0;
  for (const char *p = v; *p; p++)
    if (isspace((unsigned char)*p) || !isprint((unsigned char)*p)) return 0;
  return 1;
}

int conf_set_camera(conf_parse *st, int k, const char *name, const char *v) {
  fg_conf_camera *cam = &st->conf->cameras[st->camera];
  switch (k) {
  case K_SOURCE:
  case K_DEPTH_SOURCE:
    if (strncmp(v, "v4l2:", 5) == 0) {
      if (k == K_DEPTH_SOURCE)
        return conf_fail_at(st, st->line, st->sec_text, name,
                            "a V4L2 device gives 8-bit frames, not depth; serve the depth "
                            "images as HTTP snapshots (http://HOST:PORT/PATH)");
      if (!device_ok(v + 5))
        return conf_fail_at(st, st->line, st->sec_text, name,
                            "expected v4l2:/dev/videoN (a V4L2 device's path), got '%s'", v);
    } else if (!source_ok(v)) {
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected a snapshot URL (http://HOST:PORT/PATH) or v4l2:/dev/videoN, "
                          "got '%s'", v);
    }
    return conf_set_string(st, k == K_SOURCE ? &cam->source : &cam->depth_source, v);
  case K_DEPTH_SCALE: {
    double x;
    if (!conf_parse_double(st, name, v, &x)) return 0;
    if (!(x > 0 && x <= 1))
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected metres per depth unit above 0 and at most 1 (0.001: "
                          "millimetres), got '%s'", v);
    cam->depth_scale = x;
    return 1;
  }
  case K_MOUNT: {
    int x;
    if (!conf_parse_enum(st, name, v, mount_names, &x)) return 0;
    cam->mount = (fg_camera_mount)x;
    return 1;
  }
  case K_FEATURES_SOURCE:
    if (!source_ok(v))
      return conf_fail_at(st, st->line, st->sec_text, name,
                          "expected a URL that serves the view's features as .npy "
                          "(http://HOST:PORT/PATH), got '%s'", v);
    return conf_set_string(st, &cam->features_source, v);
  case K_TIMEOUT_MS:
    return conf_parse_int(st, name, v, 100, 600000, &cam->timeout_ms);
  }
  return 1;
}

void conf_check_cell(conf_parse *st) {
  fg_conf *c = st->conf;
  if (st->sec_line[SEC_CALIBRATION] && fg_charuco_board_check(&c->board) != 0)
    conf_fail_at(st, st->sec_line[SEC_CALIBRATION], "calibration", NULL, "%s",
                 fg_error_detail());
  for (size_t i = 0; i < c->n_cameras; i++)
    if (!c->cameras[i].source) {
      char sec[96];
      snprintf(sec, sizeof sec, "camera %s", c->cameras[i].name);
      conf_fail_at(st, st->camera_meta[i].header_line, sec, "source",
                   "missing; a camera needs source = http://HOST:PORT/PATH or "
                   "v4l2:/dev/videoN");
    }
}
