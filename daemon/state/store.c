#include "store.h"
#include "store_priv.h"

#include "conf/conf.h"
#include "voxcache.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/ref.h"
#include "field/checkpoint.h"


#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

struct fg_field_ref {
  fg_field *field;      /* owned */
  fg_voxcache *voxels;  /* owned: the field's voxel features, built at the first heatmap */
  fg_ref ref;
};

static atomic_uint name_counter;

/* ---------------------------------------------------------------- scene objects */

static void scene_free(fg_scene *s) {
  if (!s) return;
  fg_field_ref_release(s->field);
  free(s->checkpoint_error);
  pthread_mutex_destroy(&s->lock);
  free(s->frames);
  free(s->indices);
  free(s->dir);
  free(s->frames_dir);
  free(s);
}

void fg_scene_ref(fg_scene *s) { fg_ref_get(&s->ref); }

void fg_scene_unref(fg_scene *s) {
  if (s && fg_ref_put(&s->ref)) scene_free(s);
}

static fg_scene *scene_alloc(fg_store *store, const char *name) {
  fg_scene *s = calloc(1, sizeof *s);
  if (!s) return NULL;
  s->store = store;
  snprintf(s->name, sizeof s->name, "%s", name);
  s->dir = fg_path_join(store->scenes_dir, name);
  s->frames_dir = s->dir ? fg_path_join(s->dir, "frames") : NULL;
  fg_ref_init(&s->ref, 1);
  pthread_mutex_init(&s->lock, NULL);
  s->next_capture = 1;
  if (!s->frames_dir) {
    scene_free(s);
    return NULL;
  }
  return s;
}

/* ---------------------------------------------------------------- the trained field */

static int64_t file_size(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 ? (int64_t)st.st_size : 0;
}

static fg_field_ref *field_ref_new(fg_field *f) {
  fg_field_ref *r = calloc(1, sizeof *r);
  if (!r) return NULL;
  if (fg_voxcache_new(&r->voxels) != 0) {
    free(r);
    return NULL;
  }
  r->field = f;
  fg_ref_init(&r->ref, 1);
  return r;
}

/* Frees a ref that field_ref_new made, leaving its field to the caller. */
static void field_ref_discard(fg_field_ref *r) {
  if (!r) return;
  fg_voxcache_free(r->voxels);
  free(r);
}

void fg_field_ref_release(fg_field_ref *r) {
  if (r && fg_ref_put(&r->ref)) {
    fg_voxcache_free(r->voxels);
    fg_field_free(r->field);
    free(r);
  }
}

const fg_field *fg_field_ref_field(const fg_field_ref *r) { return r->field; }

fg_voxcache *fg_field_ref_voxcache(fg_field_ref *r) { return r->voxels; }

/* Records what the scene reports of its field f while f is not loaded. Under the scene's
 * lock. */
static void scene_note_field(fg_scene *s, const fg_field *f) {
  s->trained = 1;
  s->field_feature_dim = f->cfg.feature_dim;
  s->trained_steps = f->trained_steps;
  memcpy(s->field_box_min, f->cfg.box_min, sizeof s->field_box_min);
  s->field_box_size = f->cfg.box_size;
  s->field_learn_background = f->cfg.learn_background;
}

/* Puts the scene's field last in the eviction order. Under the scene's lock. */
static void field_touch(fg_scene *s) {
  s->field_used = atomic_fetch_add(&s->store->field_clock, 1) + 1;
}

static size_t max_loaded_fields(fg_store *st) {
  pthread_mutex_lock(&st->lock);
  size_t max = st->limits.max_loaded_fields;
  pthread_mutex_unlock(&st->lock);
  return max;
}

/* The fields in memory among the store's scenes (a deleted scene's, alive for the requests
 * that hold it, no longer counts). Stable only under fields_lock, which every load holds. */
static size_t fields_loaded(fg_store *st) {
  pthread_mutex_lock(&st->lock);
  size_t n = 0;
  for (size_t i = 0; i < st->n; i++) {
    pthread_mutex_lock(&st->scenes[i]->lock);
    n += st->scenes[i]->field != NULL;
    pthread_mutex_unlock(&st->scenes[i]->lock);
  }
  pthread_mutex_unlock(&st->lock);
  return n;
}

