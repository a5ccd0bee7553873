/* The physics cell's report: a line per command (cell_report.h). */
#include "cell_report.h"
#include "maths.h"

#include <math.h>
#include <stdio.h>

/* 1 when object i lies in the bin: its centre within the walls (on the floor or on what lies
 * there already) and the gripper not holding it. */
static int in_bin(const cell_report_moment *m, const cell_report_object *o) {
  return m->has_bin && !o->held && fabs(o->pos[0] - m->bin_xy[0]) <= 0.5 * SIM_BIN_INNER_M &&
         fabs(o->pos[1] - m->bin_xy[1]) <= 0.5 * SIM_BIN_INNER_M;
}

/* What became of object i during the command that ends. */
typedef struct {
  int held, lifted, moved, knocked_over;
  double dz, distance, turned, tilt;
} object_outcome;

static object_outcome object_outcome_of(const cell_report_object *o) {
  const double *p = o->pos, *q = o->quat;
  object_outcome r = {.held = o->held};
  r.dz = p[2] - o->rest_pos[2];
  r.distance = dist3(p, o->cmd_pos);
  r.turned = quat_angle(q, o->cmd_quat) * 180 / M_PI;
  /* tilt: the angle between the object's +z now and when it stood at rest */
  double zn[3], zr[3];
  quat_z(q, zn);
  quat_z(o->rest_quat, zr);
  r.tilt = acos(clampd(zn[0] * zr[0] + zn[1] * zr[1] + zn[2] * zr[2], -1, 1)) * 180 / M_PI;
  r.lifted = r.held && r.dz > CELL_LIFTED_M;
  r.moved = !r.held && (r.distance > CELL_MOVED_M || r.turned > CELL_MOVED_DEG);
  r.knocked_over = r.tilt > CELL_KNOCKED_DEG;
  return r;
}

static void put_num(FILE *f, double v, int decimals) {
  if (isfinite(v)) fprintf(f, "%.*f", decimals, v);
  else fputs("null", f);
}

static const char *tf(int b) { return b ? "true" : "false"; }

/* The block's command by name (proto/modbus.md). */
static const char *command_name(int command) {
  static const char *const names[] = {"no-op", "pick", "place", "open", "close", "move"};
  return command >= 0 && command <= 5 ? names[command] : "unknown";
}

/* One line: SPEC.md's fields (seq, command, pose, object_detected, lifted, lift_m, touched,
 * moved), then the simulator's own (proto/modbus.md). */
void cell_report_write(FILE *f, const cell_report_moment *m, const char *outcome,
                       const char *why) {
  const sim_cell_block *b = m->blk;
  object_outcome oc[CELL_MAX_OBJECTS];
  int lifted = -1;
  for (int i = 0; i < m->n_obj; i++) {
    oc[i] = object_outcome_of(&m->obj[i]);
    if (oc[i].lifted && (lifted < 0 || oc[i].dz > oc[lifted].dz)) lifted = i;
  }
  const int obj = m->gobj;
  fprintf(f, "{\"seq\":%d,\"command\":\"%s\",\"pose\":{\"position\":[", b->seq,
          command_name(b->command));
  double quat[4];
  quat_from_rv(b->rv, quat);
  for (int k = 0; k < 3; k++) {
    if (k) fputc(',', f);
    put_num(f, b->p[k], 4);
  }
  fputs("],\"quaternion\":[", f);
  for (int k = 0; k < 4; k++) {
    if (k) fputc(',', f);
    put_num(f, quat[k], 6);
  }
  fprintf(f, "]},\"object_detected\":%s,\"lifted\":", tf(obj == 1 || obj == 2));
  if (lifted >= 0) fprintf(f, "\"%s\",\"lift_m\":%.4f", m->obj[lifted].name, oc[lifted].dz);
  else fputs("null,\"lift_m\":null", f);
  fputs(",\"touched\":[", f);
  for (int i = 0, n = 0; i < m->n_obj; i++)
    if (m->obj[i].touched) fprintf(f, "%s\"%s\"", n++ ? "," : "", m->obj[i].name);
  fputs("],\"moved\":[", f);
  for (int i = 0, n = 0; i < m->n_obj; i++)
    if (oc[i].moved)
      fprintf(f, "%s{\"name\":\"%s\",\"distance_m\":%.4f,\"tilt_deg\":%.1f}", n++ ? "," : "",
              m->obj[i].name, oc[i].distance, oc[i].tilt);
  /* the simulator's own: the outcome, the rest of the block as read (a float32 block may hold
   * NaN or infinities: null), the fingers, the TCP, every object */
  fprintf(f, "],\"t\":%.3f,\"outcome\":\"%s\"", m->t, outcome);
  if (why) {
    fputs(",\"why\":\"", f);
    for (const char *p = why; *p; p++)
      if (*p != '"' && *p != '\\' && (unsigned char)*p >= 0x20) fputc(*p, f);
    fputc('"', f);
  }
  fputs(",\"rotation_vector\":[", f);
  for (int k = 0; k < 3; k++) {
    if (k) fputc(',', f);
    put_num(f, b->rv[k], 4);
  }
  static const char *const keys[5] = {"width_m", "force_n", "approach_m", "retreat_m",
                                      "speed_mps"};
  const double vals[5] = {b->width, b->force, b->approach, b->retreat, b->speed};
  fputc(']', f);
  for (int k = 0; k < 5; k++) {
    fprintf(f, ",\"%s\":", keys[k]);
    put_num(f, vals[k], 4);
  }
  fprintf(f, ",\"fingers\":{\"width_m\":%.4f,\"gobj\":%d},\"tcp\":[%.4f,%.4f,%.4f],\"objects\":[",
          m->fingers_width_m, obj, m->tcp[0], m->tcp[1], m->tcp[2]);
  for (int i = 0; i < m->n_obj; i++) {
    const cell_report_object *o = &m->obj[i];
    const double *p = o->pos;
    fprintf(f, "%s{\"name\":\"%s\",\"position\":[%.4f,%.4f,%.4f],\"held\":%s,\"lifted\":%s,"
               "\"dz_m\":%.4f,\"moved_m\":%.4f,\"turned_deg\":%.1f,\"tilt_deg\":%.1f,"
               "\"moved\":%s,\"knocked_over\":%s,\"touched\":%s,\"collided\":%s",
            i ? "," : "", o->name, p[0], p[1], p[2], tf(oc[i].held), tf(oc[i].lifted),
            oc[i].dz, oc[i].distance, oc[i].turned, oc[i].tilt, tf(oc[i].moved),
            tf(oc[i].knocked_over), tf(o->touched), tf(o->collided));
    if (m->has_bin) fprintf(f, ",\"in_bin\":%s", tf(in_bin(m, o)));
    fputc('}', f);
  }
  fputs("]}\n", f);
  fflush(f);
}
