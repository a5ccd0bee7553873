/* fieldgripd's configuration outside its file: the built-in defaults, the rules for a listen
 * address and a scene name (the API checks them too), lookups, and freeing. The file's parser
 * is conf.c. */
#include "conf.h"
#include "secret.h"

#include "core/error.h"
#include "modbus/regs.h"

#include <arpa/inet.h>
#include <ctype.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

/* ---------------------------------------------------------------- listen and scene names */

/* See conf.h. The port must be all digits: "7070x" or "+7070" are typos, not ports. */
int fg_conf_parse_listen(const char *listen, char **host, int *port) {
  if (!listen || !host || !port) return fg_fail(FG_EINVAL, "no listen address given");
  *host = NULL;
  const char *h, *colon;
  size_t hlen;
  if (listen[0] == '[') {
    const char *close = strchr(listen, ']');
    if (!close)
      return fg_fail(FG_EINVAL, "listen address '%s' lacks the closing ']' of its IPv6 host; "
                     "expected [ADDRESS]:PORT such as [::1]:7070", listen);
    h = listen + 1;
    hlen = (size_t)(close - h);
    if (close[1] != ':')
      return fg_fail(FG_EINVAL, "listen address '%s' needs ':PORT' after the ']'; expected "
                     "[ADDRESS]:PORT such as [::1]:7070", listen);
    colon = close + 1;
  } else {
    colon = strrchr(listen, ':');
    if (!colon)
      return fg_fail(FG_EINVAL, "listen address '%s' has no port; expected HOST:PORT such as "
                     "127.0.0.1:7070", listen);
    h = listen;
    hlen = (size_t)(colon - h);
    if (memchr(h, ':', hlen))
      return fg_fail(FG_EINVAL, "listen address '%s' looks like a bare IPv6 address; put it in "
                     "brackets, e.g. [::1]:7070", listen);
  }
  if (hlen == 0)
    return fg_fail(FG_EINVAL, "listen address '%s' has no host; use 127.0.0.1:PORT for this "
                   "machine only or 0.0.0.0:PORT for every interface", listen);
  for (size_t i = 0; i < hlen; i++) {
    if (isspace((unsigned char)h[i]) || h[i] == '[' || h[i] == ']')
      return fg_fail(FG_EINVAL, "listen address '%s' has a malformed host; expected HOST:PORT "
                     "or [IPv6]:PORT", listen);
  }
  const char *p = colon + 1;
  long val = 0;
  size_t nd = 0;
  for (; p[nd]; nd++) {
    if (!isdigit((unsigned char)p[nd]) || nd >= 5) break;
    val = val * 10 + (p[nd] - '0');
  }
  if (nd == 0 || p[nd] != '\0' || val > 65535)
    return fg_fail(FG_EINVAL, "listen address '%s' has a bad port; expected a number from 0 to "
                   "65535 (0 picks any free port)", listen);
  *host = strndup(h, hlen);
  if (!*host) return fg_fail(FG_ENOMEM, "out of memory");
  *port = (int)val;
  return 0;
}

/* See conf.h. Scene names become folder names under the state dir and URL path segments,
 * hence the small alphabet and no leading dot (no ".", "..", or hidden folders). */
int fg_scene_name_validate(const char *name) {
  if (!name || name[0] == '\0')
    return fg_fail(FG_EINVAL, "scene name is empty; use 1 to %d characters of A-Z a-z 0-9 _ . -",
                   FG_SCENE_NAME_MAX);
  size_t n = strlen(name);
  if (n > FG_SCENE_NAME_MAX)
    return fg_fail(FG_EINVAL, "scene name is %zu characters long; the limit is %d", n,
                   FG_SCENE_NAME_MAX);
  if (name[0] == '.')
    return fg_fail(FG_EINVAL, "scene name '%s' starts with '.'; start it with a letter, digit, "
                   "'_' or '-'", name);
  for (size_t i = 0; i < n; i++) {
    unsigned char c = (unsigned char)name[i];
    if (!isalnum(c) && c != '_' && c != '.' && c != '-')
      return fg_fail(FG_EINVAL, "scene name '%.64s' contains '%c' (byte 0x%02x); use only A-Z "
                     "a-z 0-9 _ . -", name, isprint(c) ? c : '?', c);
  }
  return 0;
}

/* ---------------------------------------------------------------- cross-site lists */

/* See conf.h. Ports are not part of an entry: a rebinding attack is told apart by its name,
 * and behind a proxy the port a browser used is not the daemon's. */