/* Whether the scene's field may leave memory: the scene's reference is its only one (an
 * acquire takes another under the scene's lock, so this holds while the lock is held), and
 * field.fgc brings it back. A partial field came from field.next.fgc, which a training
 * overwrites; it is in field.fgc only once fg_scene_keep_partial moved it. Under the
 * scene's lock. */
static int field_evictable(const fg_scene *s) {
  if (!s->field || !fg_ref_only(&s->field->ref)) return 0;
  if (!s->partial) return 1;
  char *final = fg_path_join(s->dir, "field.fgc");
  int there = final && access(final, F_OK) == 0;
  free(final);
  return there;
}

/* Evicts the least recently acquired field that may leave memory, other than keep's.
 * 0 when every loaded field is in use. Under fields_lock. */
static int evict_one(fg_store *st, const fg_scene *keep) {
  fg_field_ref *victim = NULL;
  char name[FG_SCENE_NAME_MAX + 1] = "";
  pthread_mutex_lock(&st->lock);
  fg_scene *best = NULL;
  for (size_t i = 0; i < st->n; i++) {
    fg_scene *c = st->scenes[i];
    if (c == keep) continue;
    pthread_mutex_lock(&c->lock);
    if (field_evictable(c) && (!best || c->field_used < best->field_used)) best = c;
    pthread_mutex_unlock(&c->lock);
  }
  if (best) {
    pthread_mutex_lock(&best->lock);
    if (field_evictable(best)) { /* else a request took it meanwhile: the caller looks again */
      victim = best->field;
      best->field = NULL;
      snprintf(name, sizeof name, "%s", best->name);
    }
    pthread_mutex_unlock(&best->lock);
  }
  pthread_mutex_unlock(&st->lock);
  if (victim) {
    fg_field_ref_release(victim); /* the last reference: frees the field and its caches */
    atomic_fetch_add(&st->field_evictions, 1);
    fg_info("scene %s: trained field evicted from memory ([state] max_loaded_fields); it "
            "loads again from field.fgc at its next use", name);
  }
  return best != NULL;
}

/* Evicts fields until `room` more fit within max_loaded_fields, sparing keep's. 0, or
 * FG_EBUSY (without a detail) when every loaded field is in use. Under fields_lock. */
static int make_room(fg_store *st, const fg_scene *keep, size_t room) {
  for (;;) {
    const size_t max = max_loaded_fields(st);
    if (max == 0 || fields_loaded(st) + room <= max) return 0;
    if (!evict_one(st, keep)) return FG_EBUSY;
  }
}

/* Takes a reference to the scene's loaded field into *out. 1 when done: the scene had its
 * field in memory, or has none to load (then *out stays NULL); 0 when it must be loaded. */
static int field_take(fg_scene *s, fg_field_ref **out) {
  pthread_mutex_lock(&s->lock);
  int done = 1;
  if (s->field) {
    fg_ref_get(&s->field->ref);
    field_touch(s);
    *out = s->field;
  } else {
    done = !s->trained || s->deleted;
  }
  pthread_mutex_unlock(&s->lock);
  return done;
}

/* Loads field.fgc as the scene's field and takes a reference to it into *out. A checkpoint
 * that does not load any more leaves the scene untrained, as at start-up. Under fields_lock,
 * with room made for the field. */
static int field_load(fg_scene *s, fg_field_ref **out) {
  char *path = fg_path_join(s->dir, "field.fgc");
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  fg_field *f = NULL;
  int rc = fg_checkpoint_load(path, &f);
  free(path);
  fg_field_ref *r = rc == 0 ? field_ref_new(f) : NULL;
  if (rc == 0 && !r) {
    fg_field_free(f);
    rc = fg_fail(FG_ENOMEM, "out of memory");
  }
  if (rc == FG_ENOMEM) return rc;
  pthread_mutex_lock(&s->lock);
  if (rc != 0) {
    char msg[600];
    snprintf(msg, sizeof msg, "field.fgc: %s", fg_error_detail());
    fg_error("scene %s: the trained field does not load again, so the scene is untrained until "
             "it is trained again (the file is left as it is): %s", s->name, msg);
    if (!s->deleted) {
      s->trained = 0;
      free(s->checkpoint_error);
      s->checkpoint_error = strdup(msg);
    }
    rc = 0;
  } else if (!s->deleted) {
    s->field = r;
    scene_note_field(s, f);
    field_touch(s);
    fg_ref_get(&r->ref); /* the caller's, beside the scene's */
    *out = r;
    r = NULL;
    atomic_fetch_add(&s->store->field_loads, 1);
    fg_info("scene %s: trained field loaded again from field.fgc", s->name);
  }
  pthread_mutex_unlock(&s->lock);
  fg_field_ref_release(r); /* the scene was deleted meanwhile */
  return rc;
}

