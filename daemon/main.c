/* fieldgripd: flags, configuration, start-up, the signal loop and shutdown. */
#include "api/api.h"
#include "state/app.h"
#include "robot/audit.h"
#include "robot/claim.h"
#include "state/clip_svc.h"
#include "conf/conf.h"
#include "decoder/decoder.h"
#include "state/grasp_log.h"
#include "http/http.h"
#include "state/idem.h"
#include "robot/cmd_ids.h"
#include "cell/calib_job.h"
#include "cell/cameras.h"
#include "cell/scan.h"
#include "state/job_train.h"
#include "state/jobs.h"
#include "metrics/metrics.h"
#include "notify.h"
#include "robot/robot.h"
#include "state/store.h"
#include "state/tasks.h"

#include "config.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

#include <errno.h>
#include <getopt.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

typedef struct options {
  const char *config;    /* --config, or NULL */
  const char *listen;    /* --listen override, or NULL */
  const char *state_dir; /* --state-dir override, or NULL */
} options;

static void usage(FILE *out) {
  fprintf(out,
          "Usage: fieldgripd [OPTIONS]\n"
          "Serves fieldgrip's HTTP API: scenes, scans, feature fields, heatmaps and grasps.\n\n"
          "  -c, --config FILE      configuration file (default %s if it exists,\n"
          "                         else built-in defaults)\n"
          "  -l, --listen ADDR      listen on HOST:PORT or [V6]:PORT, overriding [http] listen;\n"
          "                         port 0 picks a free port\n"
          "  -s, --state-dir DIR    keep scenes and frames in DIR, overriding [state] dir\n"
          "      --log-level LEVEL  error, warn, info (default) or debug\n"
          "      --list-routes      print the HTTP routes served, one \"METHOD PATH\" a line\n"
          "                         (paths as proto/openapi.yaml writes them), and exit\n"
          "  -V, --version          print the version and exit\n"
          "  -h, --help             print this help and exit\n\n"
          "Signals: SIGHUP reloads the configuration file, SIGTERM and SIGINT stop.\n",
          FG_CONF_DEFAULT_PATH);
}

/* Prints the route table as "METHOD PATH" lines, PATH with named parameters as
 * proto/openapi.yaml spells them, so that a test can hold the two in step. */
static void list_routes(void) {
  for (size_t i = 0; i < fg_api_n_routes; i++)
    printf("%s %s\n", fg_api_routes[i].method, fg_api_routes[i].metric);
}

static int parse_args(int argc, char **argv, options *o) {
  static const struct option longopts[] = {
    {"config", required_argument, NULL, 'c'},  {"listen", required_argument, NULL, 'l'},
    {"state-dir", required_argument, NULL, 's'}, {"log-level", required_argument, NULL, 'L'},
    {"version", no_argument, NULL, 'V'},       {"help", no_argument, NULL, 'h'},
    {"list-routes", no_argument, NULL, 'R'},
    {NULL, 0, NULL, 0},
  };
  int c;
  while ((c = getopt_long(argc, argv, "c:l:s:Vh", longopts, NULL)) != -1) {
    switch (c) {
    case 'c': o->config = optarg; break;
    case 'l': o->listen = optarg; break;
    case 's': o->state_dir = optarg; break;
    case 'L': {
      enum fg_log_level level;
      if (fg_log_level_parse(optarg, &level) != 0) {
        fprintf(stderr, "fieldgripd: %s\n", fg_error_detail());
        return 2;
      }
      fg_log_set_level(level);
      break;
    }
    case 'V': printf("fieldgripd %s\n", FG_VERSION); return 0;
    case 'h': usage(stdout); return 0;
    case 'R': list_routes(); return 0;
    default: usage(stderr); return 2;
    }
  }
  if (optind < argc) {
    fprintf(stderr, "fieldgripd: unexpected argument '%s'\n", argv[optind]);
    usage(stderr);
    return 2;
  }
  return -1; /* go on */
}

static int replace_str(char **dst, const char *src) {
  char *p = strdup(src);
  if (!p) return -1;
  free(*dst);
  *dst = p;
  return 0;
}