int fg_conf_check_host_name(const char *name) {
  size_t n = strlen(name);
  if (n == 0 || n > 253)
    return fg_fail(FG_EINVAL, "'%.64s' is not a host name; expected 1 to 253 characters", name);
  for (size_t i = 0; i < n; i++) {
    unsigned char c = (unsigned char)name[i];
    if (c == ':' || c == '/')
      return fg_fail(FG_EINVAL, "'%.64s' is not a bare host name; give the name alone, without "
                     "scheme or port (IP addresses are always allowed)", name);
    if (!isalnum(c) && c != '.' && c != '-' && c != '_')
      return fg_fail(FG_EINVAL, "'%.64s' contains '%c'; a host name has letters, digits, '.', "
                     "'-' and '_'", name, isprint(c) ? c : '?');
  }
  return 0;
}

/* See conf.h. "null" (sandboxed frames, file:// pages) and "*" are refused: either would let
 * pages of any site in. */
int fg_conf_check_origin(const char *origin) {
  const char *host = NULL;
  if (strncasecmp(origin, "http://", 7) == 0) host = origin + 7;
  else if (strncasecmp(origin, "https://", 8) == 0) host = origin + 8;
  if (!host || !*host || strpbrk(host, "/?#@"))
    return fg_fail(FG_EINVAL, "'%.80s' is not a web origin; expected http://HOST[:PORT] or "
                   "https://HOST[:PORT] as the browser's address bar shows it, without a path "
                   "or a trailing '/'", origin);
  for (const char *c = host; *c; c++)
    if (!isalnum((unsigned char)*c) && !strchr(".-_:[]", *c))
      return fg_fail(FG_EINVAL, "origin '%.80s' has '%c' in its host; expected "
                     "http://HOST[:PORT] or https://HOST[:PORT]", origin,
                     isprint((unsigned char)*c) ? *c : '?');
  return 0;
}

static void free_list(char **list, size_t n) {
  for (size_t i = 0; i < n; i++) free(list[i]);
  free(list);
}

int fg_conf_split_list(const char *v, int (*check)(const char *), char ***out, size_t *n) {
  char **list = NULL;
  size_t count = 0;
  for (const char *s = v; *s;) {
    size_t len = strcspn(s, " \t,");
    if (len > 0) {
      char *item = strndup(s, len);
      char **grown = item ? realloc(list, (count + 1) * sizeof *list) : NULL;
      if (!grown) {
        free(item);
        free_list(list, count);
        return fg_fail(FG_ENOMEM, "out of memory");
      }
      list = grown;
      list[count++] = item;
      int rc = check(item);
      if (rc != 0) {
        free_list(list, count);
        return rc;
      }
    }
    s += len;
    if (*s) s++;
  }
  free_list(*out, *n);
  *out = list;
  *n = count;
  return 0;
}

/* ---------------------------------------------------------------- exposure */

int fg_conf_listen_is_loopback(const char *listen) {
  char *host = NULL;
  int port;
  if (fg_conf_parse_listen(listen, &host, &port) != 0) return 0;
  unsigned char a[16];
  int loop = strcasecmp(host, "localhost") == 0;
  if (!loop && inet_pton(AF_INET, host, a) == 1) loop = a[0] == 127;
  if (!loop && inet_pton(AF_INET6, host, a) == 1) {
    static const unsigned char v6_loop[16] = {[15] = 1};
    static const unsigned char v4_mapped[12] = {[10] = 0xff, [11] = 0xff};
    loop = memcmp(a, v6_loop, 16) == 0 || (memcmp(a, v4_mapped, 12) == 0 && a[12] == 127);
  }
  free(host);
  return loop;
}

/* See conf.h. The token is what stops other machines: Host and Origin checks (http_guard.h)
 * stop web pages, not a client that sends what it likes. */
int fg_conf_check_exposure(const fg_conf *conf, const fg_conf *running) {
  const fg_conf *r = running ? running : conf;
  const int robot = r->robot.transport != FG_TRANSPORT_NONE;
  const int gripper = r->gripper_modbus.transport != FG_TRANSPORT_NONE;
  if ((conf->token && conf->token[0]) || (!robot && !gripper) ||
      fg_conf_listen_is_loopback(r->listen))
    return 0;
  return fg_fail(FG_EINVAL, "[http] listen %s can be reached from other machines and %s is "
                 "set, but there is no token: anyone on the network could move the robot; set "
                 "[http] token_file (or token), or listen on 127.0.0.1:PORT or [::1]:PORT",
                 r->listen, robot ? "[robot] transport" : "[gripper.modbus] transport");
}

/* ---------------------------------------------------------------- defaults */

void fg_conf_scene_defaults(fg_conf_scene *s) {
  memset(s, 0, sizeof *s);
  s->workspace_min[0] = 0.10;
  s->workspace_min[1] = -0.45;
  s->workspace_min[2] = 0.005;
  s->workspace_max[0] = 0.80;
  s->workspace_max[1] = 0.45;
  s->workspace_max[2] = 0.35;
  s->voxel_size = 0.01;
  s->background[0] = s->background[1] = s->background[2] = 1.0;
  s->learn_background = -1;
}

