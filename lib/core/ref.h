/* Reference counts: an object shared between threads carries an fg_ref, starts with the
 * references its creator hands out, and is freed by whoever drops the last one. And the slot
 * that holds the current version of such an object, replaced whole (fg_ref_slot). */
#ifndef FG_CORE_REF_H
#define FG_CORE_REF_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

typedef struct fg_ref {
  atomic_int n;
} fg_ref;

/* n references to start with (the creator's, and any it hands out at once). */
static inline void fg_ref_init(fg_ref *r, int n) { atomic_init(&r->n, n); }

/* One more reference. */
static inline void fg_ref_get(fg_ref *r) { atomic_fetch_add(&r->n, 1); }

/* Drops one reference: 1 when it was the last, and the caller frees the object. */
static inline int fg_ref_put(fg_ref *r) { return atomic_fetch_sub(&r->n, 1) == 1; }

/* 1 when the caller's is the only reference (no other thread can take one meanwhile: the
 * object is reachable only through a lock the caller holds). */
static inline int fg_ref_only(fg_ref *r) { return atomic_load(&r->n) == 1; }

/* The current version of a shared object (a loaded model, a built cache): readers take a
 * reference to whatever is current and keep using it while a writer swaps in the next one;
 * the last reader of the old one frees it. The slot holds one reference to its object. */
typedef struct fg_ref_slot {
  pthread_mutex_t lock;
  void *obj;   /* NULL: none */
  fg_ref *ref; /* obj's count */
} fg_ref_slot;

static inline void fg_ref_slot_init(fg_ref_slot *s) {
  pthread_mutex_init(&s->lock, NULL);
  s->obj = NULL;
  s->ref = NULL;
}

/* The object held (the caller drops the slot's reference to it), the slot destroyed. */
static inline void *fg_ref_slot_destroy(fg_ref_slot *s) {
  pthread_mutex_destroy(&s->lock);
  return s->obj;
}

/* A new reference to the current object, or NULL when there is none. */
static inline void *fg_ref_slot_acquire(fg_ref_slot *s) {
  pthread_mutex_lock(&s->lock);
  void *obj = s->obj;
  if (obj) fg_ref_get(s->ref);
  pthread_mutex_unlock(&s->lock);
  return obj;
}

/* Makes obj (counted by ref, which carries the slot's reference; NULL: none) current and
 * returns what was: the caller drops the slot's reference to it, outside any lock. */
static inline void *fg_ref_slot_swap(fg_ref_slot *s, void *obj, fg_ref *ref) {
  pthread_mutex_lock(&s->lock);
  void *old = s->obj;
  s->obj = obj;
  s->ref = obj ? ref : NULL;
  pthread_mutex_unlock(&s->lock);
  return old;
}

#endif