int fg_scene_field_acquire(fg_scene *s, fg_field_ref **out) {
  *out = NULL;
  if (field_take(s, out)) return 0;
  fg_store *st = s->store;
  /* One load at a time: two requests for the same scene load it once, and the count of
   * loaded fields cannot pass the cap between make_room and the load. */
  pthread_mutex_lock(&st->fields_lock);
  int rc = 0;
  if (!field_take(s, out)) {
    if (make_room(st, s, 1) == 0)
      rc = field_load(s, out);
    else
      rc = fg_fail(FG_EBUSY, "the trained field of scene '%s' is not in memory and cannot be "
                   "loaded now: %zu fields are loaded ([state] max_loaded_fields) and requests "
                   "are using every one; send the request again in a moment, or raise [state] "
                   "max_loaded_fields", s->name, max_loaded_fields(st));
  }
  pthread_mutex_unlock(&st->fields_lock);
  return rc;
}

/* Loads the field at start-up (see fg_store_open). Never fails the scene: a checkpoint that
 * does not load leaves it untrained with the reason. */
static void scene_load_field(fg_scene *s) {
  char *final = fg_path_join(s->dir, "field.fgc");
  char *next = fg_path_join(s->dir, "field.next.fgc");
  if (!final || !next) goto out;
  int have_final = access(final, F_OK) == 0, have_next = access(next, F_OK) == 0;
  s->next_at_start = have_next;
  const char *path = have_final ? final : have_next ? next : NULL;
  if (!path) goto out;
  fg_field *f = NULL;
  int rc = fg_checkpoint_load(path, &f);
  if (rc != 0) {
    char msg[600];
    snprintf(msg, sizeof msg, "%s: %s", have_final ? "field.fgc" : "field.next.fgc",
             fg_error_detail());
    fg_error("scene %s: the trained field does not load, so the scene is untrained until it "
             "is trained again (the file is left as it is%s): %s", s->name,
             have_final && have_next ? ", and so is field.next.fgc" : "", msg);
    s->checkpoint_error = strdup(msg);
    goto out;
  }
  /* field.fgc loaded: an unfinished training's field.next.fgc has nothing more to give. */
  if (have_final && have_next) {
    if (unlink(next) == 0)
      fg_info("scene %s: removed field.next.fgc, the checkpoint of a training the daemon did "
              "not finish; field.fgc stays the scene's field", s->name);
    else
      fg_warn("scene %s: cannot remove the leftover %s: %s", s->name, next, strerror(errno));
  }
  s->checkpoint_bytes = file_size(path);
  s->partial = !have_final;
  scene_note_field(s, f);
  /* Read to check it, kept only within the cap; a partial field stays, as field.fgc
   * cannot bring it back. */
  const size_t max = max_loaded_fields(s->store);
  if (!s->partial && max > 0 && fields_loaded(s->store) >= max) {
    fg_info("scene %s: trained field checked (%lld steps, %lld bytes); it loads at its first "
            "use ([state] max_loaded_fields = %zu are loaded)", s->name,
            (long long)f->trained_steps, (long long)s->checkpoint_bytes, max);
    fg_field_free(f);
    goto out;
  }
  s->field = field_ref_new(f);
  if (!s->field) {
    fg_field_free(f);
    s->trained = 0;
    s->checkpoint_error = strdup("out of memory loading the field");
    goto out;
  }
  if (s->partial)
    fg_warn("scene %s: loaded field.next.fgc, the checkpoint of a training the daemon did not "
            "finish (%lld steps); the scene reports \"partial\": true until it is trained again",
            s->name, (long long)f->trained_steps);
  else
    fg_info("scene %s: trained field loaded (%lld steps, %lld bytes)", s->name,
            (long long)f->trained_steps, (long long)s->checkpoint_bytes);
out:
  free(final);
  free(next);
}

