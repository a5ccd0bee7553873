/* The demonstration library; see tasks.h. */
#include "tasks.h"

#include "conf/conf.h"
#include "json.h"

#include "core/clock.h"
#include "core/error.h"
#include "core/fsutil.h"
#include "core/log.h"
#include "core/pose.h"
#include "core/ref.h"
#include "grasp/grasp.h"
#include "io/npy.h"

#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define TASK_JSON_MAX (16u << 20)
#define TASK_FORMAT 1

/* A snapshot with its reference count and the allocations behind its const pointers. */
typedef struct task_obj {
  fg_task pub; /* first: fg_task_unref casts back */
  fg_ref ref;
  float *p_gripper, *Z;
  fg_task_demo *demos;
  float **z; /* (n_demos) owned z of each demo */
} task_obj;

struct fg_tasks {
  char *dir;                    /* <state>/tasks */
  pthread_mutex_t write_lock;   /* serialises changes, held across their file writes */
  pthread_mutex_t lock;         /* guards the table below, held briefly */
  task_obj **tasks;             /* (n) sorted by name */
  size_t n, cap;
  char **broken;                /* (n_broken) names on disk that did not load */
  size_t n_broken;
};

static atomic_uint trash_counter;

const char *fg_task_kind_name(fg_task_kind k) { return k == FG_TASK_PLACE ? "place" : "grasp"; }

/* ---------------------------------------------------------------- snapshots */

static void obj_free(task_obj *o) {
  if (!o) return;
  for (int i = 0; o->z && i < o->pub.n_demos; i++) free(o->z[i]);
  free(o->z);
  free(o->demos);
  free(o->p_gripper);
  free(o->Z);
  free(o);
}

void fg_task_unref(const fg_task *t) {
  if (!t) return;
  task_obj *o = (task_obj *)t;
  if (fg_ref_put(&o->ref)) obj_free(o);
}

static const fg_task *obj_ref(task_obj *o) {
  fg_ref_get(&o->ref);
  return &o->pub;
}

const fg_task *fg_task_ref(const fg_task *t) { return obj_ref((task_obj *)t); }

/* A snapshot of n_demos demos (copied from demos, whose z are copied too, (n_points, dim)
 * each) and the task's other fields from base into *out; the derived fields (means, Z,
 * the query points) are computed here. FG_ENOMEM, or FG_EINVAL for bad query
 * points. */
