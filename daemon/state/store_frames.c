/* A scene's frames on disk: one NNNNNN.fgf file each under <scene>/frames, their headers
 * kept in the scene (sorted by number), batches written so that a cut-short import leaves no
 * frame of it behind, and the loads that training and the API make. See store.h. */
#include "store_priv.h"

#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static atomic_uint batch_counter;

int fg_frame_file_name(const char *n, int *index) {
  size_t len = strlen(n);
  if (len < 10 || strcmp(n + len - 4, ".fgf") != 0) return 0;
  long v = 0;
  for (size_t i = 0; i < len - 4; i++) {
    if (n[i] < '0' || n[i] > '9' || v > 100000000) return 0;
    v = v * 10 + (n[i] - '0');
  }
  *index = (int)v;
  return 1;
}

static int frame_cmp(const void *a, const void *b) {
  const int *x = a, *y = b;
  return (*x > *y) - (*x < *y);
}

static int scene_reserve(fg_scene *s, size_t extra) {
  if (s->n_frames + extra <= s->cap) return 0;
  size_t cap = s->cap ? s->cap : 64;
  while (cap < s->n_frames + extra) cap *= 2;
  fg_frame *f = realloc(s->frames, cap * sizeof *f);
  if (!f) return fg_fail(FG_ENOMEM, "out of memory");
  s->frames = f;
  int *ix = realloc(s->indices, cap * sizeof *ix);
  if (!ix) return fg_fail(FG_ENOMEM, "out of memory");
  s->indices = ix;
  s->cap = cap;
  return 0;
}

/* Removes the cached CLIP features of frame number index (clip_features.h), of every
 * model. */
static void remove_clip_cache(const fg_scene *s, int index) {
  char *dir = fg_path_join(s->dir, "clip");
  DIR *d = dir ? opendir(dir) : NULL;
  char prefix[16];
  snprintf(prefix, sizeof prefix, "%06d.", index);
  struct dirent *e;
  while (d && (e = readdir(d)) != NULL) {
    if (strncmp(e->d_name, prefix, strlen(prefix)) != 0) continue;
    char *p = fg_path_join(dir, e->d_name);
    if (p) unlink(p);
    free(p);
  }
  if (d) closedir(d);
  free(dir);
}

/* Removes the frames that the manifest at path names, with their cached CLIP features (the
 * caller removes the manifest): a batch cut short (fg_scene_add_frames) or a capture's
 * deletion (fg_scene_delete_capture). Returns how many frame files it removed. */
static int remove_listed(fg_scene *s, const char *path) {
  FILE *f = fopen(path, "r");
  char line[64];
  int removed = 0;
  while (f && fgets(line, sizeof line, f)) {
    line[strcspn(line, "\n")] = '\0';
    int index;
    if (!fg_frame_file_name(line, &index)) continue;
    char *p = fg_path_join(s->frames_dir, line);
    if (p && unlink(p) == 0) removed++;
    free(p);
    remove_clip_cache(s, index);
  }
  if (f) fclose(f);
  fg_fsync_dir(s->frames_dir);
  return removed;
}