int fg_scene_commit_field(fg_scene *s, fg_field *field, const char *next_path) {
  char *final = fg_path_join(s->dir, "field.fgc");
  fg_field_ref *r = field_ref_new(field);
  if (!final || !r) {
    free(final);
    field_ref_discard(r);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  fg_store *st = s->store;
  pthread_mutex_lock(&st->fields_lock);
  pthread_mutex_lock(&s->lock);
  int rc = 0, was_loaded = 0;
  fg_field_ref *old = NULL;
  if (s->deleted) {
    unlink(next_path);
    rc = fg_fail(FG_ENOENT, "scene %s was deleted", s->name);
  } else if (rename(next_path, final) != 0) {
    rc = fg_fail(FG_EIO, "cannot rename %s to %s: %s", next_path, final, strerror(errno));
  } else {
    fg_fsync_dir(s->dir);
    old = s->field;
    was_loaded = old != NULL;
    s->field = r;
    scene_note_field(s, field);
    field_touch(s);
    s->partial = 0;
    s->checkpoint_bytes = file_size(final);
    free(s->checkpoint_error);
    s->checkpoint_error = NULL;
    r = NULL;
  }
  pthread_mutex_unlock(&s->lock);
  field_ref_discard(r); /* on failure; the field stays the caller's */
  fg_field_ref_release(old);
  /* One field more in memory: room is made as for a load; when every other one is in use,
   * the new one waits in field.fgc instead (unless a request took it already). */
  fg_field_ref *unload = NULL;
  if (rc == 0 && !was_loaded && make_room(st, s, 0) != 0) {
    pthread_mutex_lock(&s->lock);
    if (field_evictable(s)) {
      unload = s->field;
      s->field = NULL;
    }
    pthread_mutex_unlock(&s->lock);
    if (unload)
      fg_info("scene %s: trained field saved; it loads at its first use ([state] "
              "max_loaded_fields are loaded and in use)", s->name);
  }
  pthread_mutex_unlock(&st->fields_lock);
  fg_field_ref_release(unload);
  free(final);
  return rc;
}

void fg_scene_keep_partial(fg_scene *s) {
  char *final = fg_path_join(s->dir, "field.fgc");
  char *next = fg_path_join(s->dir, "field.next.fgc");
  pthread_mutex_lock(&s->lock);
  if (final && next && s->trained && s->partial && !s->deleted && access(final, F_OK) != 0 &&
      access(next, F_OK) == 0) {
    if (rename(next, final) == 0) {
      fg_fsync_dir(s->dir);
      fg_info("scene %s: the partial field (field.next.fgc) is now field.fgc, so that the new "
              "training cannot lose it", s->name);
    } else {
      fg_warn("scene %s: cannot rename field.next.fgc to field.fgc: %s", s->name,
              strerror(errno));
    }
  }
  pthread_mutex_unlock(&s->lock);
  free(final);
  free(next);
}

int fg_scene_had_next_checkpoint(fg_scene *s) {
  pthread_mutex_lock(&s->lock);
  int had = s->next_at_start;
  pthread_mutex_unlock(&s->lock);
  return had;
}

void fg_scene_set_last_job(fg_scene *s, const char *id, const char *state) {
  pthread_mutex_lock(&s->lock);
  snprintf(s->last_job_id, sizeof s->last_job_id, "%s", id ? id : "");
  snprintf(s->last_job_state, sizeof s->last_job_state, "%s", state ? state : "");
  pthread_mutex_unlock(&s->lock);
}

int fg_scene_deleted(fg_scene *s) {
  pthread_mutex_lock(&s->lock);
  int d = s->deleted;
  pthread_mutex_unlock(&s->lock);
  return d;
}

const char *fg_scene_dir(const fg_scene *s) { return s->dir; }
const char *fg_scene_name(const fg_scene *s) { return s->name; }

/* ---------------------------------------------------------------- the store */

static int store_insert(fg_store *st, fg_scene *s) {
  if (st->n == st->cap) {
    size_t cap = st->cap ? st->cap * 2 : 16;
    fg_scene **p = realloc(st->scenes, cap * sizeof *p);
    if (!p) return fg_fail(FG_ENOMEM, "out of memory");
    st->scenes = p;
    st->cap = cap;
  }
  st->scenes[st->n++] = s;
  return 0;
}

static fg_scene *store_find_locked(fg_store *st, const char *name, size_t *pos) {
  for (size_t i = 0; i < st->n; i++)
    if (strcmp(st->scenes[i]->name, name) == 0) {
      if (pos) *pos = i;
      return st->scenes[i];
    }
  return NULL;
}

/* 1 when a scene folder holds no scene.json and no frame file: what fg_store_create leaves
 * when it is cut short between creating the folder and writing scene.json. */
static int is_unfinished_create(const fg_scene *s) {
  char *json = fg_path_join(s->dir, "scene.json");
  int has_json = !json || access(json, F_OK) == 0;
  free(json);
  if (has_json) return 0;
  DIR *d = opendir(s->frames_dir);
  if (!d) return errno == ENOENT;
  int empty = 1;
  struct dirent *e;
  while (empty && (e = readdir(d)) != NULL) {
    int index;
    empty = !fg_frame_file_name(e->d_name, &index);
  }
  closedir(d);
  return empty;
}

int fg_store_open(fg_store **out, const char *state_dir, const fg_store_limits *limits) {
  *out = NULL;
  fg_store *st = calloc(1, sizeof *st);
  if (!st) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&st->fields_lock, NULL);
  pthread_mutex_init(&st->lock, NULL);
  st->limits = *limits;
  st->scenes_dir = fg_path_join(state_dir, "scenes");
  int rc = st->scenes_dir ? fg_mkdir_p(st->scenes_dir) : fg_fail(FG_ENOMEM, "out of memory");
  if (rc == 0 && access(st->scenes_dir, W_OK) != 0)
    rc = fg_fail(FG_EIO, "state dir %s is not writable by this user", st->scenes_dir);
  DIR *d = rc == 0 ? opendir(st->scenes_dir) : NULL;
  if (rc == 0 && !d) rc = fg_fail(FG_EIO, "cannot open %s: %s", st->scenes_dir, strerror(errno));
  struct dirent *e;
  while (d && rc == 0 && (e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') {
      if (strncmp(e->d_name, ".trash-", 7) == 0) {
        char *p = fg_path_join(st->scenes_dir, e->d_name);
        if (p && fg_rmtree(p) == 0) fg_info("removed the data of a deleted scene (%s)", e->d_name);
        free(p);
      }
      continue;
    }
    if (fg_scene_name_validate(e->d_name) != 0) continue;
    fg_scene *s = scene_alloc(st, e->d_name);
    if (!s) {
      rc = fg_fail(FG_ENOMEM, "out of memory");
      break;
    }
    fg_fs_sweep_tmp(s->dir);
    if (is_unfinished_create(s)) {
      /* No scene.json and no frame: a creation cut short (by a crash, or a full disk that
       * the cleanup of fg_store_create could not beat); never acknowledged, so removed. */
      if (fg_rmtree(s->dir) == 0)
        fg_info("removed %s, the folder of a scene whose creation did not finish", s->dir);
      scene_free(s);
      continue;
    }
    if (fg_scene_json_read(s->dir, &s->params, &s->created_ms) != 0 || fg_scene_frames_read(s) != 0) {
      fg_error("scene %s is left out: %s", s->name, fg_error_detail());
      scene_free(s);
      continue;
    }
    scene_load_field(s);
    rc = store_insert(st, s);
    if (rc != 0) scene_free(s);
    else fg_info("scene %s: %zu frames", s->name, s->n_frames);
  }
  if (d) closedir(d);
  if (rc != 0) {
    fg_store_close(st);
    return rc;
  }
  if (limits->max_scenes > 0 && st->n > limits->max_scenes)
    fg_warn("the state dir holds %zu scenes, more than [state] max_scenes (%zu): all are "
            "served, but no scene can be created until enough are deleted", st->n,
            limits->max_scenes);
  *out = st;
  return 0;
}

