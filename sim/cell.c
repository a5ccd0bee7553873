/* The physics cell (cell.h). */
#include "cell.h"
#include "cell_report.h"
#include "hand.h"
#include "maths.h"

#include "core/clock.h"
#include "core/pose.h"
#include "core/strbuf.h"

#include <math.h>
#include <mujoco/mujoco.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#define CELL_MAX_PHASES 8
#define CELL_TIMESTEP 0.001      /* s: contact-rich grasps want a short step */
#define CELL_REST_V 0.005        /* m/s: an object slower than this... */
#define CELL_REST_W 0.05         /* rad/s: ...and turning slower than this is at rest */
#define CELL_REST_AFTER 3.0      /* s: after this long without a command the cell rests anyway */
#define CELL_SETTLE_MAX 5.0      /* s: objects must come to rest this soon after loading */
#define CELL_TURN_RATE 1.5       /* rad/s: the TCP's turn rate where a path turns more than moves */
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

/* Object i's pose from its free joint. */
static inline const double *obj_pos(const sim_cell *c, int i) {
  return c->d->xpos + 3 * c->obj[i].body;
}
static inline const double *obj_quat(const sim_cell *c, int i) {
  return c->d->xquat + 4 * c->obj[i].body;
}

/* The fingers' closing, per finger (m). */
static inline double finger_q(const sim_cell *c) { return c->d->qpos[c->qadr[0]]; }

static const hand_drive drives[FG_GRIPPER_N_MODELS] = {
  [FG_GRIPPER_PANDA] = {0.73, 10, 70, 0.02, 0.10},
  [FG_GRIPPER_ROBOTIQ_2F85] = {0.925, 20, 235, 0.02, 0.15},
  [FG_GRIPPER_ROBOTIQ_2F140] = {1.025, 10, 125, 0.03, 0.25},
};

#define FINGER_KP 20000.0 /* N/m: the finger servo's stiffness (its damping: SIM_FINGER_KD) */

/* ---------------------------------------------------------------- the model */

static void errf(char *err, size_t errsz, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(err, errsz, fmt, ap);
  va_end(ap);
}

/* Loads the wrapper from memory as a file beside the scene, so that the scene's own relative
 * paths (meshes, includes) resolve against its folder. */
/* The bin of cfg (cell.h) added to the wrapper's text: a worldbody of its own, which MuJoCo
 * merges with the others. NULL when out of memory (xml is freed either way). */
static char *with_bin(char *xml, const sim_cell_config *cfg) {
  if (!xml || !cfg->has_bin) return xml;
  char *end = strstr(xml, "</mujoco>");
  if (!end) return xml;
  *end = 0;
  fg_strbuf b = {0};
  /* objects piled in the bin touch in many places: MuJoCo 2.2's default of 100 contacts
   * overflowed ("contact buffer is full") when four fell in. Its arena grows with the square
   * of njmax and is all written when malloc perturbs (as under meson test): 1000 contacts
   * and 6000 rows took 2 GB and 8 s of page faults before the port opened, 500 and 3000
   * (six rows for each contact of condim 4) take 0.6 GB */
  fg_strbuf_printf(&b, "%s  <size nconmax=\"500\" njmax=\"3000\"/>\n"
                   "  <worldbody>\n    <body name=\"fg_bin\" pos=\"%.6f %.6f 0\">\n"
                   "      <geom name=\"fg_bin/floor\" type=\"box\" size=\"%.6f %.6f %.6f\" "
                   "pos=\"0 0 %.6f\" rgba=\"0.35 0.35 0.38 1\"/>\n",
                   xml, cfg->bin_xy[0], cfg->bin_xy[1], 0.5 * SIM_BIN_INNER_M + SIM_BIN_WALL_M,
                   0.5 * SIM_BIN_INNER_M + SIM_BIN_WALL_M, 0.5 * SIM_BIN_WALL_M,
                   0.5 * SIM_BIN_WALL_M);
  const double h = 0.5 * SIM_BIN_HEIGHT_M, off = 0.5 * (SIM_BIN_INNER_M + SIM_BIN_WALL_M);
  for (int k = 0; k < 4; k++) {
    const int along_x = k < 2; /* walls 0, 1 at -y and +y; 2, 3 at -x and +x */
    const double s = k % 2 ? 1 : -1;
    fg_strbuf_printf(&b, "      <geom name=\"fg_bin/wall%d\" type=\"box\" size=\"%.6f %.6f %.6f\" "
                     "pos=\"%.6f %.6f %.6f\" rgba=\"0.35 0.35 0.38 1\"/>\n", k,
                     along_x ? off + 0.5 * SIM_BIN_WALL_M : 0.5 * SIM_BIN_WALL_M,
                     along_x ? 0.5 * SIM_BIN_WALL_M : off + 0.5 * SIM_BIN_WALL_M, h,
                     along_x ? 0 : s * off, along_x ? s * off : 0, h);
  }
  fg_strbuf_printf(&b, "    </body>\n  </worldbody>\n</mujoco>\n");
  free(xml);
  return fg_strbuf_take(&b, NULL);
}

