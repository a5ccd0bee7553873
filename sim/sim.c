/* fieldgrip-sim: one Modbus TCP server that plays both peers of fieldgripd (proto/modbus.md):
 *
 *   unit --robot-unit (1)    profile pose-registers: holding registers base .. base + 11
 *                            (int16) or base .. base + 18 (float32); acknowledges each new
 *                            seq like the URScript program of proto/modbus.md
 *   unit --gripper-unit (9)  profile robotiq-2f: request registers 0x03E8..0x03EA (holding),
 *                            status registers 0x07D0..0x07D2 (input), with activation, finger
 *                            motion at the requested speed and an optional object
 *
 * With --rtu DEVICE the gripper unit is also served over Modbus RTU on that serial line (one
 * end of a socat pty pair in the tests), as a Robotiq on RS-485 is.
 *
 * Served functions: 3 (read holding), 4 (read input), 6 (write single), 16 (write multiple).
 * Others get exception 1, addresses outside a unit's registers exception 2, and unit ids that
 * are neither peer exception 0x0B (gateway target failed to respond), as a Modbus TCP gateway
 * in front of an RTU bus answers.
 *
 * Time is kept lazily: before every request the simulated state is advanced to the monotonic
 * clock, and the poll loop wakes at the next due event. Several clients may be connected at
 * once (fieldgripd opens one connection per peer). Installed beside fieldgripd, for rehearsing
 * a cell before the hardware arrives; the demo and the tests run it too. */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <getopt.h>
#include <inttypes.h>
#include <limits.h>
#include <math.h>
#include <modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "cell.h"

#define SIM_MAX_CLIENTS 32
#define SIM_NEVER INT64_MAX

/* Robotiq register addresses (proto/modbus.md "Profile robotiq-2f"). */
#define SIM_RQ_OUT 0x03E8
#define SIM_RQ_IN 0x07D0
#define SIM_RQ_FLT_NOT_ACTIVATED 0x07
#define SIM_RQ_FLT_ACTION_DELAYED 0x05

typedef struct {
  char host[256];          /* without brackets; "" = any address */
  int ipv6;                /* host was given as [v6] */
  char service[8];         /* port as text, "0" = pick a free one */
  const char *port_file;   /* NULL: none */
  const char *log_path;    /* NULL: no request log */
  const char *events_path; /* NULL: no log of the robot's motions and stops */
  double time_scale;       /* motions take their length / speed times this (default 1) */
  int robot_unit, gripper_unit;
  int base;                /* first holding register of the robot block */
  int float32;             /* 0 int16 layout (12 registers), 1 float32 layout (19) */
  int ack_init;
  int ack_delay_ms, done_delay_ms;
  int never_ack, fail;
  int exception;           /* 0 none, else the exception code for robot-block writes */
  long drop_after;         /* 0 none, else the 1-based request number to drop */
  int activation_ms, stroke_ms;
  double object_width_mm;  /* < 0: no object */
  double stroke_mm;
  const char *rtu_device;  /* also serve the gripper unit on this serial line; NULL: none */
  const char *report_path; /* the physics cell's report; NULL: none */
  sim_cell_config cell;    /* cell.scene_path != NULL: the physics mode */
} sim_config;

/* The robot block, its pending acknowledgement, and the TCP that the robot program moves:
 * along a straight path from where it is to the pre-pose (approach back along the tool's -z),
 * down to the pose, then to the retreat point, at the block's speed. */
typedef struct {
  modbus_mapping_t *map;   /* holding registers base .. base + n_regs - 1 */
  int n_regs, ack_off, status_off, stop_off;
  int pending;             /* an acknowledgement of pending_seq is scheduled */
  uint16_t pending_seq;
  int64_t ack_due_ns;      /* SIM_NEVER when none */
  int64_t done_due_ns;     /* SIM_NEVER when none */
  int stopped;             /* the stop register holds 1 */
  double tcp[3];           /* TCP position (metres) when not moving */
  double way[4][3];        /* the path of the command in progress */
  int n_way;
  int moving;              /* between the ack and done_due_ns */
  int64_t move_t0_ns;      /* the motion's start (the ack) */
  double speed_mps;
  uint16_t seq;            /* the command in progress */
  FILE *log;               /* the request log, or NULL */
  sim_cell *cell;          /* the physics mode's cell, or NULL */
} sim_robot;

/* The gripper: status bits, finger position and the motion in progress. */
typedef struct {
  modbus_mapping_t *map;   /* holding 0x03E8..0x03EA, input 0x07D0..0x07D2 */
  int act, gto, sta, obj, flt, pr, cu;
  double pos;              /* finger position, 0 open .. 255 closed, when not moving */
  int64_t act_due_ns;      /* end of the activation in progress; SIM_NEVER when none */
  int moving;              /* a motion from p0 (at t0_ns) toward stop is in progress */
  int contact;             /* the motion ends on the object */
  int force;               /* rFR of the motion in progress */
  int64_t t0_ns, arrive_ns;
  double p0, stop;
  double rate;             /* position units per ms */
  int obj_pos;             /* finger position at the object; -1 without an object */
  sim_cell *cell;          /* the physics mode's cell (which moves the fingers), or NULL */
} sim_gripper;

typedef struct {
  sim_config cfg;
  sim_robot robot;
  sim_gripper grip;
  modbus_t *ctx;           /* server context; its socket is switched per client */
  modbus_t *rtu;           /* --rtu: the serial line's context, or NULL */
  int listen_fd, sig_fd;
  int clients[SIM_MAX_CLIENTS];
  int n_clients;
  long n_requests;         /* received so far, over all connections */
  FILE *log;
  sim_cell *cell;          /* the physics mode: the cell; NULL in the kinematic mode */
  FILE *report;            /* --report */
} sim_state;

/* A request as received, for logging and for the simulated side effects. */
typedef struct {
  int unit, fn, addr, n;
  int n_words;             /* words present in the request (writes only) */
  uint16_t words[MODBUS_MAX_WRITE_REGISTERS];
  int well_formed;         /* count and byte count agree (writes) */
} sim_request;

