/* Fuzz target for the Modbus register decoders: the words a robot controller or a Robotiq
 * gripper answers with are outside input, so every pattern of words must decode without a
 * crash and the derived values must stay in their documented ranges. */
#include "modbus/regs.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  uint16_t w[FG_POSE_BLOCK_SPAN] = {0};
  for (size_t i = 0; i < FG_POSE_BLOCK_SPAN && 2 * i + 1 < size; i++)
    w[i] = (uint16_t)(data[2 * i] | data[2 * i + 1] << 8);

  for (int e = FG_POSE_INT16; e <= FG_POSE_FLOAT32; e++) {
    fg_pose_block b;
    memset(&b, 0, sizeof b);
    fg_pose_block_decode(w, (fg_pose_encoding)e, &b);
    if (fg_pose_ack_offset((fg_pose_encoding)e) + 2 > FG_POSE_BLOCK_SPAN) abort();
  }
  (void)fg_float32_from_words(w);
  (void)fg_seq_next(w[0]);

  fg_robotiq_status s;
  fg_robotiq_status_decode(w, &s);
  if (s.position < 0 || s.position > 255 || s.echo < 0 || s.echo > 255) abort();
  if (s.current < 0 || s.current > 255 || s.sta < 0 || s.sta > 3 || s.obj < 0 || s.obj > 3) abort();
  if (!fg_robotiq_fault_name(s.flt)) abort();
  (void)fg_robotiq_object_detected(&s);
  return 0;
}
