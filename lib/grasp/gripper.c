/* Gripper models as boxes (gripper.h); the numbers and their sources are in
 * proto/grippers.md. */
#include "grasp/gripper.h"

#include <math.h>
#include <string.h>

#include "core/error.h"

static const fg_gripper_spec specs[FG_GRIPPER_N_MODELS] = {
  /* Franka Hand: 80 mm stroke (2 x 40), flange to TCP 103.4 mm of which the fingers take the
   * last 45 mm (finger joints at 58.4 mm), fingers 20 mm wide, housing 204 x 63 mm. */
  [FG_GRIPPER_PANDA] = {"panda", 0.080, 0.022, 0.020, 0.045, 0.006, {0.065, 0.206, 0.0584}},
  /* Robotiq 2F-85: 85 mm stroke, 22 mm pads, coupling to fingertip 163 mm (open), housing
   * 75 mm thick and the linkage 150 mm across when open. */
  [FG_GRIPPER_ROBOTIQ_2F85] = {"robotiq-2f85", 0.085, 0.024, 0.030, 0.055, 0.006,
                               {0.075, 0.150, 0.108}},
  /* Robotiq 2F-140: 140 mm stroke, 27 mm pads, coupling to fingertip 232 mm (open), housing
   * 75 mm thick and the linkage 230 mm across when open. */
  [FG_GRIPPER_ROBOTIQ_2F140] = {"robotiq-2f140", 0.140, 0.029, 0.030, 0.100, 0.006,
                                {0.075, 0.230, 0.132}},
};

const fg_gripper_spec *fg_gripper_spec_get(fg_gripper_model m) {
  return (unsigned)m < FG_GRIPPER_N_MODELS ? &specs[m] : NULL;
}

int fg_gripper_model_parse(const char *name, fg_gripper_model *out) {
  for (int m = 0; m < FG_GRIPPER_N_MODELS; m++)
    if (name && strcmp(name, specs[m].name) == 0) {
      *out = (fg_gripper_model)m;
      return 0;
    }
  return fg_fail(FG_EINVAL, "unknown gripper model '%s'; use panda, robotiq-2f85 or "
                 "robotiq-2f140", name ? name : "(null)");
}

int fg_gripper_boxes(fg_gripper_model m, double width_m, fg_gripper_box boxes[FG_GRIPPER_N_BOXES]) {
  const fg_gripper_spec *s = fg_gripper_spec_get(m);
  if (!s) return fg_fail(FG_EINVAL, "unknown gripper model %d", (int)m);
  if (!isfinite(width_m) || width_m < 0 || width_m > s->stroke_m + 1e-9)
    return fg_fail(FG_EINVAL, "width %g m is outside the %s's stroke 0..%g m", width_m,
                   s->name, s->stroke_m);
  const double z_lo = -s->finger_length_m, z_hi = s->tip_beyond_tcp_m;
  /* palm: behind the fingers */
  boxes[0] = (fg_gripper_box){{0, 0, z_lo - s->palm_size_m[2] / 2},
                              {s->palm_size_m[0] / 2, s->palm_size_m[1] / 2,
                               s->palm_size_m[2] / 2}};
  for (int k = 0; k < 2; k++) {
    const double sign = k == 0 ? -1.0 : 1.0;
    boxes[1 + k] = (fg_gripper_box){
        {0, sign * (width_m / 2 + s->finger_thick_m / 2), (z_lo + z_hi) / 2},
        {s->finger_width_m / 2, s->finger_thick_m / 2, (z_hi - z_lo) / 2}};
  }
  return 0;
}
