/* The cross-site guards (daemon/http/http_guard.h) case by case: Host names and literals, Origin
 * against Host and [http] allowed_origins, and each route kind's Content-Type. The daemon's
 * use of them is tests/integration/test_xsite.c. */
#include "conf/conf.h"
#include "http/http.h"
#include "http/http_guard.h"

#include "core/error.h"
#include "test.h"

#include <stdio.h>
#include <stdlib.h>

static void test_host(const fg_conf *c) {
  /* absent or empty: no browser sends that */
  ASSERT_OK(fg_guard_host(c, NULL));
  ASSERT_OK(fg_guard_host(c, ""));
  /* IP literals, any address and any port; localhost in any case */
  ASSERT_OK(fg_guard_host(c, "127.0.0.1:7070"));
  ASSERT_OK(fg_guard_host(c, "192.168.1.5"));
  ASSERT_OK(fg_guard_host(c, "[::1]:7070"));
  ASSERT_OK(fg_guard_host(c, "[fe80::1]"));
  ASSERT_OK(fg_guard_host(c, "localhost:7070"));
  ASSERT_OK(fg_guard_host(c, "LOCALHOST"));
  /* listed names, any case */
  ASSERT_OK(fg_guard_host(c, "robot.lab:7070"));
  ASSERT_OK(fg_guard_host(c, "Robot.LAB"));
  /* names: a rebinding attack's */
  ASSERT_ERR(fg_guard_host(c, "evil.example:7070"), FG_EPERM, "'evil.example'");
  ASSERT_STRCONTAINS(fg_error_detail(), "[http] allowed_hosts");
  ASSERT_ERR(fg_guard_host(c, "127.0.0.1.nip.io:7070"), FG_EPERM, "DNS rebinding");
  ASSERT_ERR(fg_guard_host(c, "robot.lab.evil.example"), FG_EPERM, "allowed_hosts");
  ASSERT_ERR(fg_guard_host(c, "localhost.evil.example"), FG_EPERM, "allowed_hosts");
  ASSERT_ERR(fg_guard_host(c, "robot"), FG_EPERM, "allowed_hosts");
  /* malformed */
  ASSERT_ERR(fg_guard_host(c, "127.0.0.1:70x"), FG_EPERM, "HOST:PORT");
  ASSERT_ERR(fg_guard_host(c, "127.0.0.1:"), FG_EPERM, "HOST:PORT");
  ASSERT_ERR(fg_guard_host(c, "[::1"), FG_EPERM, "[IPv6]:PORT");
  ASSERT_ERR(fg_guard_host(c, "[evil.example]:7070"), FG_EPERM, "[IPv6]:PORT");
}

static void test_origin(const fg_conf *c) {
  const char *host = "127.0.0.1:7070";
  /* no Origin, or a method that changes nothing */
  ASSERT_OK(fg_guard_origin(c, "POST", host, NULL));
  ASSERT_OK(fg_guard_origin(c, "GET", host, "http://evil.example"));
  ASSERT_OK(fg_guard_origin(c, "HEAD", host, "http://evil.example"));
  /* the daemon's own page, also behind a TLS proxy that passes Host on */
  ASSERT_OK(fg_guard_origin(c, "POST", host, "http://127.0.0.1:7070"));
  ASSERT_OK(fg_guard_origin(c, "DELETE", host, "HTTP://127.0.0.1:7070"));
  ASSERT_OK(fg_guard_origin(c, "POST", "robot.lab", "https://robot.lab"));
  /* listed */
  ASSERT_OK(fg_guard_origin(c, "PUT", host, "http://panel.lab:8080"));
  ASSERT_OK(fg_guard_origin(c, "PUT", host, "http://PANEL.lab:8080"));
  /* everything else, for each method that changes something */
  const char *methods[] = {"POST", "PUT", "PATCH", "DELETE"};
  for (int i = 0; i < 4; i++)
    ASSERT_ERR(fg_guard_origin(c, methods[i], host, "http://evil.example"), FG_EPERM,
               "'http://evil.example'");
  ASSERT_STRCONTAINS(fg_error_detail(), "[http] allowed_origins");
  ASSERT_ERR(fg_guard_origin(c, "POST", host, "http://127.0.0.1:8000"), FG_EPERM, "origin");
  ASSERT_ERR(fg_guard_origin(c, "POST", host, "http://panel.lab"), FG_EPERM, "origin");
  ASSERT_ERR(fg_guard_origin(c, "POST", host, "null"), FG_EPERM, "'null'");
  ASSERT_ERR(fg_guard_origin(c, "POST", host, "http://127.0.0.1:7070.evil.example"), FG_EPERM,
             "origin");
  ASSERT_ERR(fg_guard_origin(c, "POST", NULL, "http://127.0.0.1:7070"), FG_EPERM, "origin");
}

