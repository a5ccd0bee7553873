#!/bin/sh
# Runs the libFuzzer targets of a build made with -Dlibfuzzer=true, each for a fixed time over
# a copy of its seed corpus (the committed corpus is never written), and fails when any target
# crashes, leaks, trips a sanitizer, hangs past 10 s on one input or runs out of memory.
#
#   tests/fuzz/run-libfuzzer.sh BUILD_DIR SECONDS [TARGET...]
#
# TARGET is a name of tests/fuzz/corpus/ (npy, json, ...); without one, every target that has
# a corpus. Prints one line per target: runs executed, corpus size at the end (files), crash
# inputs. A crashing input is kept in BUILD_DIR/fuzz-artifacts/TARGET/; reproduce it with
# BUILD_DIR/tests/fuzz/fuzz_TARGET FILE, fix the parser, then add the file to the corpus.
set -u

if [ $# -lt 2 ]; then
  echo "usage: $0 BUILD_DIR SECONDS [TARGET...]" >&2
  exit 2
fi
build=$(cd "$1" && pwd) || exit 2
seconds=$2
shift 2
here=$(cd "$(dirname "$0")" && pwd)
if [ $# -eq 0 ]; then
  set --
  for d in "$here"/corpus/*/; do set -- "$@" "$(basename "$d")"; done
fi

# A sanitizer report must stop the run, or libFuzzer would count it as an ordinary input.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}"

work=$(mktemp -d "${TMPDIR:-/tmp}/fg-libfuzzer-XXXXXX") || exit 2
trap 'rm -rf "$work"' EXIT
trap 'exit 130' INT TERM
failed=0
for t in "$@"; do
  exe="$build/tests/fuzz/fuzz_$t"
  if [ ! -x "$exe" ] || [ ! -d "$here/corpus/$t" ]; then
    echo "fuzz_$t: FAIL: no $exe or no corpus/$t"
    failed=1
    continue
  fi
  dir="$work/$t"
  mkdir -p "$dir/corpus" "$dir/artifacts"
  find "$here/corpus/$t" -maxdepth 1 -type f -exec cp {} "$dir/corpus/" \;
  # Images may legitimately take about 2 GB: FG_IMAGE_MAX_PIXELS (64 Mpx) of float RGBA as
  # OpenImageIO reads it plus the RGB copy; a few hundred bytes of EXR header can ask for it.
  # The daemon bounds that by its decoder processes' RLIMIT_AS, so only more is a finding.
  rss=2048
  case $t in image | depth) rss=4096 ;; esac
  # TMPDIR: the files a target writes its inputs to (fuzz_file.h) stay in $work, even
  # after a crash
  (cd "$dir" && TMPDIR="$dir" "$exe" -max_total_time="$seconds" -timeout=10 -rss_limit_mb="$rss" \
    -print_final_stats=1 -artifact_prefix="$dir/artifacts/" corpus >log 2>&1)
  rc=$?
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$dir/log" | tail -n 1)
  files=$(find "$dir/corpus" -type f | wc -l)
  crashes=$(find "$dir/artifacts" -type f | wc -l)
  status=ok
  if [ "$rc" -ne 0 ] || [ "$crashes" -ne 0 ]; then
    status=FAIL
    failed=1
    mkdir -p "$build/fuzz-artifacts/$t"
    find "$dir/artifacts" -type f -exec cp {} "$build/fuzz-artifacts/$t/" \;
    echo "---- fuzz_$t (exit $rc), last lines of its log:"
    tail -n 40 "$dir/log"
  fi
  echo "fuzz_$t: $status: runs ${runs:-?}, corpus $files files, crashes $crashes (${seconds} s)"
done
exit "$failed"