static mjModel *load(const char *scene_path, fg_gripper_model model, const hand_drive *dr,
                     const sim_cell_config *cfg, char *err, size_t errsz) {
  const char *slash = strrchr(scene_path, '/');
  const char *base = slash ? slash + 1 : scene_path;
  char wrapper_path[4096];
  if (snprintf(wrapper_path, sizeof wrapper_path, "%.*sfieldgrip-cell-wrapper.xml",
               slash ? (int)(slash - scene_path + 1) : 0, scene_path) >= (int)sizeof wrapper_path) {
    errf(err, errsz, "%s: path too long", scene_path);
    return NULL;
  }
  if (!*base || strchr(base, '"') || strchr(base, '<') || strchr(base, '&')) {
    errf(err, errsz, "%s: not a file name the cell can include", scene_path);
    return NULL;
  }
  FILE *probe = fopen(scene_path, "r");
  if (!probe) {
    errf(err, errsz, "%s: cannot be read", scene_path);
    return NULL;
  }
  fclose(probe);
  char *xml = with_bin(sim_hand_xml(base, model, dr->mass_kg, dr->force_max_n), cfg);
  mjVFS *vfs = xml ? malloc(sizeof *vfs) : NULL;
  if (!vfs) {
    free(xml);
    errf(err, errsz, "out of memory");
    return NULL;
  }
  mj_defaultVFS(vfs);
  const char *vname = "fieldgrip-cell-wrapper.xml";
  mjModel *m = NULL;
  const int len = (int)strlen(xml);
  if (mj_makeEmptyFileVFS(vfs, vname, len) == 0) {
    memcpy(vfs->filedata[mj_findFileVFS(vfs, vname)], xml, (size_t)len);
    char mjerr[1024] = "";
    m = mj_loadXML(wrapper_path, vfs, mjerr, sizeof mjerr);
    if (!m) {
      /* MuJoCo's message names the file and the line ("XML parse error ... Line number=" or
       * "Element 'x', line N"); keep it on one line. */
      for (char *p = mjerr; *p; p++)
        if (*p == '\n') *p = ' ';
      errf(err, errsz, "%s does not load: %s", scene_path, mjerr);
    }
  } else {
    errf(err, errsz, "out of memory");
  }
  mj_deleteVFS(vfs);
  free(vfs);
  free(xml);
  return m;
}

/* ---------------------------------------------------------------- objects and contacts */

static int object_of_body(const sim_cell *c, int body) {
  const int root = c->m->body_rootid[body];
  for (int i = 0; i < c->n_obj; i++)
    if (c->obj[i].body == root) return i;
  return -1;
}

static int hand_part_of_body(const sim_cell *c, int body) {
  if (body == c->hand) return 0;
  if (body == c->finger[0]) return 1;
  if (body == c->finger[1]) return 2;
  return -1;
}

/* Which hand parts touch object i: bit 0 palm, 1 finger_l, 2 finger_r. */
static int contact_mask(const sim_cell *c, int i) {
  int mask = 0;
  for (int k = 0; k < c->d->ncon; k++) {
    const mjContact *con = &c->d->contact[k];
    const int b1 = c->m->geom_bodyid[con->geom1], b2 = c->m->geom_bodyid[con->geom2];
    int part = -1;
    if (object_of_body(c, b1) == i) part = hand_part_of_body(c, b2);
    else if (object_of_body(c, b2) == i) part = hand_part_of_body(c, b1);
    if (part >= 0) mask |= 1 << part;
  }
  return mask;
}

/* 1 when the fingers hold object i (both touch it). */
static int cell_held(const sim_cell *c, int i) { return (contact_mask(c, i) & 6) == 6; }