int fg_scene_frames_read(fg_scene *s) {
  DIR *bd = opendir(s->frames_dir);
  if (!bd) return fg_fail(FG_EIO, "cannot open %s: %s", s->frames_dir, strerror(errno));
  struct dirent *be;
  while ((be = readdir(bd)) != NULL) {
    const int batch = strncmp(be->d_name, ".batch-", 7) == 0;
    const int deletion = strncmp(be->d_name, ".delete-", 8) == 0;
    if ((!batch && !deletion) || strstr(be->d_name, ".tmp.")) continue;
    char *p = fg_path_join(s->frames_dir, be->d_name);
    const int removed = p ? remove_listed(s, p) : 0;
    if (p && (unlink(p) == 0 || errno == ENOENT)) {
      fg_fsync_dir(s->frames_dir);
      fg_info("scene %s: removed %d frames of %s the daemon did not finish", s->name, removed,
              batch ? "an import" : "a capture's deletion");
    }
    free(p);
  }
  closedir(bd);
  DIR *d = opendir(s->frames_dir);
  if (!d) return fg_fail(FG_EIO, "cannot open %s: %s", s->frames_dir, strerror(errno));
  struct { int index; char name[256]; } *found = NULL;
  size_t n = 0, cap = 0;
  struct dirent *e;
  int rc = 0;
  while ((e = readdir(d)) != NULL) {
    int index;
    if (strncmp(e->d_name, ".incoming-", 10) == 0 || strstr(e->d_name, ".tmp.")) {
      char *p = fg_path_join(s->frames_dir, e->d_name);
      if (p && unlink(p) == 0) fg_info("scene %s: removed unfinished write %s", s->name, e->d_name);
      free(p);
      continue;
    }
    if (!fg_frame_file_name(e->d_name, &index)) continue;
    if (n == cap) {
      cap = cap ? cap * 2 : 64;
      void *p = realloc(found, cap * sizeof *found);
      if (!p) {
        rc = fg_fail(FG_ENOMEM, "out of memory");
        break;
      }
      found = p;
    }
    found[n].index = index;
    snprintf(found[n].name, sizeof found[n].name, "%s", e->d_name);
    n++;
  }
  closedir(d);
  if (rc == 0 && n) {
    qsort(found, n, sizeof *found, frame_cmp);
    rc = scene_reserve(s, n);
  }
  for (size_t i = 0; rc == 0 && i < n; i++) {
    char *p = fg_path_join(s->frames_dir, found[i].name);
    fg_frame f;
    int lrc = p ? fg_frame_load_header(p, &f) : FG_ENOMEM;
    if (lrc != 0) {
      fg_error("scene %s: frame file %s is unreadable and is left out: %s", s->name,
               p ? p : found[i].name, fg_error_detail());
    } else if (f.feat_d && s->feature_dim && f.feat_d != s->feature_dim) {
      fg_error("scene %s: frame %s has %d-d features but the scene has %d; left out", s->name,
               found[i].name, f.feat_d, s->feature_dim);
      fg_frame_clear(&f);
    } else {
      if (f.feat_d) s->feature_dim = f.feat_d;
      if (f.capture > s->latest_capture) s->latest_capture = f.capture;
      s->frames[s->n_frames] = f;
      s->indices[s->n_frames++] = found[i].index;
    }
    if (found[i].index >= s->next_index) s->next_index = found[i].index + 1;
    free(p);
  }
  free(found);
  s->next_capture = s->latest_capture + 1;
  return rc;
}

static int check_feature_dim(const fg_scene *s, const fg_frame *frames, size_t n) {
  int d = s->feature_dim;
  for (size_t i = 0; i < n; i++) {
    if (!frames[i].feat_d) continue;
    if (d && frames[i].feat_d != d)
      return fg_fail(FG_EINVAL, "features have D = %d but %s %d-d features; every frame of a "
                     "scene must have the same D", frames[i].feat_d,
                     s->feature_dim ? "the scene's frames have" : "another frame has", d);
    d = frames[i].feat_d;
  }
  return 0;
}

/* Writes the manifest of a batch of n frames numbered from first: one frame file name a
 * line, written atomically (fsutil). */
static int write_batch_manifest(const char *path, int first, size_t n) {
  fg_atomic_file af;
  FG_TRY(fg_atomic_file_open(&af, path));
  for (size_t i = 0; i < n; i++) fprintf(af.fp, "%06d.fgf\n", first + (int)i);
  return fg_atomic_file_commit(&af);
}

/* The newest capture, a new one when the scene has none. Under s->lock. */
static int64_t latest_or_new(fg_scene *s) {
  if (!s->latest_capture) s->latest_capture = s->next_capture++;
  return s->latest_capture;
}

