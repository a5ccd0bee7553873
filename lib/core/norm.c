#include "core/norm.h"
#include "core/error.h"

#include <math.h>

int fg_l2_normalize(float *v, int n) {
  double ss = 0;
  for (int i = 0; i < n; i++) ss += (double)v[i] * (double)v[i];
  double norm = sqrt(ss);
  if (!(norm > 0) || !isfinite(norm)) return fg_fail(FG_EINVAL, "the vector has norm %g", norm);
  for (int i = 0; i < n; i++) v[i] = (float)((double)v[i] / norm);
  return 0;
}
