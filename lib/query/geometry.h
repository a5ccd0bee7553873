/* The geometry a gripper would collide with: the solid part of a trained field on a voxel
 * grid (grid.h's fg_voxel_grid), as a closed triangle mesh or as the centres of the solid
 * voxels, ready for a PLY file (io/ply.h).
 *
 * Solid voxels. Both read the voxels' opacities alpha = 1 - exp(-mean sigma * voxel_size)
 * (voxfeat.h), (nz, ny, nx) in the grid's flat order: the voxel feature cache holds them
 * (fg_voxel_features_alpha), fg_voxel_alpha() samples a field for any grid. A voxel is solid
 * when alpha >= threshold, the heatmap's rule for occupied voxels; a NaN alpha is empty.
 *
 * Mesh: marching cubes (Lorensen & Cline 1987) over the lattice of voxel centres, with Paul
 * Bourke's numbering of a cell's corners and edges ("Polygonising a scalar field", 1994):
 * corners 0..7 at (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1) in voxel
 * steps, edges 0..11 joining corners 0-1 1-2 2-3 3-0 4-5 5-6 6-7 7-4 0-4 1-5 2-6 3-7, and a
 * cell's case the 8-bit mask of its solid corners (bit i for corner i).
 *   - Case table. The triangles of each of the 256 cases are derived once by the rule that
 *     the published tables follow for unambiguous cases: on each face of the cell, every run
 *     of solid corners is cut off by a segment between the two crossed edges that bound it;
 *     the segments of a cell join into closed loops, and each loop becomes a fan of
 *     triangles. A face with two diagonal solid corners and two empty ones is ambiguous; the
 *     rule joins the solid corners across it (a thin diagonal bridge of material stays, as a
 *     gripper must assume) and, because it depends on that face's corners alone, the two
 *     cells sharing a face always cut it alike: the mesh has no cracks, which a table that
 *     settles ambiguous faces case by case cannot promise.
 *   - Vertices lie on the lattice edges they cross, placed by linear interpolation of alpha
 *     to the threshold, and are shared by every triangle that meets that edge: the mesh is
 *     indexed, without duplicate vertices.
 *   - The grid is padded with one layer of empty voxels whose lattice nodes stand on the faces
 *     of the grid's box [min, min + n * voxel_size] (metres, per axis), so a solid cut by the
 *     box is capped there: the mesh is always closed (every edge belongs to exactly two
 *     triangles) and every vertex lies in the box.
 *   - Triangles are counter-clockwise seen from the empty side: (v1 - v0) x (v2 - v0) points
 *     to low density, out of the solid.
 * Points: the centre of every solid voxel, in flat-index order.
 *
 * Coordinates are world frame, metres. Nothing here keeps a pointer to its inputs; every
 * function is thread-safe. */
#ifndef FG_QUERY_GEOMETRY_H
#define FG_QUERY_GEOMETRY_H

#include <stddef.h>
#include <stdint.h>

#include "query/grid.h"

struct fg_field;

typedef struct fg_mesh {
  size_t n_vertices;
  size_t n_faces;   /* 0 for points */
  float *p_world;   /* (n_vertices, 3) metres, world frame; owned */
  uint8_t *rgb;     /* (n_vertices, 3) sRGB, or NULL until fg_mesh_colour; owned */
  uint32_t *faces;  /* (n_faces, 3) vertex indices, or NULL when n_faces is 0; owned */
  int has_faces;    /* 1: a mesh (even of 0 faces); 0: points */
} fg_mesh;

/* Frees what *m owns and zeroes it; accepts a zeroed struct. */
void fg_mesh_release(fg_mesh *m);

/* Opacities of every voxel of grid g from field f into alpha (nz, ny, nx), the caller's
 * buffer, as the voxel feature cache computes them (voxfeat.h). For fields without a
 * feature branch or grids the cache does not hold. FG_EINVAL (NULL, a grid whose sizes do not match its workspace),
 * FG_ENOMEM. */
int fg_voxel_alpha(const struct fg_field *f, const fg_voxel_grid *g, float *alpha,
                   int n_threads);

/* The marching-cubes mesh of the solid voxels of alpha (nz, ny, nx) on grid g at threshold,
 * as above, into *out (rgb NULL). On success the caller owns what *out holds
 * (fg_mesh_release); on failure it holds nothing. threshold must be in (0, 1]: FG_EINVAL
 * otherwise or for NULL or a bad grid; FG_ENOMEM. A grid without solid voxels gives an empty
 * mesh. */
int fg_mesh_marching_cubes(const fg_voxel_grid *g, const float *alpha, float threshold,
                           fg_mesh *out);

/* The centres of the solid voxels of alpha (nz, ny, nx) on grid g at threshold into *out
 * (no faces, rgb NULL). Ownership and errors as fg_mesh_marching_cubes. */
int fg_mesh_points(const fg_voxel_grid *g, const float *alpha, float threshold, fg_mesh *out);

/* Unit vertex normals (n_vertices, 3) of mesh m into normals, the caller's buffer: the
 * area-weighted mean of the normals of the triangles around each vertex, pointing out of the
 * solid; (0, 0, 0) where they cancel and for meshes without faces. */
void fg_mesh_vertex_normals(const fg_mesh *m, float *normals);

/* Colours every vertex of m from field f into m->rgb (allocated here, owned by m, replacing
 * any): the sRGB colour (fg_field_colour, rounded to 8 bits) that a ray would see emitted
 * looking at the vertex along -n, n its normal, at the point inset_m metres inside the
 * surface along -n, where the field is dense and its colour was trained (half a voxel is a
 * good inset); points, and vertices without a normal, are seen from straight above (looking
 * along -z) at their own position. f stays the caller's. Errors of fg_field_colour,
 * FG_ENOMEM; m keeps no colours then. */
int fg_mesh_colour(fg_mesh *m, const struct fg_field *f, float inset_m, int n_threads);

/* The mesh (with a face element) or the points (without one) as a binary little-endian PLY
 * (io/ply.h), with colours when m->rgb is set and comment as its comment line (may be NULL),
 * into a malloc'd buffer the caller owns. Errors of fg_ply_encode. */
int fg_mesh_encode_ply(const fg_mesh *m, const char *comment, uint8_t **out, size_t *out_len);

#endif