/* Reads the configuration the flags name, with the flags' overrides applied. */
static int load_conf(const options *o, fg_conf **out, char *err, size_t errlen) {
  fg_conf *conf = NULL;
  if (o->config) {
    if (fg_conf_load(o->config, &conf, err, errlen) != 0) return -1;
  } else if (access(FG_CONF_DEFAULT_PATH, F_OK) == 0) {
    if (fg_conf_load(FG_CONF_DEFAULT_PATH, &conf, err, errlen) != 0) return -1;
  } else {
    conf = fg_conf_defaults();
    if (!conf) {
      snprintf(err, errlen, "out of memory");
      return -1;
    }
  }
  if ((o->listen && replace_str(&conf->listen, o->listen) != 0) ||
      (o->state_dir && replace_str(&conf->state_dir, o->state_dir) != 0)) {
    fg_conf_free(conf);
    snprintf(err, errlen, "out of memory");
    return -1;
  }
  if (o->listen) {
    char *host;
    int port;
    if (fg_conf_parse_listen(o->listen, &host, &port) != 0) {
      snprintf(err, errlen, "--listen: %s", fg_error_detail());
      fg_conf_free(conf);
      return -1;
    }
    free(host);
  }
  *out = conf;
  return 0;
}

/* Whether two Modbus peer settings differ in anything the peer uses. */
static int modbus_differs(const fg_conf_modbus *a, const fg_conf_modbus *b) {
  return a->transport != b->transport || strcmp(a->host, b->host) != 0 || a->port != b->port ||
         strcmp(a->device, b->device) != 0 || a->baud != b->baud || a->parity != b->parity ||
         a->unit_id != b->unit_id || a->timeout_ms != b->timeout_ms || a->base != b->base ||
         a->encoding != b->encoding || a->ack_timeout_ms != b->ack_timeout_ms ||
         a->done_timeout_ms != b->done_timeout_ms ||
         a->motion_timeout_ms != b->motion_timeout_ms;
}

/* The robot's default position box: the union of every scene's workspace (robot.h). */
static int scenes_workspace(void *ctx, double min_m[3], double max_m[3]) {
  fg_scene_info *info = NULL;
  size_t n = 0;
  if (fg_store_list(ctx, &info, &n) != 0) return 0;
  for (size_t i = 0; i < n; i++)
    for (int k = 0; k < 3; k++) {
      const double lo = info[i].params.workspace_min[k], hi = info[i].params.workspace_max[k];
      min_m[k] = i == 0 || lo < min_m[k] ? lo : min_m[k];
      max_m[k] = i == 0 || hi > max_m[k] ? hi : max_m[k];
    }
  free(info);
  return n > 0;
}

/* The store's caps from [state]. */
static fg_store_limits store_limits(const fg_conf *conf) {
  return (fg_store_limits){.max_scenes = (size_t)conf->max_scenes,
                           .max_loaded_fields = (size_t)conf->max_loaded_fields};
}

static void reload(fg_app *app, const options *o) {
  fg_notify_reloading();
  char err[1024];
  fg_conf *conf;
  if (load_conf(o, &conf, err, sizeof err) != 0) {
    fg_error("reload failed, keeping the running configuration: %s", err);
    fg_metrics_count_reload(0);
    fg_notify_ready("running; the last reload failed, see the log");
    return;
  }
  const fg_conf *cur = fg_app_conf_acquire(app);
  /* A token dropped while the robot is reachable from the network: keep the one running.
   * Checked against the file alone too, so that it would not first fail at the restart. */
  if (fg_conf_check_exposure(conf, cur) != 0 || fg_conf_check_exposure(conf, NULL) != 0) {
    fg_error("reload failed, keeping the running configuration: %s", fg_error_detail());
    fg_app_conf_release(app, cur);
    fg_conf_free(conf);
    fg_metrics_count_reload(0);
    fg_notify_ready("running; the last reload failed, see the log");
    return;
  }
  if (strcmp(cur->listen, conf->listen) != 0)
    fg_warn("reload: [http] listen changed to %s; it takes effect at the next restart",
            conf->listen);
  if (cur->max_connections != conf->max_connections)
    fg_warn("reload: [http] max_connections changed to %d; it takes effect at the next restart",
            conf->max_connections);
  if (strcmp(cur->state_dir, conf->state_dir) != 0) {
    fg_warn("reload: [state] dir changed to %s; it takes effect at the next restart",
            conf->state_dir);
    replace_str(&conf->state_dir, cur->state_dir);
  }
  /* The Modbus peers keep their connections (and a command in flight keeps its peer). */
  if (modbus_differs(&cur->robot, &conf->robot) ||
      modbus_differs(&cur->gripper_modbus, &conf->gripper_modbus) ||
      cur->gripper_model != conf->gripper_model)
    fg_warn("reload: [robot], [gripper.modbus] or [gripper] model changed; the Modbus peers "
            "keep their settings until the next restart");
  fg_app_conf_release(app, cur);
  /* CLIP: new files are loaded now, while the old model serves; if they do not load, the old
   * model stays (requests in flight keep theirs either way). */
  fg_clip_model *had = fg_clip_svc_acquire(app->clip);
  int clip_changed = 0;
  if (fg_clip_svc_configure(app->clip, conf, &clip_changed) != 0) {
    fg_error("reload: %s; %s", fg_error_detail(),
             had ? "the CLIP model loaded before stays in use"
                 : "there is no CLIP model until the files load (the [clip] endpoints answer "
                   "409)");
    fg_metrics_count_clip_load(0);
  } else if (clip_changed && conf->clip_weights) {
    fg_metrics_count_clip_load(1);
  }
  fg_clip_model_release(had);
  fg_app_set_conf(app, conf);
  const fg_conf *now = fg_app_conf_acquire(app);
  fg_robot_svc_configure(app->robot, now); /* the motion limits apply at once */
  const fg_store_limits limits = store_limits(now);
  fg_store_set_limits(app->store, &limits);
  fg_store_sync_declared(app->store, now);
  fg_app_conf_release(app, now);
  fg_info("configuration reloaded from %s", conf->path ? conf->path : "built-in defaults");
  /* counted last, so that a reload counted in /metrics has done and logged everything */
  fg_metrics_count_reload(1);
  fg_notify_ready("running; configuration reloaded");
}

