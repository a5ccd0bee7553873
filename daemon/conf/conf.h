/* fieldgripd's configuration: the INI file of SPEC.md "Configuration file", parsed with
 * libinih, plus the command-line overrides.
 *
 * Every key has a built-in default (fg_conf_defaults), so the daemon runs without a file.
 * Unknown sections and keys, malformed values and values out of range are errors whose
 * message names the file, the line and the key ("/etc/fieldgrip/fieldgripd.conf:12: [train]
 * steps: expected an integer from 1 to 10000000, got 'many'"). Relative paths in the file
 * are taken relative to the file's folder. */
#ifndef FG_DAEMON_CONF_H
#define FG_DAEMON_CONF_H

#include <stddef.h>

#include "calib/charuco.h"

#include "field/train.h"   /* the [train] loss weights' defaults and range */
#include "grasp/gripper.h" /* fg_gripper_model: [gripper] model */

#define FG_CONF_DEFAULT_PATH "/etc/fieldgrip/fieldgripd.conf"
#define FG_CONF_DEFAULT_STATE_DIR "/var/lib/fieldgrip"
#define FG_CONF_DEFAULT_LISTEN "127.0.0.1:7070"
#define FG_SCENE_NAME_MAX 64
/* Debian's libjs-three: three.js r111's global build. */
#define FG_CONF_DEFAULT_THREE_JS "/usr/share/javascript/three/three.min.js"

typedef enum { FG_TRANSPORT_NONE = 0, FG_TRANSPORT_TCP, FG_TRANSPORT_RTU } fg_transport;
typedef enum { FG_ENCODING_INT16 = 0, FG_ENCODING_FLOAT32 } fg_encoding;

/* A Modbus peer ([robot] or [gripper.modbus]). */
typedef struct fg_conf_modbus {
  fg_transport transport;
  char *host;        /* tcp: name or address (IPv6 allowed) */
  int port;          /* tcp: 1..65535 */
  char *device;      /* rtu: serial device path */
  int baud;          /* rtu */
  char parity;       /* rtu: 'N', 'E' or 'O' (key "parity", default N) */
  int unit_id;       /* 0..247 */
  int timeout_ms;    /* response timeout, key "timeout_ms", 1..60000, default 500 */
  /* [robot] only */
  int base;          /* first holding register, 0..65535 - 20 */
  fg_encoding encoding;
  int ack_timeout_ms; /* 1..600000 */
  int done_timeout_ms; /* extension: for status done / failed, 1..3600000, default 60000 */
  int tcp_pose_base; /* first of the six TCP pose registers (proto/modbus.md), default 400;
                      * -1: none (key value "none") */
  /* [gripper.modbus] only */
  int motion_timeout_ms; /* extension: activation and each move, 1..600000, default 10000 */
} fg_conf_modbus;

/* [robot]'s motion limits and the robot program's path (lib/motion/limits.h). */
typedef struct fg_conf_motion {
  int has_box;              /* limit_min and limit_max are both set */
  double limit_min[3], limit_max[3]; /* TCP position box, metres, world frame */
  double limit_margin_m;    /* without a box: the scenes' workspaces grown by this; 0..10,
                             * default 0.10 */
  double reach_m;           /* TCP within this of the base's origin; 0..10, 0 (default): no
                             * reach limit */
  double approach_cone_deg; /* tool +z within this of straight down; 0..180, default 60 */
  double max_force_n;       /* 0 (default): the gripper model's largest force */
  double max_speed_mps;     /* > 0, default 0.25 */
  double speed_mps;         /* a command's speed when it gives none; default 0.10 */
  double approach_m;        /* pick and place come in along the tool's +z from this far
                             * back; 0..1, default 0.10 */
  double retreat_m;         /* and leave by this much afterwards; 0..1, default 0.10 */
} fg_conf_motion;

/* A [scene NAME] section. */
typedef struct fg_conf_scene {
  char name[FG_SCENE_NAME_MAX + 1];
  double workspace_min[3], workspace_max[3]; /* metres, world frame; min < max per axis */
  double voxel_size;                         /* metres, > 0 */
  double background[3];                      /* key "background", RGB in [0,1], default 1 1 1 */
  double field_scale;   /* 1..64; 0 for "auto", the default (as fg_scene_params) */
  int learn_background; /* "yes" 1, "no" 0, "auto" -1, the default (as fg_scene_params) */
} fg_conf_scene;