int fg_scene_add_frames(fg_scene *s, fg_frame *frames, size_t n, int *first_index) {
  if (n == 0) return fg_fail(FG_EINVAL, "no frames to add");
  for (size_t i = 0; i < n; i++)
    if (frames[i].capture < 0 || frames[i].capture > FG_CAPTURE_MAX)
      return fg_fail(FG_EINVAL, "capture %lld is not a number from 1 to %lld",
                     (long long)frames[i].capture, (long long)FG_CAPTURE_MAX);
  pthread_mutex_lock(&s->lock);
  int rc = s->deleted ? fg_fail(FG_ENOENT, "scene %s was deleted", s->name)
                      : check_feature_dim(s, frames, n);
  for (size_t i = 0; rc == 0 && i < n; i++)
    if (frames[i].capture == 0) frames[i].capture = latest_or_new(s);
  pthread_mutex_unlock(&s->lock);
  if (rc != 0) return rc;

  char **incoming = calloc(n, sizeof *incoming);
  if (!incoming) return fg_fail(FG_ENOMEM, "out of memory");
  unsigned batch = atomic_fetch_add(&batch_counter, 1);
  for (size_t i = 0; i < n && rc == 0; i++) {
    char name[96];
    snprintf(name, sizeof name, ".incoming-%ld-%u-%zu.fgf", (long)getpid(), batch, i);
    incoming[i] = fg_path_join(s->frames_dir, name);
    if (!incoming[i]) rc = fg_fail(FG_ENOMEM, "out of memory");
  }
  /* Writing and fsyncing dominate an import: spread them over the cores, outside the lock. */
  int write_rc = 0;
  char write_err[512] = "";
  if (rc == 0) {
#pragma omp parallel for schedule(dynamic, 1) if (n > 1)
    for (size_t i = 0; i < n; i++) {
      int r = fg_frame_save(&frames[i], incoming[i]);
      if (r != 0) {
#pragma omp critical(fg_store_write_err)
        {
          if (write_rc == 0) {
            write_rc = r;
            snprintf(write_err, sizeof write_err, "%s", fg_error_detail());
          }
        }
      }
    }
    if (write_rc != 0) rc = fg_fail(write_rc, "%s", write_err);
  }

  pthread_mutex_lock(&s->lock);
  if (rc == 0 && s->deleted) rc = fg_fail(FG_ENOENT, "scene %s was deleted", s->name);
  if (rc == 0) rc = check_feature_dim(s, frames, n); /* a concurrent upload may have set D */
  if (rc == 0) rc = scene_reserve(s, n);
  /* A batch is renamed into place one file at a time: a manifest naming its files stands
   * while that goes on, so that a start-up after a kill removes a batch that was cut short
   * instead of keeping its first frames. One frame's rename is atomic by itself. */
  char *manifest = NULL;
  if (rc == 0 && n > 1) {
    char name[64];
    snprintf(name, sizeof name, ".batch-%ld-%u", (long)getpid(), batch);
    manifest = fg_path_join(s->frames_dir, name);
    rc = manifest ? write_batch_manifest(manifest, s->next_index, n)
                  : fg_fail(FG_ENOMEM, "out of memory");
    if (rc != 0) {
      free(manifest);
      manifest = NULL;
    }
  }
  size_t renamed = 0;
  for (; rc == 0 && renamed < n; renamed++) {
    char name[32];
    snprintf(name, sizeof name, "%06d.fgf", s->next_index + (int)renamed);
    char *final = fg_path_join(s->frames_dir, name);
    if (!final) rc = fg_fail(FG_ENOMEM, "out of memory");
    else if (rename(incoming[renamed], final) != 0)
      rc = fg_fail(s->deleted ? FG_ENOENT : FG_EIO, "cannot store frame %s: %s", name,
                   strerror(errno));
    if (rc == 0) {
      free(incoming[renamed]);
      incoming[renamed] = final; /* now names the final file, for the rollback below */
    } else {
      free(final);
      break;
    }
  }
  if (rc == 0) rc = fg_fsync_dir(s->frames_dir);
  if (manifest) {
    /* Gone for good before the batch is acknowledged: a manifest that came back after a
     * crash would take acknowledged frames with it. On failure the frames go first. */
    if (rc != 0)
      for (size_t i = 0; i < n; i++)
        if (incoming[i]) unlink(incoming[i]);
    if (unlink(manifest) != 0 && rc == 0)
      rc = fg_fail(FG_EIO, "cannot remove %s: %s", manifest, strerror(errno));
    int sync_rc = fg_fsync_dir(s->frames_dir);
    if (rc == 0) rc = sync_rc;
    free(manifest);
  }
  if (rc == 0) {
    *first_index = s->next_index;
    for (size_t i = 0; i < n; i++) {
      fg_frame h = frames[i];
      h.rgb = NULL;
      h.feat = NULL;
      h.depth = NULL;
      s->frames[s->n_frames] = h;
      s->indices[s->n_frames++] = s->next_index + (int)i;
      if (h.feat_d) s->feature_dim = h.feat_d;
      if (h.capture > s->latest_capture) s->latest_capture = h.capture;
      if (h.capture >= s->next_capture) s->next_capture = h.capture + 1;
    }
    s->next_index += (int)n;
  }
  pthread_mutex_unlock(&s->lock);
  for (size_t i = 0; i < n; i++) {
    if (rc != 0 && incoming[i]) unlink(incoming[i]); /* all or none */
    free(incoming[i]);
  }
  free(incoming);
  return rc;
}