static int obj_build(const fg_task *base, const fg_task_demo *demos, int n_demos,
                     task_obj **out) {
  *out = NULL;
  task_obj *o = calloc(1, sizeof *o);
  if (!o) return fg_fail(FG_ENOMEM, "out of memory");
  fg_ref_init(&o->ref, 1);
  o->pub = *base;
  const int nq = base->n_points, D = n_demos ? base->dim : 0;
  o->pub.dim = D;
  o->pub.n_demos = n_demos;
  o->p_gripper = malloc((size_t)nq * 3 * sizeof *o->p_gripper);
  if (n_demos) {
    o->demos = calloc((size_t)n_demos, sizeof *o->demos);
    o->z = calloc((size_t)n_demos, sizeof *o->z);
    o->Z = calloc((size_t)nq * (size_t)D, sizeof *o->Z);
  }
  if (!o->p_gripper || (n_demos && (!o->demos || !o->z || !o->Z))) {
    obj_free(o);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  int rc = fg_grasp_query_points_layout(base->qp_layout, nq, base->qp_mean_m, base->qp_std_m,
                                        base->qp_size_m, o->p_gripper);
  if (rc != 0) {
    obj_free(o);
    return rc;
  }
  const size_t zn = (size_t)nq * (size_t)D;
  double width = 0, approach = 0;
  for (int i = 0; i < n_demos; i++) {
    o->demos[i] = demos[i];
    o->z[i] = malloc(zn * sizeof **o->z);
    if (!o->z[i]) {
      obj_free(o);
      return fg_fail(FG_ENOMEM, "out of memory");
    }
    memcpy(o->z[i], demos[i].z, zn * sizeof **o->z);
    o->demos[i].z = o->z[i];
    width += demos[i].width_m;
    approach += demos[i].approach_m;
  }
  if (n_demos) {
    /* Z in double, demo by demo in id order: the same demos give the same bits. */
    for (size_t k = 0; k < zn; k++) {
      double s = 0;
      for (int i = 0; i < n_demos; i++) s += o->z[i][k];
      o->Z[k] = (float)(s / n_demos);
    }
    o->pub.width_m = width / n_demos;
    o->pub.approach_m = approach / n_demos;
  } else {
    o->pub.width_m = o->pub.approach_m = 0;
  }
  o->pub.p_gripper = o->p_gripper;
  o->pub.demos = o->demos;
  o->pub.Z = o->Z;
  *out = o;
  return 0;
}

/* ---------------------------------------------------------------- task.json */

json_t *fg_task_query_points_json(const fg_task *t) {
  if (t->qp_layout == FG_GRASP_QP_BOX)
    return json_pack("{s:i, s:s, s:o, s:o}", "n", t->n_points, "layout", "box", "size",
                     fg_json_from_vec(t->qp_size_m, 3), "mean",
                     fg_json_from_vec(t->qp_mean_m, 3));
  return json_pack("{s:i, s:s, s:f, s:o}", "n", t->n_points, "layout", "gaussian", "std",
                   t->qp_std_m, "mean", fg_json_from_vec(t->qp_mean_m, 3));
}

static json_t *task_file_json(const fg_task *t) {
  json_t *demos = json_array();
  for (int i = 0; demos && i < t->n_demos; i++) {
    const fg_task_demo *d = &t->demos[i];
    json_array_append_new(
        demos, json_pack("{s:i, s:s, s:{s:o}, s:s, s:f, s:f, s:I}", "id", d->id, "scene",
                         d->scene, "pose", "matrix", fg_json_from_matrix4(d->T_world_gripper),
                         "kind", fg_task_kind_name(d->kind), "width", d->width_m, "approach",
                         d->approach_m, "created_ms", (json_int_t)d->created_ms));
  }
  return json_pack("{s:i, s:s, s:s, s:i, s:o, s:f, s:f, s:i, s:I, s:o}", "format",
                   TASK_FORMAT, "name", t->name, "kind", fg_task_kind_name(t->kind), "dim",
                   t->dim, "query_points", fg_task_query_points_json(t), "width", t->width_m,
                   "approach", t->approach_m, "next_id", t->next_id, "created_ms",
                   (json_int_t)t->created_ms, "demos", demos);
}

static char *task_path(const fg_tasks *ts, const char *name, const char *file) {
  char *dir = fg_path_join(ts->dir, name);
  char *p = dir && file ? fg_path_join(dir, file) : NULL;
  if (!file) return dir;
  free(dir);
  return p;
}

static char *demo_file(const fg_tasks *ts, const char *name, int id) {
  char file[32];
  snprintf(file, sizeof file, "demo-%d.npy", id);
  return task_path(ts, name, file);
}

static int write_task_json(const fg_tasks *ts, const fg_task *t) {
  json_t *o = task_file_json(t);
  char *text = o ? json_dumps(o, JSON_INDENT(1) | JSON_REAL_PRECISION(17)) : NULL;
  json_decref(o);
  char *path = task_path(ts, t->name, "task.json");
  int rc = text && path ? fg_write_file_atomic(path, text, strlen(text))
                        : fg_fail(FG_ENOMEM, "out of memory");
  free(text);
  free(path);
  return rc;
}

static int write_demo_npy(const fg_tasks *ts, const char *name, int id, const float *z, int nq,
                          int D) {
  const size_t shape[2] = {(size_t)nq, (size_t)D};
  uint8_t *buf = NULL;
  size_t len = 0;
  FG_TRY(fg_npy_encode(FG_DTYPE_F32, 2, shape, z, &buf, &len));
  char *path = demo_file(ts, name, id);
  int rc = path ? fg_write_file_atomic(path, buf, len) : fg_fail(FG_ENOMEM, "out of memory");
  free(path);
  free(buf);
  return rc;
}

static int json_int_in(json_t *o, const char *key, long lo, long hi, int *out) {
  long long x;
  if (fg_json_int_range(o, key, lo, hi, &x) != 1)
    return fg_fail(FG_EFORMAT, "\"%s\" must be an integer from %ld to %ld", key, lo, hi);
  *out = (int)x;
  return 0;
}

static int json_num(json_t *o, const char *key, double *out) {
  int rc = fg_json_number(o, key, out);
  if (rc != 1) return fg_fail(FG_EFORMAT, "\"%s\" must be a number", key);
  return 0;
}

static int parse_kind(json_t *o, fg_task_kind *k) {
  const char *s = NULL;
  if (fg_json_string(o, "kind", &s) != 1 || (strcmp(s, "grasp") && strcmp(s, "place")))
    return fg_fail(FG_EFORMAT, "\"kind\" must be \"grasp\" or \"place\"");
  *k = strcmp(s, "place") == 0 ? FG_TASK_PLACE : FG_TASK_GRASP;
  return 0;
}

/* Reads one demo's z (n_points, dim) into a malloc'd array. */
static int read_demo_npy(const fg_tasks *ts, const char *name, int id, int nq, int D,
                         float **z) {
  char *path = demo_file(ts, name, id);
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  char *buf = NULL;
  size_t len = 0;
  int rc = fg_read_file(path, (size_t)1 << 30, &buf, &len);
  fg_npy npy;
  if (rc == 0) rc = fg_npy_parse(buf, len, &npy);
  if (rc == 0 && (npy.dtype != FG_DTYPE_F32 || npy.ndim != 2 || npy.shape[0] != (size_t)nq ||
                  npy.shape[1] != (size_t)D))
    rc = fg_fail(FG_EFORMAT, "%s is not float32 [%d, %d]", path, nq, D);
  if (rc == 0) {
    *z = malloc(npy.count * sizeof **z);
    if (!*z) rc = fg_fail(FG_ENOMEM, "out of memory");
    else memcpy(*z, npy.data, npy.count * sizeof **z);
  } else if (rc != FG_EFORMAT && rc != FG_ENOMEM) {
    rc = fg_fail(FG_EIO, "cannot read %s: %s", path, fg_error_detail());
  }
  free(buf);
  free(path);
  return rc;
}

/* The query points of a task.json into base: a file without "layout" holds a Gaussian (every
 * task before the box layout). */
static int parse_query_points(json_t *qp, fg_task *base) {
  const char *layout = "gaussian";
  if (fg_json_string(qp, "layout", &layout) < 0 ||
      (strcmp(layout, "gaussian") && strcmp(layout, "box")))
    return fg_fail(FG_EFORMAT, "\"query_points.layout\" must be \"gaussian\" or \"box\"");
  base->qp_layout = strcmp(layout, "box") == 0 ? FG_GRASP_QP_BOX : FG_GRASP_QP_GAUSSIAN;
  FG_TRY(json_int_in(qp, "n", 1, FG_GRASP_MAX_QUERY_POINTS, &base->n_points));
  if (base->qp_layout == FG_GRASP_QP_BOX) {
    if (fg_json_vec(json_object_get(qp, "size"), base->qp_size_m, 3, "query_points.size") != 0)
      return FG_EFORMAT;
  } else {
    FG_TRY(json_num(qp, "std", &base->qp_std_m));
  }
  if (fg_json_vec(json_object_get(qp, "mean"), base->qp_mean_m, 3, "query_points.mean") != 0)
    return FG_EFORMAT;
  return 0;
}

/* Loads task `name` from its folder into *out. */
static int load_task(const fg_tasks *ts, const char *name, task_obj **out) {
  *out = NULL;
  char *path = task_path(ts, name, "task.json");
  if (!path) return fg_fail(FG_ENOMEM, "out of memory");
  char *text = NULL;
  size_t len = 0;
  int rc = fg_read_file(path, TASK_JSON_MAX, &text, &len);
  free(path);
  if (rc != 0) return rc;
  json_error_t e;
  json_t *o = json_loadb(text, len, 0, &e);
  free(text);
  if (!json_is_object(o)) {
    json_decref(o);
    return fg_fail(FG_EFORMAT, "task.json does not parse: line %d: %s", e.line, e.text);
  }
  fg_task base = {0};
  fg_task_demo *demos = NULL;
  float **zs = NULL;
  int n_demos = 0;
  json_t *qp = json_object_get(o, "query_points"), *jd = json_object_get(o, "demos");
  const char *jname = NULL;
  json_int_t created = 0;
  int format = 0;
  if ((rc = json_int_in(o, "format", TASK_FORMAT, TASK_FORMAT, &format)) != 0) goto out;
  if (fg_json_string(o, "name", &jname) != 1 || strcmp(jname, name) != 0) {
    rc = fg_fail(FG_EFORMAT, "task.json names another task than its folder");
    goto out;
  }
  snprintf(base.name, sizeof base.name, "%.64s", name);
  if ((rc = parse_kind(o, &base.kind)) != 0 ||
      (rc = json_int_in(o, "dim", 0, 1 << 20, &base.dim)) != 0 ||
      (rc = json_int_in(o, "next_id", 1, 1 << 30, &base.next_id)) != 0 ||
      (rc = parse_query_points(qp, &base)) != 0)
    goto out;
  json_t *jc = json_object_get(o, "created_ms");
  created = json_is_integer(jc) ? json_integer_value(jc) : 0;
  base.created_ms = created;
  if (!json_is_array(jd) || json_array_size(jd) > FG_TASK_MAX_DEMOS) {
    rc = fg_fail(FG_EFORMAT, "\"demos\" must be a list of at most %d", FG_TASK_MAX_DEMOS);
    goto out;
  }
  const size_t nd = json_array_size(jd);
  demos = calloc(nd ? nd : 1, sizeof *demos);
  zs = calloc(nd ? nd : 1, sizeof *zs);
  if (!demos || !zs) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto out;
  }
  for (size_t i = 0; i < nd; i++, n_demos++) {
    json_t *d = json_array_get(jd, i);
    fg_task_demo *x = &demos[i];
    const char *scene = NULL;
    if ((rc = json_int_in(d, "id", 1, base.next_id - 1, &x->id)) != 0 ||
        (rc = parse_kind(d, &x->kind)) != 0 || (rc = json_num(d, "width", &x->width_m)) != 0 ||
        (rc = json_num(d, "approach", &x->approach_m)) != 0)
      goto out;
    if (fg_json_string(d, "scene", &scene) != 1 || fg_scene_name_validate(scene) != 0) {
      rc = fg_fail(FG_EFORMAT, "demo %d: \"scene\" is not a scene name", x->id);
      goto out;
    }
    snprintf(x->scene, sizeof x->scene, "%s", scene);
    json_t *m = json_object_get(json_object_get(d, "pose"), "matrix");
    if (fg_json_matrix4(m, x->T_world_gripper, "pose.matrix") != 0 ||
        fg_pose_validate(x->T_world_gripper) != 0) {
      rc = fg_fail(FG_EFORMAT, "demo %d: bad pose: %s", x->id, fg_error_detail());
      goto out;
    }
    jc = json_object_get(d, "created_ms");
    x->created_ms = json_is_integer(jc) ? json_integer_value(jc) : 0;
    if (x->kind != base.kind || (i && x->id <= demos[i - 1].id)) {
      rc = fg_fail(FG_EFORMAT, "demo %d: kind or id out of order", x->id);
      goto out;
    }
    if ((rc = read_demo_npy(ts, name, x->id, base.n_points, base.dim, &zs[i])) != 0) goto out;
    x->z = zs[i];
  }
  if (n_demos > 0 && base.dim < 1) {
    rc = fg_fail(FG_EFORMAT, "\"dim\" must be positive for a task with demos");
    goto out;
  }
  rc = obj_build(&base, demos, n_demos, out);
  if (rc == FG_EINVAL) rc = FG_EFORMAT;
out:
  for (int i = 0; zs && i < n_demos; i++) free(zs[i]);
  free(zs);
  free(demos);
  json_decref(o);
  return rc;
}

