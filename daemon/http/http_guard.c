/* Cross-site guards: see http_guard.h. */
#include "http_guard.h"

#include "conf/conf.h"
#include "http.h"

#include "core/error.h"

#include <arpa/inet.h>
#include <ctype.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

/* Whether s[0 .. n) equals one of the n_list entries, ignoring case. */
static int listed(char *const *list, size_t n_list, const char *s, size_t n) {
  for (size_t i = 0; i < n_list; i++)
    if (strlen(list[i]) == n && strncasecmp(list[i], s, n) == 0) return 1;
  return 0;
}

/* Whether s is ":DIGITS" or empty: the port part after a Host's name. */
static int port_or_end(const char *s) {
  if (!*s) return 1;
  if (*s++ != ':' || !*s) return 0;
  for (; *s; s++)
    if (!isdigit((unsigned char)*s)) return 0;
  return 1;
}

int fg_guard_host(const fg_conf *conf, const char *host) {
  if (!host || !*host) return 0;
  char name[256];
  const char *end;
  if (host[0] == '[') { /* [IPv6]:port: always a literal, never a name */
    end = strchr(host, ']');
    size_t n = end ? (size_t)(end - host - 1) : 0;
    unsigned char a[16];
    if (end && n < sizeof name && port_or_end(end + 1)) {
      memcpy(name, host + 1, n);
      name[n] = 0;
      if (inet_pton(AF_INET6, name, a) == 1) return 0;
    }
    return fg_fail(FG_EPERM, "the Host header '%.80s' is not an [IPv6]:PORT address; send the "
                   "address the daemon was reached at", host);
  }
  end = strchr(host, ':');
  size_t n = end ? (size_t)(end - host) : strlen(host);
  if (n >= sizeof name || !port_or_end(host + n))
    return fg_fail(FG_EPERM, "the Host header '%.80s' is not HOST or HOST:PORT", host);
  memcpy(name, host, n);
  name[n] = 0;
  unsigned char a[4];
  if (inet_pton(AF_INET, name, a) == 1 || strcasecmp(name, "localhost") == 0 ||
      listed(conf->allowed_hosts, conf->n_allowed_hosts, name, n))
    return 0;
  return fg_fail(FG_EPERM, "this daemon does not answer to the name '%.80s' (Host header): "
                 "refused so that a web page cannot reach it by a DNS name pointed at this "
                 "machine (DNS rebinding); use its IP address or localhost, or list the name in "
                 "[http] allowed_hosts", name);
}

static int changes_state(const char *method) {
  return strcmp(method, "POST") == 0 || strcmp(method, "PUT") == 0 ||
         strcmp(method, "PATCH") == 0 || strcmp(method, "DELETE") == 0;
}

/* Whether origin is scheme "://" host for the schemes a page of the daemon's own may have
 * (https behind a TLS proxy that passes Host on). */
static int same_origin(const char *origin, const char *host) {
  if (!host || !*host) return 0;
  const char *rest = NULL;
  if (strncasecmp(origin, "http://", 7) == 0) rest = origin + 7;
  else if (strncasecmp(origin, "https://", 8) == 0) rest = origin + 8;
  return rest && strcasecmp(rest, host) == 0;
}

int fg_guard_origin(const fg_conf *conf, const char *method, const char *host,
                    const char *origin) {
  if (!origin || !changes_state(method) || same_origin(origin, host) ||
      listed(conf->allowed_origins, conf->n_allowed_origins, origin, strlen(origin)))
    return 0;
  return fg_fail(FG_EPERM, "%s from the web page of origin '%.100s' refused: pages of other "
                 "sites may not change anything here (cross-site request); a page that should "
                 "control this daemon must have its origin listed in [http] allowed_origins",
                 method, origin);
}

/* Whether content_type's media type (before any ';' and blanks) is type, ignoring case; a
 * type ending in '/' matches every subtype. */
static int media_type_is(const char *content_type, const char *type) {
  size_t n = strcspn(content_type, "; \t");
  size_t tn = strlen(type);
  if (type[tn - 1] == '/') return n > tn && strncasecmp(content_type, type, tn) == 0;
  return n == tn && strncasecmp(content_type, type, n) == 0;
}

int fg_guard_body_type(int route_flags, const char *method, int has_body,
                       const char *content_type) {
  const char *ct = content_type ? content_type : "";
  while (*ct == ' ' || *ct == '\t') ct++;
  char given[96];
  snprintf(given, sizeof given, *ct ? "Content-Type '%.60s'" : "no Content-Type", ct);
  if (route_flags & FG_ROUTE_MULTIPART) {
    if (media_type_is(ct, "multipart/form-data")) return 0;
    return fg_fail(FG_EFORMAT, "this endpoint takes multipart/form-data (curl -F "
                   "image=@photo.png -F meta='{...}'), got %s", given);
  }
  if (!has_body || !changes_state(method)) return 0;
  if (route_flags & FG_ROUTE_IMAGE_BODY) {
    if (media_type_is(ct, "image/") || media_type_is(ct, "application/octet-stream")) return 0;
    return fg_fail(FG_EFORMAT, "this endpoint takes the image file itself with Content-Type "
                   "image/png, image/jpeg (any image/...) or application/octet-stream "
                   "(curl --data-binary @photo.png -H 'Content-Type: image/png'), got %s",
                   given);
  }
  if (media_type_is(ct, "application/json")) return 0;
  return fg_fail(FG_EFORMAT, "this endpoint takes a JSON body with Content-Type "
                 "application/json (curl -H 'Content-Type: application/json' -d '{...}', or "
                 "curl --json '{...}'), got %s", given);
}