static void usage(FILE *f) {
  fprintf(f,
          "usage: fieldgrip-sim --listen HOST:PORT [options]\n"
          "  --listen HOST:PORT     address to serve (PORT 0: a free port; IPv6 as [::1]:PORT)\n"
          "  --port-file FILE       write the bound port + newline to FILE once listening\n"
          "  --log FILE             append one line per write request received\n"
          "  --events FILE          append one line per robot motion, stop and restart\n"
          "  --time-scale F         motions take length / speed x F (default 1: real time;\n"
          "                         0: at once)\n"
          "  --robot-unit N         unit id of the robot block (default 1)\n"
          "  --gripper-unit N       unit id of the Robotiq gripper (default 9)\n"
          "  --base N               first register of the robot block (default 128)\n"
          "  --encoding E           int16 | float32 (default int16)\n"
          "  --ack-init N           initial value of the ack register (default 0)\n"
          "  --ack-delay-ms N       acknowledge a new seq after N ms (default 0)\n"
          "  --never-ack            never acknowledge\n"
          "  --done-delay-ms N      status busy -> done N ms after the ack (default 0)\n"
          "  --fail                 commands end with status 3 (failed)\n"
          "  --exception CODE       answer robot-block writes with exception CODE (1..11)\n"
          "  --drop-after N         apply the Nth request, then close its connection unanswered\n"
          "  --activation-ms N      gripper activation time (default 100)\n"
          "  --stroke-ms N          full stroke time at speed 255 (default 200)\n"
          "  --object-width-mm W    an object of width W mm between the fingers\n"
          "  --stroke-mm S          gripper stroke in mm (default 85)\n"
          "  --rtu DEVICE           also serve the gripper unit over Modbus RTU on DEVICE\n"
          "                         (115200 8N1; e.g. one end of a socat pty pair)\n"
          "physics mode (MuJoCo): the robot program and the gripper act in a simulated cell\n"
          "  --scene FILE           the cell's MJCF file: a geom named table, objects as\n"
          "                         bodies with a free joint (fieldgrip-scenegen writes one)\n"
          "  --gripper MODEL        panda | robotiq-2f85 | robotiq-2f140 (default robotiq-2f85)\n"
          "  --report FILE          append one JSON line per command's outcome: what the\n"
          "                         fingers touch, what was lifted, what moved\n"
          "  --approach-m M         pick and place without an approach come in this far\n"
          "                         (default 0.10)\n"
          "  --lift-m M             pick without a retreat lifts this far (default 0.10)\n"
          "  --reach-m M            refuse poses farther from the base (default 0.85)\n");
}

/* ---------------------------------------------------------------- time */

static int64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

static int64_t ms_to_ns(double ms) { return (int64_t)llround(ms * 1e6); }

/* ---------------------------------------------------------------- arguments */

static int parse_long(const char *opt, const char *s, long lo, long hi, long *out) {
  char *end;
  errno = 0;
  long v = strtol(s, &end, 10);
  if (errno || end == s || *end || v < lo || v > hi) {
    fprintf(stderr, "fieldgrip-sim: %s wants an integer in %ld..%ld, got \"%s\"\n", opt, lo,
            hi, s);
    return -1;
  }
  *out = v;
  return 0;
}

static int parse_int(const char *opt, const char *s, int lo, int hi, int *out) {
  long v;
  if (parse_long(opt, s, lo, hi, &v) != 0) return -1;
  *out = (int)v;
  return 0;
}

static int parse_mm(const char *opt, const char *s, double *out) {
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || end == s || *end || !isfinite(v) || v < 0 || v > 1000) {
    fprintf(stderr, "fieldgrip-sim: %s wants millimetres in 0..1000, got \"%s\"\n", opt, s);
    return -1;
  }
  *out = v;
  return 0;
}

static int parse_metres(const char *opt, const char *s, double lo, double hi, double *out) {
  char *end;
  errno = 0;
  double v = strtod(s, &end);
  if (errno || end == s || *end || !(v >= lo && v <= hi)) {
    fprintf(stderr, "fieldgrip-sim: %s wants metres in %g..%g, got \"%s\"\n", opt, lo, hi, s);
    return -1;
  }
  *out = v;
  return 0;
}

/* Splits HOST:PORT or [V6]:PORT into cfg->host and cfg->service; returns 0 or -1. */
static int parse_listen(const char *s, sim_config *cfg) {
  const char *colon;
  size_t host_len;
  const char *host = s;
  if (s[0] == '[') {
    const char *close = strchr(s, ']');
    if (!close || close[1] != ':') goto bad;
    host = s + 1;
    host_len = (size_t)(close - host);
    colon = close + 1;
    cfg->ipv6 = 1;
  } else {
    colon = strrchr(s, ':');
    if (!colon || memchr(s, ':', (size_t)(colon - s))) goto bad;
    host_len = (size_t)(colon - s);
  }
  if (host_len >= sizeof cfg->host) goto bad;
  memcpy(cfg->host, host, host_len);
  cfg->host[host_len] = '\0';
  long port;
  if (parse_long("--listen port", colon + 1, 0, 65535, &port) != 0) return -1;
  snprintf(cfg->service, sizeof cfg->service, "%ld", port);
  return 0;
bad:
  fprintf(stderr, "fieldgrip-sim: --listen wants HOST:PORT or [IPV6]:PORT, got \"%s\"\n", s);
  return -1;
}

