/* Parallel-jaw gripper models as boxes, for collision checks, default widths and a simulator's
 * bodies.
 *
 * Gripper frame (SPEC.md): origin at the tool centre point (TCP) between the fingertips, +z the
 * approach direction (from the palm towards the object), +y the axis along which the fingers
 * close, +x = y cross z. The TCP is fixed to the palm: it lies tip_beyond_tcp_m short of the
 * pads' tips with the fingers fully open.
 *
 * A model is FG_GRIPPER_N_BOXES boxes, axis-aligned in that frame, each tagged with the part
 * it belongs to: the palm (housing), and per finger, from the tip back towards the palm,
 *   pad     the fingertip pad, the surface that touches the object, with the finger right
 *           behind it: its real width along x, thickness along y (outwards from its face,
 *           which stands width / 2 from the TCP) and height along z, nearest the object;
 *   holder  the part of the finger that carries the pad, flush with the pad's face but
 *           thicker;
 *   link    the rest of the finger down to the palm: the Franka Hand's finger base, the
 *           Robotiq's four-bar linkage, whose spring link leans inwards of the pads' faces
 *           and whose driver swings outwards beyond them.
 * The finger boxes move with the width, the palm does not. A Franka finger slides along y;
 * a Robotiq finger is carried by a parallel linkage, so its pad also moves along +z as it
 * closes (by up to 14 mm on the 2F-85, 24 mm on the 2F-140), on an arc of the linkage's
 * radius. The sizes come from the manufacturers' CAD descriptions (proto/grippers.md gives
 * every number and its source), rounded outwards: a pose whose boxes are free is free for the
 * real gripper at that opening, never the reverse. */
#ifndef FG_GRASP_GRIPPER_H
#define FG_GRASP_GRIPPER_H

typedef enum {
  FG_GRIPPER_PANDA = 0,
  FG_GRIPPER_ROBOTIQ_2F85 = 1,
  FG_GRIPPER_ROBOTIQ_2F140 = 2,
  FG_GRIPPER_N_MODELS
} fg_gripper_model;

/* The part a box belongs to: a simulator builds one body per part. */
typedef enum {
  FG_GRIPPER_PALM = 0,
  FG_GRIPPER_FINGER_MINUS_Y = 1, /* the finger standing at -y (it closes along +y) */
  FG_GRIPPER_FINGER_PLUS_Y = 2,  /* the finger standing at +y */
  FG_GRIPPER_N_PARTS
} fg_gripper_part;

/* The boxes of fg_gripper_boxes, in this order for every model. */
enum {
  FG_GRIPPER_BOX_PALM = 0,
  FG_GRIPPER_BOX_PAD_MINUS_Y = 1,
  FG_GRIPPER_BOX_PAD_PLUS_Y = 2,
  FG_GRIPPER_BOX_HOLDER_MINUS_Y = 3,
  FG_GRIPPER_BOX_HOLDER_PLUS_Y = 4,
  FG_GRIPPER_BOX_LINK_MINUS_Y = 5,
  FG_GRIPPER_BOX_LINK_PLUS_Y = 6,
  FG_GRIPPER_N_BOXES = 7
};

/* A box in the gripper frame, metres. */
typedef struct fg_gripper_box {
  double centre_m[3];
  double half_m[3];     /* half edge lengths along x, y, z */
  fg_gripper_part part;
  int pad;              /* 1: a fingertip pad, the surface that touches the object */
} fg_gripper_box;

/* A model's numbers, metres, in the gripper frame. The finger numbers describe the finger
 * at +y; the one at -y is its mirror image. */
typedef struct fg_gripper_spec {
  const char *name;          /* "panda", "robotiq-2f85", "robotiq-2f140" */
  double stroke_m;           /* largest opening between the pads' faces */
  double tip_beyond_tcp_m;   /* how far the pads' tips reach past the TCP along +z, fully open */
  double pad_size_m[3];      /* pad: width (x), thickness outwards from its face (y), height (z) */
  double holder_size_m[3];   /* holder, behind the pad: width, thickness from the pad's face,
                              * height (from the pad's bottom back towards the palm) */
  double link_half_x_m;      /* link: half its extent along x */
  double link_z_lo_m;        /* where it starts at the palm (z, fixed to the palm) */
  double link_thick_m;       /* how far out it reaches beyond the pad's face ... */
  double link_reach_m;       /* ... or at least this far from the TCP (|y|; 0: no more) */
  double link_inset;         /* how far in it reaches inside the pad's face, as a fraction of
                              * the width */
  double palm_size_m[3];     /* palm extent along x, y, z */
  double palm_top_m;         /* z of the palm's face towards the fingers (< 0) */
  double arc_radius_m;       /* the parallel linkage's length; 0 for fingers that slide */
  double arc_angle_rad;      /* its angle from +z, outwards, with the fingers fully open */
} fg_gripper_spec;

/* The model's numbers; NULL for an id out of range. Static storage. */
const fg_gripper_spec *fg_gripper_spec_get(fg_gripper_model m);

/* Parses a model name as above. 0, or FG_EINVAL with a detail listing the names. */
int fg_gripper_model_parse(const char *name, fg_gripper_model *out);

/* "palm", "pad_minus_y", "pad_plus_y", "holder_minus_y", "holder_plus_y", "link_minus_y",
 * "link_plus_y" for box index i (FG_GRIPPER_BOX_*); NULL out of range. Static storage. */
const char *fg_gripper_box_name(int i);

/* "palm", "finger_minus_y", "finger_plus_y"; NULL out of range. Static storage. */
const char *fg_gripper_part_name(fg_gripper_part p);

/* How far the pads' tips stand past where they stand fully open, along +z, with the fingers
 * open to width_m (metres, 0..stroke): 0 for fingers that slide. NaN for an unknown model. */
double fg_gripper_tip_rise(fg_gripper_model m, double width_m);

/* The model's FG_GRIPPER_N_BOXES boxes, in the order of FG_GRIPPER_BOX_*, with the fingers
 * open to width_m (metres, 0..stroke) into boxes. 0, or FG_EINVAL (unknown model, width not
 * finite or outside 0..stroke). */
int fg_gripper_boxes(fg_gripper_model m, double width_m, fg_gripper_box boxes[FG_GRIPPER_N_BOXES]);

#endif