void fg_store_set_limits(fg_store *st, const fg_store_limits *limits) {
  pthread_mutex_lock(&st->fields_lock);
  pthread_mutex_lock(&st->lock);
  st->limits = *limits;
  pthread_mutex_unlock(&st->lock);
  make_room(st, NULL, 0); /* fields in use go once released and others are needed */
  pthread_mutex_unlock(&st->fields_lock);
}

void fg_store_close(fg_store *st) {
  if (!st) return;
  for (size_t i = 0; i < st->n; i++) fg_scene_unref(st->scenes[i]);
  free(st->scenes);
  free(st->scenes_dir);
  pthread_mutex_destroy(&st->lock);
  pthread_mutex_destroy(&st->fields_lock);
  free(st);
}

int fg_store_create(fg_store *st, const char *name, const fg_scene_params *params, int declared) {
  FG_TRY(fg_scene_name_validate(name));
  FG_TRY(fg_scene_params_validate(params));
  pthread_mutex_lock(&st->lock);
  int rc = 0;
  fg_scene *s = NULL;
  if (store_find_locked(st, name, NULL)) {
    rc = fg_fail_as(FG_EEXIST, "scene_exists", "a scene named '%s' exists already; delete it "
                    "first or pick another name", name);
    goto out;
  }
  if (st->limits.max_scenes > 0 && st->n >= st->limits.max_scenes) {
    rc = fg_fail_as(FG_ERANGE, "scene_limit", "scene '%s' was not created: the daemon holds "
                    "%zu scenes, its limit ([state] max_scenes = %zu); delete a scene (DELETE "
                    "/v1/scenes/{s}) or raise [state] max_scenes in the configuration file and "
                    "reload it", name, st->n, st->limits.max_scenes);
    goto out;
  }
  s = scene_alloc(st, name);
  if (!s) {
    rc = fg_state_write_failed(fg_fail(FG_ENOMEM, "out of memory"), "the scene");
    goto out;
  }
  s->params = *params;
  s->declared = declared;
  s->created_ms = fg_real_ms();
  rc = fg_mkdir_p(s->frames_dir);
  if (rc == 0) rc = fg_scene_json_write(s->dir, s->name, &s->params, s->created_ms);
  if (rc == 0) rc = fg_fsync_dir(st->scenes_dir);
  if (rc == 0) rc = store_insert(st, s);
  if (rc == 0) {
    s = NULL;
  } else {
    rc = fg_state_write_failed(rc, "the scene");
    /* Not created (a full disk, say): the folder goes too, or the next start would find a
     * scene folder without its scene.json. */
    fg_rmtree(s->dir);
  }
out:
  pthread_mutex_unlock(&st->lock);
  scene_free(s);
  return rc;
}