/* Every object is still, but one the fingers hold (it moves with the hand, which stands). */
static int objects_at_rest(const sim_cell *c) {
  for (int i = 0; i < c->n_obj; i++) {
    if (cell_held(c, i)) continue;
    const double *v = c->d->cvel + 6 * c->obj[i].body; /* angular, then linear */
    if (sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) > CELL_REST_W) return 0;
    if (sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5]) > CELL_REST_V) return 0;
  }
  return 1;
}

/* ---------------------------------------------------------------- the fingers */

static int fingers_position(const sim_cell *c) {
  const double width = c->spec->stroke_m - 2 * finger_q(c);
  long p = lround(255.0 * (1 - width / c->spec->stroke_m));
  return (int)(p < 0 ? 0 : p > 255 ? 255 : p);
}

static void fingers_set(sim_cell *c, double q, double width_speed, double force) {
  c->f_target = clampd(q, 0, c->spec->stroke_m / 2);
  c->f_ramp = finger_q(c);
  c->f_speed = width_speed / 2;
  c->f_force = clampd(force, c->drive->force_min_n, c->drive->force_max_n);
  c->f_moving = 1;
  c->f_obj = 0;
  c->f_win_t = c->d->time;
  c->f_win_q = finger_q(c);
  c->f_deadline = c->d->time + fabs(c->f_target - c->f_ramp) / c->f_speed + 2.0;
}

/* The servo of one step: the ramp moves toward the target at the speed; each finger's motor
 * pulls toward the ramp, its force capped at the force setting. */
static void fingers_control(sim_cell *c) {
  const double dt = c->m->opt.timestep, q = finger_q(c), v = c->d->qvel[c->dadr[0]];
  const double step = c->f_speed * dt, to = c->f_target - c->f_ramp;
  double ramp_v = 0;
  if (fabs(to) <= step) {
    c->f_ramp = c->f_target;
  } else {
    c->f_ramp += to > 0 ? step : -step;
    ramp_v = to > 0 ? c->f_speed : -c->f_speed;
  }
  const double f = clampd(FINGER_KP * (c->f_ramp - q) + SIM_FINGER_KD * ramp_v, -c->f_force, c->f_force);
  c->d->ctrl[c->act[0]] = f;
  c->d->ctrl[c->act[1]] = f;
  if (!c->f_moving) return;
  if (fabs(c->f_target - q) < 0.0005 && fabs(v) < 0.005) {
    c->f_moving = 0;
    c->f_obj = 3;
    return;
  }
  /* stopped on something: over a window of 50 ms the fingers moved less than 0.5 mm while
   * the servo lags more than 2 mm behind (contacts make the velocity chatter; the position
   * over a window does not) */
  const double t = c->d->time;
  if (t > c->f_deadline) { /* never settled (fingers chattering on something): it ends here */
    c->f_moving = 0;
    c->f_obj = fabs(c->f_target - q) < 0.002 ? 3 : c->f_target > q ? 2 : 1;
    return;
  }
  if (t - c->f_win_t < 0.05) return;
  if (fabs(q - c->f_win_q) < 0.0005 && fabs(c->f_ramp - q) > 0.002) {
    c->f_moving = 0;
    c->f_obj = c->f_target > q ? 2 : 1;
  }
  c->f_win_t = t;
  c->f_win_q = q;
}

/* ---------------------------------------------------------------- the program */

static void mocap_get(const sim_cell *c, double p[3], double q[4]) {
  memcpy(p, c->d->mocap_pos + 3 * c->mocap, 3 * sizeof *p);
  memcpy(q, c->d->mocap_quat + 4 * c->mocap, 4 * sizeof *q);
}

static void phase_begin(sim_cell *c) {
  const phase *ph = &c->ph[c->i_ph];
  c->ph_t0 = c->d->time;
  if (ph->kind == PH_GRIP) {
    fingers_set(c, ph->q, c->drive->speed_max_mps, ph->force);
    if (ph->q > finger_q(c) + 1e-4) c->closed_in_cmd = 1;
  } else if (ph->kind == PH_PATH) {
    mocap_get(c, c->ph_p0, c->ph_q0);
    const double len = dist3(c->ph_p0, ph->p), turn = quat_angle(c->ph_q0, ph->quat);
    c->ph_T = fmax(len / c->blk.speed, turn / CELL_TURN_RATE);
  }
}

