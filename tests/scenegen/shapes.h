/* Analytic solids of the scene generator: a mug, a bowl, a box and a ball standing on the
 * table, each in its own object frame. Used by fieldgrip-scenegen to ray-cast its images
 * and by tests (through gt.h) to ask "is this point inside object k?".
 *
 * Object frame (metres): origin on the object's vertical axis at half its height, +z up,
 * +x along the mug's handle / the box's length; T_world_obj is a yaw about +z plus a
 * translation, so the object's base lies on the table plane z = 0 of the world frame.
 *
 * Shape parameters, all in metres and in the object frame (gt.json "shape" holds the same
 * names):
 *   mug:  the solid body {r <= outer_radius, |z| <= height/2} minus the cavity
 *         {r < inner_radius, z > -height/2 + bottom} (open at the top), plus a handle: the
 *         torus of centre handle_center, ring radius handle_major and tube radius handle_minor
 *         whose ring lies in the x-z plane (torus axis = y), kept where r >= handle_clip_radius
 *         (r = distance from the z axis), so only its outer half shows.
 *   bowl: the ball |p - c| <= outer_radius with c = (0, 0, sphere_center_z) minus the ball
 *         |p - c| < inner_radius, cut to -height/2 <= z <= height/2 (= c.z: the rim; the
 *         bottom cut gives the bowl a flat foot).
 *   box:  |x| <= size[0]/2, |y| <= size[1]/2, |z| <= size[2]/2.
 *   ball: |p| <= radius (height = 2 radius).
 * Inside tests count the boundary as inside. */
#ifndef SG_SHAPES_H
#define SG_SHAPES_H

typedef enum {
  SG_SHAPE_MUG = 0,
  SG_SHAPE_BOWL = 1,
  SG_SHAPE_BOX = 2,
  SG_SHAPE_BALL = 3,
} sg_shape_type;

typedef struct sg_shape {
  sg_shape_type type;
  double T_world_obj[16]; /* row-major, rigid (yaw about z + translation) */
  double T_obj_world[16]; /* its inverse; fill with sg_shape_finish */
  double bound_center_world[3], bound_radius; /* a sphere around the solid (sg_shape_finish) */
  /* mug and bowl */
  double outer_radius, inner_radius, height;
  /* mug */
  double bottom;            /* thickness of the mug's floor */
  double handle_center[3];  /* torus centre, object frame */
  double handle_major, handle_minor, handle_clip_radius;
  /* bowl */
  double sphere_center_z;
  /* box: full edge lengths; mug, bowl and ball leave it zero */
  double size[3];
  /* ball */
  double radius;
} sg_shape;

/* A ray hit: distance along the (unit) direction and the outward surface normal, world
 * frame. */
typedef struct sg_hit {
  double t;
  double n_world[3];
} sg_hit;

const char *sg_shape_type_name(sg_shape_type t);

/* Computes T_obj_world and the bounding sphere from T_world_obj and the parameters. */
void sg_shape_finish(sg_shape *s);

/* First intersection of the ray o + t d (world frame, d unit) with the solid for t in
 * (t_min, t_max). Returns 1 and fills *hit, or 0 when the ray misses. */
int sg_shape_intersect(const sg_shape *s, const double o_world[3], const double d_world[3],
                       double t_min, double t_max, sg_hit *hit);

/* 1 when p_world lies inside the solid (boundary included), else 0. */
int sg_shape_inside(const sg_shape *s, const double p_world[3]);

/* The shape's bounding box in its object frame, [lo, hi] per axis (the mug's reaches further
 * along +x, to the handle); gt.json's "size" is hi - lo. */
void sg_shape_local_bounds(const sg_shape *s, double lo[3], double hi[3]);

/* World-frame axis-aligned bounding box (tight for the mug's body, the bowl, the box and the
 * ball; the mug's handle contributes its local box's corners). */
void sg_shape_world_aabb(const sg_shape *s, double min_world[3], double max_world[3]);

/* Signed-distance-like value of the torus of a mug's handle (negative inside); exposed for
 * tests. */
double sg_mug_handle_sdf(const sg_shape *s, const double p_obj[3]);

/* Point and direction transforms with a row-major rigid 4x4. */
void sg_xform_point(const double T[16], const double p[3], double out[3]);
void sg_xform_dir(const double T[16], const double d[3], double out[3]);

#endif
