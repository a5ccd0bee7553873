/* The physics cell of a fieldgrip-scenegen layout: the table and the four objects as a MuJoCo
 * MJCF model (DIR/cell.xml), so that a simulator can load the very scene the images show and
 * execute grasps on it.
 *
 * MuJoCo collides convex primitives only (meshes it would replace by their convex hulls, which
 * fill the mug's cavity and the bowl's hollow), so each object is cut into convex parts that
 * follow its analytic solid of shapes.h to within about half a millimetre (1 mm just above
 * the bowl's foot) where a finger can touch it:
 *   mug:  wall00.. (boxes around the ring between the radii, from the floor's top to the rim;
 *         their faces cut the circles, straying as far inside as outside, at most 0.2 mm),
 *         bottom (a cylinder of the floor's thickness), handle00.. (capsules along chords of
 *         the handle's visible arc, ending where their caps would enter the cavity);
 *   bowl: shell_BB_SS (band BB from the bottom, segment SS around: boxes whose faces cut the
 *         inner and the outer sphere the same way, each covering its patch of the shell),
 *         foot (a cylinder where the sphere is cut flat, up to the inner sphere's lowest
 *         point);
 *   box:  solid (one box); ball: solid (one sphere).
 * The mug and the bowl also get a box inscribed in their bottom cylinder (bottom_box,
 * foot_box), invisible inside it: MuJoCo gives a box resting on the table several contacts
 * and a cylinder fewer, so the box is what makes them stand still. No other part reaches
 * within SG_CELL_CLEARANCE_M of the table, which keeps a resting cell to a handful of
 * contacts (MuJoCo 2.2's default contact buffer holds 100).
 *
 * Mass is spread uniformly over the analytic solid (its inertia integrated on a 1 mm grid),
 * with a fixed mass per object whatever its scale. */
#ifndef SG_CELL_H
#define SG_CELL_H

#include <stddef.h>

#include "scene.h"

/* Gap kept between the table and every object part but the bottom's (metres). */
#define SG_CELL_CLEARANCE_M 0.0005

/* Mass and surface of an object in the cell. friction is MuJoCo's sliding coefficient (the
 * torsional and rolling ones are MuJoCo's defaults, 0.005 and 0.0001); MuJoCo uses the larger
 * of two touching geoms' coefficients. */
typedef struct sg_cell_material {
  const char *what;  /* static: "ceramic", ... */
  double mass_kg;
  double friction;
} sg_cell_material;

/* The table's sliding friction (wood). */
#define SG_CELL_TABLE_FRICTION 0.5

/* The table plane's grid spacing, as MuJoCo draws it (metres). */
#define SG_CELL_TABLE_GRID_M 0.06

/* The material of an object type; static, never NULL. */
const sg_cell_material *sg_cell_material_of(sg_shape_type t);

/* The cell as MJCF text: the model "fieldgrip-scenegen seed N", the table geom "table" on the
 * world body (a plane at the top of the scene's table slab, drawn over it), and a body per
 * object named as the object, with a free joint of the same name, at T_world_obj, holding its
 * parts as geoms "<object>/<part>" in the object frame. No <option>: the simulator sets its
 * own. The same scene gives the same bytes.
 * 0 on success with *xml (NUL-terminated, *len bytes without the NUL) owned by the caller, who
 * frees it; otherwise *xml is NULL and the code FG_ENOMEM, or FG_ERANGE for shape parameters
 * that leave no room for the parts (none that sg_scene_build makes). */
int sg_cell_xml(const sg_scene *sc, char **xml, size_t *len);

#endif