/* The report line of the command that ends, with what the cell knows of this moment. */
static void report(const sim_cell *c, const char *outcome, const char *why) {
  if (!c->cfg.report) return;
  cell_report_moment m;
  m.blk = &c->blk;
  m.t = c->d->time;
  m.fingers_width_m = c->spec->stroke_m - 2 * finger_q(c);
  int pos, moving;
  sim_cell_fingers_status(c, &pos, &moving, &m.gobj);
  memcpy(m.tcp, c->d->xpos + 3 * c->hand, sizeof m.tcp);
  m.has_bin = c->cfg.has_bin;
  memcpy(m.bin_xy, c->cfg.bin_xy, sizeof m.bin_xy);
  m.n_obj = c->n_obj;
  for (int i = 0; i < c->n_obj; i++) {
    const cell_object *o = &c->obj[i];
    cell_report_object *r = &m.obj[i];
    r->name = o->name;
    memcpy(r->pos, obj_pos(c, i), sizeof r->pos);
    memcpy(r->quat, obj_quat(c, i), sizeof r->quat);
    memcpy(r->rest_pos, o->rest_pos, sizeof r->rest_pos);
    memcpy(r->rest_quat, o->rest_quat, sizeof r->rest_quat);
    memcpy(r->cmd_pos, o->cmd_pos, sizeof r->cmd_pos);
    memcpy(r->cmd_quat, o->cmd_quat, sizeof r->cmd_quat);
    r->held = cell_held(c, i);
    r->touched = c->touched[i];
    r->collided = c->collided[i];
  }
  cell_report_write(c->cfg.report, &m, outcome, why);
}

static void program_end(sim_cell *c, int result, const char *outcome) {
  c->running = 0;
  c->result = result;
  c->last_activity = c->d->time;
  report(c, outcome, NULL);
}

/* Advances the phase in progress by one step's worth; moves on when it is complete. */
static void program_control(sim_cell *c) {
  while (c->running) {
    const phase *ph = &c->ph[c->i_ph];
    const double t = c->d->time - c->ph_t0;
    int done = 0;
    if (ph->kind == PH_GRIP) {
      done = !c->f_moving;
    } else if (ph->kind == PH_DWELL) {
      done = t >= ph->dwell;
    } else {
      const double s = c->ph_T > 0 ? clampd(t / c->ph_T, 0, 1) : 1;
      double *p = c->d->mocap_pos + 3 * c->mocap, *q = c->d->mocap_quat + 4 * c->mocap;
      for (int k = 0; k < 3; k++) p[k] = c->ph_p0[k] + s * (ph->p[k] - c->ph_p0[k]);
      fg_quat_slerp(c->ph_q0, ph->quat, s, q);
      /* complete when the hand has caught up with the target, or a moment after */
      done = s >= 1 && (dist3(c->d->xpos + 3 * c->hand, p) < 0.002 || t > c->ph_T + 0.5);
      if (!done) {
        /* the hand touching an object before anything closed is a collision */
        if (!c->closed_in_cmd && c->f_obj != 2)
          for (int i = 0; i < c->n_obj; i++)
            if (contact_mask(c, i)) c->collided[i] = 1;
      }
    }
    if (!done) return;
    if (++c->i_ph == c->n_ph) {
      program_end(c, 2, "done");
      return;
    }
    phase_begin(c);
  }
}

static void step(sim_cell *c) {
  program_control(c);
  fingers_control(c);
  mj_step(c->m, c->d);
  for (int i = 0; i < c->n_obj; i++)
    if (contact_mask(c, i) & 6) c->touched[i] = 1;
}

int sim_cell_busy(const sim_cell *c) { return c->running || c->f_moving || !c->at_rest; }

static void update_rest(sim_cell *c) {
  c->at_rest = !c->running && !c->f_moving &&
               (objects_at_rest(c) || c->d->time - c->last_activity > CELL_REST_AFTER);
}

/* The longest a call at a time scale above 0 steps the cell before the cell's clock slips
 * behind the wall's: fieldgrip-sim holds its lock while the cell steps, so on a machine that
 * cannot keep up with the time scale the Modbus clients and the camera would otherwise wait
 * for as long as it falls behind. A slip makes motions take longer in wall time, never in
 * the cell's time, and a command's done waits for the cell's program to end. */
#define ADVANCE_BUDGET_S 0.05

