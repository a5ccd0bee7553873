/* A job's record: its state, the parameters every job shows, the copy of its progress that
 * handlers read (fg_job_info), and its JSON both ways: the API's Job object and, with its
 * times, the record in last_job.json (jobs.h). Plain data: no lock, no registry. */
#ifndef FG_DAEMON_JOB_INFO_H
#define FG_DAEMON_JOB_INFO_H

#include <stdint.h>

#include <jansson.h>

#include "conf/conf.h"
#include "store.h"

/* Kind names: 1..FG_JOB_KIND_MAX - 1 characters of [a-z_] (jobs.h's table of kinds). */
#define FG_JOB_KIND_MAX 16

/* The order of the metrics gauge's labels (metrics.h). */
typedef enum fg_job_state {
  FG_JOB_QUEUED = 0,
  FG_JOB_RUNNING,
  FG_JOB_DONE,
  FG_JOB_FAILED,
  FG_JOB_CANCELLED,
  FG_JOB_N_STATES
} fg_job_state;

/* "queued", "running", "done", "failed", "cancelled". */
const char *fg_job_state_name(fg_job_state s);
/* 1 for done, failed and cancelled. */
int fg_job_state_finished(fg_job_state s);

#define FG_TRAIN_MAX_STEPS 1000000
#define FG_JOB_MAX_CAPTURES 16 /* captures one training may name */

/* The parameters every job shows in the API (proto/openapi.yaml, Job); a training reads all
 * of them, another kind those that mean something to it (0 for the others) and takes its own
 * through fg_jobs_submit's kind_params. */
typedef struct fg_job_params {
  int64_t steps;      /* 1..FG_TRAIN_MAX_STEPS */
  uint64_t seed;
  double max_seconds; /* wall-clock limit, > 0; 0: none */
  int holdout_every;  /* 0: no frame held out; k: frames i with i % k == 0 (i counts the
                         scene's frames in number order from 0) are held out for PSNR */
  double depth_weight;      /* weight of the depth loss (field/train.h) */
  double distortion_weight; /* weight of the distortion loss */
  /* The captures (store.h) a training uses: captures[0..n_captures), or every one
   * (all_captures), or, when both are 0, the newest that holds frames ("latest"). */
  int64_t captures[FG_JOB_MAX_CAPTURES];
  int n_captures;
  int all_captures;
  int init_current; /* 1: start from the scene's field ("init": "current"), 0: "random" */
  double focus;     /* an update's share of rays drawn where the views changed
                       (fg_trainer_focus); 0: none */
} fg_job_params;

/* A consistent copy of a job. Times in Unix milliseconds, 0 when not yet. */
typedef struct fg_job_info {
  char id[FG_JOB_ID_MAX];
  char scene[FG_SCENE_NAME_MAX + 1];   /* the scene worked on; "" for a camera's job */
  char camera[FG_CAMERA_NAME_MAX + 1]; /* the camera calibrated; "" for a scene's job */
  char kind[FG_JOB_KIND_MAX]; /* the kind's name, e.g. "train" */
  fg_job_state state;
  fg_job_params params;
  int64_t step;          /* steps taken */
  double loss;           /* last step's loss; NaN before the first step */
  double psnr;           /* held-out PSNR in dB; NaN while unknown or nothing is held out */
  int psnr_full;         /* psnr covers every held-out pixel (1) or a fixed sample (0) */
  int n_frames;          /* frames of the scene the job trains on, held-out ones included */
  int n_heldout;
  int skipped;           /* a scan's viewpoints the robot refused or could not reach */
  double elapsed_s;      /* wall time since it started running */
  double eta_s;          /* seconds to go; NaN when unknown */
  double samples_per_s;  /* over the last step; NaN before the first step */
  int64_t created_ms, started_ms, finished_ms;
  char phase[16];        /* "loading" (frames), "features" (CLIP), "training", "saving";
                            "" until it runs; a finished job keeps its last */
  int features_total;    /* frames that need CLIP features; 0 when there was no such phase */
  int features_done;     /* of those, the ones that have them */
  int features_cached;   /* of done, the ones read from the scene's cache */
  double field_scale;    /* a training's field: its cube over the workspace's extent ... */
  int field_learn_background; /* ... its background ... */
  char field_chosen_by[16]; /* ... and what chose them: "settings", "depth", "cameras",
                               "current field"; "" until the field is set up */
  int64_t changes_cells;   /* an update's focus (fg_train_focus_stats): cells looked at, 0
                              until then and without a focus ... */
  int64_t changes_changed; /* ... those that changed ... */
  int64_t changes_kept;    /* ... and those its rays are drawn from */
  char error[512];       /* "" unless failed */
  uint64_t version;      /* +1 for every change */
} fg_job_info;

/* The job object of the API (proto/openapi.yaml, Job). */
json_t *fg_job_info_json(const fg_job_info *info);

/* Reads a job back from last_job.json (the API object plus created_ms, started_ms,
 * finished_ms). FG_EFORMAT when it is not one. */
int fg_job_info_from_json(json_t *o, fg_job_info *info);

#endif
