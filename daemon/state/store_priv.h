/* What store.c and store_frames.c share and nothing else sees: the scene and store objects.
 * Everything the rest of the daemon needs goes through store.h. */
#ifndef FG_DAEMON_STORE_PRIV_H
#define FG_DAEMON_STORE_PRIV_H

#include "conf/conf.h"
#include "store.h"

#include "core/ref.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>

struct fg_scene {
  fg_store *store;
  char name[FG_SCENE_NAME_MAX + 1];
  char *dir;        /* <state>/scenes/<name> */
  char *frames_dir; /* <dir>/frames */
  fg_ref ref;
  pthread_mutex_t lock; /* guards everything below */
  fg_scene_params params;
  int declared;
  int64_t created_ms;
  fg_frame *frames; /* headers only, sorted by number */
  int *indices;
  size_t n_frames, cap;
  int next_index;
  int64_t next_capture;   /* above every capture the frames have or the scene handed out */
  int64_t latest_capture; /* the newest capture (uploads without one join it); 0: none */
  int feature_dim;
  int deleted;
  /* the trained field: in memory (field) or only in field.fgc (trained, field NULL) */
  fg_field_ref *field;     /* NULL when untrained or not loaded */
  int trained;
  int field_feature_dim;   /* the trained field's D and steps, known while it is not loaded */
  int64_t trained_steps;
  double field_box_min[3], field_box_size; /* ... its cube and background likewise */
  int field_learn_background;
  uint64_t field_used;     /* the store's field_clock at the field's last acquire: LRU order */
  int partial;
  int64_t checkpoint_bytes;
  int next_at_start;       /* field.next.fgc was there when the store opened */
  char *checkpoint_error;  /* malloc'd; NULL when none */
  char last_job_id[FG_JOB_ID_MAX];
  char last_job_state[16];
};

struct fg_store {
  char *scenes_dir;
  /* Serialises what loads, commits or evicts fields, so that the count of loaded fields
   * only moves under it. Lock order: fields_lock, then lock, then a scene's lock. */
  pthread_mutex_t fields_lock;
  pthread_mutex_t lock; /* guards the scene array and the limits */
  fg_scene **scenes;
  size_t n, cap;
  fg_store_limits limits;
  atomic_ullong field_clock, field_loads, field_evictions;
};

/* 1 when n is a frame file's name (NNNNNN.fgf, at least six digits), its number in *index. */
int fg_frame_file_name(const char *n, int *index);

/* Reads the headers of a scene's frames into it when the store opens, removing what an
 * interrupted write left behind (unfinished files, the frames of a batch cut short). */
int fg_scene_frames_read(fg_scene *s);

/* The captures of s's frames into *out (malloc'd, by number; fg_scene_list_captures). Under
 * s->lock. */
int fg_scene_captures_locked(const fg_scene *s, fg_scene_capture_info **out, size_t *n);

#endif
