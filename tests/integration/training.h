/* Helpers for the training and rendering integration tests: a scenegen data set, a scene
 * imported from it, jobs started and waited for, renders and their PNG headers. Like the
 * harness, every helper asserts instead of returning an error. */
#ifndef FG_IT_TRAINING_H
#define FG_IT_TRAINING_H

#include "harness.h"

/* Runs fieldgrip-scenegen (its path as the test's argv[2]) with --out dir --views views
 * --width w --height h --dim dim --holdout 0 (and --patch patch when patch > 0, else
 * scenegen's default feature cells) and asserts that it succeeds. */
void t_scenegen(const char *scenegen, const char *dir, int views, int w, int h, int dim,
                int patch);

/* The same with --depth depth ("png" or "npy") when depth is not NULL. */
void t_scenegen_depth(const char *scenegen, const char *dir, int views, int w, int h, int dim,
                      int patch, const char *depth);

/* GET /v1/scenes/{name}, asserted 200; the caller owns the JSON (json_decref). */
json_t *t_scene_json(const char *name);

/* Writes a configuration with import_dirs = imports, [train] threads = 2, steps = 20. */
void t_write_config(const char *imports);

/* Makes the data set <tmp>/imports/sg with t_scenegen and writes the configuration
 * (t_write_config over <tmp>/imports); returns the data set's folder (caller frees). */
char *t_dataset(const char *scenegen, int views, int w, int h, int dim, int patch);

/* Creates scene name over scenegen's tabletop workspace and imports the data set in dir;
 * asserts n frames came in. */
void t_scene_from_dataset(const char *name, const char *dir, int n);

/* POST /v1/scenes/{scene}/train with body (JSON text); asserts 202, a Location header
 * naming the job and "state": "queued"; returns the job id (caller frees). */
char *t_train(const char *scene, const char *body);

/* GET /v1/jobs/{id}; asserts 200 and returns the job object (caller decrefs). */
json_t *t_job(const char *id);

/* Polls the job until it has finished (done, failed or cancelled) and asserts that it ended
 * in state; returns it (caller decrefs). A hang guard of timeout_s, not a timing assertion. */
json_t *t_wait_job(const char *id, const char *state, double timeout_s);

/* t_train, then t_wait_job until it is done; the job is not kept. */
void t_train_done(const char *scene, const char *body, double timeout_s);

/* Polls until the job runs and has taken at least min_step steps. */
void t_wait_running(const char *id, int min_step, double timeout_s);

/* A camera JSON object text (transform_matrix, fl_x, fl_y, cx, cy, w, h) at eye looking at
 * target, OpenGL convention; caller frees. */
char *t_camera(const double eye[3], const double target[3], double fl, int w, int h);

/* POST /v1/scenes/{scene}/render with body; the caller frees the reply. */
h_resp *t_render(const char *scene, const char *body);

/* Asserts r is a 200 image/png whose signature is PNG's and returns its IHDR fields. */
void t_png_header(const h_resp *r, int *w, int *h, int *bit_depth, int *colour_type);

/* Seconds on the monotonic clock. */
double t_now(void);

#endif