/* Removes demo-*.npy files of task t's folder that t does not name (a crash between writing
 * a demo's file and the task.json naming it, or after the task.json dropping one). */
static void sweep_demos(const fg_tasks *ts, const fg_task *t) {
  char *dir = task_path(ts, t->name, NULL);
  DIR *d = dir ? opendir(dir) : NULL;
  struct dirent *e;
  while (d && (e = readdir(d)) != NULL) {
    int id;
    char tail[8];
    if (sscanf(e->d_name, "demo-%d.np%1s", &id, tail) != 2 || strcmp(tail, "y") != 0) continue;
    int named = 0;
    for (int i = 0; i < t->n_demos; i++) named |= t->demos[i].id == id;
    if (named) continue;
    char *p = fg_path_join(dir, e->d_name);
    if (p && unlink(p) == 0) fg_info("task %s: removed %s, which no demo names", t->name,
                                    e->d_name);
    free(p);
  }
  if (d) closedir(d);
  free(dir);
}

/* ---------------------------------------------------------------- the table */

static int cmp_obj(const void *a, const void *b) {
  return strcmp((*(task_obj *const *)a)->pub.name, (*(task_obj *const *)b)->pub.name);
}

static task_obj **find_locked(fg_tasks *ts, const char *name) {
  for (size_t i = 0; i < ts->n; i++)
    if (strcmp(ts->tasks[i]->pub.name, name) == 0) return &ts->tasks[i];
  return NULL;
}