/* Fills a Modbus peer's defaults; 0 on allocation failure. */
static int modbus_defaults(fg_conf_modbus *m, int unit_id) {
  memset(m, 0, sizeof *m);
  m->transport = FG_TRANSPORT_NONE;
  m->host = strdup("127.0.0.1");
  m->port = 502;
  m->device = strdup("/dev/ttyUSB0");
  m->baud = 115200;
  m->parity = 'N';
  m->unit_id = unit_id;
  m->timeout_ms = 500;
  m->base = 128;
  m->encoding = FG_ENCODING_INT16;
  m->ack_timeout_ms = 2000;
  m->done_timeout_ms = 60000;
  m->tcp_pose_base = FG_TCP_POSE_BASE_DEFAULT;
  m->motion_timeout_ms = 10000;
  return m->host && m->device;
}

fg_conf *fg_conf_defaults(void) {
  fg_conf *c = calloc(1, sizeof *c);
  if (!c) return NULL;
  c->listen = strdup(FG_CONF_DEFAULT_LISTEN);
  c->max_upload_bytes = (size_t)64 << 20;
  c->max_json_bytes = (size_t)1 << 20;
  c->max_connections = 1024;
  c->header_timeout_s = 10;
  c->idle_timeout_s = 60;
  c->min_body_bytes_per_s = (size_t)8 << 10;
  c->max_queued_requests = 64;
  c->three_js = strdup(FG_CONF_DEFAULT_THREE_JS);
  c->state_dir = strdup(FG_CONF_DEFAULT_STATE_DIR);
  c->max_scenes = 64;
  c->board = (fg_charuco_board){7, 5, 0.035, 0.026, 5 /* DICT_5X5_100 */};
  c->max_loaded_fields = 4;
  c->train_steps = 2000;
  c->depth_weight = FG_TRAIN_DEPTH_WEIGHT;
  c->distortion_weight = FG_TRAIN_DISTORTION_WEIGHT;
  c->train_threads = 0;
  c->max_image_side = 400;
  c->gripper_model = FG_GRIPPER_PANDA;
  c->motion = (fg_conf_motion){
      .limit_margin_m = 0.10,
      .approach_cone_deg = 60,
      .max_speed_mps = 0.25,
      .speed_mps = 0.10,
      .approach_m = 0.10,
      .retreat_m = 0.10,
  };
  int ok = modbus_defaults(&c->robot, 1);
  ok &= modbus_defaults(&c->gripper_modbus, 9);
  c->audit_max_bytes = (size_t)16 << 20;
  c->audit_keep = 8;
  if (!ok || !c->listen || !c->state_dir || !c->three_js) {
    fg_conf_free(c);
    return NULL;
  }
  return c;
}

const fg_conf_camera *fg_conf_find_camera(const fg_conf *conf, const char *name) {
  for (size_t i = 0; i < conf->n_cameras; i++)
    if (strcmp(conf->cameras[i].name, name) == 0) return &conf->cameras[i];
  return NULL;
}

const fg_conf_scene *fg_conf_find_scene(const fg_conf *conf, const char *name) {
  if (!conf || !name) return NULL;
  for (size_t i = 0; i < conf->n_scenes; i++)
    if (strcmp(conf->scenes[i].name, name) == 0) return &conf->scenes[i];
  return NULL;
}

int fg_conf_threads(const fg_conf *conf) {
  if (conf->train_threads > 0) return conf->train_threads;
  long n = sysconf(_SC_NPROCESSORS_ONLN);
  return n > 0 ? (int)n : 1;
}

static void modbus_free(fg_conf_modbus *m) {
  free(m->host);
  free(m->device);
}

void fg_conf_free(fg_conf *conf) {
  if (!conf) return;
  free(conf->path);
  free(conf->listen);
  fg_secret_free(conf->token);
  free(conf->token_file);
  free(conf->viewer_dir);
  free(conf->three_js);
  free(conf->state_dir);
  for (size_t i = 0; i < conf->n_import_dirs; i++) free(conf->import_dirs[i]);
  free(conf->import_dirs);
  free_list(conf->allowed_hosts, conf->n_allowed_hosts);
  free_list(conf->allowed_origins, conf->n_allowed_origins);
  free(conf->clip_weights);
  free(conf->clip_vocab);
  modbus_free(&conf->robot);
  modbus_free(&conf->gripper_modbus);
  free(conf->lock_dir);
  free(conf->scenes);
  for (size_t i = 0; i < conf->n_cameras; i++) {
    free(conf->cameras[i].source);
    free(conf->cameras[i].depth_source);
    free(conf->cameras[i].features_source);
  }
  free(conf->cameras);
  free(conf);
}
