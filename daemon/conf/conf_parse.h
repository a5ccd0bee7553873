/* The configuration parser's state and its value parsers, shared by conf.c (the line reader,
 * the key handler and the checks at the end) and conf_parse.c (errors, paths and values).
 * Private to conf/. */
#ifndef FG_DAEMON_CONF_PARSE_H
#define FG_DAEMON_CONF_PARSE_H

#include "conf.h"

#include <stddef.h>
#include <stdio.h>

typedef enum {
  SEC_NONE = 0, /* before the first header */
  SEC_HTTP,
  SEC_STATE,
  SEC_CLIP,
  SEC_TRAIN,
  SEC_GRIPPER,
  SEC_ROBOT,
  SEC_GRIPPER_MODBUS,
  SEC_CALIBRATION,
  SEC_SCENE,  /* the named sections: [scene NAME], [camera NAME] */
  SEC_CAMERA,
  SEC_COUNT
} conf_section;

#define MAX_KEYS 32

/* Per-scene parse bookkeeping, parallel to fg_conf.scenes. */
typedef struct scene_meta {
  int header_line;
  int key_line[MAX_KEYS]; /* line of each scene key, 0 when not set */
} scene_meta;

/* Per-camera parse bookkeeping, parallel to fg_conf.cameras. */
typedef struct camera_meta {
  int header_line;
  int key_line[MAX_KEYS]; /* line of each camera key, 0 when not set */
} camera_meta;

typedef enum { LINE_BLANK, LINE_COMMENT, LINE_HEADER, LINE_KEY, LINE_CONTINUATION } line_kind;

typedef struct conf_parse {
  fg_conf *conf;
  const char *path; /* as the caller gave it: messages name the file the user named */
  char *base_dir;   /* the file's folder, absolute: relative paths are taken from here */
  FILE *fp;

  char *raw; /* the current physical line, without its newline */
  size_t raw_cap;
  int line;
  line_kind kind;
  int key_active;    /* mirrors inih's prev_name: an indented line now continues a value */
  char last_key[64]; /* for the continuation message */

  conf_section sec;
  char sec_text[96]; /* the current header's text, e.g. "scene tabletop" */
  size_t scene;      /* index into conf->scenes when sec == SEC_SCENE */
  int sec_line[SEC_COUNT];
  int key_line[SEC_COUNT][MAX_KEYS];
  scene_meta *scene_meta;
  size_t camera;     /* index into conf->cameras when sec == SEC_CAMERA */
  camera_meta *camera_meta;

  int failed;    /* an error has been recorded */
  int err_line;  /* its line, to keep the earliest of the end-of-file checks */
  int err_code;
  char err[768];
} conf_parse;

/* ---- conf_cell.c: [calibration] and [camera NAME] ---- */

extern const char *const conf_calibration_keys[];
extern const char *const conf_camera_keys[];

/* Opens a [camera NAME] section (the text after "camera"). 1, or 0 after an error. */
int conf_enter_camera(conf_parse *st, const char *name);

/* One key of the section; k indexes its key list. 1, or 0 after an error. */
int conf_set_calibration(conf_parse *st, int k, const char *name, const char *v);
int conf_set_camera(conf_parse *st, int k, const char *name, const char *v);

/* The checks once the file is read: the board OpenCV can make, each camera's source. */
void conf_check_cell(conf_parse *st);

/* ---- errors: each records its error and returns 0 (inih's "failed" value) ---- */

/* Records "FILE:LINE: [section] key: message" unless an error on an earlier line is already
 * recorded. */
__attribute__((format(printf, 5, 6))) int conf_fail_at(conf_parse *st, int line,
                                                       const char *section, const char *key,
                                                       const char *fmt, ...);

/* An allocation failure while parsing: not the file's fault, but reported the same way. */
int conf_fail_nomem(conf_parse *st);

/* ---- paths ---- */

/* base and p joined (unless p is absolute), ".", ".." and repeated slashes removed lexically;
 * NULL on allocation failure. */
char *conf_path_absolute(const char *base, const char *p);

/* The folder holding the file at path, absolute (through realpath()); NULL on failure. */
char *conf_folder_of(const char *path);

/* ---- values: each returns 1 and stores the value, or records an error naming the current
 * line and key and returns 0 ---- */

int conf_parse_int(conf_parse *st, const char *key, const char *v, long lo, long hi, int *out);
int conf_parse_double(conf_parse *st, const char *key, const char *v, double *out);
int conf_parse_vec3(conf_parse *st, const char *key, const char *v, const char *what,
                    double out[3]);
int conf_parse_enum(conf_parse *st, const char *key, const char *v, const char *const *names,
                    int *out);
int conf_set_string(conf_parse *st, char **dst, const char *v);
int conf_set_path(conf_parse *st, const char *key, char **dst, const char *v);
int conf_set_token_file(conf_parse *st, const char *key, const char *v);
int conf_set_import_dirs(conf_parse *st, const char *key, const char *v);

#endif