/* Puts o in the table (replacing the task of its name, whose reference is dropped). */
static int table_put(fg_tasks *ts, task_obj *o) {
  pthread_mutex_lock(&ts->lock);
  task_obj **slot = find_locked(ts, o->pub.name), *old = NULL;
  if (slot) {
    old = *slot;
    *slot = o;
  } else {
    if (ts->n == ts->cap) {
      size_t cap = ts->cap ? ts->cap * 2 : 16;
      task_obj **t = realloc(ts->tasks, cap * sizeof *t);
      if (!t) {
        pthread_mutex_unlock(&ts->lock);
        return fg_fail(FG_ENOMEM, "out of memory");
      }
      ts->tasks = t;
      ts->cap = cap;
    }
    ts->tasks[ts->n++] = o;
    qsort(ts->tasks, ts->n, sizeof *ts->tasks, cmp_obj);
  }
  pthread_mutex_unlock(&ts->lock);
  if (old) fg_task_unref(&old->pub);
  return 0;
}

static int is_broken(const fg_tasks *ts, const char *name) {
  for (size_t i = 0; i < ts->n_broken; i++)
    if (strcmp(ts->broken[i], name) == 0) return 1;
  return 0;
}

int fg_tasks_open(fg_tasks **out, const char *state_dir) {
  *out = NULL;
  fg_tasks *ts = calloc(1, sizeof *ts);
  if (!ts) return fg_fail(FG_ENOMEM, "out of memory");
  pthread_mutex_init(&ts->lock, NULL);
  pthread_mutex_init(&ts->write_lock, NULL);
  ts->dir = fg_path_join(state_dir, "tasks");
  int rc = ts->dir ? fg_mkdir_p(ts->dir) : fg_fail(FG_ENOMEM, "out of memory");
  DIR *d = rc == 0 ? opendir(ts->dir) : NULL;
  if (rc == 0 && !d) rc = fg_fail(FG_EIO, "cannot open %s: %s", ts->dir, strerror(errno));
  struct dirent *e;
  while (d && rc == 0 && (e = readdir(d)) != NULL) {
    if (e->d_name[0] == '.') {
      if (strncmp(e->d_name, ".trash-", 7) == 0) {
        char *p = fg_path_join(ts->dir, e->d_name);
        if (p && fg_rmtree(p) == 0) fg_info("removed the data of a deleted task (%s)", e->d_name);
        free(p);
      }
      continue;
    }
    if (fg_scene_name_validate(e->d_name) != 0) continue;
    char *dir = fg_path_join(ts->dir, e->d_name);
    struct stat sb;
    if (!dir || stat(dir, &sb) != 0 || !S_ISDIR(sb.st_mode)) {
      free(dir);
      continue;
    }
    fg_fs_sweep_tmp(dir);
    char *json = fg_path_join(dir, "task.json");
    const int has_json = json && access(json, F_OK) == 0;
    free(json);
    free(dir);
    if (!has_json) continue; /* a first demo cut short: its files are replaced when sent again */
    task_obj *o = NULL;
    int lrc = load_task(ts, e->d_name, &o);
    if (lrc == FG_ENOMEM) {
      rc = lrc;
      break;
    }
    if (lrc != 0) {
      fg_error("task %s is left out: %s; fix or remove %s/%s (new demos for this name are "
               "refused until then)", e->d_name, fg_error_detail(), ts->dir, e->d_name);
      char **b = realloc(ts->broken, (ts->n_broken + 1) * sizeof *b);
      char *name = strdup(e->d_name);
      if (!b || !name) {
        free(name);
        if (b) ts->broken = b;
        rc = fg_fail(FG_ENOMEM, "out of memory");
        break;
      }
      ts->broken = b;
      ts->broken[ts->n_broken++] = name;
      continue;
    }
    sweep_demos(ts, &o->pub);
    rc = table_put(ts, o);
    if (rc != 0) obj_free(o);
    else fg_info("task %s: %d demos", o->pub.name, o->pub.n_demos);
  }
  if (d) closedir(d);
  if (rc != 0) {
    fg_tasks_free(ts);
    return rc;
  }
  *out = ts;
  return 0;
}

