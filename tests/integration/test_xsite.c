/* No cross-site motion: what a web page in the operator's browser could send to a daemon
 * without a token on loopback, against fieldgrip-sim as robot and gripper. A cross-origin
 * text/plain POST (no CORS preflight), a foreign Origin with JSON, bodies of no or a form
 * type, and a DNS-rebinding Host are refused and nothing reaches the simulator; the daemon's
 * own origin, no Origin, [http] allowed_hosts and allowed_origins, multipart uploads, raw
 * images and an empty-body POST work; a robot on a network address without a token does
 * not start. argv[1]: fieldgripd, argv[2]: fieldgrip-sim. */
#include "robot_util.h"
#include "simproc.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAXW 64
static simproc_write g_w[MAXW];
static simproc g_sim;

#define PICK R_EXAMPLE_BODY "}"

/* Every write the simulator logged, robot and gripper. */
static int writes(void) { return simproc_writes(&g_sim, -1, g_w, MAXW); }

/* A request with a body of content_type (NULL: JSON) and up to two extra header lines. */
static h_resp *send(const char *method, const char *path, const char *content_type,
                    const char *body, const char *h1, const char *h2) {
  const char *headers[3] = {h1, h1 ? h2 : NULL, NULL};
  h_req q = {.method = method, .path = path, .body = body, .body_len = body ? strlen(body) : 0,
             .content_type = content_type, .headers = headers};
  return h_request(&q);
}

static void expect(h_resp *r, long status, const char *code, const char *in_message) {
  if (code) {
    ASSERT_HTTP_ERROR(r, status, code);
    if (in_message) ASSERT_STRCONTAINS(JSTR(r->json, "error.message"), in_message);
  } else {
    ASSERT_STATUS(r, status);
  }
  h_resp_free(r);
}

/* The status line of a raw request on its own connection, "HTTP/1.1 415" say. */
static void expect_raw(const char *req, const char *status_line) {
  char reply[8192];
  ASSERT(h_raw_exchange(req, strlen(req), reply, sizeof reply) > 0);
  if (strncmp(reply, status_line, strlen(status_line)) != 0)
    FG_TEST_FAIL("expected %s, got: %.300s", status_line, reply);
}

/* What a page of another site can send without a preflight, and what it cannot. */
static void check_refused(void) {
  const char *evil = "Origin: http://evil.example";
  /* the attack of the report: text/plain from another origin */
  expect(send("POST", "/v1/robot/commands", "text/plain", PICK, evil, NULL), 403,
         "origin_not_allowed", "allowed_origins");
  /* the same without Origin (a client that hides it): the type alone refuses it */
  expect(send("POST", "/v1/robot/commands", "text/plain", PICK, NULL, NULL), 415,
         "unsupported_media_type", "application/json");
  expect(send("POST", "/v1/robot/commands", "application/x-www-form-urlencoded", PICK, NULL,
              NULL), 415, "unsupported_media_type", "application/json");
  expect(send("POST", "/v1/gripper/close", "text/plain", "{}", NULL, NULL), 415,
         "unsupported_media_type", NULL);
  /* a body of no type (fetch() with a Blob) */
  char *raw = h_fmt("POST /v1/robot/commands HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n"
                    "Content-Length: %zu\r\nConnection: close\r\n\r\n%s", h_port(),
                    strlen(PICK), PICK);
  expect_raw(raw, "HTTP/1.1 415");
  free(raw);
  /* JSON from a foreign origin (after a preflight the daemon never grants) */
  expect(send("POST", "/v1/robot/commands", NULL, PICK, evil, NULL), 403, "origin_not_allowed",
         "http://evil.example");
  expect(send("POST", "/v1/gripper/open", NULL, NULL, evil, NULL), 403, "origin_not_allowed",
         NULL);
  expect(send("POST", "/v1/robot/commands", NULL, PICK, "Origin: null", NULL), 403,
         "origin_not_allowed", NULL);
  /* another port of this machine is another origin */
  char *port8000 = h_fmt("Origin: http://127.0.0.1:%d", h_port() == 8000 ? 8001 : 8000);
  expect(send("POST", "/v1/robot/commands", NULL, PICK, port8000, NULL), 403,
         "origin_not_allowed", NULL);
  free(port8000);
  /* DNS rebinding: the page's own name, pointed at 127.0.0.1; reads are refused too */
  char *rebound = h_fmt("Host: evil.example:%d", h_port());
  expect(send("GET", "/v1/robot", NULL, NULL, rebound, NULL), 403, "host_not_allowed",
         "allowed_hosts");
  char *rebound_origin = h_fmt("Origin: http://evil.example:%d", h_port());
  expect(send("POST", "/v1/robot/commands", NULL, PICK, rebound, rebound_origin), 403,
         "host_not_allowed", "DNS rebinding");
  free(rebound_origin);
  free(rebound);
  /* nothing reached the robot or the gripper */
  ASSERT_EQ(writes(), 0);
  h_resp *r = h_get("/v1/robot");
  ASSERT(json_is_null(JGET(r->json, "last_command")));
  h_resp_free(r);
}

