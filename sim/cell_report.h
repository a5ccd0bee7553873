/* The physics cell's report (cell.h: cfg.report): one JSON line per command, written from a
 * snapshot of the moment the command ends that cell.c takes, so that the report knows nothing
 * of MuJoCo or of the cell's insides. Which object counts as lifted, moved or knocked over is
 * decided here. */
#ifndef SIM_CELL_REPORT_H
#define SIM_CELL_REPORT_H

#include <stdio.h>

#include "cell.h"

#define CELL_MAX_OBJECTS 64
#define CELL_LIFTED_M 0.02       /* held and this far above its rest height: lifted */
#define CELL_MOVED_M 0.005       /* not held and moved this far, or turned CELL_MOVED_DEG: moved */
#define CELL_MOVED_DEG 5.0
#define CELL_KNOCKED_DEG 45.0    /* tilted this far from how it stood: knocked over */

/* An object as the command ends. */
typedef struct {
  const char *name;
  double pos[3], quat[4];           /* now */
  double rest_pos[3], rest_quat[4]; /* when the cell came to rest after loading */
  double cmd_pos[3], cmd_quat[4];   /* when the command started */
  int held;                         /* both fingers touch it */
  int touched, collided;            /* during the command: by a finger; by the hand's approach */
} cell_report_object;

/* The moment a command ends. */
typedef struct {
  const sim_cell_block *blk; /* the command's block as read */
  double t;                  /* the cell's clock, s */
  double fingers_width_m;    /* the opening between the fingers */
  int gobj;                  /* the gripper's object status */
  double tcp[3];
  int has_bin;
  double bin_xy[2];
  int n_obj;
  cell_report_object obj[CELL_MAX_OBJECTS];
} cell_report_moment;

/* Writes the moment's line to f (SPEC.md's fields, then the simulator's own): outcome "done",
 * "failed" (with why, or NULL) or "stopped". */
void cell_report_write(FILE *f, const cell_report_moment *m, const char *outcome,
                       const char *why);

#endif