void sim_cell_advance(sim_cell *c, int64_t now_ns) {
  if (sim_cell_busy(c)) {
    /* at time scale 0 up to a minute of the cell's time per call, so that the server answers
     * even if something never comes to rest */
    const int scaled = c->cfg.time_scale > 0;
    const double until = scaled ? c->anchor_sim + (double)(now_ns - c->anchor_wall_ns) * 1e-9 /
                                                      c->cfg.time_scale
                                : c->d->time + 60;
    const double give_up = scaled ? fg_mono_s() + ADVANCE_BUDGET_S : 0;
    while (c->d->time < until) {
      step(c);
      update_rest(c);
      if (c->at_rest) break;
      if (scaled && fg_mono_s() > give_up) { /* behind: the cell's clock slips */
        c->anchor_wall_ns = (int64_t)(fg_mono_s() * 1e9); /* sim.c's clock, CLOCK_MONOTONIC */
        c->anchor_sim = c->d->time;
        break;
      }
    }
  }
  if (!sim_cell_busy(c)) {
    /* at rest the clock stands still */
    c->anchor_wall_ns = now_ns;
    c->anchor_sim = c->d->time;
  }
}

void sim_cell_tcp(const sim_cell *c, double p[3], double q_wxyz[4]) {
  memcpy(p, c->d->xpos + 3 * c->hand, 3 * sizeof *p);
  memcpy(q_wxyz, c->d->xquat + 4 * c->hand, 4 * sizeof *q_wxyz);
}

/* ---------------------------------------------------------------- views */

struct sim_cell_view {
  const mjModel *m; /* the cell's: the model never changes */
  mjData *d;
  int hand;
};

sim_cell_view *sim_cell_view_new(const sim_cell *c) {
  sim_cell_view *v = calloc(1, sizeof *v);
  if (!v) return NULL;
  v->m = c->m;
  v->hand = c->hand;
  v->d = mj_makeData(c->m);
  if (!v->d) {
    free(v);
    return NULL;
  }
  return v;
}

void sim_cell_view_free(sim_cell_view *v) {
  if (!v) return;
  mj_deleteData(v->d);
  free(v);
}

void sim_cell_view_take(sim_cell_view *v, const sim_cell *c) { mj_copyData(v->d, c->m, c->d); }

int sim_cell_view_same(const sim_cell_view *a, const sim_cell_view *b) {
  const size_t ng = (size_t)a->m->ngeom;
  return a->m == b->m &&
         memcmp(a->d->geom_xpos, b->d->geom_xpos, 3 * ng * sizeof *a->d->geom_xpos) == 0 &&
         memcmp(a->d->geom_xmat, b->d->geom_xmat, 9 * ng * sizeof *a->d->geom_xmat) == 0 &&
         memcmp(a->d->xpos + 3 * a->hand, b->d->xpos + 3 * b->hand, 3 * sizeof(mjtNum)) == 0 &&
         memcmp(a->d->xquat + 4 * a->hand, b->d->xquat + 4 * b->hand, 4 * sizeof(mjtNum)) == 0;
}

void sim_cell_view_tcp(const sim_cell_view *v, double p[3], double q_wxyz[4]) {
  memcpy(p, v->d->xpos + 3 * v->hand, 3 * sizeof *p);
  memcpy(q_wxyz, v->d->xquat + 4 * v->hand, 4 * sizeof *q_wxyz);
}

double sim_cell_view_ray(const sim_cell_view *v, const double p[3], const double dir[3],
                         float rgb[3], int *geom_out) {
  int geom = -1;
  const double t = mj_ray(v->m, v->d, p, dir, NULL, 1, v->hand, &geom);
  if (geom_out) *geom_out = t < 0 ? -1 : geom;
  if (t < 0 || geom < 0) return -1;
  const int mat = v->m->geom_matid[geom];
  const float *c = mat >= 0 ? v->m->mat_rgba + 4 * mat : v->m->geom_rgba + 4 * geom;
  for (int k = 0; k < 3; k++) rgb[k] = c[k];
  return t;
}

double sim_cell_time(const sim_cell *c) { return c->d->time; }

static void command_begin(sim_cell *c, int64_t now_ns) {
  sim_cell_advance(c, now_ns);
  c->anchor_wall_ns = now_ns;
  c->anchor_sim = c->d->time;
  c->last_activity = c->d->time;
  c->at_rest = 0;
}

static int in_reach(const sim_cell *c, const double p[3]) {
  return isfinite(p[0]) && isfinite(p[1]) && isfinite(p[2]) &&
         sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) <= c->cfg.reach_m;
}

