/* Fuzz target for the JSON request decoders the endpoints share: the body parser
 * (fg_json_parse, with its limits), and on what it yields the decoders of a frame upload's
 * `meta` part and of poses and cameras in other bodies: the pose in either SPEC.md form, the
 * camera keys strict or not, 4x4 matrices and number vectors. Every input either decodes or
 * fails with an error code; decoded poses are finite. */
#include "core/error.h"
#include "core/pose.h"
#include "state/json.h"

#include <jansson.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The decoders run on v as a pose, a matrix, a vector and a camera. */
static void decode_value(json_t *v, const char *what) {
  double T[16], q[4], vec[3];
  if (fg_json_pose_parse(v, what, T, q) == 0) {
    for (int i = 0; i < 16; i++)
      if (!isfinite(T[i])) abort();
  }
  (void)fg_json_matrix4(v, T, what);
  (void)fg_json_vec(v, vec, 3, what);
  if (json_is_object(v)) {
    for (int strict = 0; strict <= 1; strict++) {
      fg_transforms_frame f;
      memset(&f, 0, sizeof f);
      f.file_path = "upload";
      if (fg_json_camera(v, strict, &f) == 0) (void)fg_transforms_complete_camera(&f, 64, 48);
    }
  }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  char err[256];
  json_t *body = fg_json_parse(data, size, err, sizeof err);
  if (!body) return 0;
  decode_value(body, "body");
  if (json_is_object(body)) {
    /* the fields the upload's meta and the pose-carrying bodies read */
    static const char *const keys[] = {"transform_matrix", "pose", "camera", "position",
                                       "quaternion", "matrix", "T_world_tcp", "target"};
    for (size_t k = 0; k < sizeof keys / sizeof keys[0]; k++) {
      json_t *v = json_object_get(body, keys[k]);
      if (v) decode_value(v, keys[k]);
    }
    const char *s;
    double d;
    (void)fg_json_string(body, "convention", &s);
    (void)fg_json_number(body, "depth_scale", &d);
  }
  json_decref(body);
  return 0;
}