/* Fills cfg from the command line; returns 0, 1 for --help, or -1 after a message. */
static int parse_args(int argc, char **argv, sim_config *cfg) {
  static const struct option opts[] = {
      {"listen", required_argument, NULL, 'l'},
      {"port-file", required_argument, NULL, 'p'},
      {"log", required_argument, NULL, 'L'},
      {"events", required_argument, NULL, 'V'},
      {"time-scale", required_argument, NULL, 'T'},
      {"robot-unit", required_argument, NULL, 'r'},
      {"gripper-unit", required_argument, NULL, 'g'},
      {"base", required_argument, NULL, 'b'},
      {"encoding", required_argument, NULL, 'e'},
      {"ack-init", required_argument, NULL, 'i'},
      {"ack-delay-ms", required_argument, NULL, 'a'},
      {"never-ack", no_argument, NULL, 'n'},
      {"done-delay-ms", required_argument, NULL, 'd'},
      {"fail", no_argument, NULL, 'f'},
      {"exception", required_argument, NULL, 'x'},
      {"drop-after", required_argument, NULL, 'D'},
      {"activation-ms", required_argument, NULL, 'A'},
      {"stroke-ms", required_argument, NULL, 's'},
      {"object-width-mm", required_argument, NULL, 'o'},
      {"stroke-mm", required_argument, NULL, 'S'},
      {"rtu", required_argument, NULL, 'R'},
      {"scene", required_argument, NULL, 'C'},
      {"gripper", required_argument, NULL, 'G'},
      {"report", required_argument, NULL, 'P'},
      {"approach-m", required_argument, NULL, 1001},
      {"lift-m", required_argument, NULL, 1002},
      {"reach-m", required_argument, NULL, 1003},
      {"help", no_argument, NULL, 'h'},
      {NULL, 0, NULL, 0},
  };
  memset(cfg, 0, sizeof *cfg);
  cfg->robot_unit = 1;
  cfg->time_scale = 1;
  cfg->gripper_unit = 9;
  cfg->base = 128;
  cfg->activation_ms = 100;
  cfg->stroke_ms = 200;
  cfg->object_width_mm = -1;
  cfg->stroke_mm = 85;
  sim_cell_config_default(&cfg->cell);
  int have_listen = 0, have_object = 0, rc = 0, c;
  const int max_ms = 3600000;
  opterr = 0;
  while ((c = getopt_long(argc, argv, "", opts, NULL)) != -1) {
    switch (c) {
    case 'l':
      rc = parse_listen(optarg, cfg);
      have_listen = 1;
      break;
    case 'p': cfg->port_file = optarg; break;
    case 'L': cfg->log_path = optarg; break;
    case 'V': cfg->events_path = optarg; break;
    case 'T': {
      char *end;
      cfg->time_scale = strtod(optarg, &end);
      if (*end || end == optarg || !(cfg->time_scale >= 0 && cfg->time_scale <= 1000)) {
        fprintf(stderr, "fieldgrip-sim: --time-scale expects a number from 0 to 1000, got "
                "'%s'\n", optarg);
        return -1;
      }
      break;
    }
    case 'r': rc = parse_int("--robot-unit", optarg, 0, 255, &cfg->robot_unit); break;
    case 'g': rc = parse_int("--gripper-unit", optarg, 0, 255, &cfg->gripper_unit); break;
    case 'b': rc = parse_int("--base", optarg, 0, 65535 - 18, &cfg->base); break;
    case 'e':
      if (strcmp(optarg, "int16") == 0) {
        cfg->float32 = 0;
      } else if (strcmp(optarg, "float32") == 0) {
        cfg->float32 = 1;
      } else {
        fprintf(stderr, "fieldgrip-sim: --encoding wants int16 or float32, got \"%s\"\n",
                optarg);
        rc = -1;
      }
      break;
    case 'i': rc = parse_int("--ack-init", optarg, 0, 65535, &cfg->ack_init); break;
    case 'a': rc = parse_int("--ack-delay-ms", optarg, 0, max_ms, &cfg->ack_delay_ms); break;
    case 'n': cfg->never_ack = 1; break;
    case 'd': rc = parse_int("--done-delay-ms", optarg, 0, max_ms, &cfg->done_delay_ms); break;
    case 'f': cfg->fail = 1; break;
    case 'x': rc = parse_int("--exception", optarg, 1, 11, &cfg->exception); break;
    case 'D': rc = parse_long("--drop-after", optarg, 1, LONG_MAX, &cfg->drop_after); break;
    case 'A': rc = parse_int("--activation-ms", optarg, 0, max_ms, &cfg->activation_ms); break;
    case 's': rc = parse_int("--stroke-ms", optarg, 1, max_ms, &cfg->stroke_ms); break;
    case 'o':
      rc = parse_mm("--object-width-mm", optarg, &cfg->object_width_mm);
      have_object = 1;
      break;
    case 'S': rc = parse_mm("--stroke-mm", optarg, &cfg->stroke_mm); break;
    case 'R': cfg->rtu_device = optarg; break;
    case 'C': cfg->cell.scene_path = optarg; break;
    case 'G':
      if (fg_gripper_model_parse(optarg, &cfg->cell.gripper) != 0) {
        fprintf(stderr, "fieldgrip-sim: --gripper wants panda, robotiq-2f85 or robotiq-2f140, "
                "got \"%s\"\n", optarg);
        rc = -1;
      }
      break;
    case 'P': cfg->report_path = optarg; break;
    case 1001: rc = parse_metres("--approach-m", optarg, 0, 1, &cfg->cell.approach_m); break;
    case 1002: rc = parse_metres("--lift-m", optarg, 0, 1, &cfg->cell.lift_m); break;
    case 1003: rc = parse_metres("--reach-m", optarg, 0.1, 5, &cfg->cell.reach_m); break;
    case 'h': usage(stdout); return 1;
    default:
      fprintf(stderr, "fieldgrip-sim: unknown or incomplete option \"%s\"\n",
              argv[optind - 1]);
      usage(stderr);
      return -1;
    }
    if (rc != 0) return -1;
  }
  if (optind < argc) {
    fprintf(stderr, "fieldgrip-sim: unexpected argument \"%s\"\n", argv[optind]);
    return -1;
  }
  if (!have_listen) {
    fprintf(stderr, "fieldgrip-sim: --listen HOST:PORT is required\n");
    usage(stderr);
    return -1;
  }
  if (cfg->robot_unit == cfg->gripper_unit) {
    fprintf(stderr, "fieldgrip-sim: --robot-unit and --gripper-unit must differ (both %d)\n",
            cfg->robot_unit);
    return -1;
  }
  if (cfg->stroke_mm <= 0) {
    fprintf(stderr, "fieldgrip-sim: --stroke-mm must be positive\n");
    return -1;
  }
  if (cfg->cell.scene_path && have_object) {
    fprintf(stderr, "fieldgrip-sim: --object-width-mm is of the kinematic mode; with --scene the "
            "cell's objects are what the fingers meet\n");
    return -1;
  }
  if (!cfg->cell.scene_path && cfg->report_path) {
    fprintf(stderr, "fieldgrip-sim: --report needs --scene (the physics mode)\n");
    return -1;
  }
  cfg->cell.time_scale = cfg->time_scale;
  if (cfg->object_width_mm > cfg->stroke_mm) {
    fprintf(stderr, "fieldgrip-sim: --object-width-mm %g is wider than the stroke (%g mm)\n",
            cfg->object_width_mm, cfg->stroke_mm);
    return -1;
  }
  return 0;
}

/* ---------------------------------------------------------------- robot block */

/* Register offsets of proto/modbus.md: the block fieldgrip writes, then ack, status, stop. */
static int robot_init(sim_robot *r, const sim_config *cfg) {
  memset(r, 0, sizeof *r);
  const int words = cfg->float32 ? 23 : 13;
  r->ack_off = words;
  r->status_off = words + 1;
  r->stop_off = words + 2;
  r->n_regs = words + 3;
  r->map = modbus_mapping_new_start_address(0, 0, 0, 0, (unsigned)cfg->base,
                                            (unsigned)r->n_regs, 0, 0);
  if (!r->map) return -1;
  r->map->tab_registers[r->ack_off] = (uint16_t)cfg->ack_init;
  r->ack_due_ns = SIM_NEVER;
  r->done_due_ns = SIM_NEVER;
  r->tcp[0] = 0.30; /* a home pose above the table, as a robot starts at one */
  r->tcp[2] = 0.40;
  return 0;
}