/* Builds the phases of block b; 0, or -1 with why. */
static int program_build(sim_cell *c, const sim_cell_block *b, char *why, size_t whysz) {
  const double stroke = c->spec->stroke_m;
  const double width = b->width > 0 ? fmin(b->width, stroke) : stroke;
  const double q_open = (stroke - width) / 2, q_closed = stroke / 2;
  c->n_ph = 0;
  if (b->command == 3 || b->command == 4) {
    c->ph[c->n_ph++] = (phase){.kind = PH_GRIP, .q = b->command == 3 ? q_open : q_closed,
                               .force = b->force};
    return 0;
  }
  if (b->command != 1 && b->command != 2 && b->command != 5) {
    errf(why, whysz, "unknown command %d", b->command);
    return -1;
  }
  for (int k = 0; k < 3; k++)
    if (!isfinite(b->p[k]) || !isfinite(b->rv[k])) {
      errf(why, whysz, "the pose is not finite");
      return -1;
    }
  if (!(b->speed > 0) || !isfinite(b->speed)) {
    errf(why, whysz, "a motion without a speed");
    return -1;
  }
  double quat[4], z[3];
  quat_from_rv(b->rv, quat);
  quat_z(quat, z);
  double approach = b->approach;
  if (approach <= 0 && b->command != 5) approach = c->cfg.approach_m;
  double pre[3], end[3];
  for (int k = 0; k < 3; k++) pre[k] = b->p[k] - approach * z[k];
  const double out = b->retreat > 0 ? b->retreat : b->command == 1 ? c->cfg.lift_m
                                                                     : c->cfg.approach_m;
  for (int k = 0; k < 3; k++) end[k] = b->command == 2 ? b->p[k] - out * z[k] : b->p[k];
  if (b->command == 1) end[2] += out;
  if (!in_reach(c, pre) || !in_reach(c, b->p) || !in_reach(c, end)) {
    errf(why, whysz, "the path leaves the robot's reach (%.2f m from the base)", c->cfg.reach_m);
    return -1;
  }
  phase path = {.kind = PH_PATH};
  memcpy(path.quat, quat, sizeof quat);
  if (b->command == 1)
    c->ph[c->n_ph++] = (phase){.kind = PH_GRIP, .q = q_open, .force = b->force};
  if (approach > 0) {
    memcpy(path.p, pre, sizeof pre);
    c->ph[c->n_ph++] = path;
  }
  memcpy(path.p, b->p, sizeof pre);
  c->ph[c->n_ph++] = path;
  if (b->command == 5) return 0;
  c->ph[c->n_ph++] = (phase){.kind = PH_GRIP, .q = b->command == 1 ? q_closed : q_open,
                             .force = b->force};
  c->ph[c->n_ph++] = (phase){.kind = PH_DWELL, .dwell = 0.2};
  memcpy(path.p, end, sizeof end);
  c->ph[c->n_ph++] = path;
  return 0;
}

int sim_cell_program_start(sim_cell *c, const sim_cell_block *b, int64_t now_ns, char *why,
                           size_t whysz) {
  command_begin(c, now_ns);
  if (c->running) program_end(c, 0, "superseded");
  c->blk = *b;
  c->result = 0;
  c->closed_in_cmd = 0;
  memset(c->touched, 0, sizeof c->touched);
  memset(c->collided, 0, sizeof c->collided);
  for (int i = 0; i < c->n_obj; i++) {
    memcpy(c->obj[i].cmd_pos, obj_pos(c, i), 3 * sizeof(double));
    memcpy(c->obj[i].cmd_quat, obj_quat(c, i), 4 * sizeof(double));
  }
  if (program_build(c, b, why, whysz) != 0) {
    c->result = 3;
    report(c, "failed", why);
    return -1;
  }
  c->running = 1;
  c->i_ph = 0;
  phase_begin(c);
  return 0;
}

int sim_cell_program_result(const sim_cell *c) { return c->result; }
int sim_cell_program_running(const sim_cell *c) { return c->running; }

void sim_cell_program_stop(sim_cell *c, int64_t now_ns) {
  sim_cell_advance(c, now_ns);
  if (!c->running) return;
  c->running = 0;
  c->result = 0;
  c->last_activity = c->d->time;
  report(c, "stopped", NULL);
}

void sim_cell_fingers_goto(sim_cell *c, int position, int speed, int force, int64_t now_ns) {
  command_begin(c, now_ns);
  const hand_drive *dr = c->drive;
  fingers_set(c, c->spec->stroke_m / 2 * clampd(position, 0, 255) / 255.0,
              dr->speed_min_mps + (dr->speed_max_mps - dr->speed_min_mps) * speed / 255.0,
              dr->force_min_n + (dr->force_max_n - dr->force_min_n) * force / 255.0);
}

