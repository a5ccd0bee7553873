#include "robot_util.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

const uint16_t r_example_int16[13] = {7, 1, 4523, 64329, 350, 2902, 64334, 0, 800, 40,
                                       1000, 1000, 100};
const uint16_t r_example_float32[23] = {0x0007, 0x0001, 0x3EE7, 0x93DE, 0xBDF7, 0x3190,
                                        0x3D0F, 0x5C29, 0x4039, 0xC1CB, 0xBF99, 0xE2DA,
                                        0x0000, 0x0000, 0x3DA3, 0xD70A, 0x0028, 0x3DCC,
                                        0xCCCD, 0x3DCC, 0xCCCD, 0x3DCC, 0xCCCD};

void r_config(int robot_port, const char *robot_extra, int gripper_port,
              const char *gripper_extra) {
  char text[2048];
  int n = snprintf(text, sizeof text, "[gripper]\nmodel = robotiq-2f85\n");
  if (robot_port)
    n += snprintf(text + n, sizeof text - n,
                  "[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\ntimeout_ms = 300\n"
                  "%s%s\n",
                  robot_port,
                  robot_extra && strstr(robot_extra, "limit_min")
                      ? ""
                      : "limit_min = -1.5 -1.5 -0.5\nlimit_max = 1.5 1.5 1.5\n",
                  robot_extra ? robot_extra : "");
  if (gripper_port)
    n += snprintf(text + n, sizeof text - n,
                  "[gripper.modbus]\ntransport = tcp\nhost = 127.0.0.1\nport = %d\n"
                  "timeout_ms = 300\n%s\n",
                  gripper_port, gripper_extra ? gripper_extra : "");
  ASSERT(n < (int)sizeof text);
  h_write_config(text);
}

h_resp *r_post(const char *path, const char *json, const char *idem_key) {
  char header[256];
  const char *headers[2] = {NULL, NULL};
  if (idem_key) {
    snprintf(header, sizeof header, "Idempotency-Key: %s", idem_key);
    headers[0] = header;
  }
  h_req req = {.method = "POST", .path = path, .body = json, .body_len = strlen(json),
               .headers = headers};
  return h_request(&req);
}

int r_wait_true(const char *path, const char *key, double timeout_s) {
  for (int i = 0; i < (int)(timeout_s * 50); i++) {
    h_resp *r = h_get(path);
    int yes = r->json && json_is_true(json_object_get(r->json, key));
    h_resp_free(r);
    if (yes) return 1;
    const struct timespec ts = {0, 20000000};
    nanosleep(&ts, NULL);
  }
  return 0;
}

int r_wait_status(const char *path, double timeout_s) {
  const double deadline = h_now_s() + timeout_s;
  for (;;) {
    h_resp *r = h_get(path);
    json_t *o = r->json;
    const char *state = json_string_value(json_object_get(o, "state"));
    const int yes = o && json_is_true(json_object_get(o, "connected")) &&
                    (state ? strcmp(state, "connected") != 0
                           : json_is_integer(json_object_get(o, "ack")));
    h_resp_free(r);
    if (yes) return 1;
    if (h_now_s() > deadline) return 0;
    h_sleep_ms(20);
  }
}

void r_expect_at(const char *file, int line, const h_resp *r, long status, const char *code) {
  if (r->status != status) {
    fprintf(stderr, "%s:%d: status %ld, expected %ld: %s\n", file, line, r->status, status,
            r->body);
    exit(1);
  }
  if (!code) return;
  json_t *c = json_object_get(json_object_get(r->json, "error"), "code");
  if (!json_is_string(c) || strcmp(json_string_value(c), code) != 0) {
    fprintf(stderr, "%s:%d: error code is not %s: %s\n", file, line, code, r->body);
    exit(1);
  }
}

json_t *r_command(const h_resp *r) {
  json_t *c = json_object_get(r->json, "command");
  return json_is_object(c) ? c : r->json;
}

int r_robot_words(const h_resp *r, uint16_t *w, int max) {
  json_t *words = json_object_get(
      json_object_get(json_object_get(r_command(r), "registers"), "robot"), "words");
  ASSERT(json_is_array(words));
  int n = (int)json_array_size(words);
  for (int i = 0; i < n && i < max; i++)
    w[i] = (uint16_t)json_integer_value(json_array_get(words, i));
  return n;
}

int r_wait_state(long long id, const char *want, double timeout_s) {
  char path[64];
  snprintf(path, sizeof path, "/v1/robot/commands/%lld", id);
  for (int i = 0; i < (int)(timeout_s * 100); i++) {
    h_resp *r = h_get(path);
    const char *state = json_string_value(json_object_get(r->json, "state"));
    const int there = r->status == 200 && state && strcmp(state, want) == 0;
    h_resp_free(r);
    if (there) return 1;
    h_sleep_ms(10);
  }
  return 0;
}
