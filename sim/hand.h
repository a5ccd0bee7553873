/* The simulated gripper: the [gripper] model's boxes (lib/grasp/gripper.h) as MuJoCo bodies,
 * for the physics cell (cell.h). */
#ifndef FG_SIM_HAND_H
#define FG_SIM_HAND_H

#include "grasp/gripper.h"

#define SIM_FINGER_KD 120.0 /* N s/m: the finger joints' damping (integrated implicitly) */

/* The finger bodies' and motors' names without the "fg_" prefix: [0] stands at -y and closes
 * along +y, [1] at +y. */
extern const char *const sim_hand_finger[2];

/* The wrapper model as MJCF text: scene_file (a name beside the wrapper) included, then the
 * mocap target fg_target, the hand fg_hand (palm with a free joint welded to the target, the
 * fingers fg_finger_l and fg_finger_r on slide joints of the same names, coupled) weighing
 * mass_kg, and a motor per finger capped at force_max_n newtons. NULL when out of memory.
 * The caller frees it. */
char *sim_hand_xml(const char *scene_file, fg_gripper_model model, double mass_kg,
                   double force_max_n);

#endif
