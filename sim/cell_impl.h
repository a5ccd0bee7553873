/* The physics cell's insides, shared by its files (cell.c: the model, the steps, the programs;
 * cell_report.c: the report of each command). Not for the cell's users: they include cell.h. */
#ifndef FG_SIM_CELL_IMPL_H
#define FG_SIM_CELL_IMPL_H

#include "cell.h"

#include <math.h>
#include <mujoco/mujoco.h>

#define CELL_MAX_OBJECTS 64
#define CELL_MAX_PHASES 8
#define CELL_TIMESTEP 0.001      /* s: contact-rich grasps want a short step */
#define CELL_REST_V 0.005        /* m/s: an object slower than this... */
#define CELL_REST_W 0.05         /* rad/s: ...and turning slower than this is at rest */
#define CELL_REST_AFTER 3.0      /* s: after this long without a command the cell rests anyway */
#define CELL_SETTLE_MAX 5.0      /* s: objects must come to rest this soon after loading */
#define CELL_TURN_RATE 1.5       /* rad/s: the TCP's turn rate where a path turns more than moves */
#define CELL_LIFTED_M 0.02       /* held and this far above its rest height: lifted */
#define CELL_MOVED_M 0.005       /* not held and moved this far, or turned CELL_MOVED_DEG: moved */
#define CELL_MOVED_DEG 5.0
#define CELL_KNOCKED_DEG 45.0    /* tilted this far from how it stood: knocked over */
#define CELL_PENETRATION_M 0.002 /* deeper into the table at load: inside it */

/* Per model: the gripper's mass and its force and speed ranges, as the registers scale them
 * (force and speed 0..255 map linearly onto these), from the data sheets: Franka Hand 0.73 kg,
 * 70 N continuous, fingers up to 50 mm/s each; Robotiq 2F-85 0.925 kg, 20-235 N, 20-150 mm/s;
 * Robotiq 2F-140 1.025 kg, 10-125 N, 30-250 mm/s. Speeds are of the opening (both fingers). */
typedef struct {
  double mass_kg, force_min_n, force_max_n, speed_min_mps, speed_max_mps;
} hand_drive;

typedef enum { PH_GRIP, PH_PATH, PH_DWELL } phase_kind;

typedef struct {
  phase_kind kind;
  double q, force;   /* PH_GRIP: finger target (closing per finger, m) and force (N) */
  double p[3], quat[4]; /* PH_PATH: where the TCP goes */
  double dwell;      /* PH_DWELL: seconds */
} phase;

typedef struct {
  int body;
  char name[64];
  double rest_pos[3], rest_quat[4]; /* when the cell came to rest after loading */
  double cmd_pos[3], cmd_quat[4];   /* when the current command started */
} cell_object;

struct sim_cell {
  sim_cell_config cfg;
  const fg_gripper_spec *spec;
  const hand_drive *drive;
  mjModel *m;
  mjData *d;
  int mocap;              /* mocap index of the target */
  int hand, finger[2];    /* body ids */
  int qadr[2], dadr[2];   /* the finger joints' qpos and qvel addresses */
  int act[2];             /* their motors */
  int hand_qadr;          /* the hand's free joint */
  int table_geom;
  int feat_dim;           /* the length of the model's feature vectors; 0: it has none */
  int *geom_feat;         /* per geom, the custom numeric of its feature vector */
  int feat_background;    /* ... and of what a ray that meets nothing shows */
  cell_object obj[CELL_MAX_OBJECTS];
  int n_obj;
  /* clock */
  int64_t anchor_wall_ns;
  double anchor_sim;
  double last_activity;   /* cell time when the last command started or ended */
  int at_rest;
  /* fingers */
  double f_target, f_ramp, f_speed, f_force; /* per finger: m, m, m/s, N */
  int f_moving, f_obj;
  double f_win_t, f_win_q; /* where the fingers were at the start of the stall window */
  double f_deadline;       /* a motion not over by then ends where it is */
  /* program */
  phase ph[CELL_MAX_PHASES];
  int n_ph, i_ph;
  double ph_t0, ph_p0[3], ph_q0[4], ph_T;
  int running, result;
  int closed_in_cmd;      /* a close phase of this command has run */
  sim_cell_block blk;
  unsigned char touched[CELL_MAX_OBJECTS], collided[CELL_MAX_OBJECTS];
};

/* ---------------------------------------------------------------- small maths */

static inline double clampd(double x, double lo, double hi) {
  return x < lo ? lo : x > hi ? hi : x;
}

static inline void quat_from_rv(const double rv[3], double q[4]) {
  const double th = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
  if (th < 1e-12) {
    q[0] = 1;
    q[1] = q[2] = q[3] = 0;
    return;
  }
  const double s = sin(th / 2) / th;
  q[0] = cos(th / 2);
  for (int k = 0; k < 3; k++) q[1 + k] = rv[k] * s;
}

/* The angle between two orientations, radians. */
static inline double quat_angle(const double a[4], const double b[4]) {
  double dot = fabs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
  return 2 * acos(clampd(dot, 0, 1));
}

/* The tool's +z of orientation q (w, x, y, z). */
static inline void quat_z(const double q[4], double z[3]) {
  z[0] = 2 * (q[1] * q[3] + q[0] * q[2]);
  z[1] = 2 * (q[2] * q[3] - q[0] * q[1]);
  z[2] = 1 - 2 * (q[1] * q[1] + q[2] * q[2]);
}

static inline double dist3(const double a[3], const double b[3]) {
  return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
              (a[2] - b[2]) * (a[2] - b[2]));
}

/* Object i's pose from its free joint. */
static inline const double *obj_pos(const sim_cell *c, int i) {
  return c->d->xpos + 3 * c->obj[i].body;
}
static inline const double *obj_quat(const sim_cell *c, int i) {
  return c->d->xquat + 4 * c->obj[i].body;
}

/* The fingers' closing, per finger (m). */
static inline double finger_q(const sim_cell *c) { return c->d->qpos[c->qadr[0]]; }

/* What the cell knows of the moment a command ends, beyond the model's state, for its report:
 * which objects the fingers hold (both touch it) and the gripper's object status (gOBJ). */
typedef struct {
  unsigned char held[CELL_MAX_OBJECTS];
  int gobj;
} cell_report_facts;

/* Writes the report line of the command that ends (cfg.report; SPEC.md's fields, then the
 * simulator's own): outcome "done", "failed" (with why) or "stopped". */
void cell_report_command(const sim_cell *c, const cell_report_facts *facts, const char *outcome,
                         const char *why);

#endif
