/* The application object's configuration references; see app.h. */
#include "app.h"

#include <stdlib.h>

/* Every configuration still in use stays on a short list until its last request ends;
 * the head is the current one, which holds a reference of its own. */
struct fg_conf_ref {
  fg_conf *conf;
  int refs; /* guarded by fg_app.conf_lock */
  fg_conf_ref *next;
};

/* Drops one reference under the lock; returns the configuration to free, if it was the last. */
static fg_conf_ref *unref_locked(fg_app *app, const fg_conf *conf) {
  for (fg_conf_ref **p = &app->conf; *p; p = &(*p)->next) {
    fg_conf_ref *r = *p;
    if (r->conf != conf) continue;
    if (--r->refs > 0) return NULL;
    *p = r->next;
    return r;
  }
  return NULL;
}

static void ref_free(fg_conf_ref *r) {
  if (!r) return;
  fg_conf_free(r->conf);
  free(r);
}

void fg_app_set_conf(fg_app *app, fg_conf *conf) {
  fg_conf_ref *r = calloc(1, sizeof *r);
  if (!r) abort(); /* a few bytes at start-up or reload; nothing sensible to do without them */
  r->conf = conf;
  r->refs = 1;
  pthread_mutex_lock(&app->conf_lock);
  fg_conf_ref *old = app->conf;
  r->next = old;
  app->conf = r;
  fg_conf_ref *dead = old ? unref_locked(app, old->conf) : NULL;
  pthread_mutex_unlock(&app->conf_lock);
  ref_free(dead);
}

void fg_app_clear_conf(fg_app *app) {
  pthread_mutex_lock(&app->conf_lock);
  fg_conf_ref *dead = app->conf ? unref_locked(app, app->conf->conf) : NULL;
  pthread_mutex_unlock(&app->conf_lock);
  ref_free(dead);
}

const fg_conf *fg_app_conf_acquire(fg_app *app) {
  pthread_mutex_lock(&app->conf_lock);
  app->conf->refs++;
  const fg_conf *c = app->conf->conf;
  pthread_mutex_unlock(&app->conf_lock);
  return c;
}

void fg_app_conf_release(fg_app *app, const fg_conf *conf) {
  pthread_mutex_lock(&app->conf_lock);
  fg_conf_ref *dead = unref_locked(app, conf);
  pthread_mutex_unlock(&app->conf_lock);
  ref_free(dead);
}
