/* gen_clip: writes a random CLIP in safetensors format (clipgen.h) for tests and benchmarks.
 *
 *   gen_clip OUT [--preset tiny|vit-b-16] [--naming openai|hf] [--dtype f32|f16|bf16]
 *                [--seed N] [--no-metadata]
 *
 * On success it prints one line: "OUT: N tensors, B bytes, fnv1a64 HEX" (the FNV-1a 64 of
 * the file's bytes, as tests/clip/data/golden_model.txt records it). Exit status 0, 1 on
 * failure, 2 on a usage error. */
#include <errno.h>
#include <getopt.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clipgen.h"
#include "core/error.h"

/* The command line, to f. */
static void usage(FILE *f) {
  fprintf(f,
          "usage: gen_clip OUT [--preset tiny|vit-b-16] [--naming openai|hf]\n"
          "                    [--dtype f32|f16|bf16] [--seed N] [--no-metadata]\n"
          "  OUT            the .safetensors file to write (replaced atomically)\n"
          "  --preset P     tiny (32 px, patch 8, widths 48/40; default) or vit-b-16\n"
          "  --naming N     openai (visual.*, transformer.*; default) or hf (CLIPModel)\n"
          "  --dtype D      f32 (default), f16 or bf16: the same values in each\n"
          "  --seed N       weights seed (default 0)\n"
          "  --no-metadata  leave out __metadata__ (vision_heads, text_heads)\n");
}

/* Parses a decimal unsigned 64-bit seed; 0 on success. */
static int parse_seed(const char *s, uint64_t *out) {
  char *end;
  errno = 0;
  if (!*s || *s == '-') return -1;
  unsigned long long v = strtoull(s, &end, 10);
  if (errno || *end) return -1;
  *out = (uint64_t)v;
  return 0;
}

/* Parses the options, writes the file and prints its summary line. */
int main(int argc, char **argv) {
  enum { OPT_PRESET = 256, OPT_NAMING, OPT_DTYPE, OPT_SEED, OPT_NO_METADATA, OPT_HELP };
  static const struct option opts[] = {
      {"preset", required_argument, NULL, OPT_PRESET},
      {"naming", required_argument, NULL, OPT_NAMING},
      {"dtype", required_argument, NULL, OPT_DTYPE},
      {"seed", required_argument, NULL, OPT_SEED},
      {"no-metadata", no_argument, NULL, OPT_NO_METADATA},
      {"help", no_argument, NULL, OPT_HELP},
      {NULL, 0, NULL, 0},
  };
  clipgen_preset preset = CLIPGEN_TINY;
  clipgen_naming naming = CLIPGEN_OPENAI;
  clipgen_dtype dtype = CLIPGEN_F32;
  uint64_t seed = 0;
  int metadata = 1, c;
  while ((c = getopt_long(argc, argv, "h", opts, NULL)) != -1) {
    switch (c) {
    case OPT_PRESET:
      if (!strcmp(optarg, "tiny")) {
        preset = CLIPGEN_TINY;
      } else if (!strcmp(optarg, "vit-b-16")) {
        preset = CLIPGEN_VIT_B_16;
      } else {
        fprintf(stderr, "gen_clip: unknown preset '%s' (tiny or vit-b-16)\n", optarg);
        return 2;
      }
      break;
    case OPT_NAMING:
      if (!strcmp(optarg, "openai")) {
        naming = CLIPGEN_OPENAI;
      } else if (!strcmp(optarg, "hf")) {
        naming = CLIPGEN_HF;
      } else {
        fprintf(stderr, "gen_clip: unknown naming '%s' (openai or hf)\n", optarg);
        return 2;
      }
      break;
    case OPT_DTYPE:
      if (!strcmp(optarg, "f32")) {
        dtype = CLIPGEN_F32;
      } else if (!strcmp(optarg, "f16")) {
        dtype = CLIPGEN_F16;
      } else if (!strcmp(optarg, "bf16")) {
        dtype = CLIPGEN_BF16;
      } else {
        fprintf(stderr, "gen_clip: unknown dtype '%s' (f32, f16 or bf16)\n", optarg);
        return 2;
      }
      break;
    case OPT_SEED:
      if (parse_seed(optarg, &seed)) {
        fprintf(stderr, "gen_clip: --seed wants a non-negative integer, got '%s'\n", optarg);
        return 2;
      }
      break;
    case OPT_NO_METADATA: metadata = 0; break;
    case OPT_HELP:
    case 'h': usage(stdout); return 0;
    default: usage(stderr); return 2;
    }
  }
  if (optind != argc - 1) {
    usage(stderr);
    return 2;
  }
  const char *out = argv[optind];

  clipgen_cfg cfg;
  if (clipgen_cfg_preset(&cfg, preset) != 0) {
    fprintf(stderr, "gen_clip: %s\n", fg_error_detail());
    return 1;
  }
  cfg.naming = naming;
  cfg.dtype = dtype;
  cfg.seed = seed;
  cfg.write_metadata = metadata;

  clipgen_tensor *t = NULL;
  int n = 0;
  size_t bytes = 0;
  uint64_t h = 0;
  if (clipgen_tensors(&cfg, &t, &n) != 0 || clipgen_write(out, &cfg, &bytes) != 0 ||
      clipgen_file_fnv1a64(out, &h) != 0) {
    fprintf(stderr, "gen_clip: %s\n", fg_error_detail());
    free(t);
    return 1;
  }
  free(t);
  printf("%s: %d tensors, %zu bytes, fnv1a64 %016" PRIx64 "\n", out, n, bytes, h);
  return 0;
}