static double f32_at(const uint16_t *w) {
  const uint32_t bits = (uint32_t)w[0] << 16 | w[1];
  float f;
  memcpy(&f, &bits, sizeof f);
  return f;
}

/* The block as the robot program reads it. */
typedef struct {
  int command;
  double p[3], rv[3], width, force, approach, retreat, speed;
} sim_block;

static void block_read(const sim_robot *r, const sim_config *cfg, sim_block *b) {
  const uint16_t *w = r->map->tab_registers;
  b->command = w[1];
  if (cfg->float32) {
    for (int i = 0; i < 3; i++) {
      b->p[i] = f32_at(&w[2 + 2 * i]);
      b->rv[i] = f32_at(&w[8 + 2 * i]);
    }
    b->width = f32_at(&w[14]);
    b->force = w[16];
    b->approach = f32_at(&w[17]);
    b->retreat = f32_at(&w[19]);
    b->speed = f32_at(&w[21]);
    return;
  }
  for (int i = 0; i < 3; i++) {
    b->p[i] = (int16_t)w[2 + i] * 1e-4;
    b->rv[i] = (int16_t)w[5 + i] * 1e-3;
  }
  b->width = w[8] * 1e-4;
  b->force = w[9];
  b->approach = w[10] * 1e-4;
  b->retreat = w[11] * 1e-4;
  b->speed = w[12] * 1e-3;
}

/* The tool's +z in the base frame: R(rv) applied to (0, 0, 1) (Rodrigues). */
static void tool_z(const double rv[3], double z[3]) {
  const double th = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
  if (th < 1e-12) {
    z[0] = z[1] = 0;
    z[2] = 1;
    return;
  }
  const double k[3] = {rv[0] / th, rv[1] / th, rv[2] / th}, c = cos(th), s = sin(th);
  /* v cos + (k x v) sin + k (k . v)(1 - cos) with v = (0, 0, 1) */
  z[0] = k[1] * s + k[0] * k[2] * (1 - c);
  z[1] = -k[0] * s + k[1] * k[2] * (1 - c);
  z[2] = c + k[2] * k[2] * (1 - c);
}

static double path_length(const sim_robot *r) {
  double len = 0;
  for (int i = 1; i < r->n_way; i++) {
    double d2 = 0;
    for (int k = 0; k < 3; k++) d2 += (r->way[i][k] - r->way[i - 1][k]) * (r->way[i][k] - r->way[i - 1][k]);
    len += sqrt(d2);
  }
  return len;
}

/* Where the TCP is at time t of the motion in progress. */
static void tcp_at(const sim_robot *r, const sim_config *cfg, int64_t t, double p[3]) {
  if (cfg->time_scale == 0) { /* motions are instant: it is where it goes */
    memcpy(p, r->way[r->n_way - 1], sizeof r->way[0]);
    return;
  }
  double left = r->speed_mps * (double)(t - r->move_t0_ns) * 1e-9 / cfg->time_scale;
  memcpy(p, r->way[0], sizeof r->way[0]);
  for (int i = 1; i < r->n_way; i++) {
    double d[3], len = 0;
    for (int k = 0; k < 3; k++) {
      d[k] = r->way[i][k] - r->way[i - 1][k];
      len += d[k] * d[k];
    }
    len = sqrt(len);
    if (left <= len) {
      for (int k = 0; k < 3; k++) p[k] = r->way[i - 1][k] + (len > 0 ? d[k] * left / len : 0);
      return;
    }
    left -= len;
    memcpy(p, r->way[i], sizeof r->way[i]);
  }
}

static void log_point(FILE *f, const char *name, const double p[3]) {
  fprintf(f, " %s=%.4f,%.4f,%.4f", name, p[0], p[1], p[2]);
}

/* The robot program takes the block of seq: builds the path and says how long it runs
 * (ns), or -1 when it refuses the block (a motion without a speed). */
static int64_t robot_start(sim_robot *r, const sim_config *cfg, int64_t now) {
  sim_block b;
  block_read(r, cfg, &b);
  r->n_way = 1;
  memcpy(r->way[0], r->tcp, sizeof r->tcp);
  const int posed = b.command == 1 || b.command == 2 || b.command == 5;
  if (posed) {
    double z[3];
    tool_z(b.rv, z);
    for (int k = 0; k < 3; k++) {
      r->way[1][k] = b.p[k] - b.approach * z[k];
      r->way[2][k] = b.p[k];
      r->way[3][k] = b.p[k] - (b.command == 2 ? b.retreat * z[k] : 0);
    }
    if (b.command == 1) r->way[3][2] += b.retreat;
    r->n_way = 4;
  }
  r->speed_mps = b.speed;
  r->move_t0_ns = now;
  if (r->log) {
    fprintf(r->log, "motion seq=%u cmd=%d", r->map->tab_registers[0], b.command);
    log_point(r->log, "from", r->way[0]);
    if (posed) {
      log_point(r->log, "pre", r->way[1]);
      log_point(r->log, "pose", r->way[2]);
      log_point(r->log, "end", r->way[3]);
    }
    fprintf(r->log, " speed=%.4f approach=%.4f retreat=%.4f\n", b.speed, b.approach, b.retreat);
    fflush(r->log);
  }
  if (r->cell) {
    /* the cell runs the program; robot_advance asks it when it ends */
    const sim_cell_block cb = {r->map->tab_registers[0], b.command, {b.p[0], b.p[1], b.p[2]},
                               {b.rv[0], b.rv[1], b.rv[2]}, b.width, b.force, b.approach,
                               b.retreat, b.speed};
    char why[256];
    return sim_cell_program_start(r->cell, &cb, now, why, sizeof why) != 0 ? -1 : SIM_NEVER;
  }
  if (!posed || path_length(r) == 0) return 0;
  if (!(b.speed > 0)) return -1;
  return (int64_t)(path_length(r) / b.speed * 1e9 * cfg->time_scale);
}