void fg_tasks_free(fg_tasks *ts) {
  if (!ts) return;
  for (size_t i = 0; i < ts->n; i++) fg_task_unref(&ts->tasks[i]->pub);
  for (size_t i = 0; i < ts->n_broken; i++) free(ts->broken[i]);
  free(ts->broken);
  free(ts->tasks);
  free(ts->dir);
  pthread_mutex_destroy(&ts->lock);
  pthread_mutex_destroy(&ts->write_lock);
  free(ts);
}

const fg_task *fg_tasks_get(fg_tasks *ts, const char *name) {
  pthread_mutex_lock(&ts->lock);
  task_obj **slot = find_locked(ts, name);
  const fg_task *t = slot ? obj_ref(*slot) : NULL;
  pthread_mutex_unlock(&ts->lock);
  return t;
}

int fg_tasks_list(fg_tasks *ts, const fg_task ***out, size_t *n) {
  pthread_mutex_lock(&ts->lock);
  const fg_task **list = malloc((ts->n ? ts->n : 1) * sizeof *list);
  if (!list) {
    pthread_mutex_unlock(&ts->lock);
    return fg_fail(FG_ENOMEM, "out of memory");
  }
  for (size_t i = 0; i < ts->n; i++) list[i] = obj_ref(ts->tasks[i]);
  *n = ts->n;
  pthread_mutex_unlock(&ts->lock);
  *out = list;
  return 0;
}

