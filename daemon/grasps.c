/* The daemon's side of lib/grasp; see grasps.h. This file includes grasp/grasp.h and never
 * daemon/conf.h (both define fg_gripper_model). */
#include "grasps.h"

#include "core/error.h"
#include "grasp/grasp.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

_Static_assert(FG_GRASPS_MAX_QUERY_POINTS == FG_GRASP_MAX_QUERY_POINTS, "query point limit");
_Static_assert(FG_GRASPS_MAX_TOP_K == FG_GRASP_MAX_TOP_K, "top_k limit");
_Static_assert(FG_GRASPS_DEFAULT_QUERY_POINTS == FG_GRASP_DEFAULT_QUERY_POINTS, "default N_q");
_Static_assert(FG_GRASPS_MIN_ROTATIONS == FG_GRASP_MIN_ROTATIONS, "rotations limit");

/* ---------------------------------------------------------------- samples and searches */

int fg_grasps_query_points(int n, const double mean_m[3], double std_m, float *p_gripper) {
  return fg_grasp_query_points(n, mean_m, std_m, p_gripper);
}

int fg_grasps_stroke(const char *gripper, double *stroke_m) {
  fg_gripper_model m;
  FG_TRY(fg_gripper_model_parse(gripper, &m));
  *stroke_m = fg_gripper_spec_get(m)->stroke_m;
  return 0;
}

int fg_grasps_sample(const fg_voxel_features *vf, const double T_world_gripper[16],
                     const float *p_gripper, int n, float *z, int n_threads) {
  fg_grasp_field *gf = NULL;
  FG_TRY(fg_grasp_field_new(&gf, vf, n_threads));
  int rc = fg_grasp_sample(gf, T_world_gripper, p_gripper, n, z);
  fg_grasp_field_free(gf);
  return rc;
}

int fg_grasps_find(const fg_grasps_query *q, fg_grasps_result *out) {
  memset(out, 0, sizeof *out);
  fg_grasp_options o;
  fg_grasp_options_default(&o);
  FG_TRY(fg_gripper_model_parse(q->gripper, &o.gripper));
  o.width_m = q->width_m;
  o.candidate_mask = q->candidate_mask;
  o.top_k = q->top_k;
  o.seed = q->seed;
  o.n_threads = q->n_threads;
  if (q->rotations > FG_GRASPS_MAX_ROTATIONS)
    return fg_fail(FG_EINVAL, "rotations must be at most %d", FG_GRASPS_MAX_ROTATIONS);
  o.n_rotations = q->rotations;
  const fg_grasp_target t = {.n_points = q->n_points, .dim = q->dim, .p_gripper = q->p_gripper,
                             .Z = q->Z, .q = q->q};
  fg_grasp_field *gf = NULL;
  FG_TRY(fg_grasp_field_new(&gf, q->vf, q->n_threads));
  fg_grasp_result r;
  int rc = fg_grasp_search(gf, &t, &o, &r);
  fg_grasp_field_free(gf);
  if (rc != 0) return rc;
  if (r.n > 0) {
    out->poses = calloc((size_t)r.n, sizeof *out->poses);
    if (!out->poses) {
      fg_grasp_result_release(&r);
      return fg_fail(FG_ENOMEM, "out of memory");
    }
  }
  for (int i = 0; i < r.n; i++) {
    memcpy(out->poses[i].T_world_gripper, r.poses[i].T_world_gripper,
           sizeof r.poses[i].T_world_gripper);
    out->poses[i].score = r.poses[i].score;
    out->poses[i].cost = r.poses[i].cost;
    out->poses[i].collision_free = r.poses[i].collision_free;
  }
  out->n = r.n;
  out->candidates = r.stats.candidates;
  out->rotations = r.stats.rotations;
  out->poses_scored = r.stats.poses_scored;
  out->poses_optimised = r.stats.poses_optimised;
  out->iterations = r.stats.iterations;
  out->evaluations = r.stats.evaluations;
  out->seconds = r.stats.seconds;
  out->reason = r.reason;
  fg_grasp_result_release(&r);
  return 0;
}

void fg_grasps_result_release(fg_grasps_result *r) {
  if (!r) return;
  free(r->poses);
  memset(r, 0, sizeof *r);
}

/* ---------------------------------------------------------------- field identity */

/* FNV-1a over 64-bit words, then splitmix's finaliser: a few hundred MB/s is plenty for a
 * cache of a few MB, and the bytes are not adversarial. */
static uint64_t hash_bytes(uint64_t h, const void *data, size_t len) {
  const unsigned char *p = data;
  size_t i = 0;
  for (; i + 8 <= len; i += 8) {
    uint64_t w;
    memcpy(&w, p + i, 8);
    h = (h ^ w) * 0x100000001b3ULL;
  }
  for (; i < len; i++) h = (h ^ p[i]) * 0x100000001b3ULL;
  return h;
}

