/* fieldgrip-sim: one Modbus TCP server that plays both peers of fieldgripd (proto/modbus.md):
 *
 *   unit --robot-unit (1)    profile pose-registers: holding registers base .. base + 15
 *                            (int16) or base .. base + 25 (float32); acknowledges each new
 *                            seq like the URScript program of proto/modbus.md; and the TCP
 *                            pose, read only, at 400 .. 405 (--tcp-pose-base) as a Universal
 *                            Robots controller publishes it
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
 * With --scene the simulator runs in its physics mode (cell.h): the robot program and the
 * gripper's fingers act on the table and objects of an MJCF file in MuJoCo, and the gripper's
 * status comes from the finger joints. The registers, the failure modes and the logs are the
 * same in both modes. The robot block is in robot.c, the gripper in gripper.c.
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
#include <pthread.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "modbus/regs.h"
#include "gripper.h"
#include "robot.h"

#define SIM_MAX_CLIENTS 32

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
  sim_camera *camera;      /* --camera-listen: the camera on the tool, or NULL */
  pthread_mutex_t lock;    /* held while the cell changes (the camera's thread copies it) */
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
          "  --tcp-pose-base N|none first of the six TCP pose registers (default 400)\n"
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
          "  --reach-m M            refuse poses farther from the base (default 0.85)\n"
          "  --bin X,Y              an open bin 0.34 m square inside, 0.10 m high, on the table\n"
          "                         at X,Y: a place over it drops what the gripper holds; the\n"
          "                         report says of each object whether it lies in the bin\n"
          "  --camera-listen H:P    serve GET /rgb.png and /depth.png (16-bit mm) of the cell\n"
          "                         as a camera on the tool sees it from the current TCP pose\n"
          "  --camera-port-file F   write the camera's bound port + newline to F\n"
          "  --camera-log F         append \"rgb|depth|features x y z qw qx qy qz\" per answer: the\n"
          "                         camera's true pose (world frame, OpenCV convention)\n"
          "  --camera-mount \"x y z qw qx qy qz\"  T_tcp_cam, OpenCV convention (default\n"
          "                         0.05 m behind the TCP, looking along the tool's +z)\n"
          "  --camera \"fx fy cx cy w h [k1 k2 p1 p2]\"  intrinsics (default 600 600 319.5\n"
          "                         239.5 640 480)\n"
          "  --board \"sx sy square_m marker_m DICT x y z yaw_deg\"  a ChArUco board on the\n"
          "                         table, its frame's origin at x y z\n"
          "  --camera-fixed \"x y z qw qx qy qz\"  the camera stands there (T_base_cam) instead\n"
          "                         of riding on the tool\n"
          "  --board-on-tool \"sx sy square_m marker_m DICT x y z qw qx qy qz\"  the tool holds\n"
          "                         the board (T_tcp_board) instead of the table\n"
          "  --camera-patch P       with a scene that holds feature vectors (custom numerics\n"
          "                         feature:NAME, as scenegen writes them), GET /features.npy\n"
          "                         serves one per P x P patch (default 16)\n");
}

/* ---------------------------------------------------------------- time */