void fg_tasks_list_free(const fg_task **list, size_t n) {
  for (size_t i = 0; list && i < n; i++) fg_task_unref(list[i]);
  free(list);
}

/* ---------------------------------------------------------------- changes */

fg_task_fit fg_task_check_demo(const fg_task *t, const fg_task_demo_new *d) {
  if (!t || t->n_demos == 0) return FG_TASK_FITS;
  if (t->n_demos >= FG_TASK_MAX_DEMOS)
    return fg_fail(FG_ERANGE, "task '%s' has %d demos, the most it keeps; delete one "
                   "(DELETE /v1/tasks/%s/demos/{id}) first", t->name, t->n_demos, t->name),
           FG_TASK_FULL;
  if (d->n_points != t->n_points || d->qp_layout != t->qp_layout ||
      d->qp_std_m != t->qp_std_m || memcmp(d->qp_size_m, t->qp_size_m, sizeof d->qp_size_m) ||
      memcmp(d->qp_mean_m, t->qp_mean_m, sizeof d->qp_mean_m) != 0) {
    json_t *qp = fg_task_query_points_json(t);
    char *text = qp ? json_dumps(qp, JSON_COMPACT | JSON_REAL_PRECISION(17)) : NULL;
    fg_fail(FG_EINVAL, "task '%s' samples the field at query points %s, fixed by its first "
            "demo; leave \"query_points\" out (or give those) to add a demo to it, or name "
            "another task", t->name, text ? text : "(out of memory)");
    free(text);
    json_decref(qp);
    return FG_TASK_QUERY_POINTS_DIFFER;
  }
  if (d->kind != t->kind)
    return fg_fail(FG_EINVAL, "task '%s' is a %s task; a %s demo belongs to another task",
                   t->name, fg_task_kind_name(t->kind), fg_task_kind_name(d->kind)),
           FG_TASK_KIND_DIFFERS;
  if (d->dim != t->dim)
    return fg_fail(FG_EINVAL, "task '%s' holds features of D = %d, but scene '%s' was trained "
                   "with D = %d; show it on a scene with features of D = %d, or name another "
                   "task", t->name, t->dim, d->scene, d->dim, t->dim),
           FG_TASK_DIM_DIFFERS;
  return FG_TASK_FITS;
}