/* The daemon's own page, a client without Origin, and what the lists admit. */
static void check_admitted(void) {
  char *own = h_fmt("Origin: http://127.0.0.1:%d", h_port());
  h_resp *r = send("POST", "/v1/robot/commands", NULL, PICK, own, NULL);
  r_expect(r, 200, NULL);
  ASSERT_STREQ(JSTR(r->json, "state"), "done");
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&g_sim, 1, g_w, MAXW), 2); /* a pick: its block and its retreat */
  /* no Origin, JSON with parameters */
  r = send("POST", "/v1/robot/commands", "Application/JSON; charset=utf-8", PICK, NULL, NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&g_sim, 1, g_w, MAXW), 4);
  /* localhost by name, and its own origin */
  char *lh = h_fmt("Host: localhost:%d", h_port());
  char *lh_origin = h_fmt("Origin: http://localhost:%d", h_port());
  expect(send("GET", "/v1/robot", NULL, NULL, lh, NULL), 200, NULL, NULL);
  expect(send("POST", "/v1/gripper/open", NULL, "{}", lh, lh_origin), 200, NULL, NULL);
  free(lh);
  free(lh_origin);
  /* an empty POST as `curl -X POST` sends it: no body, no type */
  char *raw = h_fmt("POST /v1/gripper/close HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n"
                    "Connection: close\r\n\r\n", h_port());
  expect_raw(raw, "HTTP/1.1 200");
  free(raw);
  free(own);

  /* the lists, through a reload */
  char *conf = h_fmt("[http]\nallowed_hosts = robot.lab\n"
                     "allowed_origins = http://panel.lab:8080, https://other.lab\n"
                     "[gripper]\nmodel = robotiq-2f85\n"
                     "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 300\n"
                     "limit_min = -1.5 -1.5 -0.5\nlimit_max = 1.5 1.5 1.5\n"
                     "[gripper.modbus]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\n"
                     "timeout_ms = 300\n", g_sim.port, g_sim.port);
  h_write_config(conf);
  free(conf);
  h_reload();
  ASSERT_EQ(h_log_count("reload failed"), 0);
  int before = simproc_writes(&g_sim, 1, g_w, MAXW);
  char *named = h_fmt("Host: robot.lab:%d", h_port());
  char *named_origin = h_fmt("Origin: http://robot.lab:%d", h_port());
  expect(send("GET", "/v1/robot", NULL, NULL, named, NULL), 200, NULL, NULL);
  r = send("POST", "/v1/robot/commands", NULL, PICK, named, named_origin);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  r = send("POST", "/v1/robot/commands", NULL, PICK, "Origin: http://panel.lab:8080", NULL);
  r_expect(r, 200, NULL);
  h_resp_free(r);
  ASSERT_EQ(simproc_writes(&g_sim, 1, g_w, MAXW), before + 4);
  /* only what is listed */
  expect(send("POST", "/v1/robot/commands", NULL, PICK, "Origin: http://panel.lab:8081", NULL),
         403, "origin_not_allowed", NULL);
  char *sub = h_fmt("Host: x.robot.lab:%d", h_port());
  expect(send("GET", "/v1/robot", NULL, NULL, sub, NULL), 403, "host_not_allowed", NULL);
  free(sub);
  free(named);
  free(named_origin);
  ASSERT_EQ(simproc_writes(&g_sim, 1, g_w, MAXW), before + 4);
}

