/* The physics cell of fieldgrip-sim: a table and objects from an MJCF file, and a floating
 * parallel-jaw gripper built from the boxes of lib/grasp/gripper.h, simulated by MuJoCo.
 *
 * The gripper: a palm welded to a mocap target (the robot's TCP, gripper frame of SPEC.md),
 * two fingers on slide joints coupled to close symmetrically, each driven by a motor whose
 * force is capped at the gripper's force setting and which moves at the speed setting until
 * the finger stops on something: the Robotiq's behaviour. The robot program of proto/modbus.md
 * moves the target along straight Cartesian paths.
 *
 * Time: the cell keeps its own clock. It steps only while something happens (a program runs,
 * the fingers move, or an object has not come to rest), so a command that starts while the
 * cell is at rest starts from the same state however long the cell waited: the same scene and
 * the same commands give the same outcomes.
 *
 * Every function but sim_cell_open is called with a valid cell; none prints. */
#ifndef SIM_CELL_H
#define SIM_CELL_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "grasp/gripper.h"

typedef struct sim_cell sim_cell;

typedef struct sim_cell_config {
  const char *scene_path;   /* the MJCF file of the table and the objects */
  fg_gripper_model gripper; /* the hand's model */
  double approach_m;        /* pick and place without an approach in the block: this far */
  double lift_m;            /* pick without a retreat in the block lifts this far */
  double reach_m;           /* poses farther than this from the base origin are refused */
  double time_scale;        /* simulated seconds take this many seconds (0: as fast as it can) */
  FILE *report;             /* JSON lines, one per command's outcome; NULL: none */
  int has_bin;              /* a bin stands on the table (SIM_BIN_*) ... */
  double bin_xy[2];         /* ... its floor's centre there (world x, y on z = 0) */
} sim_cell_config;

/* The bin (--bin): an open box of SIM_BIN_INNER_M square inside, walls SIM_BIN_WALL_M thick
 * and SIM_BIN_HEIGHT_M high, standing on the table plane, its geoms fg_bin/floor and
 * fg_bin/wall0..3 (static: not an object). A place over it drops what the gripper holds into
 * it, as a robot clears a table; the report says of each object whether it lies inside. */
#define SIM_BIN_INNER_M 0.34
#define SIM_BIN_WALL_M 0.01
#define SIM_BIN_HEIGHT_M 0.10

/* Defaults of the command line: robotiq-2f85, approach 0.10 m, lift 0.10 m, reach 0.85 m,
 * time scale 1, no bin. */
void sim_cell_config_default(sim_cell_config *cfg);

/* Loads the scene with the gripper at its home pose (0.30, 0, 0.40), pointing down and open,
 * and lets the objects come to rest. NULL with a message in err (MuJoCo's, with the file and
 * line, for a file that does not load; or an object below or inside the table, or one that
 * does not come to rest). The scene needs a geom named "table"; every body with a free joint
 * is an object. */
sim_cell *sim_cell_open(const sim_cell_config *cfg, char *err, size_t errsz);
void sim_cell_close(sim_cell *c);

/* Steps the cell to the wall-clock time now_ns (monotonic), or until it is at rest. */
void sim_cell_advance(sim_cell *c, int64_t now_ns);

/* 1 while something moves, so the caller must keep calling sim_cell_advance. */
int sim_cell_busy(const sim_cell *c);

/* A block of the robot program (proto/modbus.md): command 1 pick, 2 place, 3 open, 4 close,
 * 5 move; the pose (metres, rotation vector), width (m), force (N), approach, retreat (m)
 * and speed (m/s). */
typedef struct sim_cell_block {
  int seq, command;
  double p[3], rv[3];
  double width, force, approach, retreat, speed;
} sim_cell_block;

/* Starts the block at now_ns, superseding a program that runs. 0, or -1 when the robot
 * refuses it (a pose not finite or out of reach, a motion without a speed, an unknown
 * command), with the reason in why (reported too). */
int sim_cell_program_start(sim_cell *c, const sim_cell_block *b, int64_t now_ns,
                           char *why, size_t whysz);

/* The program's state: 0 none or still running, 2 done, 3 failed. */
int sim_cell_program_result(const sim_cell *c);
int sim_cell_program_running(const sim_cell *c);

/* The stop register: the target halts where it is; the program ends as stopped. */
void sim_cell_program_stop(sim_cell *c, int64_t now_ns);

/* A Robotiq go-to: position 0 (open) .. 255 (closed), speed and force 0..255 as the
 * registers hold them. */
void sim_cell_fingers_goto(sim_cell *c, int position, int speed, int force, int64_t now_ns);

/* The fingers' Robotiq status: position 0..255 from the joints; moving 1 while a go-to is in
 * progress; obj as gOBJ (0 moving, 1 stopped opening, 2 stopped closing, 3 at the position). */
void sim_cell_fingers_status(const sim_cell *c, int *position, int *moving, int *obj);

/* Where the hand is now (what physics holds, not where the target is): the TCP position
 * (metres) and orientation (w, x, y, z), base frame. */
void sim_cell_tcp(const sim_cell *c, double p[3], double q_wxyz[4]);

/* A copy of the cell's state to look at from another thread (the camera): taken under the
 * caller's lock, then rendered from without it. */
typedef struct sim_cell_view sim_cell_view;
sim_cell_view *sim_cell_view_new(const sim_cell *c);
void sim_cell_view_free(sim_cell_view *v);
void sim_cell_view_take(sim_cell_view *v, const sim_cell *c);

/* 1 when two copies look the same to a camera: every geom and the hand where they were. */
int sim_cell_view_same(const sim_cell_view *a, const sim_cell_view *b);

/* The hand's pose in the copy (as sim_cell_tcp). */
void sim_cell_view_tcp(const sim_cell_view *v, double p[3], double q_wxyz[4]);

/* The nearest surface along the ray from p in the unit direction dir, leaving out the palm
 * (a camera on the tool sits on it; the fingers stay in view): its distance in metres and
 * its colour (the geom's material or rgba, 0..1), or -1 when the ray meets nothing; *geom
 * (may be NULL) the geom met, -1 for none. */
double sim_cell_view_ray(const sim_cell_view *v, const double p[3], const double dir[3],
                         float rgb[3], int *geom);

/* Feature vectors: what a feature extractor would see on each geom, from the model's custom
 * numerics "feature:NAME" (scenegen's cell.xml writes its classes' embeddings so): the
 * vector of a geom named NAME or NAME/PART, else "feature:background", which is also what a
 * ray that meets nothing (geom -1) shows. A model without "feature:background" has none:
 * dimension 0, NULL. */
int sim_cell_feature_dim(const sim_cell *c);
const double *sim_cell_feature(const sim_cell *c, int geom);

/* The cell's clock, seconds. */
double sim_cell_time(const sim_cell *c);

#endif
