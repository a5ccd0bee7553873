/* The recent grasps and their fields' identity; see grasp_log.h. */
#include "grasp_log.h"

#include "core/error.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

uint64_t fg_grasp_log_field_version(const fg_voxel_features *vf) {
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
  char scene[FG_SCENE_NAME_MAX + 1];
  fg_grasp_entry *ring; /* (FG_GRASP_LOG_PER_SCENE) */
  int n, head;          /* entries held; next slot to write */
  uint64_t used;        /* log clock at the last put: the least recent is evicted */
} scene_log;

struct fg_grasp_log {
  pthread_mutex_t lock;
  scene_log scenes[FG_GRASP_LOG_SCENES];
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
  for (int i = 0; i < FG_GRASP_LOG_SCENES; i++) free(log->scenes[i].ring);
  pthread_mutex_destroy(&log->lock);
  free(log);
}

static scene_log *find_locked(fg_grasp_log *log, const char *scene) {
  for (int i = 0; i < FG_GRASP_LOG_SCENES; i++)
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
    for (int i = 0; i < FG_GRASP_LOG_SCENES; i++) {
      scene_log *c = &log->scenes[i];
      if (!c->ring) {
        s = c;
        break;
      }
      if (c->used < s->used) s = c;
    }
    if (!s->ring) s->ring = malloc(FG_GRASP_LOG_PER_SCENE * sizeof *s->ring);
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
    s->head = (s->head + 1) % FG_GRASP_LOG_PER_SCENE;
    if (s->n < FG_GRASP_LOG_PER_SCENE) s->n++;
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