/* Uploads stay multipart, the image embedding a raw image; a cross-site upload is refused. */
static void check_uploads(void) {
  expect(send("POST", "/v1/scenes", NULL, "{\"name\": \"x\"}", NULL, NULL), 201, NULL, NULL);
  uint8_t *png;
  size_t png_len;
  h_png(8, 6, 3, 8, 1, 0, &png, &png_len);
  double T[16];
  h_pose(T, 0, 0, 0, 0.4, 0, 0.9);
  char *meta = h_meta(T, "opengl", 10, 4, 3, 8, 6);
  h_resp *r = h_upload("/v1/scenes/x/frames", png, png_len, meta, NULL, 0);
  ASSERT_STATUS(r, 201);
  h_resp_free(r);
  h_part parts[2] = {{"image", png, png_len, "a.png", "image/png"},
                     {"meta", meta, strlen(meta), NULL, NULL}};
  const char *evil[] = {"Origin: http://evil.example", NULL};
  h_req q = {.method = "POST", .path = "/v1/scenes/x/frames", .parts = parts, .n_parts = 2,
             .headers = evil};
  expect(h_request(&q), 403, "origin_not_allowed", NULL);
  r = h_get("/v1/scenes/x/frames");
  ASSERT_EQ(json_array_size(JGET(r->json, "frames")), 1);
  h_resp_free(r);
  /* POST /v1/embed/image: an image type passes the guard (and meets the missing [clip]) */
  h_req img = {.method = "POST", .path = "/v1/embed/image", .body = png, .body_len = png_len,
               .content_type = "image/png"};
  expect(h_request(&img), 409, "clip_not_configured", NULL);
  img.content_type = "application/octet-stream";
  expect(h_request(&img), 409, "clip_not_configured", NULL);
  img.content_type = "text/plain";
  expect(h_request(&img), 415, "unsupported_media_type", "image/png");
  free(meta);
  free(png);
}

/* With a robot, a listen address other machines reach and no token: no start (a loopback
 * one started in main). The addresses are documentation ones that no machine has, so a
 * daemon that did not refuse would fail to bind instead, with another message: nothing
 * listens beyond loopback either way. A token lets it start: tests/unit/test_conf.c. */
static void check_startup(void) {
  const char *listens[] = {"192.0.2.1:0", "[2001:db8::1]:0"};
  for (int i = 0; i < 2; i++) {
    char *state = h_fmt("%s/state-refused", h_tmpdir());
    const char *args[] = {"--config", h_config_path(), "--state-dir", state, "--listen",
                          listens[i], NULL};
    char *out = NULL;
    int rc = h_run_daemon_capture(args, &out);
    if (rc != 2) FG_TEST_FAIL("--listen %s: exit %d, expected 2; output: %s", listens[i], rc, out);
    ASSERT_STRCONTAINS(out, "[robot] transport");
    ASSERT_STRCONTAINS(out, "[http] token_file");
    ASSERT(strstr(out, "cannot listen") == NULL && strstr(out, "listening on") == NULL);
    free(out);
    free(state);
  }
}

int main(int argc, char **argv) {
  h_init(argc, argv);
  ASSERT(argc >= 3);
  simproc_init(argv[2], h_tmpdir());
  simproc_start(&g_sim, 0, NULL);
  r_config(g_sim.port, NULL, g_sim.port, NULL); /* no [http] token: loopback is fine */
  h_start();
  ASSERT(r_wait_status("/v1/robot", 10));
  ASSERT(r_wait_status("/v1/gripper", 10));
  check_refused();
  check_admitted();
  check_uploads();
  h_stop();
  r_config(g_sim.port, NULL, 0, NULL);
  check_startup();
  simproc_stop(&g_sim);
  h_done();
  return 0;
}
