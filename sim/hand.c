/* The simulated gripper as MJCF (hand.h). */
#include "hand.h"

#include "core/strbuf.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#define FINGER_MASS_KG 0.08 /* a finger's pad and holder ... */
#define LINK_MASS_KG 0.01   /* ... and its link: a contact's stiffness in newtons per metre
                             * scales with the body's mass, so the pads' body is the heavy one */

/* The finger bodies, by part: finger_l stands at -y and closes along +y. */
const char *const sim_hand_finger[2] = {"finger_l", "finger_r"};

/* The pads' rise as a Robotiq finger closes (gripper.h), as the quartic a[1..4] in the
 * closing per finger q (a[0] = 0) that MuJoCo's joint coupling takes: a least-squares fit over
 * the stroke, within 0.02 mm of the arc for the models here. All zeros for fingers that slide. */
static void rise_poly(fg_gripper_model model, double a[5]) {
  const fg_gripper_spec *s = fg_gripper_spec_get(model);
  double ata[4][5] = {{0}};
  for (int k = 0; k < 5; k++) a[k] = 0;
  if (s->arc_radius_m <= 0) return;
  const int n = 64;
  for (int i = 0; i <= n; i++) {
    const double q = s->stroke_m / 2 * i / n, r = fg_gripper_tip_rise(model, s->stroke_m - 2 * q);
    double x[4] = {q, q * q, q * q * q, q * q * q * q};
    for (int u = 0; u < 4; u++) {
      for (int v = 0; v < 4; v++) ata[u][v] += x[u] * x[v];
      ata[u][4] += x[u] * r;
    }
  }
  /* Gaussian elimination with partial pivoting on the 4x4 normal equations */
  for (int c = 0; c < 4; c++) {
    int piv = c;
    for (int r = c + 1; r < 4; r++)
      if (fabs(ata[r][c]) > fabs(ata[piv][c])) piv = r;
    for (int k = 0; k < 5; k++) {
      const double t = ata[c][k];
      ata[c][k] = ata[piv][k];
      ata[piv][k] = t;
    }
    for (int r = c + 1; r < 4; r++) {
      const double f = ata[r][c] / ata[c][c];
      for (int k = c; k < 5; k++) ata[r][k] -= f * ata[c][k];
    }
  }
  for (int c = 3; c >= 0; c--) {
    double t = ata[c][4];
    for (int k = c + 1; k < 4; k++) t -= ata[c][k] * a[1 + k];
    a[1 + c] = t / ata[c][c];
  }
}

/* The wrapper model (hand.h): the scene included, then the target, the hand and its drive. The
 * hand is the model's boxes (gripper.h), built open (at the stroke): the palm with a free joint
 * welded to the target; each finger on a slide joint along y, the two coupled to close
 * symmetrically, and for a Robotiq a second slide along +z coupled to the first, so the pads rise
 * on the linkage's arc as they close. A finger's link box hangs on a third slide along y, coupled
 * so that its inner face stays inset * width inside the pads' faces as gripper.h has it (its outer
 * face moves with the finger). The hand's geoms collide with the scene, never with each other
 * (contype 2, conaffinity 1). Pads grip (friction 1, torsional 0.01). */