/* [camera NAME] (SPEC.md "The cell around the field"): a source fieldgripd captures from. */
typedef enum { FG_MOUNT_HAND = 0, FG_MOUNT_FIXED } fg_camera_mount;

#define FG_CAMERA_NAME_MAX 63
#define FG_CAMERA_TIMEOUT_MS 5000 /* a snapshot's default limit */

typedef struct fg_conf_camera {
  char name[FG_CAMERA_NAME_MAX + 1]; /* a scene name's characters */
  char *source;         /* "http://..." (a snapshot URL; V4L2 devices are not supported yet) */
  char *depth_source;   /* the same for a depth image (16-bit PNG), or NULL */
  double depth_scale;   /* metres per depth unit; default 0.001 (millimetres) */
  fg_camera_mount mount; /* key "mount": hand (default) or fixed */
  char *features_source; /* a URL that serves the view's patch features (.npy, SPEC.md's
                            layout: what a feature extractor beside the camera computes), or
                            NULL: the frames get CLIP's ([clip]) or none */
  int timeout_ms;       /* key "timeout_ms" (100..600000): how long each snapshot may take */
} fg_conf_camera;

typedef struct fg_conf {
  char *path;            /* the file read, or NULL for built-in defaults */
  /* [http] */
  char *listen;          /* "host:port", "[v6]:port" */
  char *token;           /* NULL or "" = no authentication; from token or token_file */
  char *token_file;      /* [http] token_file, resolved (absolute), or NULL */
  size_t max_upload_bytes; /* from max_upload_mb (1..4096): frame uploads, image embeddings */
  size_t max_json_bytes; /* from max_json_kb (1..1048576, default 1024): every other body */
  int max_connections;   /* 16..1000000, default 1024; past it the oldest idle one is shed */
  int header_timeout_s;  /* 1..3600, default 10: a new connection's request headers */
  int idle_timeout_s;    /* 1..86400, default 60: kept alive without a next request, or silent */
  size_t min_body_bytes_per_s; /* from min_body_kb_per_s (0..1048576, default 8); 0: none */
  int max_queued_requests; /* 1..100000, default 64: long work waiting for a thread */
  char *viewer_dir;      /* the web viewer's files (absolute); NULL: the built-in place
                          * (daemon/api/api_viewer.c) */
  char *three_js;        /* three.min.js for the viewer (absolute); default
                          * FG_CONF_DEFAULT_THREE_JS */
  char **allowed_hosts;  /* Host names served besides IP addresses and localhost
                          * (http_guard.h); separated by spaces or commas in the file */
  size_t n_allowed_hosts;
  char **allowed_origins; /* web origins ("http://panel.lab:8080") that may send requests that
                           * change something, besides the daemon's own; same separators */
  size_t n_allowed_origins;
  /* [state] */
  char *state_dir;
  char **import_dirs;    /* absolute paths */
  size_t n_import_dirs;
  int max_scenes;        /* 0..1000000, default 64; 0: no limit */
  int max_loaded_fields; /* 0..100000, default 4: trained fields in memory; 0: no limit */
  /* [clip] */
  char *clip_weights;    /* NULL when [clip] is absent; absolute */
  char *clip_vocab;
  int clip_threads;      /* 0 = fg_conf_threads(), else 1..1024 */
  int clip_weights_line; /* lines of the weights and vocab keys, for messages about the files */
  int clip_vocab_line;   /* (0 with built-in defaults) */
  /* [train] */
  int train_steps;       /* 1..10000000, default 2000 */
  int train_threads;     /* 0 = all cores, else 1..1024 */
  int max_image_side;    /* 16..16384, default 400 */
  int half_precision;    /* 1: checkpoints keep hash tables in float16; default 0 */
  double depth_weight;   /* [train] depth_weight, 0..FG_TRAIN_MAX_LOSS_WEIGHT */
  double distortion_weight; /* [train] distortion_weight, same range */
  /* [gripper] */
  fg_gripper_model gripper_model;
  /* [robot], [gripper.modbus] */
  fg_conf_modbus robot;
  fg_conf_motion motion; /* [robot]'s limit and path keys */
  fg_conf_modbus gripper_modbus;
  /* [robot] audit log (audit.h) and the claim on the peers (claim.h), read at start-up */
  size_t audit_max_bytes; /* from audit_max_mb (a number of MiB > 0, fractions allowed; 16) */
  int audit_keep;        /* 1..1000, default 8: rotated files kept beside robot.log */
  char *lock_dir;        /* absolute, or NULL: /run/lock when writable, else the state dir */
  /* [scene NAME] */
  fg_conf_scene *scenes;
  size_t n_scenes;
  /* [camera NAME] */
  fg_conf_camera *cameras;
  size_t n_cameras;
  /* [calibration]: the ChArUco board; default 7 x 5 squares of 35 mm with 26 mm markers of
   * DICT_5X5_100 (it prints on A4) */
  fg_charuco_board board;
} fg_conf;

