/* The voxel feature cache of a trained field; see voxcache.h. */
#include "voxcache.h"

#include "core/error.h"
#include "core/clock.h"
#include "core/ref.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

struct fg_voxels {
  fg_voxel_features *vf; /* owned */
  fg_ref ref;
  pthread_mutex_t lock;  /* guards the three below */
  pthread_cond_t done;   /* signalled when a grasp field build ends */
  int gf_building;
  fg_grasp_field *gf;    /* owned; NULL until built; reads vf */
};

struct fg_voxcache {
  pthread_mutex_t lock; /* guards the two below */
  pthread_cond_t done;  /* signalled when a build ends */
  int building;
  fg_voxels *current;   /* NULL until built; holds one reference */
};

int fg_voxcache_new(fg_voxcache **out) {
  fg_voxcache *c = calloc(1, sizeof *c);
  if (!c) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&c->lock, NULL);
  pthread_cond_init(&c->done, NULL);
  *out = c;
  return 0;
}

void fg_voxcache_free(fg_voxcache *c) {
  if (!c) return;
  fg_voxels_release(c->current);
  pthread_cond_destroy(&c->done);
  pthread_mutex_destroy(&c->lock);
  free(c);
}

const fg_voxel_features *fg_voxels_features(const fg_voxels *v) { return v->vf; }

void fg_voxels_release(fg_voxels *v) {
  if (v && fg_ref_put(&v->ref)) {
    fg_grasp_field_free(v->gf); /* before the features it reads */
    fg_voxel_features_free(v->vf);
    pthread_cond_destroy(&v->done);
    pthread_mutex_destroy(&v->lock);
    free(v);
  }
}

int fg_voxels_grasp_field(fg_voxels *v, int n_threads, const fg_grasp_field **out,
                          double *built_s) {
  *out = NULL;
  if (built_s) *built_s = 0;
  pthread_mutex_lock(&v->lock);
  while (v->gf_building) pthread_cond_wait(&v->done, &v->lock);
  if (v->gf) {
    *out = v->gf;
    pthread_mutex_unlock(&v->lock);
    return 0;
  }
  v->gf_building = 1;
  pthread_mutex_unlock(&v->lock);

  /* Built without the lock, so that describing the cache never waits for it. */
  const double t0 = fg_mono_s();
  fg_grasp_field *gf = NULL;
  int rc = fg_grasp_field_new(&gf, v->vf, n_threads);
  pthread_mutex_lock(&v->lock);
  v->gf_building = 0;
  if (rc == 0) {
    v->gf = gf;
    *out = gf;
    if (built_s) *built_s = fg_mono_s() - t0;
  }
  pthread_cond_broadcast(&v->done);
  pthread_mutex_unlock(&v->lock);
  return rc;
}

/* Whether the cached voxels were built for grid g. */
static int same_grid(const fg_voxels *v, const fg_voxel_grid *g) {
  const fg_voxel_grid *h = fg_voxel_features_grid(v->vf);
  for (int a = 0; a < 3; a++)
    if (h->min[a] != g->min[a] || h->max[a] != g->max[a]) return 0;
  return h->voxel_size == g->voxel_size && h->nx == g->nx && h->ny == g->ny && h->nz == g->nz;
}

int fg_voxcache_get(fg_voxcache *c, const fg_field *f, const fg_voxel_grid *g, int n_threads,
                    fg_voxels **out, double *built_s) {
  *out = NULL;
  if (built_s) *built_s = 0;
  pthread_mutex_lock(&c->lock);
  while (c->building) pthread_cond_wait(&c->done, &c->lock);
  if (c->current && same_grid(c->current, g)) {
    fg_ref_get(&c->current->ref);
    *out = c->current;
    pthread_mutex_unlock(&c->lock);
    return 0;
  }
  c->building = 1;
  pthread_mutex_unlock(&c->lock);

  /* The build runs without the lock, so that describing the cache never waits for it. */
  double t0 = fg_mono_s();
  fg_voxels *v = calloc(1, sizeof *v);
  int rc = v ? fg_voxel_features_build(&v->vf, f, g, n_threads)
             : fg_fail(FG_ENOMEM, "out of memory");
  if (rc == 0) {
    pthread_mutex_init(&v->lock, NULL);
    pthread_cond_init(&v->done, NULL);
  }
  double seconds = fg_mono_s() - t0;
  fg_voxels *old = NULL;
  pthread_mutex_lock(&c->lock);
  c->building = 0;
  if (rc == 0) {
    fg_ref_init(&v->ref, 2); /* the cache's and the caller's */
    old = c->current;
    c->current = v;
    *out = v;
    if (built_s) *built_s = seconds;
  }
  pthread_cond_broadcast(&c->done);
  pthread_mutex_unlock(&c->lock);
  if (rc != 0) free(v);
  fg_voxels_release(old);
  return rc;
}

void fg_voxcache_describe(fg_voxcache *c, fg_voxcache_info *out) {
  memset(out, 0, sizeof *out);
  if (!c) return;
  pthread_mutex_lock(&c->lock);
  out->building = c->building;
  if (c->current) {
    const fg_voxel_features *vf = c->current->vf;
    out->built = 1;
    out->bytes = fg_voxel_features_bytes(vf);
    pthread_mutex_lock(&c->current->lock); /* order: the cache's lock, then its voxels' */
    if (c->current->gf) out->bytes += fg_grasp_field_bytes(c->current->gf);
    pthread_mutex_unlock(&c->current->lock);
    out->voxels = fg_voxel_grid_count(fg_voxel_features_grid(vf));
    out->kept = fg_voxel_features_n_kept(vf);
    out->voxel_size = fg_voxel_features_grid(vf)->voxel_size;
    out->build_seconds = fg_voxel_features_build_seconds(vf);
  }
  pthread_mutex_unlock(&c->lock);
}