/* Applies the acknowledgement and the end of the command when they are due at now. */
static void robot_advance(sim_robot *r, const sim_config *cfg, int64_t now) {
  uint16_t *reg = r->map->tab_registers;
  if (r->pending && now >= r->ack_due_ns) {
    /* Both in one step, as one function-16 write of the robot program would. */
    const int64_t t = r->ack_due_ns;
    reg[r->status_off] = 1;
    reg[r->ack_off] = r->pending_seq;
    r->seq = r->pending_seq;
    r->pending = 0;
    r->ack_due_ns = SIM_NEVER;
    const int64_t run = robot_start(r, cfg, t);
    if (run < 0) {
      reg[r->status_off] = 3;
      r->done_due_ns = SIM_NEVER;
    } else {
      r->moving = 1;
      r->done_due_ns = run == SIM_NEVER ? SIM_NEVER : t + run + ms_to_ns(cfg->done_delay_ms);
    }
  }
  if (r->cell && r->moving && r->done_due_ns == SIM_NEVER &&
      !sim_cell_program_running(r->cell)) {
    /* the cell's program ended: done, or failed; --done-delay-ms counts from here */
    r->done_due_ns = now + ms_to_ns(cfg->done_delay_ms);
    if (sim_cell_program_result(r->cell) == 3) {
      reg[r->status_off] = 3;
      r->moving = 0;
      r->done_due_ns = SIM_NEVER;
    }
  }
  if (now >= r->done_due_ns) {
    reg[r->status_off] = cfg->fail ? 3 : 2;
    r->done_due_ns = SIM_NEVER;
    if (r->moving) memcpy(r->tcp, r->way[r->n_way - 1], sizeof r->tcp);
    r->moving = 0;
  }
}

/* The stop register went to 1: the motion halts where it is (status 4) and nothing new
 * starts until it goes back to 0. */
static void robot_stop(sim_robot *r, const sim_config *cfg, int64_t now) {
  uint16_t *reg = r->map->tab_registers;
  r->stopped = 1;
  r->pending = 0;
  r->ack_due_ns = SIM_NEVER;
  if (r->cell) sim_cell_program_stop(r->cell, now);
  if (r->moving) {
    tcp_at(r, cfg, now, r->tcp);
    r->moving = 0;
    r->done_due_ns = SIM_NEVER;
    reg[r->status_off] = 4;
  }
  if (r->log) {
    fprintf(r->log, "stop seq=%u", r->seq);
    log_point(r->log, "at", r->tcp);
    fputc('\n', r->log);
    fflush(r->log);
  }
}

/* After a write that reached the block: the stop register first; then a seq that is nonzero,
 * not yet acknowledged and not already scheduled starts a new command, superseding one that
 * has not finished. */
static void robot_on_write(sim_robot *r, const sim_config *cfg, int64_t now) {
  const uint16_t *reg = r->map->tab_registers;
  robot_advance(r, cfg, now);
  if (reg[r->stop_off] && !r->stopped) robot_stop(r, cfg, now);
  if (!reg[r->stop_off] && r->stopped) {
    r->stopped = 0;
    if (r->log) {
      fprintf(r->log, "run\n");
      fflush(r->log);
    }
  }
  if (r->stopped) return;
  uint16_t seq = reg[0];
  if (cfg->never_ack || seq == 0 || seq == reg[r->ack_off]) return;
  if (r->pending && seq == r->pending_seq) return;
  if (r->moving) tcp_at(r, cfg, now, r->tcp); /* superseded: the new path starts here */
  r->moving = 0;
  r->pending = 1;
  r->pending_seq = seq;
  r->ack_due_ns = now + ms_to_ns(cfg->ack_delay_ms);
  r->done_due_ns = SIM_NEVER;
  robot_advance(r, cfg, now);
}

/* ---------------------------------------------------------------- gripper */

static int gripper_init(sim_gripper *g, const sim_config *cfg) {
  memset(g, 0, sizeof *g);
  g->map = modbus_mapping_new_start_address(0, 0, 0, 0, SIM_RQ_OUT, 3, SIM_RQ_IN, 3);
  if (!g->map) return -1;
  g->act_due_ns = SIM_NEVER;
  g->obj_pos = -1;
  if (cfg->object_width_mm >= 0)
    g->obj_pos = (int)lround(255.0 * (cfg->stroke_mm - cfg->object_width_mm) / cfg->stroke_mm);
  return 0;
}

/* Finger position at time t (0 open .. 255 closed). */
static double gripper_pos_at(const sim_gripper *g, int64_t t) {
  if (g->cell) {
    int pos, moving, obj;
    sim_cell_fingers_status(g->cell, &pos, &moving, &obj);
    return pos;
  }
  if (!g->moving) return g->pos;
  double travel = fabs(g->stop - g->p0);
  double done = g->rate * (double)(t - g->t0_ns) * 1e-6;
  if (done > travel) done = travel;
  return g->stop > g->p0 ? g->p0 + done : g->p0 - done;
}

/* Freezes the fingers where they are at t. */
static void gripper_halt(sim_gripper *g, int64_t t) {
  g->pos = gripper_pos_at(g, t);
  if (g->cell && g->moving) sim_cell_fingers_goto(g->cell, (int)g->pos, 255, g->force, t);
  g->moving = 0;
}

static void gripper_arrive(sim_gripper *g) {
  g->pos = g->stop;
  g->moving = 0;
  g->obj = g->contact ? 2 : 3;
  /* Holding an object draws current that grows with the force setting (x 10 mA). */
  g->cu = g->contact ? 1 + g->force * 63 / 255 : 0;
}

/* Starts a motion at time t toward the requested position at the requested speed; closing
 * past the object stops at it. */
static void gripper_start_move(sim_gripper *g, const sim_config *cfg, int target, int speed,
                               int force, int64_t t) {
  gripper_halt(g, t);
  g->pr = target;
  g->force = force;
  if (g->cell) {
    sim_cell_fingers_goto(g->cell, target, speed, force, t);
    g->moving = 1;
    g->obj = 0;
    g->cu = 0;
    g->arrive_ns = SIM_NEVER;
    return;
  }
  g->rate = 255.0 / cfg->stroke_ms * (0.25 + 0.75 * speed / 255.0);
  g->stop = target;
  g->contact = 0;
  if (g->obj_pos >= 0 && target > g->obj_pos && g->pos <= g->obj_pos) {
    g->stop = g->obj_pos;
    g->contact = 1;
  }
  g->p0 = g->pos;
  g->t0_ns = t;
  double travel = fabs(g->stop - g->p0);
  if (travel < 1e-9) {
    gripper_arrive(g);
    return;
  }
  g->moving = 1;
  g->obj = 0;
  g->cu = 0;
  g->arrive_ns = t + ms_to_ns(travel / g->rate);
}