fg_scene *fg_store_get(fg_store *st, const char *name) {
  pthread_mutex_lock(&st->lock);
  fg_scene *s = store_find_locked(st, name, NULL);
  if (s) fg_ref_get(&s->ref);
  pthread_mutex_unlock(&st->lock);
  return s;
}

int fg_store_delete(fg_store *st, const char *name) {
  pthread_mutex_lock(&st->lock);
  size_t pos;
  fg_scene *s = store_find_locked(st, name, &pos);
  if (!s) {
    pthread_mutex_unlock(&st->lock);
    return fg_fail_as(FG_ENOENT, "scene_not_found", "no scene named '%s'", name);
  }
  char trash[128];
  snprintf(trash, sizeof trash, ".trash-%s-%ld-%u", name, (long)getpid(),
           atomic_fetch_add(&name_counter, 1));
  char *trash_path = fg_path_join(st->scenes_dir, trash);
  pthread_mutex_lock(&s->lock);
  int rc = 0;
  if (!trash_path) rc = fg_fail(FG_ENOMEM, "out of memory");
  else if (rename(s->dir, trash_path) != 0)
    rc = fg_fail(FG_EIO, "cannot remove scene %s: rename failed: %s", name, strerror(errno));
  if (rc == 0) s->deleted = 1;
  pthread_mutex_unlock(&s->lock);
  if (rc == 0) {
    st->scenes[pos] = st->scenes[--st->n];
    fg_fsync_dir(st->scenes_dir);
  }
  pthread_mutex_unlock(&st->lock);
  if (rc == 0) {
    if (fg_rmtree(trash_path) != 0)
      fg_warn("scene %s deleted, but its data stays in %s until the next start: %s", name,
              trash_path, fg_error_detail());
    fg_scene_unref(s);
  }
  free(trash_path);
  return rc;
}

