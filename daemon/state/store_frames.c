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

/* Removes the frames that the batch manifest at path names (a batch cut short, see
 * fg_scene_add_frames), then the manifest. */
static void scene_undo_batch(fg_scene *s, const char *path) {
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
  }
  if (f) fclose(f);
  if (unlink(path) == 0 || errno == ENOENT) {
    fg_fsync_dir(s->frames_dir);
    fg_info("scene %s: removed %d frames of an import the daemon did not finish", s->name,
            removed);
  }
}

int fg_scene_frames_read(fg_scene *s) {
  DIR *bd = opendir(s->frames_dir);
  if (!bd) return fg_fail(FG_EIO, "cannot open %s: %s", s->frames_dir, strerror(errno));
  struct dirent *be;
  while ((be = readdir(bd)) != NULL) {
    if (strncmp(be->d_name, ".batch-", 7) != 0 || strstr(be->d_name, ".tmp.")) continue;
    char *p = fg_path_join(s->frames_dir, be->d_name);
    if (p) scene_undo_batch(s, p);
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
      s->frames[s->n_frames] = f;
      s->indices[s->n_frames++] = found[i].index;
    }
    if (found[i].index >= s->next_index) s->next_index = found[i].index + 1;
    free(p);
  }
  free(found);
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

int fg_scene_add_frames(fg_scene *s, const fg_frame *frames, size_t n, int *first_index) {
  if (n == 0) return fg_fail(FG_EINVAL, "no frames to add");
  pthread_mutex_lock(&s->lock);
  int rc = s->deleted ? fg_fail(FG_ENOENT, "scene %s was deleted", s->name)
                      : check_feature_dim(s, frames, n);
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

int fg_scene_load_frames(fg_scene *s, fg_frame **frames, int **indices, size_t *n,
                         int (*stop)(void *), void *stop_ud) {
  *frames = NULL;
  if (indices) *indices = NULL;
  *n = 0;
  pthread_mutex_lock(&s->lock);
  size_t k = s->n_frames;
  int *ix = malloc((k ? k : 1) * sizeof *ix);
  if (ix && k) memcpy(ix, s->indices, k * sizeof *ix);
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