static int64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}


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
      {"tcp-pose-base", required_argument, NULL, 1004},
      {"camera-listen", required_argument, NULL, 1005},
      {"camera-port-file", required_argument, NULL, 1006},
      {"camera-mount", required_argument, NULL, 1007},
      {"camera", required_argument, NULL, 1008},
      {"board", required_argument, NULL, 1009},
      {"camera-log", required_argument, NULL, 1010},
      {"camera-fixed", required_argument, NULL, 1011},
      {"board-on-tool", required_argument, NULL, 1012},
      {"camera-patch", required_argument, NULL, 1013},
      {"bin", required_argument, NULL, 1014},
      {"help", no_argument, NULL, 'h'},
      {NULL, 0, NULL, 0},
  };
  memset(cfg, 0, sizeof *cfg);
  cfg->robot_unit = 1;
  cfg->time_scale = 1;
  cfg->gripper_unit = 9;
  cfg->base = 128;
  cfg->tcp_base = 400;
  cfg->activation_ms = 100;
  cfg->stroke_ms = 200;
  cfg->object_width_mm = -1;
  cfg->stroke_mm = 85;
  sim_cell_config_default(&cfg->cell);
  sim_camera_config_default(&cfg->camera);
  char err[512];
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
    case 1014: {
      char tail;
      if (sscanf(optarg, "%lf,%lf%c", &cfg->cell.bin_xy[0], &cfg->cell.bin_xy[1], &tail) != 2 ||
          !isfinite(cfg->cell.bin_xy[0]) || !isfinite(cfg->cell.bin_xy[1]) ||
          fabs(cfg->cell.bin_xy[0]) > 5 || fabs(cfg->cell.bin_xy[1]) > 5) {
        fprintf(stderr, "fieldgrip-sim: --bin wants X,Y in metres (within 5 m of the base), "
                "got \"%s\"\n", optarg);
        rc = -1;
      }
      cfg->cell.has_bin = 1;
      break;
    }
    case 1004:
      if (strcmp(optarg, "none") == 0)
        cfg->tcp_base = -1;
      else
        rc = parse_int("--tcp-pose-base", optarg, 0, 65535 - 6, &cfg->tcp_base);
      break;
    case 1005:
      cfg->camera.on = 1;
      if (snprintf(cfg->camera.listen, sizeof cfg->camera.listen, "%s", optarg) >=
          (int)sizeof cfg->camera.listen) {
        fprintf(stderr, "fieldgrip-sim: --camera-listen is too long\n");
        rc = -1;
      }
      break;
    case 1006: cfg->camera.port_file = optarg; break;
    case 1010: cfg->camera.log_path = optarg; break;
    case 1011: rc = sim_camera_parse_fixed(&cfg->camera, optarg, err, sizeof err); break;
    case 1012: rc = sim_camera_parse_board_on_tool(&cfg->camera, optarg, err, sizeof err); break;
    case 1013: rc = sim_camera_parse_patch(&cfg->camera, optarg, err, sizeof err); break;
    case 1007: rc = sim_camera_parse_mount(&cfg->camera, optarg, err, sizeof err); break;
    case 1008: rc = sim_camera_parse_intrinsics(&cfg->camera, optarg, err, sizeof err); break;
    case 1009: rc = sim_camera_parse_board(&cfg->camera, optarg, err, sizeof err); break;
    case 'h': usage(stdout); return 1;
    default:
      fprintf(stderr, "fieldgrip-sim: unknown or incomplete option \"%s\"\n",
              argv[optind - 1]);
      usage(stderr);
      return -1;
    }
    if (rc != 0) {
      if ((c >= 1007 && c <= 1009) || c == 1011 || c == 1012)
        fprintf(stderr, "fieldgrip-sim: %s\n", err);
      return -1;
    }
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
  const int block_end = cfg->base + (cfg->float32 ? 26 : 16);
  if (cfg->tcp_base >= 0 && cfg->tcp_base < block_end && cfg->base < cfg->tcp_base + 6) {
    fprintf(stderr, "fieldgrip-sim: the TCP pose registers %d..%d overlap the robot block "
            "%d..%d\n", cfg->tcp_base, cfg->tcp_base + 5, cfg->base, block_end - 1);
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
  if (!cfg->cell.scene_path && cfg->camera.on) {
    fprintf(stderr, "fieldgrip-sim: --camera-listen needs --scene (the camera sees the "
            "physics cell)\n");
    return -1;
  }
  if (!cfg->cell.scene_path && cfg->report_path) {
    fprintf(stderr, "fieldgrip-sim: --report needs --scene (the physics mode)\n");
    return -1;
  }
  if (!cfg->cell.scene_path && cfg->cell.has_bin) {
    fprintf(stderr, "fieldgrip-sim: --bin needs --scene (the physics mode)\n");
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

/* ---------------------------------------------------------------- state and events */

static void sim_advance(sim_state *s, int64_t now) {
  if (s->cell) sim_cell_advance(s->cell, now);
  sim_robot_advance(&s->robot, &s->cfg, now);
  sim_gripper_advance(&s->grip, &s->cfg, now);
}

/* Milliseconds until the next due event (rounded up), or -1 when nothing is scheduled. */
static int sim_poll_timeout(const sim_state *s, int64_t now) {
  int64_t due = s->robot.ack_due_ns;
  if (s->robot.done_due_ns < due) due = s->robot.done_due_ns;
  if (s->grip.act_due_ns < due) due = s->grip.act_due_ns;
  if (s->grip.moving && s->grip.arrive_ns < due) due = s->grip.arrive_ns;
  if (s->cell && sim_cell_busy(s->cell)) {
    /* the cell steps while something moves: at once, or every 2 ms */
    const int64_t tick = now + (s->cfg.time_scale > 0 ? sim_ms_to_ns(2) : 0);
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

/* Whether a request addresses the TCP pose registers (any of them). */
static int in_tcp_pose(const sim_state *s, const sim_request *r) {
  const int base = s->cfg.tcp_base;
  return s->robot.tcp_map && r->addr < base + FG_TCP_POSE_WORDS && r->addr + r->n > base;
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
  if (robot && in_tcp_pose(s, &r)) {
    /* read only, as a controller's are */
    if (is_write(r.fn) || r.fn != MODBUS_FC_READ_HOLDING_REGISTERS) {
      if (drop) return -1;
      return modbus_reply_exception(ctx, req, MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS) < 0 ? -1
                                                                                          : 0;
    }
    sim_robot_publish_tcp(&s->robot, &s->cfg, now);
    map = s->robot.tcp_map;
  }
  if (gripper) sim_gripper_publish(&s->grip, now);
  int applied = is_write(r.fn) && write_fits(map, &r);
  if (drop) {
    if (applied) write_apply(map, &r);
  } else if (modbus_reply(ctx, req, len, map) < 0) {
    return -1;
  }
  if (applied) {
    if (robot)
      sim_robot_on_write(&s->robot, &s->cfg, now);
    else
      sim_gripper_on_write(&s->grip, &s->cfg, now);
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
  if (!s->cfg.camera.on) return 0;
  int port;
  s->camera = sim_camera_new(&s->cfg.camera, s->cell, err, sizeof err);
  if (!s->camera || sim_camera_serve(s->camera, &s->lock, &port, err, sizeof err) != 0) {
    fprintf(stderr, "fieldgrip-sim: %s\n", err);
    return -1;
  }
  if (s->cfg.camera.port_file && port_file_write(s->cfg.camera.port_file, port) != 0) {
    fprintf(stderr, "fieldgrip-sim: cannot write port file %s: %s\n", s->cfg.camera.port_file,
            strerror(errno));
    return -1;
  }
  return 0;
}

/* SIGTERM, SIGINT and SIGUSR1 reach the main loop through a pipe: a handler, unlike a
 * signalfd, works whichever thread the signal lands on (libraries start threads of their own
 * before main, which a signal mask set here would not cover). */
static int g_sig_pipe = -1;

static void on_signal(int sig) {
  const int saved = errno;
  const unsigned char b = (unsigned char)sig;
  if (write(g_sig_pipe, &b, 1) < 0) { /* full: a signal of each kind is already waiting */
  }
  errno = saved;
}

/* The pipe's read end, or -1. */
static int signals_open(void) {
  int p[2];
  if (pipe2(p, O_CLOEXEC | O_NONBLOCK) != 0) return -1;
  g_sig_pipe = p[1];
  struct sigaction sa = {.sa_handler = on_signal, .sa_flags = SA_RESTART};
  sigemptyset(&sa.sa_mask);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGUSR1, &sa, NULL);
  signal(SIGPIPE, SIG_IGN);
  return p[0];
}

static int sim_open(sim_state *s) {
  s->listen_fd = -1;
  s->sig_fd = -1;
  if (sim_robot_init(&s->robot, &s->cfg) != 0 || sim_gripper_init(&s->grip, &s->cfg) != 0) {
    fprintf(stderr, "fieldgrip-sim: out of memory\n");
    return -1;
  }
  s->sig_fd = signals_open();
  if (s->sig_fd < 0) {
    fprintf(stderr, "fieldgrip-sim: pipe: %s\n", strerror(errno));
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
  modbus_mapping_free(s->robot.tcp_map);
  modbus_mapping_free(s->grip.map);
  if (s->log) fclose(s->log);
  if (s->robot.log) fclose(s->robot.log);
  sim_camera_free(s->camera); /* its thread first: it copies the cell */
  sim_cell_close(s->cell);
  if (s->report) fclose(s->report);
}

/* Serves until SIGTERM or SIGINT; returns 0, or -1 when poll fails. */
static int sim_run(sim_state *s) {
  struct pollfd fds[3 + SIM_MAX_CLIENTS];
  pthread_mutex_lock(&s->lock);
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
    pthread_mutex_unlock(&s->lock); /* the camera may copy the cell meanwhile */
    const int ready = poll(fds, (nfds_t)(2 + n + (s->rtu != NULL)), timeout);
    pthread_mutex_lock(&s->lock);
    if (ready < 0) {
      if (errno == EINTR) continue;
      fprintf(stderr, "fieldgrip-sim: poll: %s\n", strerror(errno));
      pthread_mutex_unlock(&s->lock);
      return -1;
    }
    if (fds[0].revents & POLLIN) {
      unsigned char sig[16];
      const ssize_t n_sig = read(s->sig_fd, sig, sizeof sig);
      for (ssize_t k = 0; k < n_sig; k++) {
        if (sig[k] != SIGUSR1) {
          pthread_mutex_unlock(&s->lock);
          return 0;
        }
        log_open(s);
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
  pthread_mutex_init(&s.lock, NULL);
  int rc = parse_args(argc, argv, &s.cfg);
  if (rc != 0) return rc > 0 ? 0 : 2;
  rc = sim_open(&s);
  if (rc == 0) rc = sim_run(&s);
  sim_close(&s);
  return rc == 0 ? 0 : 1;
}
