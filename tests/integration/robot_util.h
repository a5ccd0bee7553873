/* Shared by the robot tests: configurations pointing the daemon at peers, requests with
 * headers, and JSON checks of command replies. */
#ifndef FG_IT_ROBOT_UTIL_H
#define FG_IT_ROBOT_UTIL_H

#include "harness.h"

/* Writes a configuration with [robot] on robot_port and [gripper.modbus] on gripper_port
 * (0 leaves the section out), model robotiq-2f85, a position box of [-1.5, 1.5] m in x and
 * y and [-0.5, 1.5] m in z unless robot_extra sets limit_min and limit_max, plus extra lines appended to [robot]
 * (robot_extra) and [gripper.modbus] (gripper_extra), either may be NULL. */
void r_config(int robot_port, const char *robot_extra, int gripper_port,
              const char *gripper_extra);

/* POST of a JSON body with an optional Idempotency-Key (NULL: none). */
h_resp *r_post(const char *path, const char *json, const char *idem_key);

/* Waits up to timeout_s for GET path's JSON key to be true (a boolean). 1 when it was. */
int r_wait_true(const char *path, const char *key, double timeout_s);

/* Waits up to timeout_s for GET path (/v1/robot or /v1/gripper) to report its peer
 * connected and its registers read: the robot's "ack" is a number, the gripper's "state"
 * is past "connected" (connected, no status read yet on this connection). "connected"
 * alone says nothing about the registers. 1 when it did. */
int r_wait_status(const char *path, double timeout_s);

/* Polls GET /v1/robot/commands/{id} up to timeout_s until its state is want. 1 when it
 * got there. */
int r_wait_state(long long id, const char *want, double timeout_s);

/* Asserts r's status, and for an error its code. */
void r_expect_at(const char *file, int line, const h_resp *r, long status, const char *code);
#define r_expect(r, status, code) r_expect_at(__FILE__, __LINE__, (r), (status), (code))

/* The command object of a reply: the body, or its "command" beside an error. */
json_t *r_command(const h_resp *r);

/* The robot words of a command reply into w; returns their count. */
int r_robot_words(const h_resp *r, uint16_t *w, int max);

/* The worked example of proto/modbus.md: a pick with seq 7 (without a gripper of fieldgrip's
 * own, so the block carries the 0.10 m retreat; approach 0.10 m, speed 0.10 m/s by default),
 * and its words. */
#define R_EXAMPLE_BODY                                                                         \
  "{\"command\": \"pick\", \"pose\": {\"position\": [0.4523, -0.1207, 0.0350], "             \
  "\"quaternion\": [0, 0.9238795, -0.3826834, 0]}, \"width\": 0.08, \"force\": 40"
extern const uint16_t r_example_int16[13];
extern const uint16_t r_example_float32[23];

#endif
