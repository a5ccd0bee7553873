/* Request parsing and the JSON views of poses and vectors: the translation between JSON and
 * library structs (the views of scenes and frames: api_views.h).
 * Parsers return 0 or FG_EINVAL with a detail naming the field, so a handler can pass the
 * sentence to the client unchanged. */
#ifndef FG_DAEMON_JSON_H
#define FG_DAEMON_JSON_H

#include <stddef.h>
#include <stdint.h>

#include <jansson.h>

#include "io/camera.h"
#include "io/frame.h"
#include "io/transforms.h"

/* Parses a request body. On failure returns NULL and writes "line L, column C: what" into
 * err. An empty body is an error too. */
json_t *fg_json_parse(const void *body, size_t len, char *err, size_t errlen);

/* Reads key of obj as a finite number. Returns 1 if present, 0 if absent, FG_EINVAL if
 * present but not a number. */
int fg_json_number(json_t *obj, const char *key, double *out);

/* Reads key of obj as a string; 1 present, 0 absent, FG_EINVAL if not a string. */
int fg_json_string(json_t *obj, const char *key, const char **out);

/* Reads an array of exactly n finite numbers; what names it in the error. */
int fg_json_vec(json_t *v, double *out, size_t n, const char *what);

/* Reads key of obj as an integer in [lo, hi]: 1 present, 0 absent (or null), -1 present but
 * not an integer in range. No error detail: the caller says what the number means. */
int fg_json_int_range(json_t *obj, const char *key, long long lo, long long hi, long long *out);

/* A scene's field settings (fg_scene_params): "field_scale" ("auto" or a number) and
 * "learn_background" ("auto" or a boolean) of obj, each left as it is when absent or null.
 * 0, or FG_EINVAL naming the key. Their views:
 * new references, NULL on allocation failure. */
int fg_json_read_field_settings(json_t *obj, double *field_scale, int *learn_background);
json_t *fg_json_field_scale(double field_scale);
json_t *fg_json_learn_background(int learn_background);

/* A 4x4 row-major nested array of numbers (not validated as rigid). */
int fg_json_matrix4(json_t *v, double T[16], const char *what);

/* ---- poses: the one JSON view of SPEC.md "Pose in JSON" ---- */

/* Parses a pose T_world_x in either form SPEC.md allows: {"position": [x, y, z] (metres),
 * "quaternion": [w, x, y, z]} or {"matrix": 4x4 rows} (the matrix wins when both are given),
 * or a bare 4x4 array. A quaternion must be finite and of unit length within
 * FG_POSE_ORTHO_TOL (1e-3; rounding within it is normalised away); a matrix must be rigid
 * (fg_pose_validate: orthonormal, right-handed, last row [0, 0, 0, 1]). On success T holds
 * the pose and q_wxyz (may be NULL) its unit quaternion: as given for the quaternion form
 * (its sign kept: a robot's rotation vector at a half turn depends on it), else the
 * matrix's with w >= 0. FG_EINVAL otherwise, with a detail that names `what` or its field
 * ("pose.quaternion must be an array of 4 numbers", "quaternion [w, x, y, z] must have unit
 * length, its norm is 2", "pose: rotation part is not orthonormal: ..."). */
int fg_json_pose_parse(json_t *v, const char *what, double T[16], double q_wxyz[4]);

/* The JSON view of a rigid pose T: {"position": [x, y, z], "quaternion": [w, x, y, z] (unit,
 * w >= 0), "matrix": 4x4 rows}. New reference; NULL on allocation failure. */
json_t *fg_json_pose(const double T[16]);

/* The same view of a pose given as position p (metres) and unit quaternion q_wxyz, whose
 * sign is kept in "quaternion" (a request's pose echoed as it came). */
json_t *fg_json_pose_quat(const double p[3], const double q_wxyz[4]);

/* Intrinsics of SPEC.md "Frames and units" from obj (a "camera" object, or a frame object
 * whose camera keys stand at the top level, as in a transforms.json frame; strict says
 * unknown keys are errors) into the camera fields of *f (cam, camera angles and the has_*
 * flags), ready for fg_transforms_complete_camera once the image's size is known. */
int fg_json_camera(json_t *obj, int strict, fg_transforms_frame *f);

json_t *fg_json_from_matrix4(const double T[16]);
json_t *fg_json_from_vec(const double *v, size_t n);

/* The first key of obj (in its order) that is not among keys (NULL-terminated), or NULL:
 * what a request's "unknown key" refusal names. */
const char *fg_json_unknown_key(json_t *obj, const char *const *keys);

/* "2026-11-22T00:00:00.123Z" for a Unix time in milliseconds. */
void fg_iso8601(int64_t ms, char out[32]);

/* The JSON view of a time: fg_iso8601's string, or null when ms <= 0 (not set). New
 * reference. */
json_t *fg_json_time_ms(int64_t ms);

#endif