int fg_tasks_add_demo(fg_tasks *ts, const char *name, const fg_task_demo_new *d,
                      fg_task_fit *fit, const fg_task **task, int *demo_id) {
  *fit = FG_TASK_FITS;
  if (task) *task = NULL;
  pthread_mutex_lock(&ts->write_lock);
  const fg_task *cur = fg_tasks_get(ts, name);
  int rc = 0, id = 0, wrote = 0;
  task_obj *o = NULL;
  fg_task_demo *demos = NULL;
  if (!cur && is_broken(ts, name)) {
    rc = fg_fail(FG_EBUSY, "a task '%s' is on disk (%s/%s) but did not load at start-up (see "
                 "the daemon's log); fix or remove that folder and restart, or name another "
                 "task", name, ts->dir, name);
    goto out;
  }
  *fit = fg_task_check_demo(cur, d);
  if (*fit != FG_TASK_FITS) {
    rc = FG_EEXIST;
    goto out;
  }
  fg_task base = {0};
  int n_old = 0;
  if (cur) {
    base = *cur;
    n_old = cur->n_demos;
  } else {
    snprintf(base.name, sizeof base.name, "%s", name);
    base.created_ms = fg_real_ms();
    base.next_id = 1;
  }
  if (n_old == 0) { /* the first demo fixes the query points, the kind and D */
    base.n_points = d->n_points;
    base.qp_layout = d->qp_layout;
    memcpy(base.qp_mean_m, d->qp_mean_m, sizeof base.qp_mean_m);
    base.qp_std_m = d->qp_std_m;
    memcpy(base.qp_size_m, d->qp_size_m, sizeof base.qp_size_m);
    base.kind = d->kind;
    base.dim = d->dim;
  }
  id = base.next_id++;
  demos = calloc((size_t)n_old + 1, sizeof *demos);
  if (!demos) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto out;
  }
  if (n_old) memcpy(demos, cur->demos, (size_t)n_old * sizeof *demos);
  fg_task_demo *x = &demos[n_old];
  x->id = id;
  snprintf(x->scene, sizeof x->scene, "%s", d->scene);
  memcpy(x->T_world_gripper, d->T_world_gripper, sizeof x->T_world_gripper);
  x->kind = d->kind;
  x->width_m = d->width_m;
  x->approach_m = d->approach_m;
  x->created_ms = fg_real_ms();
  x->z = d->z;
  if ((rc = obj_build(&base, demos, n_old + 1, &o)) != 0) goto out;
  char *dir = task_path(ts, name, NULL);
  rc = dir ? fg_mkdir_p(dir) : fg_fail(FG_ENOMEM, "out of memory");
  free(dir);
  /* A new task's folder: its entry in tasks/ must be durable before the demo is answered,
   * or a power cut could take the acknowledged task with it. */
  if (rc == 0 && !cur) rc = fg_fsync_dir(ts->dir);
  if (rc == 0) rc = write_demo_npy(ts, name, id, d->z, d->n_points, d->dim);
  wrote = rc == 0;
  if (rc == 0) rc = write_task_json(ts, &o->pub);
  if (rc == 0) rc = table_put(ts, o);
  if (rc != 0) goto out;
  if (task) *task = obj_ref(o);
  o = NULL;
  *demo_id = id;
