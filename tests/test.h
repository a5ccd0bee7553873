/* Minimal test macros: each test is its own executable (one process per test, as libuv),
 * run by meson test. A failed ASSERT prints both values with file and line and exits 1. */
#ifndef FG_TEST_H
#define FG_TEST_H

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FG_TEST_FAIL(...)                                                                  \
  do {                                                                                     \
    fprintf(stderr, "%s:%d: ", __FILE__, __LINE__);                                        \
    fprintf(stderr, __VA_ARGS__);                                                          \
    fputc('\n', stderr);                                                                   \
    exit(1);                                                                               \
  } while (0)

#define ASSERT(cond)                                                                       \
  do {                                                                                     \
    if (!(cond)) FG_TEST_FAIL("assertion failed: %s", #cond);                              \
  } while (0)

#define ASSERT_EQ(a, b)                                                                    \
  do {                                                                                     \
    long long fg_a_ = (long long)(a), fg_b_ = (long long)(b);                              \
    if (fg_a_ != fg_b_) FG_TEST_FAIL("%s == %s: %lld != %lld", #a, #b, fg_a_, fg_b_);      \
  } while (0)

#define ASSERT_NE(a, b)                                                                    \
  do {                                                                                     \
    long long fg_a_ = (long long)(a), fg_b_ = (long long)(b);                              \
    if (fg_a_ == fg_b_) FG_TEST_FAIL("%s != %s: both %lld", #a, #b, fg_a_);                \
  } while (0)

/* A library call that must succeed; prints its detail message when it does not. */
#define ASSERT_OK(expr)                                                                    \
  do {                                                                                     \
    int fg_rc_ = (expr);                                                                   \
    if (fg_rc_ != 0)                                                                       \
      FG_TEST_FAIL("%s failed: %d (%s) %s", #expr, fg_rc_, fg_strerror(fg_rc_),            \
                   fg_error_detail());                                                     \
  } while (0)

/* A library call that must fail with a given code and a detail containing a substring. */
#define ASSERT_ERR(expr, code, substr)                                                     \
  do {                                                                                     \
    int fg_rc_ = (expr);                                                                   \
    if (fg_rc_ != (code))                                                                  \
      FG_TEST_FAIL("%s returned %d, expected %d (detail: %s)", #expr, fg_rc_, (int)(code), \
                   fg_error_detail());                                                     \
    if ((substr) && !strstr(fg_error_detail(), (substr)))                                  \
      FG_TEST_FAIL("%s detail \"%s\" lacks \"%s\"", #expr, fg_error_detail(), (substr));   \
  } while (0)

#define ASSERT_NEAR(a, b, tol)                                                             \
  do {                                                                                     \
    double fg_a_ = (double)(a), fg_b_ = (double)(b);                                       \
    if (!(fabs(fg_a_ - fg_b_) <= (tol)))                                                   \
      FG_TEST_FAIL("%s ~ %s: %.9g vs %.9g (tol %g)", #a, #b, fg_a_, fg_b_, (double)(tol)); \
  } while (0)

#define ASSERT_STREQ(a, b)                                                                 \
  do {                                                                                     \
    const char *fg_a_ = (a), *fg_b_ = (b);                                                 \
    if (!fg_a_ || !fg_b_ || strcmp(fg_a_, fg_b_) != 0)                                     \
      FG_TEST_FAIL("%s == %s: \"%s\" != \"%s\"", #a, #b, fg_a_ ? fg_a_ : "(null)",         \
                   fg_b_ ? fg_b_ : "(null)");                                              \
  } while (0)

#define ASSERT_STRCONTAINS(hay, needle)                                                    \
  do {                                                                                     \
    const char *fg_h_ = (hay), *fg_n_ = (needle);                                          \
    if (!fg_h_ || !strstr(fg_h_, fg_n_))                                                   \
      FG_TEST_FAIL("%s does not contain \"%s\": \"%s\"", #hay, fg_n_,                      \
                   fg_h_ ? fg_h_ : "(null)");                                              \
  } while (0)

#endif