/* Raises the soft open-files limit to the hard one: every client connection is a file
 * descriptor, and the soft default of 1024 would stall accept() long before [http]
 * max_connections. Failing is not fatal: the HTTP layer fits its cap to the limit. */
static void raise_fd_limit(void) {
  struct rlimit rl;
  if (getrlimit(RLIMIT_NOFILE, &rl) != 0 || rl.rlim_cur >= rl.rlim_max) return;
  rlim_t was = rl.rlim_cur;
  rl.rlim_cur = rl.rlim_max;
  if (setrlimit(RLIMIT_NOFILE, &rl) != 0)
    fg_warn("cannot raise the open-files limit from %llu to %llu: %s", (unsigned long long)was,
            (unsigned long long)rl.rlim_max, strerror(errno));
  else
    fg_debug("open-files limit raised from %llu to %llu", (unsigned long long)was,
             (unsigned long long)rl.rlim_max);
}

static pthread_t g_main_thread;

/* Runs on a thread that did not block SIGHUP, SIGTERM or SIGINT: one that a library started
 * before main() (OpenBLAS starts its pool from a constructor) and so did not inherit the mask.
 * The kernel hands a signal to such a thread whenever the main thread is not inside
 * sigtimedwait, during a reload say, and the default action would end the daemon at once.
 * Passed on to the main thread, which blocks it until its loop takes it. Async-signal-safe. */
static void signal_to_main(int sig) {
  const int saved = errno;
  pthread_kill(g_main_thread, sig);
  errno = saved;
}

/* Opens <state>/audit/robot.log (audit.h) with [robot]'s audit settings. */
static int audit_open(fg_app *app, const fg_conf *conf) {
  char *dir = fg_path_join(conf->state_dir, "audit");
  if (!dir) return FG_ENOMEM;
  const fg_audit_config ac = {.dir = dir, .max_bytes = conf->audit_max_bytes,
                              .keep = conf->audit_keep};
  int rc = fg_audit_open(&app->audit, &ac);
  free(dir);
  return rc;
}

/* Frees what the start-up set up once the configuration was installed, in reverse order;
 * parts not set up yet are NULL. A running training stops after its step and keeps its
 * field. */
static void app_teardown(fg_app *app) {
  fg_cameras_free(app->cameras);
  fg_grasp_log_free(app->grasps);
  fg_tasks_free(app->tasks);
  fg_robot_svc_free(app->robot);
  fg_audit_free(app->audit); /* after the robot: the ends of its last commands are written */
  fg_peer_claim_release(app->claim);
  fg_idem_free(app->idem);
  fg_cmd_ids_free(app->cmd_ids);
  fg_jobs_free(app->jobs);
  fg_decoder_free(app->decoder);
  fg_store_close(app->store);
  fg_clip_svc_free(app->clip);
  fg_app_clear_conf(app);
}