char *sim_hand_xml(const char *scene_file, fg_gripper_model model, double mass_kg,
                   double force_max_n) {
  const fg_gripper_spec *s = fg_gripper_spec_get(model);
  fg_gripper_box box[FG_GRIPPER_N_BOXES];
  if (fg_gripper_boxes(model, s->stroke_m, box) != 0) return NULL;
  double rise[5];
  rise_poly(model, rise);
  const double rise_max = fg_gripper_tip_rise(model, 0), spread = 2 * s->link_inset;
  double volume[FG_GRIPPER_N_PARTS] = {0}; /* of the boxes that are not links */
  for (int i = 0; i < FG_GRIPPER_N_BOXES; i++)
    if (i != FG_GRIPPER_BOX_LINK_MINUS_Y && i != FG_GRIPPER_BOX_LINK_PLUS_Y)
      volume[box[i].part] += box[i].half_m[0] * box[i].half_m[1] * box[i].half_m[2];
  fg_strbuf b = {0};
  fg_strbuf_printf(&b, "<mujoco model=\"fieldgrip cell\">\n  <include file=\"%s\"/>\n", scene_file);
  fg_strbuf_printf(&b, "  <worldbody>\n    <body name=\"fg_target\" mocap=\"true\" pos=\"0.3 0 0.4\" "
                "quat=\"0 1 0 0\"/>\n");
  fg_strbuf_printf(&b, "    <body name=\"fg_hand\" pos=\"0.3 0 0.4\" quat=\"0 1 0 0\">\n"
                "      <freejoint name=\"fg_hand\"/>\n");
  for (int part = FG_GRIPPER_PALM; part < FG_GRIPPER_N_PARTS; part++) {
    const int finger = part != FG_GRIPPER_PALM;
    const char *name = finger ? sim_hand_finger[part - 1] : "palm";
    const double mass =
        finger ? FINGER_MASS_KG : mass_kg - 2 * (FINGER_MASS_KG + LINK_MASS_KG);
    if (finger) {
      fg_strbuf_printf(&b, "      <body name=\"fg_%s\">\n        <joint name=\"fg_%s\" type=\"slide\" "
                    "axis=\"0 %d 0\" limited=\"true\" range=\"0 %.6f\" damping=\"%.1f\"/>\n",
                name, name, part == FG_GRIPPER_FINGER_MINUS_Y ? 1 : -1, s->stroke_m / 2,
                SIM_FINGER_KD);
      if (rise_max > 0)
        fg_strbuf_printf(&b, "        <joint name=\"fg_%s_rise\" type=\"slide\" axis=\"0 0 1\" "
                      "limited=\"true\" range=\"-0.001 %.6f\" damping=\"%.1f\"/>\n",
                  name, rise_max + 0.001, SIM_FINGER_KD);
    }
    for (int i = 0; i < FG_GRIPPER_N_BOXES; i++) {
      const fg_gripper_box *x = &box[i];
      if ((int)x->part != part) continue;
      const int link = i == FG_GRIPPER_BOX_LINK_MINUS_Y || i == FG_GRIPPER_BOX_LINK_PLUS_Y;
      if (link && spread > 0)
        fg_strbuf_printf(&b, "        <body name=\"fg_%s_link\">\n          <joint name=\"fg_%s_link\" "
                      "type=\"slide\" axis=\"0 %d 0\" limited=\"true\" range=\"%.6f 0.001\" "
                      "damping=\"%.1f\"/>\n",
                  name, name, part == FG_GRIPPER_FINGER_MINUS_Y ? 1 : -1,
                  -spread * s->stroke_m / 2 - 0.001, SIM_FINGER_KD);
      fg_strbuf_printf(&b, "%*s<geom name=\"fg_%s\" type=\"box\" pos=\"%.6f %.6f %.6f\" "
                    "size=\"%.6f %.6f %.6f\" mass=\"%.4f\" contype=\"2\" conaffinity=\"1\"%s/>\n",
                finger ? (link && spread > 0 ? 10 : 8) : 6, "", fg_gripper_box_name(i),
                x->centre_m[0], x->centre_m[1], x->centre_m[2], x->half_m[0], x->half_m[1],
                x->half_m[2],
                link ? LINK_MASS_KG
                     : mass * x->half_m[0] * x->half_m[1] * x->half_m[2] / volume[part],
                x->pad ? " friction=\"1 0.01 0.0001\" condim=\"4\" solref=\"0.004 1\" "
                         "solimp=\"0.95 0.99 0.001\""
                : finger ? " solref=\"0.004 1\" solimp=\"0.95 0.99 0.001\"" : "");
      if (link && spread > 0) fg_strbuf_printf(&b, "        </body>\n");
    }
    if (finger) fg_strbuf_printf(&b, "      </body>\n");
  }
  fg_strbuf_printf(&b, "    </body>\n  </worldbody>\n");
  fg_strbuf_printf(&b, "  <equality>\n    <weld body1=\"fg_target\" body2=\"fg_hand\" "
                "solref=\"0.005 1\"/>\n    <joint joint1=\"fg_finger_r\" joint2=\"fg_finger_l\" "
                "polycoef=\"0 1 0 0 0\" solref=\"0.005 1\"/>\n");
  for (int k = 0; k < 2; k++) {
    if (rise_max > 0)
      fg_strbuf_printf(&b, "    <joint joint1=\"fg_%s_rise\" joint2=\"fg_%s\" polycoef=\"0 %.9g %.9g "
                    "%.9g %.9g\" solref=\"0.005 1\"/>\n",
                sim_hand_finger[k], sim_hand_finger[k], rise[1], rise[2], rise[3], rise[4]);
    if (spread > 0)
      fg_strbuf_printf(&b, "    <joint joint1=\"fg_%s_link\" joint2=\"fg_%s\" polycoef=\"0 %.9g 0 0 0\" "
                    "solref=\"0.005 1\"/>\n",
                sim_hand_finger[k], sim_hand_finger[k], -spread);
  }
  fg_strbuf_printf(&b, "  </equality>\n  <actuator>\n");
  for (int k = 0; k < 2; k++)
    fg_strbuf_printf(&b, "    <motor name=\"fg_%s\" joint=\"fg_%s\" ctrllimited=\"true\" "
                  "ctrlrange=\"-%.1f %.1f\"/>\n",
              sim_hand_finger[k], sim_hand_finger[k], force_max_n, force_max_n);
  fg_strbuf_printf(&b, "  </actuator>\n</mujoco>\n");
  return fg_strbuf_take(&b, NULL);
}