void fg_scene_get_info(fg_scene *s, fg_scene_info *out) {
  pthread_mutex_lock(&s->lock);
  snprintf(out->name, sizeof out->name, "%s", s->name);
  out->params = s->params;
  out->declared_in_config = s->declared;
  out->created_ms = s->created_ms;
  out->n_frames = s->n_frames;
  fg_scene_capture_info *captures = NULL;
  out->n_captures = 0;
  if (fg_scene_captures_locked(s, &captures, &out->n_captures) != 0) out->n_captures = 0;
  out->latest_capture = out->n_captures ? captures[out->n_captures - 1].capture : 0;
  free(captures);
  out->feature_dim = s->feature_dim;
  out->field_feature_dim = s->trained ? s->field_feature_dim : 0;
  out->trained = s->trained;
  out->loaded = s->field != NULL;
  out->partial = s->trained && s->partial;
  out->trained_steps = s->trained ? s->trained_steps : 0;
  if (s->trained) {
    memcpy(out->field_box_min, s->field_box_min, sizeof out->field_box_min);
    out->field_box_size = s->field_box_size;
    out->field_learn_background = s->field_learn_background;
  } else {
    memset(out->field_box_min, 0, sizeof out->field_box_min);
    out->field_box_size = 0;
    out->field_learn_background = 0;
  }
  out->checkpoint_bytes = s->trained ? s->checkpoint_bytes : 0;
  fg_voxcache_describe(s->field ? s->field->voxels : NULL, &out->voxel_cache);
  snprintf(out->checkpoint_error, sizeof out->checkpoint_error, "%s",
           s->checkpoint_error ? s->checkpoint_error : "");
  snprintf(out->last_job_id, sizeof out->last_job_id, "%s", s->last_job_id);
  snprintf(out->last_job_state, sizeof out->last_job_state, "%s", s->last_job_state);
  pthread_mutex_unlock(&s->lock);
}

static int info_cmp(const void *a, const void *b) {
  return strcmp(((const fg_scene_info *)a)->name, ((const fg_scene_info *)b)->name);
}