void sim_cell_fingers_status(const sim_cell *c, int *position, int *moving, int *obj) {
  *position = fingers_position(c);
  *moving = c->f_moving;
  *obj = c->f_moving ? 0 : c->f_obj;
}

/* ---------------------------------------------------------------- open and close */

void sim_cell_config_default(sim_cell_config *cfg) {
  memset(cfg, 0, sizeof *cfg);
  cfg->gripper = FG_GRIPPER_ROBOTIQ_2F85;
  cfg->approach_m = 0.10;
  cfg->lift_m = 0.10;
  cfg->reach_m = 0.85;
  cfg->time_scale = 1;
}

/* Finds the hand's parts and the objects; checks that every object stands on or above the
 * table. 0, or -1 with err. */
/* The feature vectors of the model's geoms (cell.h, sim_cell_feature): "feature:NAME" for a
 * geom named NAME or NAME/PART, else "feature:background". A model without
 * "feature:background" has none; vectors of different lengths are refused. */
static int feature_index(sim_cell *c, char *err, size_t errsz) {
  const mjModel *m = c->m;
  c->feat_background = mj_name2id(m, mjOBJ_NUMERIC, "feature:background");
  if (c->feat_background < 0) return 0;
  c->feat_dim = m->numeric_size[c->feat_background];
  c->geom_feat = malloc(sizeof *c->geom_feat * (size_t)(m->ngeom ? m->ngeom : 1));
  if (!c->geom_feat) {
    errf(err, errsz, "out of memory");
    return -1;
  }
  for (int g = 0; g < m->ngeom; g++) {
    const char *name = mj_id2name(m, mjOBJ_GEOM, g);
    char key[128];
    snprintf(key, sizeof key, "feature:%.*s", name ? (int)strcspn(name, "/") : 0,
             name ? name : "");
    const int id = name ? mj_name2id(m, mjOBJ_NUMERIC, key) : -1;
    c->geom_feat[g] = id >= 0 ? id : c->feat_background;
    if (m->numeric_size[c->geom_feat[g]] != c->feat_dim) {
      errf(err, errsz, "%s: numeric %s has %d values, feature:background %d",
           c->cfg.scene_path, key, m->numeric_size[c->geom_feat[g]], c->feat_dim);
      return -1;
    }
  }
  return 0;
}

int sim_cell_feature_dim(const sim_cell *c) { return c->feat_dim; }

const double *sim_cell_feature(const sim_cell *c, int geom) {
  if (!c->feat_dim) return NULL;
  const int id = geom >= 0 && geom < c->m->ngeom ? c->geom_feat[geom] : c->feat_background;
  return c->m->numeric_data + c->m->numeric_adr[id];
}

static int cell_index(sim_cell *c, char *err, size_t errsz) {
  const mjModel *m = c->m;
  const int target = mj_name2id(m, mjOBJ_BODY, "fg_target");
  c->mocap = m->body_mocapid[target];
  c->hand = mj_name2id(m, mjOBJ_BODY, "fg_hand");
  c->hand_qadr = m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, "fg_hand")];
  for (int k = 0; k < 2; k++) {
    char name[32];
    snprintf(name, sizeof name, "fg_%s", sim_hand_finger[k]);
    const int j = mj_name2id(m, mjOBJ_JOINT, name);
    c->finger[k] = mj_name2id(m, mjOBJ_BODY, name);
    c->qadr[k] = m->jnt_qposadr[j];
    c->dadr[k] = m->jnt_dofadr[j];
    c->act[k] = mj_name2id(m, mjOBJ_ACTUATOR, name);
  }
  c->table_geom = mj_name2id(m, mjOBJ_GEOM, "table");
  if (c->table_geom < 0) {
    errf(err, errsz, "%s has no geom named \"table\"", c->cfg.scene_path);
    return -1;
  }
  for (int j = 0; j < m->njnt; j++) {
    if (m->jnt_type[j] != mjJNT_FREE) continue;
    const int body = m->jnt_bodyid[j];
    if (body == c->hand) continue;
    if (c->n_obj == CELL_MAX_OBJECTS) {
      errf(err, errsz, "%s has more than %d objects", c->cfg.scene_path, CELL_MAX_OBJECTS);
      return -1;
    }
    cell_object *o = &c->obj[c->n_obj++];
    o->body = body;
    const char *name = mj_id2name(m, mjOBJ_BODY, body);
    if (name) snprintf(o->name, sizeof o->name, "%s", name);
    else snprintf(o->name, sizeof o->name, "body%d", body);
  }
  return 0;
}

