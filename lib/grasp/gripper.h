/* Parallel-jaw gripper models as boxes, for collision checks and default widths.
 *
 * Gripper frame (SPEC.md): origin at the tool centre point (TCP) between the fingertips, +z the
 * approach direction (from the palm towards the object), +y the axis along which the fingers
 * close, +x = y cross z. A model is three boxes, axis-aligned in that frame: the palm (the
 * housing and the finger mechanism, behind the fingers) and two fingers standing at +-y,
 * their inner faces width / 2 from the TCP. The sizes are the overall envelopes of the
 * manufacturers' drawings (proto/grippers.md gives every number and its source), rounded
 * outwards: a pose whose boxes are free is free for the real gripper, never the reverse. */
#ifndef FG_GRASP_GRIPPER_H
#define FG_GRASP_GRIPPER_H

typedef enum {
  FG_GRIPPER_PANDA = 0,
  FG_GRIPPER_ROBOTIQ_2F85 = 1,
  FG_GRIPPER_ROBOTIQ_2F140 = 2,
  FG_GRIPPER_N_MODELS
} fg_gripper_model;

#define FG_GRIPPER_N_BOXES 3 /* palm, finger at -y, finger at +y */

/* A box in the gripper frame, metres. */
typedef struct fg_gripper_box {
  double centre_m[3];
  double half_m[3]; /* half edge lengths along x, y, z */
} fg_gripper_box;

typedef struct fg_gripper_spec {
  const char *name;         /* "panda", "robotiq-2f85", "robotiq-2f140" */
  double stroke_m;          /* largest opening between the finger pads */
  double finger_width_m;    /* pad extent along x */
  double finger_thick_m;    /* finger extent along y, outwards from the pad */
  double finger_length_m;   /* finger extent along z, from the palm to the fingertip */
  double tip_beyond_tcp_m;  /* how far the fingertips reach past the TCP along +z */
  double palm_size_m[3];    /* palm extent along x, y, z; it ends where the fingers start */
} fg_gripper_spec;

/* The model's numbers; NULL for an id out of range. Static storage. */
const fg_gripper_spec *fg_gripper_spec_get(fg_gripper_model m);

/* Parses a model name as above. 0, or FG_EINVAL with a detail listing the names. */
int fg_gripper_model_parse(const char *name, fg_gripper_model *out);

/* The model's three boxes with the fingers open to width_m (metres, 0..stroke) into boxes.
 * 0, or FG_EINVAL (unknown model, width not finite or outside 0..stroke). */
int fg_gripper_boxes(fg_gripper_model m, double width_m, fg_gripper_box boxes[FG_GRIPPER_N_BOXES]);

#endif