/* Applies the end of the activation and the end of a motion when they are due at now. */
static void gripper_advance(sim_gripper *g, const sim_config *cfg, int64_t now) {
  if (now >= g->act_due_ns) {
    int64_t t = g->act_due_ns;
    g->act_due_ns = SIM_NEVER;
    g->sta = 3;
    g->act = 1;
    g->pos = 0; /* activation ends with the fingers fully open */
    g->moving = 0;
    if (g->cell) sim_cell_fingers_goto(g->cell, 0, 255, 0, t);
    const uint16_t *reg = g->map->tab_registers;
    if ((reg[0] >> 8) & 0x08) {
      /* A go-to that waited for the activation runs now. */
      g->flt = 0;
      gripper_start_move(g, cfg, reg[1] & 0xFF, reg[2] >> 8, reg[2] & 0xFF, t);
    }
  }
  if (g->cell && g->moving) {
    /* the cell's fingers stop at the position or on something */
    int pos, moving, obj;
    sim_cell_fingers_status(g->cell, &pos, &moving, &obj);
    if (!moving) {
      g->stop = pos;
      g->contact = obj == 2 || obj == 1;
      gripper_arrive(g);
      g->obj = obj;
    }
    return;
  }
  if (g->moving && now >= g->arrive_ns) gripper_arrive(g);
}

/* After a write that reached the request registers: reset, activation or a go-to. */
static void gripper_on_write(sim_gripper *g, const sim_config *cfg, int64_t now) {
  const uint16_t *reg = g->map->tab_registers;
  int action = reg[0] >> 8;
  int ract = action & 0x01, rgto = (action >> 3) & 0x01;
  g->gto = rgto;
  if (!ract) {
    gripper_halt(g, now);
    g->act = 0;
    g->sta = 0;
    g->obj = 0;
    g->cu = 0;
    g->act_due_ns = SIM_NEVER;
    g->flt = rgto ? SIM_RQ_FLT_NOT_ACTIVATED : 0;
    return;
  }
  if (g->sta == 0) {
    gripper_halt(g, now);
    g->act = 1; /* gACT echoes rACT; gSTA tells when the activation is complete */
    g->sta = 1;
    g->obj = 0;
    g->act_due_ns = now + ms_to_ns(cfg->activation_ms);
  }
  if (g->sta == 1) {
    g->flt = rgto ? SIM_RQ_FLT_ACTION_DELAYED : 0;
    gripper_advance(g, cfg, now); /* an activation of 0 ms completes at once */
    return;
  }
  g->flt = 0;
  if (rgto)
    gripper_start_move(g, cfg, reg[1] & 0xFF, reg[2] >> 8, reg[2] & 0xFF, now);
  else
    gripper_halt(g, now);
}

/* Writes the status (input) registers from the state at now. */
static void gripper_publish(sim_gripper *g, int64_t now) {
  uint16_t *in = g->map->tab_input_registers;
  int status = g->act | g->gto << 3 | g->sta << 4 | g->obj << 6;
  long po = lround(gripper_pos_at(g, now));
  if (po < 0) po = 0;
  if (po > 255) po = 255;
  in[0] = (uint16_t)(status << 8);
  in[1] = (uint16_t)(g->flt << 8 | g->pr);
  in[2] = (uint16_t)(po << 8 | g->cu);
}

/* ---------------------------------------------------------------- state and events */

static void sim_advance(sim_state *s, int64_t now) {
  if (s->cell) sim_cell_advance(s->cell, now);
  robot_advance(&s->robot, &s->cfg, now);
  gripper_advance(&s->grip, &s->cfg, now);
}

/* Milliseconds until the next due event (rounded up), or -1 when nothing is scheduled. */
static int sim_poll_timeout(const sim_state *s, int64_t now) {
  int64_t due = s->robot.ack_due_ns;
  if (s->robot.done_due_ns < due) due = s->robot.done_due_ns;
  if (s->grip.act_due_ns < due) due = s->grip.act_due_ns;
  if (s->grip.moving && s->grip.arrive_ns < due) due = s->grip.arrive_ns;
  if (s->cell && sim_cell_busy(s->cell)) {
    /* the cell steps while something moves: at once, or every 2 ms */
    const int64_t tick = now + (s->cfg.time_scale > 0 ? ms_to_ns(2) : 0);
    if (tick < due) due = tick;
  }
  if (due == SIM_NEVER) return -1;
  if (due <= now) return 0;
  int64_t ms = (due - now + 999999) / 1000000;
  return ms > INT_MAX ? INT_MAX : (int)ms;
}

/* ---------------------------------------------------------------- requests */

static int is_write(int fn) {
  return fn == MODBUS_FC_WRITE_SINGLE_REGISTER || fn == MODBUS_FC_WRITE_MULTIPLE_REGISTERS;
}

/* Decodes the fields of a received request (len bytes, MBAP header first). */
static void request_parse(const uint8_t *req, int len, int header, sim_request *r) {
  memset(r, 0, sizeof *r);
  const uint8_t *pdu = req + header;
  int avail = len - header;
  r->unit = req[header - 1];
  r->fn = pdu[0];
  if (avail >= 5) {
    r->addr = pdu[1] << 8 | pdu[2];
    r->n = pdu[3] << 8 | pdu[4];
  }
  if (r->fn == MODBUS_FC_WRITE_SINGLE_REGISTER && avail >= 5) {
    r->words[0] = (uint16_t)r->n;
    r->n = 1;
    r->n_words = 1;
    r->well_formed = 1;
  } else if (r->fn == MODBUS_FC_WRITE_MULTIPLE_REGISTERS && avail >= 6) {
    int bytes = pdu[5];
    int present = (avail - 6) / 2;
    if (present > bytes / 2) present = bytes / 2;
    if (present > MODBUS_MAX_WRITE_REGISTERS) present = MODBUS_MAX_WRITE_REGISTERS;
    for (int i = 0; i < present; i++) r->words[i] = (uint16_t)(pdu[6 + 2 * i] << 8 | pdu[7 + 2 * i]);
    r->n_words = present;
    r->well_formed = r->n >= 1 && r->n <= MODBUS_MAX_WRITE_REGISTERS && bytes == 2 * r->n &&
                     present == r->n;
  }
}

/* One line per write request, as received: "write unit=U fn=F addr=A n=N words=W1,W2". */
static void request_log(sim_state *s, const sim_request *r) {
  if (!s->log) return;
  fprintf(s->log, "write unit=%d fn=%d addr=%d n=%d words=", r->unit, r->fn, r->addr, r->n);
  for (int i = 0; i < r->n_words; i++) fprintf(s->log, "%s%u", i ? "," : "", r->words[i]);
  fputc('\n', s->log);
  fflush(s->log);
}

