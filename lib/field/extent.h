/* How large a field's cube should be, and whether it learns a background, from what a
 * capture's frames show (the scene settings field_scale and learn_background on "auto").
 *
 * A tabletop cell's cameras look down at the workspace and what they see lies on or near the
 * table: a cube twice the workspace's largest extent holds it, and a learned background would
 * absorb the table (model.h). A phone walked around an object in a room (instant-ngp's fox)
 * sees walls metres beyond the workspace: the cube must reach the cameras, and what lies
 * beyond it is a background colour per direction, which the field must learn. The frames tell
 * which case holds:
 *  - with depth maps (any frame has one): the depth hits, every FG_FIELD_EXTENT_STRIDE-th
 *    pixel on both axes. While at most FG_FIELD_EXTENT_NEED_SHARE of them lie outside the
 *    cube of scale 2 (a floor or a wall at the edge of some views), the cell's field: scale
 *    2, no learned background. Else the smallest scale (a power of two, up to 64) whose cube
 *    holds all but FG_FIELD_EXTENT_FAR_SHARE of them, with a learned background;
 *  - without depth: the camera centres. All inside the cube of scale 2: the cell's field;
 *    else the smallest power of two whose cube holds every one (up to 64), with a learned
 *    background.
 * Frames given: camera-to-world in the OpenGL convention (fg_frame), PINHOLE, z-depth. */
#ifndef FG_FIELD_EXTENT_H
#define FG_FIELD_EXTENT_H

#include <stddef.h>

#include "io/frame.h"

#define FG_FIELD_EXTENT_STRIDE 4
#define FG_FIELD_EXTENT_NEED_SHARE 0.25
#define FG_FIELD_EXTENT_FAR_SHARE 0.05
#define FG_FIELD_EXTENT_DEFAULT_SCALE 2.0
#define FG_FIELD_EXTENT_MAX_SCALE 64.0

typedef struct fg_field_extent {
  double field_scale;   /* a power of two in [2, 64] */
  int learn_background; /* 1 when the frames see beyond the cube of scale 2 */
  int from_depth;       /* 1: depth hits decided; 0: camera centres */
  size_t points;        /* depth hits or camera centres looked at */
  double outside_share; /* of them, outside the cube of scale 2 */
} fg_field_extent;

/* The extent frames[0..n) call for over the workspace [ws_min, ws_max] (min < max on every
 * axis). Header-only frames (fg_frame_load_header: no depth values) count by their cameras.
 * n == 0 gives the cell's field. */
void fg_field_extent_choose(const double ws_min[3], const double ws_max[3],
                            const fg_frame *frames, size_t n, fg_field_extent *out);

#endif