static void test_body_type(void) {
  /* JSON routes */
  ASSERT_OK(fg_guard_body_type(0, "POST", 1, "application/json"));
  ASSERT_OK(fg_guard_body_type(0, "POST", 1, "Application/JSON; charset=utf-8"));
  ASSERT_OK(fg_guard_body_type(0, "PATCH", 1, "application/json;charset=UTF-8"));
  ASSERT_OK(fg_guard_body_type(0, "POST", 0, NULL));       /* curl -X POST, no body */
  ASSERT_OK(fg_guard_body_type(0, "POST", 0, "text/plain")); /* nothing to read */
  ASSERT_OK(fg_guard_body_type(0, "GET", 1, "text/plain"));
  ASSERT_ERR(fg_guard_body_type(0, "POST", 1, "text/plain"), FG_EFORMAT, "application/json");
  ASSERT_STRCONTAINS(fg_error_detail(), "got Content-Type 'text/plain'");
  ASSERT_ERR(fg_guard_body_type(0, "POST", 1, NULL), FG_EFORMAT, "got no Content-Type");
  ASSERT_ERR(fg_guard_body_type(0, "DELETE", 1, "application/x-www-form-urlencoded"),
             FG_EFORMAT, "application/json");
  ASSERT_ERR(fg_guard_body_type(0, "POST", 1, "application/jsonp"), FG_EFORMAT, "JSON");
  ASSERT_ERR(fg_guard_body_type(0, "POST", 1, "multipart/form-data; boundary=x"), FG_EFORMAT,
             "JSON");
  /* multipart routes: always, body or not */
  ASSERT_OK(fg_guard_body_type(FG_ROUTE_MULTIPART, "POST", 1, "multipart/form-data; boundary=x"));
  ASSERT_OK(fg_guard_body_type(FG_ROUTE_MULTIPART, "POST", 1, "Multipart/Form-Data;boundary=x"));
  ASSERT_ERR(fg_guard_body_type(FG_ROUTE_MULTIPART, "POST", 0, NULL), FG_EFORMAT,
             "multipart/form-data");
  ASSERT_ERR(fg_guard_body_type(FG_ROUTE_MULTIPART, "POST", 1, "application/json"), FG_EFORMAT,
             "multipart/form-data");
  /* a raw image */
  const int img = FG_ROUTE_IMAGE_BODY | FG_ROUTE_LARGE_BODY;
  ASSERT_OK(fg_guard_body_type(img, "POST", 1, "image/png"));
  ASSERT_OK(fg_guard_body_type(img, "POST", 1, "IMAGE/JPEG"));
  ASSERT_OK(fg_guard_body_type(img, "POST", 1, "application/octet-stream"));
  ASSERT_ERR(fg_guard_body_type(img, "POST", 1, "text/plain"), FG_EFORMAT, "image/png");
  ASSERT_ERR(fg_guard_body_type(img, "POST", 1, "image/"), FG_EFORMAT, "octet-stream");
  ASSERT_ERR(fg_guard_body_type(img, "POST", 1, NULL), FG_EFORMAT, "image/png");
}

int main(void) {
  fg_conf *c = fg_conf_defaults();
  ASSERT(c != NULL);
  ASSERT_OK(fg_conf_split_list("robot.lab", fg_conf_check_host_name, &c->allowed_hosts,
                               &c->n_allowed_hosts));
  ASSERT_OK(fg_conf_split_list("http://panel.lab:8080", fg_conf_check_origin,
                               &c->allowed_origins, &c->n_allowed_origins));
  test_host(c);
  test_origin(c);
  test_body_type();
  fg_conf_free(c);
  printf("http_guard: ok\n");
  return 0;
}