int fg_store_list(fg_store *st, fg_scene_info **out, size_t *n) {
  pthread_mutex_lock(&st->lock);
  fg_scene_info *v = calloc(st->n ? st->n : 1, sizeof *v);
  if (!v) {
    pthread_mutex_unlock(&st->lock);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  for (size_t i = 0; i < st->n; i++) fg_scene_get_info(st->scenes[i], &v[i]);
  *n = st->n;
  pthread_mutex_unlock(&st->lock);
  qsort(v, *n, sizeof *v, info_cmp);
  *out = v;
  return 0;
}

void fg_store_totals(fg_store *st, size_t *scenes, size_t *frames) {
  pthread_mutex_lock(&st->lock);
  *scenes = st->n;
  *frames = 0;
  for (size_t i = 0; i < st->n; i++) {
    pthread_mutex_lock(&st->scenes[i]->lock);
    *frames += st->scenes[i]->n_frames;
    pthread_mutex_unlock(&st->scenes[i]->lock);
  }
  pthread_mutex_unlock(&st->lock);
}

size_t fg_store_trained(fg_store *st) {
  pthread_mutex_lock(&st->lock);
  size_t n = 0;
  for (size_t i = 0; i < st->n; i++) {
    pthread_mutex_lock(&st->scenes[i]->lock);
    n += st->scenes[i]->trained;
    pthread_mutex_unlock(&st->scenes[i]->lock);
  }
  pthread_mutex_unlock(&st->lock);
  return n;
}

void fg_store_field_stats_get(fg_store *st, fg_store_field_stats *out) {
  out->loaded = fields_loaded(st);
  out->max_loaded = max_loaded_fields(st);
  out->loads = atomic_load(&st->field_loads);
  out->evictions = atomic_load(&st->field_evictions);
}

size_t fg_store_voxel_cache_bytes(fg_store *st) {
  pthread_mutex_lock(&st->lock);
  size_t n = 0;
  for (size_t i = 0; i < st->n; i++) {
    pthread_mutex_lock(&st->scenes[i]->lock);
    fg_voxcache_info vi;
    fg_voxcache_describe(st->scenes[i]->field ? st->scenes[i]->field->voxels : NULL, &vi);
    n += vi.bytes;
    pthread_mutex_unlock(&st->scenes[i]->lock);
  }
  pthread_mutex_unlock(&st->lock);
  return n;
}

int fg_store_sync_declared(fg_store *st, const struct fg_conf *conf) {
  int first = 0;
  for (size_t i = 0; i < conf->n_scenes; i++) {
    const fg_conf_scene *cs = &conf->scenes[i];
    fg_scene_params p;
    memcpy(p.workspace_min, cs->workspace_min, sizeof p.workspace_min);
    memcpy(p.workspace_max, cs->workspace_max, sizeof p.workspace_max);
    memcpy(p.background, cs->background, sizeof p.background);
    p.voxel_size = cs->voxel_size;
    p.field_scale = cs->field_scale;
    p.learn_background = cs->learn_background;
    fg_scene *s = fg_store_get(st, cs->name);
    int rc = 0;
    if (!s) {
      rc = fg_store_create(st, cs->name, &p, 1);
      if (rc == 0) fg_info("scene %s created from the configuration file", cs->name);
    } else {
      pthread_mutex_lock(&s->lock);
      s->declared = 1;
      if (!fg_scene_params_equal(&s->params, &p)) {
        fg_scene_params old = s->params;
        s->params = p;
        rc = fg_scene_json_write(s->dir, s->name, &s->params, s->created_ms);
        if (rc != 0) s->params = old;
        else fg_info("scene %s: workspace, voxel size, background and field settings updated "
                     "from the configuration file", cs->name);
      }
      pthread_mutex_unlock(&s->lock);
      fg_scene_unref(s);
    }
    if (rc != 0) {
      fg_error("scene %s from the configuration file: %s", cs->name, fg_error_detail());
      if (!first) first = rc;
    }
  }
  pthread_mutex_lock(&st->lock);
  for (size_t i = 0; i < st->n; i++) {
    fg_scene *s = st->scenes[i];
    pthread_mutex_lock(&s->lock);
    s->declared = fg_conf_find_scene(conf, s->name) != NULL;
    pthread_mutex_unlock(&s->lock);
  }
  pthread_mutex_unlock(&st->lock);
  return first;
}

int fg_scene_set_field_settings(fg_scene *s, const double *field_scale,
                                const int *learn_background) {
  pthread_mutex_lock(&s->lock);
  fg_scene_params p = s->params;
  if (field_scale) p.field_scale = *field_scale;
  if (learn_background) p.learn_background = *learn_background;
  int rc = 0;
  if (s->deleted)
    rc = fg_fail_as(FG_ENOENT, "scene_not_found", "scene '%s' was deleted", s->name);
  else if (s->declared)
    rc = fg_fail_as(FG_EPERM, "declared_in_config", "scene '%s' is declared in the "
                    "configuration file: set field_scale and learn_background in its [scene %s] "
                    "section and reload", s->name, s->name);
  else if (fg_scene_params_validate(&p) != 0)
    rc = FG_EINVAL;
  else if (!fg_scene_params_equal(&p, &s->params)) {
    const fg_scene_params old = s->params;
    s->params = p;
    rc = fg_scene_json_write(s->dir, s->name, &s->params, s->created_ms);
    if (rc != 0) {
      s->params = old;
      rc = fg_state_write_failed(rc, "the scene's settings");
    }
  }
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int fg_state_write_failed(int rc, const char *what) {
  if (rc == FG_ENOSPC)
    return fg_fail_as(rc, "insufficient_storage", "%s was not stored: the state dir's file "
                      "system is full; nothing of this request was kept and what was stored "
                      "before is intact; free space and send it again (%s)", what,
                      fg_error_detail());
  return fg_fail_as(rc, "internal_error", "%s was not stored: %s", what, fg_error_detail());
}
