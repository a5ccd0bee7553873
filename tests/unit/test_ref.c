/* fg_ref_slot (core/ref.h): readers take the current object while a writer swaps versions in;
 * every version is freed exactly once, by whoever drops its last reference, and never while
 * a reader holds it (a freed version's canary would show; the sanitized build sees more). */
#include "test.h"

#include <pthread.h>

#include "core/ref.h"

typedef struct {
  fg_ref ref;
  int version;
  atomic_int alive; /* 1 until freed: a reader that sees 0 used a freed version */
} obj;

static atomic_int n_freed;

static obj *obj_new(int version) {
  obj *o = malloc(sizeof *o);
  ASSERT(o);
  fg_ref_init(&o->ref, 1); /* the slot's */
  o->version = version;
  atomic_init(&o->alive, 1);
  return o;
}

static void obj_release(obj *o) {
  if (o && fg_ref_put(&o->ref)) {
    atomic_store(&o->alive, 0);
    atomic_fetch_add(&n_freed, 1);
    free(o);
  }
}

#define N_READERS 4
#define N_VERSIONS 2000

static fg_ref_slot g_slot;
static atomic_int g_done;

static void *reader(void *arg) {
  (void)arg;
  long seen = 0, last = 0;
  while (!atomic_load(&g_done)) {
    obj *o = fg_ref_slot_acquire(&g_slot);
    if (!o) continue;
    ASSERT_EQ(atomic_load(&o->alive), 1);
    ASSERT(o->version >= last); /* versions only move forward */
    last = o->version;
    seen++;
    obj_release(o);
  }
  return (void *)seen;
}

int main(void) {
  /* one thread: the counts by hand */
  fg_ref_slot_init(&g_slot);
  ASSERT(fg_ref_slot_acquire(&g_slot) == NULL);
  obj *a = obj_new(1);
  ASSERT(fg_ref_slot_swap(&g_slot, a, &a->ref) == NULL);
  obj *r = fg_ref_slot_acquire(&g_slot);
  ASSERT(r == a);
  ASSERT(!fg_ref_only(&a->ref)); /* the slot's and ours */
  obj *b = obj_new(2);
  obj *old = fg_ref_slot_swap(&g_slot, b, &b->ref);
  ASSERT(old == a);
  obj_release(old); /* the slot's: ours keeps it */
  ASSERT_EQ(atomic_load(&n_freed), 0);
  ASSERT_EQ(r->version, 1);
  obj_release(r);
  ASSERT_EQ(atomic_load(&n_freed), 1);
  obj *none = fg_ref_slot_swap(&g_slot, NULL, NULL); /* emptied */
  ASSERT(none == b);
  ASSERT(fg_ref_slot_acquire(&g_slot) == NULL);
  obj_release(none);
  ASSERT_EQ(atomic_load(&n_freed), 2);
  ASSERT(fg_ref_slot_destroy(&g_slot) == NULL);

  /* readers against a writer */
  atomic_store(&n_freed, 0);
  fg_ref_slot_init(&g_slot);
  pthread_t t[N_READERS];
  for (int i = 0; i < N_READERS; i++) ASSERT_EQ(pthread_create(&t[i], NULL, reader, NULL), 0);
  for (int v = 1; v <= N_VERSIONS; v++) {
    obj *o = obj_new(v);
    obj_release(fg_ref_slot_swap(&g_slot, o, &o->ref));
  }
  atomic_store(&g_done, 1);
  long seen = 0;
  for (int i = 0; i < N_READERS; i++) {
    void *s;
    ASSERT_EQ(pthread_join(t[i], &s), 0);
    seen += (long)s;
  }
  ASSERT_EQ(atomic_load(&n_freed), N_VERSIONS - 1); /* all but the current one */
  obj_release(fg_ref_slot_destroy(&g_slot));
  ASSERT_EQ(atomic_load(&n_freed), N_VERSIONS);
  printf("ok: %d versions swapped under %d readers (%ld acquisitions), each freed once\n",
         N_VERSIONS, N_READERS, seen);
  return 0;
}
