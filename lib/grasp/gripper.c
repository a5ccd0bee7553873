/* Gripper models as boxes (gripper.h); the numbers and their sources are in
 * proto/grippers.md. */
#include "grasp/gripper.h"

#include <math.h>
#include <string.h>

#include "core/error.h"

static const fg_gripper_spec specs[FG_GRIPPER_N_MODELS] = {
  /* Franka Hand (franka_ros's franka_description: TCP 103.4 mm from the flange, fingers on
   * 58.4 mm, finger mesh 21 x 26.3 x 53.9 mm, rubber tip 17.8 mm wide and 14.4 mm thick from
   * 36 mm up, hand mesh 63 x 208 mm from 26 mm behind the flange to 66 mm before it). */
  [FG_GRIPPER_PANDA] = {
    .name = "panda", .stroke_m = 0.080, .tip_beyond_tcp_m = 0.009,
    .pad_size_m = {0.018, 0.015, 0.018}, .holder_size_m = {0.021, 0.026, 0.016},
    .link_half_x_m = 0.011, .link_z_lo_m = -0.045, .link_thick_m = 0.027,
    .palm_size_m = {0.064, 0.210, 0.093}, .palm_top_m = -0.037},
  /* Robotiq 2F-85 (ROS-Industrial's robotiq_2f_85_gripper_visualization and MuJoCo
   * Menagerie's robotiq_2f85: pads 22 x 37.5 mm; the four-bar linkage 57.1 mm long at 41.2
   * degrees from the approach axis when open; housing 75 x 85 mm, 101 mm with the coupling). */
  [FG_GRIPPER_ROBOTIQ_2F85] = {
    .name = "robotiq-2f85", .stroke_m = 0.085, .tip_beyond_tcp_m = 0.006,
    .pad_size_m = {0.022, 0.018, 0.025}, .holder_size_m = {0.026, 0.025, 0.015},
    .link_half_x_m = 0.0175, .link_z_lo_m = -0.099, .link_thick_m = 0.032,
    .link_reach_m = 0.068, .link_inset = 0.0, /* its lean-in lies in the palm box */
    .palm_size_m = {0.075, 0.085, 0.101}, .palm_top_m = -0.053,
    .arc_radius_m = 0.05712, .arc_angle_rad = 0.7185},
  /* Robotiq 2F-140 (ROS-Industrial's robotiq_2f_140_gripper_visualization and Menagerie's
   * robotiq_2f140: pads 27 x 65 mm; the linkage 100 mm long at 40.3 degrees; the 2F-85's
   * housing). */
  [FG_GRIPPER_ROBOTIQ_2F140] = {
    .name = "robotiq-2f140", .stroke_m = 0.140, .tip_beyond_tcp_m = 0.006,
    .pad_size_m = {0.027, 0.018, 0.040}, .holder_size_m = {0.039, 0.036, 0.035},
    .link_half_x_m = 0.020, .link_z_lo_m = -0.159, .link_thick_m = 0.037,
    .link_reach_m = 0.073, .link_inset = 0.26,
    .palm_size_m = {0.075, 0.085, 0.102}, .palm_top_m = -0.113,
    .arc_radius_m = 0.1000, .arc_angle_rad = 0.7028},
};

static const char *const box_names[FG_GRIPPER_N_BOXES] = {
  "palm", "pad_minus_y", "pad_plus_y", "holder_minus_y", "holder_plus_y", "link_minus_y",
  "link_plus_y"};
static const char *const part_names[FG_GRIPPER_N_PARTS] = {"palm", "finger_minus_y",
                                                           "finger_plus_y"};

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

const char *fg_gripper_box_name(int i) {
  return i >= 0 && i < FG_GRIPPER_N_BOXES ? box_names[i] : NULL;
}

const char *fg_gripper_part_name(fg_gripper_part p) {
  return (unsigned)p < FG_GRIPPER_N_PARTS ? part_names[p] : NULL;
}

/* The pad's rise on the linkage's arc: each face has moved (stroke - width) / 2 inwards, so
 * the link turned from arc_angle to asin(sin(arc_angle) - that / radius). */
static double tip_rise(const fg_gripper_spec *s, double width_m) {
  if (s->arc_radius_m <= 0) return 0.0;
  const double sn = sin(s->arc_angle_rad) - (s->stroke_m - width_m) / (2.0 * s->arc_radius_m);
  return s->arc_radius_m * (sqrt(fmax(0.0, 1.0 - sn * sn)) - cos(s->arc_angle_rad));
}

double fg_gripper_tip_rise(fg_gripper_model m, double width_m) {
  const fg_gripper_spec *s = fg_gripper_spec_get(m);
  return s ? tip_rise(s, width_m) : NAN;
}

/* The box spanning lo..hi (metres, gripper frame). */
static fg_gripper_box box_span(const double lo[3], const double hi[3], fg_gripper_part part,
                               int pad) {
  fg_gripper_box b = {.part = part, .pad = pad};
  for (int a = 0; a < 3; a++) {
    b.centre_m[a] = (lo[a] + hi[a]) / 2;
    b.half_m[a] = (hi[a] - lo[a]) / 2;
  }
  return b;
}

int fg_gripper_boxes(fg_gripper_model m, double width_m, fg_gripper_box boxes[FG_GRIPPER_N_BOXES]) {
  const fg_gripper_spec *s = fg_gripper_spec_get(m);
  if (!s) return fg_fail(FG_EINVAL, "unknown gripper model %d", (int)m);
  if (!isfinite(width_m) || width_m < 0 || width_m > s->stroke_m + 1e-9)
    return fg_fail(FG_EINVAL, "width %g m is outside the %s's stroke 0..%g m", width_m,
                   s->name, s->stroke_m);
  const double *ps = s->palm_size_m;
  const double palm_lo[3] = {-ps[0] / 2, -ps[1] / 2, s->palm_top_m - ps[2]};
  const double palm_hi[3] = {ps[0] / 2, ps[1] / 2, s->palm_top_m};
  boxes[FG_GRIPPER_BOX_PALM] = box_span(palm_lo, palm_hi, FG_GRIPPER_PALM, 0);
  /* the finger at +y, then its mirror image at -y */
  const double face = width_m / 2, tip = s->tip_beyond_tcp_m + tip_rise(s, width_m);
  const double pad_lo = tip - s->pad_size_m[2], holder_lo = pad_lo - s->holder_size_m[2];
  const double link_out = fmax(face + s->link_thick_m, s->link_reach_m);
  const double lo[3][3] = {{-s->pad_size_m[0] / 2, face, pad_lo},
                           {-s->holder_size_m[0] / 2, face, holder_lo},
                           {-s->link_half_x_m, face - s->link_inset * width_m, s->link_z_lo_m}};
  const double hi[3][3] = {{s->pad_size_m[0] / 2, face + s->pad_size_m[1], tip},
                           {s->holder_size_m[0] / 2, face + s->holder_size_m[1], pad_lo},
                           {s->link_half_x_m, link_out, holder_lo}};
  for (int k = 0; k < 3; k++) {
    const int plus = FG_GRIPPER_BOX_PAD_PLUS_Y + 2 * k, minus = plus - 1;
    boxes[plus] = box_span(lo[k], hi[k], FG_GRIPPER_FINGER_PLUS_Y, k == 0);
    boxes[minus] = boxes[plus];
    boxes[minus].centre_m[1] = -boxes[plus].centre_m[1];
    boxes[minus].part = FG_GRIPPER_FINGER_MINUS_Y;
  }
  return 0;
}
