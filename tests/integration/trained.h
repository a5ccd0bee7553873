/* The trained fixture: the grasp tests' scenegen tabletop (grasp_util.h: G_VIEWS views of
 * G_W x G_H, D = G_DIM) imported and trained once per build folder by it_make_fixture, whose
 * scenes the tests that need a trained field copy into their own state dir instead of training
 * them again. Training is what train, render, depth, caps and the demo test; the tests that
 * copy the fixture test what is done with a trained field.
 *
 * The fixture, <build>/tests/integration/it-fixture/:
 *   sg/                 the data set (gt.json, transforms.json, transforms_nofeat.json: the
 *                       same frames without their features)
 *   scenes/t250/        the tabletop at 1 cm voxels, trained {"steps": 250}
 *   scenes/raw1/        the same, untrained
 *   scenes/t60/         the tabletop at 2 cm voxels, trained {"steps": 60}
 *   scenes/nofeat/      at 2 cm from transforms_nofeat.json, trained {"steps": 2}: colour only
 *   scenes/raw/         at 2 cm, untrained
 *   key                 what it was built with (fieldgripd's and scenegen's size and time)
 * A training gives the same field for the same frames, options and threads ([train] threads
 * = 2), so a copied scene is the scene the test trained before. The first test that needs the
 * fixture builds it under a lock, the others wait for it; a fieldgripd or scenegen built
 * since makes it be built again. */
#ifndef FG_IT_TRAINED_H
#define FG_IT_TRAINED_H

/* The fixture's folder, built first if needed with the daemon under test and scenegen
 * (paths). Fails the test when it cannot be built, with the builder's output.
 * $FG_IT_FIXTURE, when set, names a fixture another build of the same tree has built (CI's
 * sanitized stage takes its release stage's): it is used as it is, never built, so that the
 * sanitized stage spends its time on the code that uses a trained field, not on training it
 * again (training itself is what train, render, depth, caps and the demo test there). */
const char *f_fixture(const char *scenegen);

/* Copies the fixture's data set to <tmp>/imports/sg, loads its gt.json for g_gt() and g_dir()
 * (grasp_util.h), and returns <tmp>/imports (caller frees). */
char *f_dataset(const char *scenegen);

/* Copies fixture scene `from` into the state dir as scene `as`; before h_start. */
void f_scene(const char *from, const char *as);

#endif
