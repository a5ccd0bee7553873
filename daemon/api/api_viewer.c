/* GET / and GET /viewer/{file}: the web viewer, static files served as they lie on disk.
 *
 * The page (index.html), its script and style sheet come from [http] viewer_dir, and
 * /viewer/three.min.js from [http] three_js (Debian's libjs-three), so that nothing is
 * fetched from outside the machine and nothing is built. Without viewer_dir the daemon takes
 * the build tree's viewer/ folder when it runs from there (<folder of the executable>/../viewer
 * holds an index.html, as build/daemon/fieldgripd finds build/viewer), else the folder the
 * install puts it in, FG_DATADIR/fieldgrip/viewer: the same rule as the image decoder's.
 *
 * These routes are public (FG_ROUTE_PUBLIC): the page must load before it can ask for the
 * token, and it holds nothing secret; every data endpoint it calls still needs the token.
 * A file name is one path segment of [A-Za-z0-9._-], not starting with a dot, with a known
 * extension: no way out of the folder, no hidden files, no file of another kind. Files are
 * read at each request (a few hundred kB at most), so an upgrade of the files or of
 * libjs-three shows at the next reload of the page; "Cache-Control: no-cache" makes browsers
 * ask again. */
#include "api.h"

#include "config.h"
#include "core/error.h"
#include "core/fsutil.h"

#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Larger files are refused: three.min.js is about 600 kB. */
#define VIEWER_MAX_FILE ((size_t)16 << 20)
#define VIEWER_NAME_MAX 128
#define THREE_JS_NAME "three.min.js"

static char g_default_dir[PATH_MAX];
static pthread_once_t g_default_once = PTHREAD_ONCE_INIT;

static void default_dir_find(void) {
  snprintf(g_default_dir, sizeof g_default_dir, "%s/fieldgrip/viewer", FG_DATADIR);
  char exe[PATH_MAX];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
  if (n <= 0) return;
  exe[n] = '\0';
  char *slash = strrchr(exe, '/');
  if (!slash) return;
  *slash = '\0';
  char dir[PATH_MAX], index[PATH_MAX + 16];
  if (snprintf(dir, sizeof dir, "%s/../viewer", exe) >= (int)sizeof dir) return;
  snprintf(index, sizeof index, "%s/index.html", dir);
  char real[PATH_MAX];
  if (access(index, R_OK) == 0 && realpath(dir, real))
    snprintf(g_default_dir, sizeof g_default_dir, "%s", real);
}

/* The folder the viewer's files are served from. */
static const char *viewer_dir(const fg_conf *conf) {
  if (conf->viewer_dir) return conf->viewer_dir;
  pthread_once(&g_default_once, default_dir_find);
  return g_default_dir;
}

/* The Content-Type of a file name by its extension; NULL for a kind the viewer has none of. */
static const char *content_type_of(const char *name) {
  static const struct { const char *ext, *type; } types[] = {
    {".html", "text/html; charset=utf-8"}, {".js", "text/javascript; charset=utf-8"},
    {".css", "text/css; charset=utf-8"},   {".png", "image/png"},
    {".svg", "image/svg+xml"},             {".json", "application/json"},
  };
  const char *dot = strrchr(name, '.');
  for (size_t i = 0; dot && i < sizeof types / sizeof types[0]; i++)
    if (strcmp(dot, types[i].ext) == 0) return types[i].type;
  return NULL;
}

/* A name that stays in the folder: [A-Za-z0-9._-], not starting with '.'. */
static int name_ok(const char *name) {
  const size_t n = strlen(name);
  if (n == 0 || n > VIEWER_NAME_MAX || name[0] == '.') return 0;
  for (size_t i = 0; i < n; i++) {
    const char c = name[i];
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
          c == '.' || c == '_' || c == '-'))
      return 0;
  }
  return 1;
}

/* Answers with the file at path; `missing` is the message's end when it does not exist. */
static int send_file(fg_resp *resp, const char *path, const char *type, const char *missing) {
  char *buf = NULL;
  size_t len = 0;
  const int rc = fg_read_file(path, VIEWER_MAX_FILE, &buf, &len);
  if (rc == FG_ENOENT)
    return fg_resp_error(resp, 404, "not_found", "%s does not exist%s", path, missing);
  if (rc != 0)
    return fg_resp_error(resp, 500, "internal_error", "cannot read %s: %s", path,
                         fg_error_detail());
  fg_resp_take(resp, 200, type, buf, len);
  snprintf(resp->header, sizeof resp->header,
           "Cache-Control: no-cache\r\nX-Content-Type-Options: nosniff");
  return 0;
}

static int send_viewer_file(fg_req *req, fg_resp *resp, const char *name) {
  const char *dir = viewer_dir(req->conf);
  char path[PATH_MAX];
  if (snprintf(path, sizeof path, "%s/%s", dir, name) >= (int)sizeof path)
    return fg_resp_error(resp, 404, "not_found", "no viewer file \"%s\"", name);
  return send_file(resp, path, content_type_of(name),
                   "; the web viewer's files are installed with fieldgripd (or set [http] "
                   "viewer_dir to the folder that holds them)");
}

int fg_api_viewer_index(fg_req *req, fg_resp *resp) {
  return send_viewer_file(req, resp, "index.html");
}

int fg_api_viewer_file(fg_req *req, fg_resp *resp) {
  const char *name = req->params[0];
  const char *type = name_ok(name) ? content_type_of(name) : NULL;
  if (!type)
    return fg_resp_error(resp, 404, "not_found", "no viewer file \"%.60s\": the viewer serves "
                         "the .html, .js, .css, .png, .svg and .json files of its folder by "
                         "name, without paths or hidden files", name);
  if (strcmp(name, THREE_JS_NAME) == 0)
    return send_file(resp, req->conf->three_js, type,
                     "; the viewer needs three.js: install Debian's package libjs-three "
                     "(apt-get install libjs-three), or set [http] three_js to a copy of "
                     "three.min.js (r111 or a later global build)");
  return send_viewer_file(req, resp, name);
}
