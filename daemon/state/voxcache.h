/* The voxel feature cache of a trained field (query/voxfeat.h): the field sampled once on the
 * scene's workspace grid, shared by every heatmap, demo and grasp search of that field.
 *
 * One fg_voxcache belongs to each trained field the store holds (store.h, fg_field_ref) and
 * dies with it, so a new field (a training committed, a restart, the scene deleted) starts
 * with an empty cache while requests still holding the old field keep using the old one.
 * The cache is built lazily, by the first request that needs it, on that request's thread;
 * requests arriving during the build wait for it instead of building again. A built cache
 * (fg_voxels) is immutable and reference counted: any number of heatmaps read it at once,
 * and one built for another grid (the scene's workspace or voxel size changed in the
 * configuration) replaces it without pulling it from under a reader.
 *
 * The grasp field (grasp/grasp.h) is a function of the voxel features alone, so a built
 * fg_voxels keeps one too: the first demo or grasp search that asks for it builds it on its
 * own thread, requests asking meanwhile wait for that build, and it is freed with its
 * fg_voxels. Its bytes count in the cache's. All functions are thread-safe. */
#ifndef FG_DAEMON_VOXCACHE_H
#define FG_DAEMON_VOXCACHE_H

#include <stddef.h>

#include "field/model.h"
#include "grasp/grasp.h"
#include "query/voxfeat.h"

typedef struct fg_voxcache fg_voxcache;
typedef struct fg_voxels fg_voxels;

/* An empty cache. On success the caller owns *out (fg_voxcache_free). FG_ENOMEM. */
int fg_voxcache_new(fg_voxcache **out);

/* Drops the cache's reference to its voxels (readers holding one keep them). Must not be
 * called while a build runs (the store frees it with the last reference to its field, and a
 * build holds one). Accepts NULL. */
void fg_voxcache_free(fg_voxcache *c);

/* The voxel features of field f (which the caller keeps alive for the call) on grid g:
 * the cached ones when they were built for g, else built now with n_threads (waiting first
 * for a build in progress). On success *out holds a reference the caller drops with
 * fg_voxels_release, and *built_s (may be NULL) receives the seconds this call spent
 * building (0 when it found them built). Errors of fg_voxel_features_build, with its
 * detail; the cache stays as it was. */
int fg_voxcache_get(fg_voxcache *c, const fg_field *f, const fg_voxel_grid *g, int n_threads,
                    fg_voxels **out, double *built_s);

/* The features, owned by v. */
const fg_voxel_features *fg_voxels_features(const fg_voxels *v);

/* The grasp field of v's features: the one v keeps, else built now with n_threads (waiting
 * first for a build in progress) and kept. On success *out is owned by v and valid while the
 * caller holds its reference to v; *built_s (may be NULL) receives the seconds this call
 * spent building (0 when it found it built). Errors of fg_grasp_field_new, with its detail;
 * the next caller tries again. */
int fg_voxels_grasp_field(fg_voxels *v, int n_threads, const fg_grasp_field **out,
                          double *built_s);
/* Accepts NULL. */
void fg_voxels_release(fg_voxels *v);

/* A consistent description of the cache. */
typedef struct fg_voxcache_info {
  int built;            /* voxels are cached */
  int building;         /* a build is in progress */
  size_t bytes;         /* heap bytes of the cached voxels and their grasp field */
  size_t voxels;        /* voxels of their grid */
  size_t kept;          /* voxels that keep features (alpha >= FG_QUERY_ALPHA_FLOOR) */
  double voxel_size;    /* metres */
  double build_seconds; /* wall time of their build */
} fg_voxcache_info;

/* Accepts NULL (all zero). */
void fg_voxcache_describe(fg_voxcache *c, fg_voxcache_info *out);

#endif