/* Allocates a configuration holding every built-in default. NULL on allocation failure. */
fg_conf *fg_conf_defaults(void);

/* Parses the file at path over the built-in defaults. On success *out is a new configuration
 * the caller owns; on failure *out is NULL and err holds "FILE:LINE: [section] key: what is
 * wrong" (or "FILE: cannot open: ..."). */
int fg_conf_load(const char *path, fg_conf **out, char *err, size_t errlen);

/* Parses "host:port" / "[v6]:port" into host (malloc'd, brackets removed) and port (0..65535).
 * FG_EINVAL with a detail otherwise. */
int fg_conf_parse_listen(const char *listen, char **host, int *port);

/* Checks one [http] allowed_hosts entry: a host name (letters, digits, '.', '-', '_'), no
 * port. FG_EINVAL with a detail otherwise. */
int fg_conf_check_host_name(const char *name);

/* Checks one [http] allowed_origins entry: an origin as browsers send it, "http://HOST" or
 * "https://HOST" with an optional ":PORT" and nothing after it. FG_EINVAL with a detail
 * otherwise. */
int fg_conf_check_origin(const char *origin);

/* Splits a list value at spaces and commas, checking each entry with check. On success *out
 * (malloc'd strings in a malloc'd array, NULL when empty) and *n are the caller's; on failure
 * they are untouched and check's detail (or FG_ENOMEM) is returned. */
int fg_conf_split_list(const char *v, int (*check)(const char *), char ***out, size_t *n);

/* 1 when a listen address ("host:port") can be reached from this machine only: 127.0.0.0/8,
 * ::1 (also v4-mapped) or "localhost". Wildcards and every other name count as reachable
 * from elsewhere. */
int fg_conf_listen_is_loopback(const char *listen);

/* Refuses a daemon that anyone on its network could make move the robot: a [robot] or
 * [gripper.modbus] transport, a listen address that is not loopback and no [http] token.
 * The listen address and the transports are running's when running is not NULL (at a
 * reload they change only at a restart), the token is conf's. 0, or FG_EINVAL with a detail
 * that names the keys to set. */
int fg_conf_check_exposure(const fg_conf *conf, const fg_conf *running);

/* Checks a scene name: 1..64 characters of [A-Za-z0-9_.-], not starting with '.'.
 * FG_EINVAL with a detail otherwise. */
int fg_scene_name_validate(const char *name);

/* Sets a [scene NAME] section's built-in values (SPEC.md's tabletop workspace at 1 cm voxels,
 * white background); the name is left empty. */
void fg_conf_scene_defaults(fg_conf_scene *s);

/* Finds a [camera NAME] by name; NULL if absent. */
const fg_conf_camera *fg_conf_find_camera(const fg_conf *conf, const char *name);

/* Finds a [scene NAME] by name; NULL if absent. */
const fg_conf_scene *fg_conf_find_scene(const fg_conf *conf, const char *name);

/* [train] threads of conf, 0 resolved to the number of online cores; always >= 1. */
int fg_conf_threads(const fg_conf *conf);

void fg_conf_free(fg_conf *conf);

#endif
