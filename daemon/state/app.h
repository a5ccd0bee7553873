/* The daemon's application object: the services every part of fieldgripd reaches (store,
 * decoder pool, jobs, CLIP, robot, idempotency keys, task library, recent grasps) and the
 * configuration in force.
 *
 * The configuration is reference-counted: fg_app_set_conf installs a new one (start-up,
 * SIGHUP) while requests and jobs that started under the old one keep it until they release
 * it; the old one is freed with its last reference. Lower modules (jobs, CLIP, robot) include
 * this header, never api.h, so no daemon file depends on the module that depends on it. */
#ifndef FG_DAEMON_APP_H
#define FG_DAEMON_APP_H

#include <pthread.h>

#include "conf/conf.h"
#include "store.h"

typedef struct fg_conf_ref fg_conf_ref;

typedef struct fg_app {
  fg_store *store;
  pthread_mutex_t conf_lock;
  fg_conf_ref *conf; /* current configuration; requests hold references */
  int threads;       /* [train] threads at start-up, resolved (>= 1): sizes the decoder pool */
  struct fg_decoder *decoder; /* image decoding in child processes (decoder.h) */
  struct fg_jobs *jobs;       /* background jobs: trainings, ... (jobs.h) */
  struct fg_clip_svc *clip;   /* the CLIP model of [clip] (clip_svc.h) */
  struct fg_robot_svc *robot; /* the [robot] and [gripper.modbus] peers (robot.h) */
  struct fg_idem *idem;       /* Idempotency-Keys of actuating requests (idem.h) */
  struct fg_cmd_ids *cmd_ids; /* the robot's command ids, unique across restarts (cmd_ids.h) */
  struct fg_audit *audit;     /* the robot's audit log (audit.h) */
  struct fg_peer_claim *claim; /* this daemon's claim on its Modbus peers (claim.h) */
  struct fg_tasks *tasks;     /* the demonstration library (tasks.h) */
  struct fg_grasp_log *grasps; /* recent grasps, for execute (grasp_log.h) */
  struct fg_cameras *cameras; /* the cameras' calibrations and captures (cell/cameras.h) */
} fg_app;

/* Installs conf as the current configuration; the app takes ownership of conf. Requests and
 * jobs already running keep the configuration they acquired; the previous one is freed when
 * its last reference is released. Aborts only when a few bytes cannot be allocated. */
void fg_app_set_conf(fg_app *app, fg_conf *conf);

/* The current configuration with a reference: it stays valid, unchanged, until the caller
 * hands it back with fg_app_conf_release (also the fg_http_config callbacks). A configuration
 * must be installed (fg_app_set_conf) first. */
const fg_conf *fg_app_conf_acquire(fg_app *app);

/* Drops a reference taken by fg_app_conf_acquire; frees conf when it was the last one of a
 * configuration that is no longer current. */
void fg_app_conf_release(fg_app *app, const fg_conf *conf);

/* Drops the app's own reference to the current configuration at shutdown (freed now unless a
 * request still holds it). */
void fg_app_clear_conf(fg_app *app);

#endif
