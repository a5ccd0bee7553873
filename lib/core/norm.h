/* Vector norms. */
#ifndef FG_CORE_NORM_H
#define FG_CORE_NORM_H

/* Scales v [n] to unit L2 norm (summed in double). FG_EINVAL when its norm is 0 or not
 * finite. */
int fg_l2_normalize(float *v, int n);

#endif
