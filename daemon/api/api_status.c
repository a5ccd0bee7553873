/* The one table from an error's code to its HTTP status (api.h: fg_api_status). */
#include "api.h"

#include "core/error.h"

#include <stdio.h>
#include <string.h>

typedef struct code_status {
  const char *code;
  int status;
} code_status;

/* Every code a service fails with (fg_fail_as), and the default of each FG_E* below. The
 * decoders' own 400s (malformed_json, invalid_query, ...) are answered where they are found. */
static const code_status table[] = {
  {"invalid_request", 400},      {"value_out_of_range", 400},  {"grid_too_large", 400},
  {"invalid_name", 400},         {"invalid_image", 400},       {"invalid_depth", 400},
  {"invalid_features", 400},     {"invalid_pose", 400},        {"invalid_camera", 400},
  {"invalid_query_points", 400}, {"demo_in_free_space", 400},  {"pose_outside_workspace", 400},
  {"invalid_transforms", 400},   {"not_enough_views", 400},    {"degenerate_motion", 400},   {"forbidden_path", 403},       {"not_found", 404},           {"scene_not_found", 404},
  {"task_not_found", 404},       {"demo_not_found", 404},      {"frame_not_found", 404},
  {"capture_not_found", 404},
  {"grasp_not_found", 404},      {"camera_not_found", 404},      {"job_not_found", 404},       {"path_not_found", 404},
  {"not_configured", 409},       {"not_trained", 409},         {"no_features", 409},
  {"feature_dim_mismatch", 409}, {"field_mismatch", 409},      {"task_empty", 409},
  {"task_unreadable", 409},
  {"no_matching_task", 409},     {"query_points_mismatch", 409}, {"kind_mismatch", 409},
  {"too_many_demos", 409},     {"grasp_stale", 409},         {"scene_exists", 409},
  {"declared_in_config", 409},
  {"training_in_progress", 409}, {"job_in_progress", 409},     {"no_frames", 409},           {"job_finished", 409},           {"robot_busy", 409},
  {"robot_stopped", 409},        {"robot_moved", 409},         {"not_calibrated", 409},
  {"too_many_views", 409},       {"calibration_rejected", 422},  {"board_not_found", 422},        {"gripper_holding", 409},     {"gripper_not_activated", 409},
  {"unsupported_media_type", 415}, {"motion_limit", 422},         {"internal_error", 500},      {"robot_unknown", 502},
  {"robot_failed", 502},         {"modbus_exception", 502},    {"gripper_fault", 502},
  {"gripper_error", 502},        {"camera_unavailable", 502},  {"tcp_pose_invalid", 502},        {"memory_limit", 503},        {"robot_disconnected", 503},
  {"gripper_disconnected", 503}, {"shutting_down", 503},       {"busy", 503},
  {"state_unavailable", 503},    {"robot_timeout", 504},       {"ack_timeout", 504},
  {"gripper_timeout", 504},      {"camera_timeout", 504},      {"insufficient_storage", 507}, {"scene_limit", 507},
};

/* The code of a failure that named none. */
static const char *default_code(int rc) {
  switch (rc) {
  case FG_EINVAL: return "invalid_request";
  case FG_ERANGE: return "value_out_of_range";
  case FG_ENOENT: return "not_found";
  case FG_ENOSPC: return "insufficient_storage";
  case FG_ELIMIT: return "motion_limit";
  case FG_ESTOPPED: return "robot_stopped";
  default: return "internal_error";
  }
}

int fg_api_status(const char *code) {
  for (size_t i = 0; i < sizeof table / sizeof table[0]; i++)
    if (strcmp(table[i].code, code) == 0) return table[i].status;
  return 500;
}

const char *fg_api_fail_code(int rc) {
  const char *why = fg_error_reason();
  return why ? why : default_code(rc);
}

int fg_api_fail(fg_resp *resp, int rc) {
  const char *code = fg_api_fail_code(rc);
  if (strcmp(code, "memory_limit") == 0) /* the field is loadable again once one is let go */
    snprintf(resp->header, sizeof resp->header, "Retry-After: 1");
  return fg_resp_error(resp, fg_api_status(code), code, "%s", fg_error_detail());
}