out:
  if (rc != 0 && wrote) { /* task.json does not name it: remove the file again */
    char *p = demo_file(ts, name, id);
    if (p) unlink(p);
    free(p);
  }
  obj_free(o);
  free(demos);
  fg_task_unref(cur);
  pthread_mutex_unlock(&ts->write_lock);
  return rc;
}

int fg_tasks_delete_demo(fg_tasks *ts, const char *name, int id, const fg_task **task) {
  if (task) *task = NULL;
  pthread_mutex_lock(&ts->write_lock);
  const fg_task *cur = fg_tasks_get(ts, name);
  int rc = 0, pos = -1;
  task_obj *o = NULL;
  fg_task_demo *demos = NULL;
  if (!cur) {
    rc = fg_fail(FG_ENOENT, "no task named '%s'", name);
    goto out;
  }
  for (int i = 0; i < cur->n_demos; i++)
    if (cur->demos[i].id == id) pos = i;
  if (pos < 0) {
    rc = fg_fail(FG_ERANGE, "task '%s' has no demo %d", name, id);
    goto out;
  }
  demos = calloc((size_t)cur->n_demos, sizeof *demos);
  if (!demos) {
    rc = fg_fail(FG_ENOMEM, "out of memory");
    goto out;
  }
  int n = 0;
  for (int i = 0; i < cur->n_demos; i++)
    if (i != pos) demos[n++] = cur->demos[i];
  if ((rc = obj_build(cur, demos, n, &o)) != 0) goto out;
  rc = write_task_json(ts, &o->pub);
  if (rc == 0) rc = table_put(ts, o);
  if (rc != 0) goto out;
  if (task) *task = obj_ref(o);
  o = NULL;
  char *p = demo_file(ts, name, id);
  if (p && unlink(p) != 0)
    fg_warn("task %s: demo %d removed, but not its file %s: %s (it goes at the next start)",
            name, id, p, strerror(errno));
  free(p);
out:
  obj_free(o);
  free(demos);
  fg_task_unref(cur);
  pthread_mutex_unlock(&ts->write_lock);
  return rc;
}

int fg_tasks_delete(fg_tasks *ts, const char *name) {
  pthread_mutex_lock(&ts->write_lock);
  pthread_mutex_lock(&ts->lock);
  task_obj **slot = find_locked(ts, name);
  if (!slot) {
    pthread_mutex_unlock(&ts->lock);
    pthread_mutex_unlock(&ts->write_lock);
    return fg_fail(FG_ENOENT, "no task named '%s'", name);
  }
  pthread_mutex_unlock(&ts->lock);
  char trash[128];
  snprintf(trash, sizeof trash, ".trash-%s-%ld-%u", name, (long)getpid(),
           atomic_fetch_add(&trash_counter, 1));
  char *from = task_path(ts, name, NULL), *to = fg_path_join(ts->dir, trash);
  int rc = 0;
  if (!from || !to) rc = fg_fail(FG_ENOMEM, "out of memory");
  else if (rename(from, to) != 0)
    rc = fg_fail(FG_EIO, "cannot remove task %s: rename failed: %s", name, strerror(errno));
  task_obj *old = NULL;
  if (rc == 0) {
    fg_fsync_dir(ts->dir);
    pthread_mutex_lock(&ts->lock);
    slot = find_locked(ts, name);
    old = *slot;
    const size_t pos = (size_t)(slot - ts->tasks);
    memmove(ts->tasks + pos, ts->tasks + pos + 1, (ts->n - pos - 1) * sizeof *ts->tasks);
    ts->n--;
    pthread_mutex_unlock(&ts->lock);
  }
  pthread_mutex_unlock(&ts->write_lock);
  if (old) fg_task_unref(&old->pub);
  if (rc == 0 && fg_rmtree(to) != 0)
    fg_warn("task %s deleted, but its data stays in %s until the next start: %s", name, to,
            fg_error_detail());
  free(from);
  free(to);
  return rc;
}
