/* What cameras.c (calibrations, captures) and calibration.c (views, calibrating) share.
 * Private to cell/. */
#ifndef FG_DAEMON_CELL_CAMERAS_PRIV_H
#define FG_DAEMON_CELL_CAMERAS_PRIV_H

#include <limits.h>
#include <pthread.h>

#include "cameras.h"

#define MAX_CAMERAS 64

/* One view kept for calibration: the corners found, the robot's pose. */
typedef struct kept_view {
  int n;
  int *ids;
  double *px;
  int w, h;
  int has_robot_pose;
  double T_base_tcp[16];
} kept_view;

typedef struct entry {
  char name[FG_CAMERA_NAME_MAX + 1];
  fg_camera_calib calib;
  kept_view *views;
  int n_views;
} entry;

struct fg_cameras {
  char *dir; /* <state>/cameras */
  char grabber[PATH_MAX]; /* fieldgrip-grab: beside the daemon, else the installed one */
  pthread_mutex_t lock; /* guards e and n */
  entry e[MAX_CAMERAS];
  int n;
};

/* The entry of name under the lock; with add, a new empty one when there is none (NULL when
 * the table is full). */
entry *cameras_find_locked(fg_cameras *c, const char *name, int add);

/* Frees an entry's views (cameras.c: the table's owner frees what its entries hold). */
void cameras_views_free(entry *e);

#endif