uint64_t fg_grasps_field_version(const fg_voxel_features *vf) {
  uint64_t h = 0xcbf29ce484222325ULL;
  const int64_t steps = fg_voxel_features_trained_steps(vf);
  const int dim = fg_voxel_features_dim(vf);
  const fg_voxel_grid *g = fg_voxel_features_grid(vf);
  h = hash_bytes(h, &steps, sizeof steps);
  h = hash_bytes(h, &dim, sizeof dim);
  h = hash_bytes(h, g->min, sizeof g->min);
  h = hash_bytes(h, g->max, sizeof g->max);
  h = hash_bytes(h, &g->voxel_size, sizeof g->voxel_size);
  const size_t n_vox = fg_voxel_grid_count(g), n_kept = fg_voxel_features_n_kept(vf);
  h = hash_bytes(h, fg_voxel_features_alpha(vf), n_vox * sizeof(float));
  const uint16_t *h16 = NULL;
  fg_voxel_features_raw(vf, NULL, &h16, NULL);
  if (h16) h = hash_bytes(h, h16, n_kept * 64 * sizeof *h16);
  h ^= h >> 31;
  h *= 0x94d049bb133111ebULL;
  return h ^ (h >> 29);
}

/* ---------------------------------------------------------------- recent results */

typedef struct scene_log {
  char scene[FG_GRASPS_NAME_MAX + 1];
  fg_grasp_entry *ring; /* (FG_GRASPS_LOG_PER_SCENE) */
  int n, head;          /* entries held; next slot to write */
  uint64_t used;        /* log clock at the last put: the least recent is evicted */
} scene_log;

struct fg_grasp_log {
  pthread_mutex_t lock;
  scene_log scenes[FG_GRASPS_LOG_SCENES];
  uint64_t clock;
};

int fg_grasp_log_new(fg_grasp_log **out) {
  fg_grasp_log *log = calloc(1, sizeof *log);
  if (!log) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&log->lock, NULL);
  *out = log;
  return 0;
}

void fg_grasp_log_free(fg_grasp_log *log) {
  if (!log) return;
  for (int i = 0; i < FG_GRASPS_LOG_SCENES; i++) free(log->scenes[i].ring);
  pthread_mutex_destroy(&log->lock);
  free(log);
}

static scene_log *find_locked(fg_grasp_log *log, const char *scene) {
  for (int i = 0; i < FG_GRASPS_LOG_SCENES; i++)
    if (log->scenes[i].ring && strcmp(log->scenes[i].scene, scene) == 0) return &log->scenes[i];
  return NULL;
}

static fg_grasp_entry *entry_locked(scene_log *s, const char *id) {
  for (int i = 0; i < s->n; i++)
    if (strcmp(s->ring[i].id, id) == 0) return &s->ring[i];
  return NULL;
}

void fg_grasp_log_put(fg_grasp_log *log, const fg_grasp_entry *e, int n) {
  if (n <= 0) return;
  pthread_mutex_lock(&log->lock);
  scene_log *s = find_locked(log, e[0].scene);
  if (!s) { /* a free slot, else the least recently used scene's */
    s = &log->scenes[0];
    for (int i = 0; i < FG_GRASPS_LOG_SCENES; i++) {
      scene_log *c = &log->scenes[i];
      if (!c->ring) {
        s = c;
        break;
      }
      if (c->used < s->used) s = c;
    }
    if (!s->ring) s->ring = malloc(FG_GRASPS_LOG_PER_SCENE * sizeof *s->ring);
    if (!s->ring) { /* nothing kept: execute will answer 404 for these ids */
      pthread_mutex_unlock(&log->lock);
      return;
    }
    snprintf(s->scene, sizeof s->scene, "%s", e[0].scene);
    s->n = s->head = 0;
  }
  s->used = ++log->clock;
  for (int i = 0; i < n; i++) {
    fg_grasp_entry *old = entry_locked(s, e[i].id);
    if (old) {
      *old = e[i];
      continue;
    }
    s->ring[s->head] = e[i];
    s->head = (s->head + 1) % FG_GRASPS_LOG_PER_SCENE;
    if (s->n < FG_GRASPS_LOG_PER_SCENE) s->n++;
  }
  pthread_mutex_unlock(&log->lock);
}

int fg_grasp_log_get(fg_grasp_log *log, const char *scene, const char *id, fg_grasp_entry *out) {
  pthread_mutex_lock(&log->lock);
  scene_log *s = find_locked(log, scene);
  fg_grasp_entry *e = s ? entry_locked(s, id) : NULL;
  if (e) *out = *e;
  pthread_mutex_unlock(&log->lock);
  return e ? 0 : FG_ENOENT;
}
