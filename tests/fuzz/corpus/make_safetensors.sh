#!/bin/sh
# Writes the seed corpus of fuzz_safetensors into corpus/safetensors/ (run from this folder;
# the output is committed, so the tests never run this). Each file is an 8-byte little-endian
# header length, the JSON header and the data bytes, all a few dozen bytes long.
set -eu
out=safetensors
mkdir -p "$out"

# st FILE HEADER DATA [pad]: DATA is a printf format of the data bytes; with "pad" the header
# gets trailing spaces up to a multiple of 8 bytes.
st() {
  h=$2
  if [ "${4:-}" = pad ]; then
    while [ $(($(printf '%s' "$h" | wc -c) % 8)) -ne 0 ]; do h="$h "; done
  fi
  n=$(printf '%s' "$h" | wc -c)
  {
    printf "\\$(printf %03o $((n & 255)))\\$(printf %03o $((n >> 8 & 255)))"
    printf '\000\000\000\000\000\000'
    printf '%s' "$h"
    printf "$3"
  } > "$out/$1"
}

# valid: float dtypes with metadata, padded with spaces to a multiple of 8 like the Python writer
st valid_float.st '{"__metadata__":{"format":"pt"},"a":{"dtype":"F32","shape":[2,2],"data_offsets":[0,16]},"b":{"dtype":"F16","shape":[3],"data_offsets":[16,22]},"c":{"dtype":"BF16","shape":[1,2],"data_offsets":[22,26]}}' \
  '\000\000\200\077\000\000\000\300\000\000\040\101\000\000\200\277\000\074\101\300\377\173\200\077\040\300' pad
# valid: int64 position ids next to an f32 matrix
st valid_i64.st '{"position_ids":{"dtype":"I64","shape":[1,3],"data_offsets":[0,24]},"w":{"dtype":"F32","shape":[1,1],"data_offsets":[24,28]}}' \
  '\000\000\000\000\000\000\000\000\001\000\000\000\000\000\000\000\002\000\000\000\000\000\000\000\000\000\200\077'
# valid: a scalar, an empty tensor, bools
st valid_edge.st '{"s":{"dtype":"F32","shape":[],"data_offsets":[0,4]},"e":{"dtype":"F16","shape":[0,3],"data_offsets":[4,4]},"m":{"dtype":"BOOL","shape":[2],"data_offsets":[4,6]}}' \
  '\000\000\000\100\001\000'
# valid: dtypes read as raw bytes
st valid_other.st '{"u":{"dtype":"U16","shape":[1],"data_offsets":[0,2]},"f8":{"dtype":"F8_E4M3","shape":[2],"data_offsets":[2,4]},"i":{"dtype":"I32","shape":[1],"data_offsets":[4,8]},"d":{"dtype":"F64","shape":[1],"data_offsets":[8,16]}}' \
  '\001\000\070\100\377\377\377\377\000\000\000\000\000\000\360\077'
# valid: nothing at all
st valid_empty.st '{}      ' ''
# invalid: overlapping tensors, a gap, a wrong byte count, an unknown dtype
st bad_overlap.st '{"a":{"dtype":"F32","shape":[2],"data_offsets":[0,8]},"b":{"dtype":"F32","shape":[2],"data_offsets":[4,12]}}' \
  '\000\000\000\000\000\000\000\000\000\000\000\000'
st bad_gap.st '{"a":{"dtype":"F32","shape":[1],"data_offsets":[0,4]},"b":{"dtype":"F32","shape":[1],"data_offsets":[8,12]}}' \
  '\000\000\000\000\000\000\000\000\000\000\000\000'
st bad_nbytes.st '{"visual.proj":{"dtype":"F32","shape":[2,4],"data_offsets":[0,12]}}' \
  '\000\000\000\000\000\000\000\000\000\000\000\000'
st bad_dtype.st '{"a":{"dtype":"Q4","shape":[2],"data_offsets":[0,2]}}' '\000\000'
# invalid: a valid file cut short, a header length past the end, too short for the length
head -c 60 "$out/valid_float.st" > "$out/bad_truncated.st"
printf '\377\000\000\000\000\000\000\000{}' > "$out/bad_hlen.st"
printf '\002\000\000' > "$out/bad_short.st"
