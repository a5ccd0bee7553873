#include "store.h"
#include "store_priv.h"

#include "conf.h"
#include "voxcache.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "field/checkpoint.h"

#include <jansson.h>

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
  atomic_int refs;
};

static atomic_uint name_counter;

static int64_t now_ms(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

/* ---------------------------------------------------------------- parameters */

int fg_scene_params_validate(const fg_scene_params *p) {
  static const char axis[] = "xyz";
  for (int i = 0; i < 3; i++) {
    if (!isfinite(p->workspace_min[i]) || !isfinite(p->workspace_max[i]))
      return fg_fail(FG_EINVAL, "workspace %c bounds must be finite numbers (metres)", axis[i]);
    if (!(p->workspace_min[i] < p->workspace_max[i]))
      return fg_fail(FG_EINVAL, "workspace min %c (%g) must be less than max %c (%g)", axis[i],
                     p->workspace_min[i], axis[i], p->workspace_max[i]);
    if (!(p->background[i] >= 0 && p->background[i] <= 1))
      return fg_fail(FG_EINVAL, "background must hold three numbers in [0, 1]");
  }
  double smallest = INFINITY;
  for (int i = 0; i < 3; i++)
    smallest = fmin(smallest, p->workspace_max[i] - p->workspace_min[i]);
  if (!(p->voxel_size > 0) || !isfinite(p->voxel_size) || p->voxel_size > smallest)
    return fg_fail(FG_EINVAL, "voxel_size must be a positive length in metres no larger than the "
                   "workspace's smallest side (%g), got %g", smallest, p->voxel_size);
  return 0;
}

static int params_equal(const fg_scene_params *a, const fg_scene_params *b) {
  for (int i = 0; i < 3; i++)
    if (a->workspace_min[i] != b->workspace_min[i] || a->workspace_max[i] != b->workspace_max[i] ||
        a->background[i] != b->background[i])
      return 0;
  return a->voxel_size == b->voxel_size;
}

/* ---------------------------------------------------------------- scene.json */

static int write_scene_json(const fg_scene *s) {
  json_t *o = json_pack(
    "{s:s,s:{s:[f,f,f],s:[f,f,f]},s:f,s:[f,f,f],s:I}", "name", s->name, "workspace", "min",
    s->params.workspace_min[0], s->params.workspace_min[1], s->params.workspace_min[2], "max",
    s->params.workspace_max[0], s->params.workspace_max[1], s->params.workspace_max[2],
    "voxel_size", s->params.voxel_size, "background", s->params.background[0],
    s->params.background[1], s->params.background[2], "created_ms", (json_int_t)s->created_ms);
  char *text = o ? json_dumps(o, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) : NULL;
  json_decref(o);
  if (!text) return fg_fail(FG_ENOMEM, "out of memory");
  char *path = fg_path_join(s->dir, "scene.json");
  int rc = path ? fg_write_file_atomic(path, text, strlen(text)) : fg_fail(FG_ENOMEM, "oom");
  free(path);
  free(text);
  return rc;
}

static int read_vec3(json_t *a, double out[3]) {
  if (!json_is_array(a) || json_array_size(a) != 3) return -1;
  for (int i = 0; i < 3; i++) {
    json_t *v = json_array_get(a, (size_t)i);
    if (!json_is_number(v)) return -1;
    out[i] = json_number_value(v);
  }
  return 0;
}

static int read_scene_json(fg_scene *s) {
  char *path = fg_path_join(s->dir, "scene.json");
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  json_error_t jerr;
  json_t *o = json_load_file(path, 0, &jerr);
  int rc = 0;
  json_t *ws = o ? json_object_get(o, "workspace") : NULL;
  if (!o) {
    rc = fg_fail(FG_EFORMAT, "%s: %s (line %d)", path, jerr.text, jerr.line);
  } else if (read_vec3(json_object_get(ws, "min"), s->params.workspace_min) ||
             read_vec3(json_object_get(ws, "max"), s->params.workspace_max) ||
             read_vec3(json_object_get(o, "background"), s->params.background) ||
             !json_is_number(json_object_get(o, "voxel_size"))) {
    rc = fg_fail(FG_EFORMAT, "%s: missing or malformed workspace, voxel_size or background", path);
  } else {
    s->params.voxel_size = json_number_value(json_object_get(o, "voxel_size"));
    s->created_ms = json_integer_value(json_object_get(o, "created_ms"));
    if (fg_scene_params_validate(&s->params) != 0)
      rc = fg_fail(FG_EFORMAT, "%s: %s", path, fg_error_detail());
  }
  json_decref(o);
  free(path);
  return rc;
}

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

void fg_scene_ref(fg_scene *s) { atomic_fetch_add(&s->refs, 1); }

void fg_scene_unref(fg_scene *s) {
  if (s && atomic_fetch_sub(&s->refs, 1) == 1) scene_free(s);
}

static fg_scene *scene_alloc(fg_store *store, const char *name) {
  fg_scene *s = calloc(1, sizeof *s);
  if (!s) return NULL;
  s->store = store;
  snprintf(s->name, sizeof s->name, "%s", name);
  s->dir = fg_path_join(store->scenes_dir, name);
  s->frames_dir = s->dir ? fg_path_join(s->dir, "frames") : NULL;
  atomic_init(&s->refs, 1);
  pthread_mutex_init(&s->lock, NULL);
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
  atomic_init(&r->refs, 1);
  return r;
}

/* Frees a ref that field_ref_new made, leaving its field to the caller. */
static void field_ref_discard(fg_field_ref *r) {
  if (!r) return;
  fg_voxcache_free(r->voxels);
  free(r);
}

void fg_field_ref_release(fg_field_ref *r) {
  if (r && atomic_fetch_sub(&r->refs, 1) == 1) {
    fg_voxcache_free(r->voxels);
    fg_field_free(r->field);
    free(r);
  }
}

const fg_field *fg_field_ref_field(const fg_field_ref *r) { return r->field; }

fg_voxcache *fg_field_ref_voxcache(fg_field_ref *r) { return r->voxels; }

fg_field_ref *fg_scene_field_acquire(fg_scene *s) {
  pthread_mutex_lock(&s->lock);
  fg_field_ref *r = s->field;
  if (r) atomic_fetch_add(&r->refs, 1);
  pthread_mutex_unlock(&s->lock);
  return r;
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
  s->field = field_ref_new(f);
  if (!s->field) {
    fg_field_free(f);
    s->checkpoint_error = strdup("out of memory loading the field");
    goto out;
  }
  s->checkpoint_bytes = file_size(path);
  s->partial = !have_final;
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
  pthread_mutex_lock(&s->lock);
  int rc = 0;
  fg_field_ref *old = NULL;
  if (s->deleted) {
    unlink(next_path);
    rc = fg_fail(FG_ENOENT, "scene %s was deleted", s->name);
  } else if (rename(next_path, final) != 0) {
    rc = fg_fail(FG_EIO, "cannot rename %s to %s: %s", next_path, final, strerror(errno));
  } else {
    fg_fsync_dir(s->dir);
    old = s->field;
    s->field = r;
    s->partial = 0;
    s->checkpoint_bytes = file_size(final);
    free(s->checkpoint_error);
    s->checkpoint_error = NULL;
    r = NULL;
  }
  pthread_mutex_unlock(&s->lock);
  field_ref_discard(r); /* on failure; the field stays the caller's */
  fg_field_ref_release(old);
  free(final);
  return rc;
}

void fg_scene_keep_partial(fg_scene *s) {
  char *final = fg_path_join(s->dir, "field.fgc");
  char *next = fg_path_join(s->dir, "field.next.fgc");
  pthread_mutex_lock(&s->lock);
  if (final && next && s->field && s->partial && !s->deleted && access(final, F_OK) != 0 &&
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

int fg_store_open(fg_store **out, const char *state_dir) {
  *out = NULL;
  fg_store *st = calloc(1, sizeof *st);
  if (!st) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&st->lock, NULL);
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
    if (read_scene_json(s) != 0 || fg_scene_frames_read(s) != 0) {
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
  *out = st;
  return 0;
}

void fg_store_close(fg_store *st) {
  if (!st) return;
  for (size_t i = 0; i < st->n; i++) fg_scene_unref(st->scenes[i]);
  free(st->scenes);
  free(st->scenes_dir);
  pthread_mutex_destroy(&st->lock);
  free(st);
}

int fg_store_create(fg_store *st, const char *name, const fg_scene_params *params, int declared) {
  FG_TRY(fg_scene_name_validate(name));
  FG_TRY(fg_scene_params_validate(params));
  pthread_mutex_lock(&st->lock);
  int rc = 0;
  fg_scene *s = NULL;
  if (store_find_locked(st, name, NULL)) {
    rc = fg_fail(FG_EEXIST, "a scene named '%s' exists already; delete it first or pick another "
                 "name", name);
    goto out;
  }
  s = scene_alloc(st, name);
  if (!s) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto out;
  }
  s->params = *params;
  s->declared = declared;
  s->created_ms = now_ms();
  rc = fg_mkdir_p(s->frames_dir);
  if (rc == 0) rc = write_scene_json(s);
  if (rc == 0) rc = fg_fsync_dir(st->scenes_dir);
  if (rc == 0) rc = store_insert(st, s);
  if (rc == 0) s = NULL;
  /* Not created (a full disk, say): the folder goes too, or the next start would find a
   * scene folder without its scene.json. */
  else if (s) fg_rmtree(s->dir);
out:
  pthread_mutex_unlock(&st->lock);
  scene_free(s);
  return rc;
}

fg_scene *fg_store_get(fg_store *st, const char *name) {
  pthread_mutex_lock(&st->lock);
  fg_scene *s = store_find_locked(st, name, NULL);
  if (s) atomic_fetch_add(&s->refs, 1);
  pthread_mutex_unlock(&st->lock);
  return s;
}

int fg_store_delete(fg_store *st, const char *name) {
  pthread_mutex_lock(&st->lock);
  size_t pos;
  fg_scene *s = store_find_locked(st, name, &pos);
  if (!s) {
    pthread_mutex_unlock(&st->lock);
    return fg_fail(FG_ENOENT, "no scene named '%s'", name);
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
  out->feature_dim = s->feature_dim;
  out->field_feature_dim = s->field ? s->field->field->cfg.feature_dim : 0;
  out->trained = s->field != NULL;
  out->partial = s->field && s->partial;
  out->trained_steps = s->field ? s->field->field->trained_steps : 0;
  out->checkpoint_bytes = s->field ? s->checkpoint_bytes : 0;
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
    n += st->scenes[i]->field != NULL;
    pthread_mutex_unlock(&st->scenes[i]->lock);
  }
  pthread_mutex_unlock(&st->lock);
  return n;
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
    fg_scene *s = fg_store_get(st, cs->name);
    int rc = 0;
    if (!s) {
      rc = fg_store_create(st, cs->name, &p, 1);
      if (rc == 0) fg_info("scene %s created from the configuration file", cs->name);
    } else {
      pthread_mutex_lock(&s->lock);
      s->declared = 1;
      if (!params_equal(&s->params, &p)) {
        fg_scene_params old = s->params;
        s->params = p;
        rc = write_scene_json(s);
        if (rc != 0) s->params = old;
        else fg_info("scene %s: workspace, voxel size and background updated from the "
                     "configuration file", cs->name);
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