/* OpenMP's waiting threads spin for about 300,000 iterations at every barrier before they
 * sleep (libgomp's default when it has as many cores as threads). A training that shares its
 * cores with anything else then loses most of its time: two trainings of two threads on two
 * cores each took ten times as long as one alone, not twice. With a spin of 1,000 they take
 * twice as long and one alone is as fast as before. libgomp reads its settings before main()
 * runs, so the daemon sets the short spin and starts itself again, unless the environment
 * already chose (GOMP_SPINCOUNT or OMP_WAIT_POLICY). Returns only when it does not restart. */
static void omp_spin_short(char **argv) {
  if (getenv("GOMP_SPINCOUNT") || getenv("OMP_WAIT_POLICY")) return;
  if (setenv("GOMP_SPINCOUNT", "1000", 1) != 0) return;
  execv("/proc/self/exe", argv);
  fg_warn("could not restart with a short OpenMP spin (%s); training may share cores badly",
          strerror(errno));
}

int main(int argc, char **argv) {
  omp_spin_short(argv);
  options o = {0};
  int rc = parse_args(argc, argv, &o);
  if (rc >= 0) return rc;

  /* Signals are taken synchronously by the main thread; every thread started later inherits
   * this mask, so none of them is interrupted. Threads that libraries started before main()
   * did not, and pass what they get on to the main thread (signal_to_main). */
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &sigs, NULL);
  g_main_thread = pthread_self();
  struct sigaction sa = {.sa_handler = signal_to_main, .sa_flags = SA_RESTART};
  sigfillset(&sa.sa_mask);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGHUP, &sa, NULL);
  signal(SIGPIPE, SIG_IGN);

  char err[1024];
  fg_conf *conf;
  if (load_conf(&o, &conf, err, sizeof err) != 0) {
    fg_error("%s", err);
    return 2;
  }
  if (fg_conf_check_exposure(conf, NULL) != 0) {
    fg_error("%s", fg_error_detail());
    fg_conf_free(conf);
    return 2;
  }
  fg_info("fieldgripd %s starting; configuration: %s", FG_VERSION,
          conf->path ? conf->path : "built-in defaults");

  fg_app app = {0};
  pthread_mutex_init(&app.conf_lock, NULL);
  app.threads = fg_conf_threads(conf);
  /* The CLIP model loads once, here or at a reload; files that do not load stop the start
   * like a bad configuration does. */
  if (fg_clip_svc_new(&app.clip) != 0 || fg_clip_svc_configure(app.clip, conf, NULL) != 0) {
    fg_error("%s", fg_error_detail());
    fg_clip_svc_free(app.clip);
    fg_conf_free(conf);
    pthread_mutex_destroy(&app.conf_lock);
    return 2;
  }
  if (conf->clip_weights) fg_metrics_count_clip_load(1);
  const fg_store_limits limits = store_limits(conf);
  if (fg_store_open(&app.store, conf->state_dir, &limits) != 0) {
    fg_error("cannot open the state dir %s: %s", conf->state_dir, fg_error_detail());
    fg_clip_svc_free(app.clip);
    fg_conf_free(conf);
    return 1;
  }
  fg_app_set_conf(&app, conf);
  fg_store_sync_declared(app.store, conf);
  /* Images are decoded by fieldgrip-decode children (one per ingest thread at most), found
   * beside this executable or in the libexec folder. Without it the daemon still serves
   * everything but uploads and imports, which answer 500 saying where it was looked for. */
  if (fg_decoder_new(&app.decoder, NULL, app.threads, FG_DECODER_IDLE_SECONDS) != 0) {
    fg_error("cannot set up the image decoder: %s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }
  if (fg_decoder_check(app.decoder) != 0)
    fg_warn("%s; uploads, imports and renders will fail until it is there", fg_error_detail());
  /* Jobs: each scene's last job comes back from its last_job.json; one kind per job that
   * the API can start. */
  if (fg_jobs_new(&app.jobs, &app) != 0 ||
      fg_jobs_register_kind(app.jobs, &fg_job_kind_train) != 0 ||
      fg_jobs_register_kind(app.jobs, &fg_job_kind_scan) != 0 ||
      fg_jobs_register_kind(app.jobs, &fg_job_kind_calibrate) != 0) {
    fg_error("cannot set up background jobs: %s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }

  /* The robot and the gripper: peers that are down are fine, their workers keep trying. */
  char *robot_dir = fg_path_join(conf->state_dir, "robot");
  char *ids_path = robot_dir ? fg_path_join(robot_dir, "command_ids") : NULL;
  int robot_rc = !ids_path ? FG_ENOMEM : fg_mkdir_p(robot_dir);
  if (robot_rc == 0) robot_rc = fg_idem_open(&app.idem, robot_dir, NULL);
  if (robot_rc == 0) robot_rc = fg_cmd_ids_open(&app.cmd_ids, ids_path);
  /* One daemon per robot: claimed before anything connects to it (claim.h). */
  if (robot_rc == 0) robot_rc = fg_peer_claim_take(&app.claim, conf, conf->listen);
  if (robot_rc == 0) robot_rc = audit_open(&app, conf);
  if (robot_rc == 0) robot_rc = fg_robot_svc_new(&app.robot, conf);
  if (robot_rc == 0) fg_robot_svc_on_finish(app.robot, fg_api_robot_finished, &app);
  if (robot_rc == 0) fg_robot_svc_set_workspace_source(app.robot, scenes_workspace, app.store);
  if (robot_rc == 0) fg_robot_svc_set_ids(app.robot, app.cmd_ids);
  free(robot_dir);
  free(ids_path);
  if (robot_rc != 0) {
    fg_error("cannot set up the robot and gripper: %s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }

  /* The demonstration library; a task that does not load is logged and left out. */
  if (fg_tasks_open(&app.tasks, conf->state_dir) != 0 || fg_grasp_log_new(&app.grasps) != 0) {
    fg_error("cannot set up the task library: %s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }
  /* The cameras' calibrations; one that does not load is logged and left out. */
  if (fg_cameras_new(&app.cameras, conf->state_dir) != 0) {
    fg_error("cannot set up the cameras: %s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }

  long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
  int poll_threads = ncpu > 2 ? (int)(ncpu < 8 ? ncpu : 8) : 2;
  fg_http_config hc = {
    .listen = conf->listen,
    .poll_threads = poll_threads,
    /* Two more than the polling threads: requests waiting for a scene's voxel features to be
     * built (voxcache.h) sleep on an offload thread, and must not hold every one of them
     * while other scenes' heatmaps and renders wait. */
    .offload_threads = poll_threads + 2,
    .routes = fg_api_routes,
    .n_routes = fg_api_n_routes,
    .app = &app,
    .conf_acquire = fg_app_conf_acquire,
    .conf_release = fg_app_conf_release,
  };
  raise_fd_limit();
  fg_http *http;
  char bound[128];
  if (fg_http_start(&http, &hc, bound, sizeof bound) != 0) {
    fg_error("%s", fg_error_detail());
    app_teardown(&app);
    return 1;
  }
  size_t n_scenes, n_frames;
  fg_store_totals(app.store, &n_scenes, &n_frames);
  fg_info("listening on %s (state dir %s, %zu scenes, %zu frames)", bound, conf->state_dir,
          n_scenes, n_frames);
  fg_notify_ready("serving");
  fg_notify_status("serving on %s: %zu scenes, %zu frames", bound, n_scenes, n_frames);

  uint64_t wd_usec = fg_notify_watchdog_usec();
  struct timespec tick = {.tv_sec = 1};
  if (wd_usec) { /* ping at a third of the interval */
    tick.tv_sec = (time_t)(wd_usec / 3 / 1000000);
    tick.tv_nsec = (long)(wd_usec / 3 % 1000000 * 1000);
  }
  for (;;) {
    siginfo_t si;
    int sig = sigtimedwait(&sigs, &si, &tick);
    if (wd_usec) fg_notify_watchdog();
    fg_decoder_reap_idle(app.decoder);
    if (sig < 0) continue; /* timeout or EINTR */
    if (sig == SIGHUP) {
      reload(&app, &o);
      continue;
    }
    fg_info("%s received, stopping", sig == SIGTERM ? "SIGTERM" : "SIGINT");
    break;
  }
  fg_notify_stopping();
  fg_robot_svc_stop(app.robot); /* a command being waited for ends now, as unknown */
  fg_http_stop(http);
  app_teardown(&app);
  pthread_mutex_destroy(&app.conf_lock);
  fg_info("stopped");
  return 0;
}