/* Whether a write lies wholly inside the mapping's holding registers (so modbus_reply
 * applies it). */
static int write_fits(const modbus_mapping_t *map, const sim_request *r) {
  if (!r->well_formed) return 0;
  int first = r->addr - map->start_registers;
  return first >= 0 && first + r->n <= map->nb_registers;
}

/* Applies a fitting write to the mapping without answering (for --drop-after). */
static void write_apply(modbus_mapping_t *map, const sim_request *r) {
  int first = r->addr - map->start_registers;
  for (int i = 0; i < r->n; i++) map->tab_registers[first + i] = r->words[i];
}

/* Serves one request received on the current socket. Returns 0 to keep the connection,
 * -1 to close it (a send failed, or the request was the one to drop). */
static int sim_handle(sim_state *s, modbus_t *ctx, const uint8_t *req, int len) {
  sim_request r;
  int header = modbus_get_header_length(ctx);
  if (len <= header) return -1;
  request_parse(req, len, header, &r);
  int64_t now = now_ns();
  sim_advance(s, now);
  s->n_requests++;
  int drop = s->cfg.drop_after > 0 && s->n_requests == s->cfg.drop_after;
  if (is_write(r.fn)) request_log(s, &r);

  int robot = r.unit == s->cfg.robot_unit;
  int gripper = r.unit == s->cfg.gripper_unit;
  int code = 0;
  if (!robot && !gripper)
    code = MODBUS_EXCEPTION_GATEWAY_TARGET;
  else if (r.fn != MODBUS_FC_READ_HOLDING_REGISTERS && r.fn != MODBUS_FC_READ_INPUT_REGISTERS &&
           !is_write(r.fn))
    code = MODBUS_EXCEPTION_ILLEGAL_FUNCTION;
  else if (robot && is_write(r.fn) && s->cfg.exception)
    code = s->cfg.exception;
  if (code) {
    if (drop) return -1;
    return modbus_reply_exception(ctx, req, (unsigned)code) < 0 ? -1 : 0;
  }

  modbus_mapping_t *map = robot ? s->robot.map : s->grip.map;
  if (gripper) gripper_publish(&s->grip, now);
  int applied = is_write(r.fn) && write_fits(map, &r);
  if (drop) {
    if (applied) write_apply(map, &r);
  } else if (modbus_reply(ctx, req, len, map) < 0) {
    return -1;
  }
  if (applied) {
    if (robot)
      robot_on_write(&s->robot, &s->cfg, now);
    else
      gripper_on_write(&s->grip, &s->cfg, now);
  }
  return drop ? -1 : 0;
}

/* ---------------------------------------------------------------- server */

static void client_close(sim_state *s, int i) {
  close(s->clients[i]);
  s->clients[i] = s->clients[--s->n_clients];
}

static void client_accept(sim_state *s) {
  int fd = accept4(s->listen_fd, NULL, NULL, SOCK_CLOEXEC);
  if (fd < 0) return;
  if (s->n_clients == SIM_MAX_CLIENTS) {
    fprintf(stderr, "fieldgrip-sim: more than %d clients, refusing one\n", SIM_MAX_CLIENTS);
    close(fd);
    return;
  }
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  s->clients[s->n_clients++] = fd;
}

/* Receives and serves one request from client i; closes it when it went away. */
static void client_serve(sim_state *s, int i) {
  uint8_t req[MODBUS_TCP_MAX_ADU_LENGTH];
  modbus_set_socket(s->ctx, s->clients[i]);
  int len = modbus_receive(s->ctx, req);
  if (len == 0) return; /* ignored by libmodbus */
  if (len < 0 || sim_handle(s, s->ctx, req, len) != 0) client_close(s, i);
}

/* Receives and serves one request from the serial line; a garbled frame is flushed. */
static void rtu_serve(sim_state *s) {
  uint8_t req[MODBUS_RTU_MAX_ADU_LENGTH];
  int len = modbus_receive(s->rtu, req);
  if (len < 0) modbus_flush(s->rtu);
  if (len > 0) sim_handle(s, s->rtu, req, len);
}

/* Writes the port and a newline to path through a temp file and a rename. */
static int port_file_write(const char *path, int port) {
  char tmp[PATH_MAX];
  if (snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid()) >= (int)sizeof tmp) return -1;
  FILE *f = fopen(tmp, "w");
  if (!f) return -1;
  int ok = fprintf(f, "%d\n", port) > 0;
  ok &= fflush(f) == 0 && fsync(fileno(f)) == 0;
  ok &= fclose(f) == 0;
  if (!ok || rename(tmp, path) != 0) {
    unlink(tmp);
    return -1;
  }
  return 0;
}

static int bound_port(int fd) {
  struct sockaddr_storage ss;
  socklen_t len = sizeof ss;
  if (getsockname(fd, (struct sockaddr *)&ss, &len) != 0) return -1;
  if (ss.ss_family == AF_INET) return ntohs(((struct sockaddr_in *)&ss)->sin_port);
  if (ss.ss_family == AF_INET6) return ntohs(((struct sockaddr_in6 *)&ss)->sin6_port);
  return -1;
}

static int log_open(sim_state *s) {
  if (s->cfg.log_path) {
    if (s->log) fclose(s->log);
    s->log = fopen(s->cfg.log_path, "a");
  }
  if (s->cfg.log_path && !s->log) {
    fprintf(stderr, "fieldgrip-sim: cannot open log %s: %s\n", s->cfg.log_path, strerror(errno));
    return -1;
  }
  if (s->cfg.events_path) {
    if (s->robot.log) fclose(s->robot.log);
    s->robot.log = fopen(s->cfg.events_path, "a");
    if (!s->robot.log) {
      fprintf(stderr, "fieldgrip-sim: cannot open %s: %s\n", s->cfg.events_path,
              strerror(errno));
      return -1;
    }
  }
  return 0;
}

/* Sets up the mappings, the signal fd, the log and the listening socket; returns 0 or -1
 * after a message. */