/* Before any step: no object may lie below the table's top or reach into the table. */
static int check_on_table(sim_cell *c, char *err, size_t errsz) {
  const mjModel *m = c->m;
  mjData *d = c->d;
  mj_forward(m, d);
  const int tg = c->table_geom;
  /* the top of a level box or plane; any other shape by its bounding sphere */
  const double half = m->geom_type[tg] == mjGEOM_BOX ? m->geom_size[3 * tg + 2]
                      : m->geom_type[tg] == mjGEOM_PLANE ? 0 : m->geom_rbound[tg];
  const double top = d->geom_xpos[3 * tg + 2] + half;
  for (int i = 0; i < c->n_obj; i++)
    if (obj_pos(c, i)[2] < top) {
      errf(err, errsz, "object \"%s\" is below the table's top (z %.4f m < %.4f m)",
           c->obj[i].name, obj_pos(c, i)[2], top);
      return -1;
    }
  for (int k = 0; k < d->ncon; k++) {
    const mjContact *con = &d->contact[k];
    const int other = con->geom1 == tg ? con->geom2 : con->geom2 == tg ? con->geom1 : -1;
    if (other < 0) continue;
    const int i = object_of_body(c, m->geom_bodyid[other]);
    if (i >= 0 && con->dist < -CELL_PENETRATION_M) {
      errf(err, errsz, "object \"%s\" is inside the table (%.1f mm deep)", c->obj[i].name,
           -con->dist * 1e3);
      return -1;
    }
  }
  return 0;
}

sim_cell *sim_cell_open(const sim_cell_config *cfg, char *err, size_t errsz) {
  const fg_gripper_spec *spec = fg_gripper_spec_get(cfg->gripper);
  if (!spec) {
    errf(err, errsz, "unknown gripper model");
    return NULL;
  }
  sim_cell *c = calloc(1, sizeof *c);
  if (!c) {
    errf(err, errsz, "out of memory");
    return NULL;
  }
  c->cfg = *cfg;
  c->spec = spec;
  c->drive = &drives[cfg->gripper];
  c->m = load(cfg->scene_path, cfg->gripper, c->drive, cfg, err, errsz);
  if (!c->m) goto fail;
  c->m->opt.timestep = CELL_TIMESTEP;
  c->m->opt.cone = mjCONE_ELLIPTIC;
  c->m->opt.impratio = 10;
  c->d = mj_makeData(c->m);
  if (!c->d) {
    errf(err, errsz, "out of memory");
    goto fail;
  }
  if (cell_index(c, err, errsz) != 0 || feature_index(c, err, errsz) != 0 ||
      check_on_table(c, err, errsz) != 0)
    goto fail;
  c->f_target = c->f_ramp = 0;
  c->f_speed = c->drive->speed_max_mps / 2;
  c->f_force = c->drive->force_min_n;
  c->f_obj = 3;
  /* the objects settle */
  while (!objects_at_rest(c) || c->d->time < 0.05) {
    if (c->d->time > CELL_SETTLE_MAX) {
      errf(err, errsz, "the objects of %s do not come to rest within %.0f s", cfg->scene_path,
           CELL_SETTLE_MAX);
      goto fail;
    }
    step(c);
  }
  memset(c->touched, 0, sizeof c->touched);
  for (int i = 0; i < c->n_obj; i++) {
    memcpy(c->obj[i].rest_pos, obj_pos(c, i), 3 * sizeof(double));
    memcpy(c->obj[i].rest_quat, obj_quat(c, i), 4 * sizeof(double));
    memcpy(c->obj[i].cmd_pos, obj_pos(c, i), 3 * sizeof(double));
    memcpy(c->obj[i].cmd_quat, obj_quat(c, i), 4 * sizeof(double));
  }
  c->at_rest = 1;
  c->last_activity = c->d->time;
  return c;
fail:
  sim_cell_close(c);
  return NULL;
}

void sim_cell_close(sim_cell *c) {
  if (!c) return;
  if (c->d) mj_deleteData(c->d);
  if (c->m) mj_deleteModel(c->m);
  free(c->geom_feat);
  free(c);
}
