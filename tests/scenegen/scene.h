/* The procedural tabletop of fieldgrip-scenegen: objects placed by a seed, cameras on a
 * hemisphere, class embeddings, and a ray caster that renders a view's colours, class mask and
 * patch features.
 *
 * World frame of SPEC.md: metres, right-handed, +z up; the table top is the plane z = 0. */
#ifndef SG_SCENE_H
#define SG_SCENE_H

#include <stdint.h>

#include "io/camera.h"
#include "shapes.h"

/* Class indices; mask pixels hold them. There is one object per object class, so object k of
 * the scene has class k + SG_CLASS_MUG. */
enum {
  SG_CLASS_BACKGROUND = 0,
  SG_CLASS_TABLE = 1,
  SG_CLASS_MUG = 2,
  SG_CLASS_BOWL = 3,
  SG_CLASS_BOX = 4,
  SG_CLASS_BALL = 5,
  SG_N_CLASSES = 6,
};

#define SG_N_OBJECTS 4

/* Largest pairwise cosine between class embeddings. */
#define SG_MAX_CLASS_COSINE 0.3

/* Depth maps written beside the images (scenegen's --depth). */
typedef enum sg_depth_format {
  SG_DEPTH_NONE = 0, /* none: the data set of a plain RGB camera */
  SG_DEPTH_PNG = 1,  /* depth/NNNN.png: 16-bit grey, millimetres */
  SG_DEPTH_NPY = 2,  /* depth/NNNN.npy: float32 [h, w], metres */
} sg_depth_format;

typedef struct sg_config {
  uint64_t seed;
  int64_t embedding_seed; /* class embeddings' seed; -1: seed's (every layout its own) */
  int n_views;  /* cameras */
  int w, h;     /* image size, pixels */
  int dim;      /* feature dimension D, >= SG_N_CLASSES */
  int patch;    /* feature cell size, pixels */
  double noise; /* expected norm of the noise added to a unit class embedding */
  int holdout;  /* view i goes to transforms_test.json when i % holdout == 0; 0: none */
  sg_depth_format depth; /* depth maps to write; SG_DEPTH_NONE by default */
  /* The same layout after the scene changed: objects left out (bit k: object k, of class
   * SG_CLASS_MUG + k; --remove) and moved along the table (metres in x and y; --move). The
   * others keep their poses, the cameras theirs. */
  unsigned removed;
  double moved_xy[SG_N_OBJECTS][2];
} sg_config;

/* Defaults of the command line. */
void sg_config_default(sg_config *cfg);

typedef struct sg_object {
  const char *name; /* static: "mug", "bowl", "box", "ball" */
  int present;      /* 0: left out of the scene (sg_config.removed) */
  int class_id;
  sg_shape shape;
  double albedo[3];           /* linear RGB */
  double T_world_grasp[16];   /* gripper frame of SPEC.md at the grasp */
  double grasp_width_m;       /* distance between the contacts */
} sg_object;

typedef struct sg_scene {
  sg_config cfg;
  sg_object objects[SG_N_OBJECTS];
  double table_min[3], table_max[3]; /* the table slab, world frame */
  double look_at_world[3];           /* every camera looks at this point */
  double camera_radius_m;
  double light_dir_world[3];         /* unit, towards the light */
  double ambient;                    /* ambient share of the light, [0, 1] */
  float background_rgb[3];           /* sRGB-encoded [0, 1], exactly the PNG's value */
  fg_camera cam;                     /* PINHOLE, shared by all views */
  double *T_world_cam;               /* (n_views, 16) row-major, OpenGL convention; owned */
  float *embeddings;                 /* (SG_N_CLASSES, dim), unit rows; owned */
  int feat_h, feat_w;                /* ceil(h / patch), ceil(w / patch) */
  /* Private to scene.c: the linear value of each sRGB code k - 0.5, the background in linear. */
  float srgb_thresholds[256];
  float background_linear[3];
} sg_scene;

extern const char *const sg_class_names[SG_N_CLASSES];

/* Builds the scene for a configuration. 0 on success (the caller frees the scene with
 * sg_scene_free); FG_EINVAL (fg_error_detail says why) for a configuration it cannot honour,
 * FG_ENOMEM; on failure *sc holds nothing to free. */
int sg_scene_build(sg_scene *sc, const sg_config *cfg);

void sg_scene_free(sg_scene *sc);

/* Renders view i: rgb is (h, w, 3) 8-bit sRGB, mask is (h, w) class indices of the ray
 * through each pixel's centre. depth_m, when not NULL, is (h, w): the z-depth of that same
 * ray's hit in metres, measured along the camera's optical axis (an RGB-D camera's depth, not
 * the distance along the ray), 0 where the ray hits nothing. OpenMP over rows; the result
 * does not depend on threads. */
void sg_scene_render(const sg_scene *sc, int view, uint8_t *rgb, uint8_t *mask, float *depth_m);

/* The patch features of view i from its mask: feat is (feat_h, feat_w, dim); 0, or
 * FG_ENOMEM. A pixel (u, v)
 * belongs to cell (floor(v feat_h / h), floor(u feat_w / w)) (SPEC.md "Files"); each cell
 * holds the embedding of the class most of its pixels show (ties to the lower index), plus
 * Gaussian noise of per-component std noise / sqrt(dim), renormalised. */
int sg_scene_features(const sg_scene *sc, int view, const uint8_t *mask, float *feat);

/* First hit of a world ray among the table and the objects: returns the class index
 * (SG_CLASS_BACKGROUND when nothing is hit) and fills *hit when something is. */
int sg_scene_trace(const sg_scene *sc, const double o[3], const double d[3], double t_min,
                   sg_hit *hit);

#endif