/* The physics mode: the report, then the cell, whose objects settle before the port opens. */
static int cell_open(sim_state *s) {
  if (!s->cfg.cell.scene_path) return 0;
  if (s->cfg.report_path) {
    s->report = fopen(s->cfg.report_path, "a");
    if (!s->report) {
      fprintf(stderr, "fieldgrip-sim: cannot open report %s: %s\n", s->cfg.report_path,
              strerror(errno));
      return -1;
    }
    s->cfg.cell.report = s->report;
  }
  char err[1536];
  s->cell = sim_cell_open(&s->cfg.cell, err, sizeof err);
  if (!s->cell) {
    fprintf(stderr, "fieldgrip-sim: %s\n", err);
    return -1;
  }
  s->robot.cell = s->cell;
  s->grip.cell = s->cell;
  return 0;
}

static int sim_open(sim_state *s) {
  s->listen_fd = -1;
  s->sig_fd = -1;
  if (robot_init(&s->robot, &s->cfg) != 0 || gripper_init(&s->grip, &s->cfg) != 0) {
    fprintf(stderr, "fieldgrip-sim: out of memory\n");
    return -1;
  }
  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGUSR1);
  sigprocmask(SIG_BLOCK, &mask, NULL);
  signal(SIGPIPE, SIG_IGN);
  s->sig_fd = signalfd(-1, &mask, SFD_CLOEXEC);
  if (s->sig_fd < 0) {
    fprintf(stderr, "fieldgrip-sim: signalfd: %s\n", strerror(errno));
    return -1;
  }
  if (log_open(s) != 0 || cell_open(s) != 0) return -1;

  s->ctx = modbus_new_tcp_pi(s->cfg.host[0] ? s->cfg.host : NULL, s->cfg.service);
  if (!s->ctx) {
    fprintf(stderr, "fieldgrip-sim: modbus_new_tcp_pi: %s\n", modbus_strerror(errno));
    return -1;
  }
  /* Kept short: libmodbus sleeps this long before flushing a malformed request. */
  modbus_set_response_timeout(s->ctx, 0, 50000);
  /* SO_REUSEADDR is set by libmodbus, so a restarted simulator binds the port at once. */
  s->listen_fd = modbus_tcp_pi_listen(s->ctx, SIM_MAX_CLIENTS);
  int port = s->listen_fd >= 0 ? bound_port(s->listen_fd) : -1;
  if (port < 0) {
    fprintf(stderr, "fieldgrip-sim: cannot listen on %s%s%s:%s: %s\n", s->cfg.ipv6 ? "[" : "",
            s->cfg.host, s->cfg.ipv6 ? "]" : "", s->cfg.service, modbus_strerror(errno));
    return -1;
  }
  if (s->cfg.port_file && port_file_write(s->cfg.port_file, port) != 0) {
    fprintf(stderr, "fieldgrip-sim: cannot write port file %s: %s\n", s->cfg.port_file,
            strerror(errno));
    return -1;
  }
  if (s->cfg.rtu_device) {
    /* a serial line is a bus: libmodbus answers only the unit set here */
    s->rtu = modbus_new_rtu(s->cfg.rtu_device, 115200, 'N', 8, 1);
    if (!s->rtu || modbus_set_slave(s->rtu, s->cfg.gripper_unit) != 0 ||
        modbus_connect(s->rtu) != 0) {
      fprintf(stderr, "fieldgrip-sim: cannot open %s for RTU: %s\n", s->cfg.rtu_device,
              modbus_strerror(errno));
      return -1;
    }
  }
  fprintf(stderr, "fieldgrip-sim: listening on %s%s%s:%d%s%s\n", s->cfg.ipv6 ? "[" : "",
          s->cfg.host[0] ? s->cfg.host : "0.0.0.0", s->cfg.ipv6 ? "]" : "", port,
          s->rtu ? " and RTU " : "", s->rtu ? s->cfg.rtu_device : "");
  return 0;
}

static void sim_close(sim_state *s) {
  while (s->n_clients > 0) client_close(s, s->n_clients - 1);
  if (s->listen_fd >= 0) close(s->listen_fd);
  if (s->sig_fd >= 0) close(s->sig_fd);
  if (s->rtu) {
    modbus_close(s->rtu);
    modbus_free(s->rtu);
  }
  if (s->ctx) {
    modbus_set_socket(s->ctx, -1);
    modbus_free(s->ctx);
  }
  modbus_mapping_free(s->robot.map);
  modbus_mapping_free(s->grip.map);
  if (s->log) fclose(s->log);
  if (s->robot.log) fclose(s->robot.log);
  sim_cell_close(s->cell);
  if (s->report) fclose(s->report);
}

/* Serves until SIGTERM or SIGINT; returns 0, or -1 when poll fails. */
static int sim_run(sim_state *s) {
  struct pollfd fds[3 + SIM_MAX_CLIENTS];
  for (;;) {
    int64_t now = now_ns();
    sim_advance(s, now);
    int timeout = sim_poll_timeout(s, now);
    fds[0] = (struct pollfd){.fd = s->sig_fd, .events = POLLIN};
    fds[1] = (struct pollfd){.fd = s->listen_fd, .events = POLLIN};
    int n = s->n_clients;
    for (int i = 0; i < n; i++) fds[2 + i] = (struct pollfd){.fd = s->clients[i], .events = POLLIN};
    const int rtu = s->rtu ? 2 + n : -1;
    if (s->rtu) fds[rtu] = (struct pollfd){.fd = modbus_get_socket(s->rtu), .events = POLLIN};
    if (poll(fds, (nfds_t)(2 + n + (s->rtu != NULL)), timeout) < 0) {
      if (errno == EINTR) continue;
      fprintf(stderr, "fieldgrip-sim: poll: %s\n", strerror(errno));
      return -1;
    }
    if (fds[0].revents & POLLIN) {
      struct signalfd_siginfo si;
      if (read(s->sig_fd, &si, sizeof si) == (ssize_t)sizeof si) {
        if (si.ssi_signo == SIGUSR1) {
          log_open(s);
        } else {
          return 0;
        }
      }
    }
    /* Clients from the last to the first, so that closing one (which moves the last into
     * its slot) leaves the slots still to visit in place. */
    for (int i = n - 1; i >= 0; i--) {
      if (fds[2 + i].revents & (POLLIN | POLLHUP | POLLERR)) client_serve(s, i);
    }
    if (rtu >= 0 && (fds[rtu].revents & POLLIN)) rtu_serve(s);
    if (fds[1].revents & POLLIN) client_accept(s);
  }
}

int main(int argc, char **argv) {
  sim_state s;
  memset(&s, 0, sizeof s);
  int rc = parse_args(argc, argv, &s.cfg);
  if (rc != 0) return rc > 0 ? 0 : 2;
  rc = sim_open(&s);
  if (rc == 0) rc = sim_run(&s);
  sim_close(&s);
  return rc == 0 ? 0 : 1;
}