int fg_scene_list_frames(fg_scene *s, fg_frame **frames, int **indices, size_t *n) {
  pthread_mutex_lock(&s->lock);
  size_t k = s->n_frames;
  fg_frame *f = malloc((k ? k : 1) * sizeof *f);
  int *ix = malloc((k ? k : 1) * sizeof *ix);
  if (!f || !ix) {
    pthread_mutex_unlock(&s->lock);
    free(f);
    free(ix);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  if (k) {
    memcpy(f, s->frames, k * sizeof *f);
    memcpy(ix, s->indices, k * sizeof *ix);
  }
  pthread_mutex_unlock(&s->lock);
  *frames = f;
  *indices = ix;
  *n = k;
  return 0;
}

void fg_scene_frames_free(fg_frame *frames, size_t n) {
  for (size_t i = 0; frames && i < n; i++) fg_frame_clear(&frames[i]);
  free(frames);
}

/* Loads frame file number `number` of s whole into *out, the error naming the frame. */
static int load_frame_file(fg_scene *s, int number, fg_frame *out) {
  char name[32];
  snprintf(name, sizeof name, "%06d.fgf", number);
  char *path = fg_path_join(s->frames_dir, name);
  int rc = path ? fg_frame_load(path, out) : fg_fail(FG_ENOMEM, "out of memory");
  if (rc != 0 && path) {
    char detail[512];
    snprintf(detail, sizeof detail, "%s", fg_error_detail());
    rc = fg_fail(rc, "frame %d (%s): %s", number, path, detail);
  }
  free(path);
  return rc;
}

int fg_scene_load_frame(fg_scene *s, int number, fg_frame *out) {
  memset(out, 0, sizeof *out);
  pthread_mutex_lock(&s->lock);
  int found = 0;
  for (size_t i = 0; i < s->n_frames && !found; i++) found = s->indices[i] == number;
  pthread_mutex_unlock(&s->lock);
  if (!found) return fg_fail(FG_ENOENT, "scene '%s' has no frame %d", s->name, number);
  return load_frame_file(s, number, out);
}

/* 1 when capture is one of captures[0..n), or captures is NULL (every capture). */
static int capture_chosen(int64_t capture, const int64_t *captures, size_t n) {
  if (!captures) return 1;
  for (size_t i = 0; i < n; i++)
    if (captures[i] == capture) return 1;
  return 0;
}

int fg_scene_load_frames(fg_scene *s, const int64_t *captures, size_t n_captures,
                         fg_frame **frames, int **indices, size_t *n, int (*stop)(void *),
                         void *stop_ud) {
  *frames = NULL;
  if (indices) *indices = NULL;
  *n = 0;
  pthread_mutex_lock(&s->lock);
  size_t k = 0;
  int *ix = malloc((s->n_frames ? s->n_frames : 1) * sizeof *ix);
  for (size_t i = 0; ix && i < s->n_frames; i++)
    if (capture_chosen(s->frames[i].capture, captures, n_captures)) ix[k++] = s->indices[i];
  pthread_mutex_unlock(&s->lock);
  fg_frame *f = calloc(k ? k : 1, sizeof *f);
  if (!ix || !f) {
    free(ix);
    free(f);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  int rc = 0;
  for (size_t i = 0; i < k && rc == 0; i++) {
    if (stop && stop(stop_ud)) {
      rc = fg_fail(FG_ECANCELED, "stopped while loading frames");
      break;
    }
    rc = load_frame_file(s, ix[i], &f[i]);
  }
  if (rc != 0) {
    free(ix);
    fg_scene_frames_free(f, k);
    return rc;
  }
  if (indices) *indices = ix;
  else free(ix);
  *frames = f;
  *n = k;
  return 0;
}

/* ---------------------------------------------------------------- captures */

static int capture_info_cmp(const void *a, const void *b) {
  const int64_t x = ((const fg_scene_capture_info *)a)->capture;
  const int64_t y = ((const fg_scene_capture_info *)b)->capture;
  return (x > y) - (x < y);
}

int fg_scene_captures_locked(const fg_scene *s, fg_scene_capture_info **out, size_t *n) {
  fg_scene_capture_info *v = calloc(s->n_frames ? s->n_frames : 1, sizeof *v);
  if (!v) return fg_fail(FG_ENOMEM, "out of memory");
  size_t k = 0;
  for (size_t i = 0; i < s->n_frames; i++) { /* frames are sorted by number */
    const fg_frame *f = &s->frames[i];
    size_t j = 0;
    while (j < k && v[j].capture != f->capture) j++;
    if (j == k) {
      v[k++] = (fg_scene_capture_info){.capture = f->capture, .first_frame = s->indices[i],
                                       .first_ms = f->created_ms};
    }
    v[j].n_frames++;
    v[j].n_depth += f->depth_w > 0;
    v[j].n_robot_pose += f->has_robot_pose != 0;
    v[j].last_frame = s->indices[i];
    v[j].last_ms = f->created_ms;
  }
  qsort(v, k, sizeof *v, capture_info_cmp);
  *out = v;
  *n = k;
  return 0;
}

int fg_scene_list_captures(fg_scene *s, fg_scene_capture_info **out, size_t *n) {
  pthread_mutex_lock(&s->lock);
  const int rc = fg_scene_captures_locked(s, out, n);
  pthread_mutex_unlock(&s->lock);
  return rc;
}

int64_t fg_scene_latest_capture(fg_scene *s) {
  pthread_mutex_lock(&s->lock);
  const int64_t c = s->latest_capture;
  pthread_mutex_unlock(&s->lock);
  return c;
}

int64_t fg_scene_new_capture(fg_scene *s) {
  pthread_mutex_lock(&s->lock);
  const int64_t c = s->next_capture++;
  s->latest_capture = c;
  pthread_mutex_unlock(&s->lock);
  return c;
}

/* Writes the manifest of a deletion: the file names of the frames numbered numbers[0..n),
 * one a line, written atomically (fsutil). */
static int write_deletion_manifest(const char *path, const int *numbers, size_t n) {
  fg_atomic_file af;
  FG_TRY(fg_atomic_file_open(&af, path));
  for (size_t i = 0; i < n; i++) fprintf(af.fp, "%06d.fgf\n", numbers[i]);
  return fg_atomic_file_commit(&af);
}

int fg_scene_delete_capture(fg_scene *s, int64_t capture, size_t *n_removed) {
  if (n_removed) *n_removed = 0;
  pthread_mutex_lock(&s->lock);
  int rc = 0;
  int *numbers = NULL;
  size_t k = 0;
  char *manifest = NULL;
  if (s->deleted) {
    rc = fg_fail(FG_ENOENT, "scene %s was deleted", s->name);
    goto out;
  }
  numbers = malloc((s->n_frames ? s->n_frames : 1) * sizeof *numbers);
  if (!numbers) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto out;
  }
  for (size_t i = 0; i < s->n_frames; i++)
    if (s->frames[i].capture == capture) numbers[k++] = s->indices[i];
  if (k == 0) {
    rc = fg_fail(FG_ENOENT, "scene '%s' has no capture %lld", s->name, (long long)capture);
    goto out;
  }
  /* The list first: a crash from here on leaves it, and the next start finishes the job. */
  char name[64];
  snprintf(name, sizeof name, ".delete-%ld-%u", (long)getpid(),
           atomic_fetch_add(&batch_counter, 1));
  manifest = fg_path_join(s->frames_dir, name);
  rc = manifest ? write_deletion_manifest(manifest, numbers, k)
                : fg_fail(FG_ENOMEM, "out of memory");
  if (rc == 0) rc = fg_fsync_dir(s->frames_dir);
  if (rc != 0) {
    if (manifest) unlink(manifest);
    goto out;
  }
  remove_listed(s, manifest);
  if (unlink(manifest) != 0)
    fg_warn("scene %s: cannot remove %s (the next start removes it): %s", s->name, manifest,
            strerror(errno));
  fg_fsync_dir(s->frames_dir);
  /* The scene forgets them, and the newest capture is the highest left. */
  size_t kept = 0;
  s->latest_capture = 0;
  s->feature_dim = 0; /* the D of the frames left, if any has features */
  for (size_t i = 0; i < s->n_frames; i++) {
    const fg_frame *f = &s->frames[i];
    if (f->capture == capture) continue;
    if (f->capture > s->latest_capture) s->latest_capture = f->capture;
    if (f->feat_d) s->feature_dim = f->feat_d;
    s->indices[kept] = s->indices[i];
    s->frames[kept++] = *f;
  }
  s->n_frames = kept;
  if (n_removed) *n_removed = k;
  fg_info("scene %s: capture %lld deleted (%zu frames)", s->name, (long long)capture, k);
out:
  pthread_mutex_unlock(&s->lock);
  free(manifest);
  free(numbers);
  return rc;
}
