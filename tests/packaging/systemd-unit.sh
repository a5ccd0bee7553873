#!/usr/bin/env bash
# Checks systemd/fieldgripd.service:
#  1. `systemd-analyze verify` prints nothing, on a copy whose ExecStart names the freshly
#     built daemon (the installed path /usr/local/sbin/fieldgripd need not exist here);
#  2. `systemd-analyze security --offline=true` rates the sandbox at most MAX_EXPOSURE;
#  3. the unit hands over the token credential that config/fieldgripd.conf reads
#     (token_file = ${CREDENTIALS_DIRECTORY}/token);
#  4. the unit allows seccomp, so that fieldgrip-decode can add its own filter.
# Usage: systemd-unit.sh UNIT_FILE FIELDGRIPD_BINARY
# A missing systemd-analyze is a failure, not a skip: CI installs systemd.
set -euo pipefail

MAX_EXPOSURE=2.5

if [ $# -ne 2 ]; then
  echo "usage: $0 UNIT_FILE FIELDGRIPD_BINARY" >&2
  exit 2
fi
unit=$1
daemon=$2

if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "FAIL: systemd-analyze not found; install the 'systemd' package" >&2
  exit 1
fi
if [ ! -f "$unit" ]; then
  echo "FAIL: no unit file at $unit" >&2
  exit 1
fi
if [ ! -x "$daemon" ]; then
  echo "FAIL: $daemon is not an executable" >&2
  exit 1
fi
daemon=$(realpath "$daemon")

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The copy keeps the unit's name: verify derives the unit type and name from it.
copy=$tmp/fieldgripd.service
grep -q '^ExecStart=/usr/local/sbin/fieldgripd ' "$unit" || {
  echo "FAIL: $unit: ExecStart does not start /usr/local/sbin/fieldgripd" >&2
  exit 1
}
sed "s#^ExecStart=/usr/local/sbin/fieldgripd #ExecStart=$daemon #" "$unit" > "$copy"

# verify exits 0 on many problems (unknown keys, bad values are only logged), so any output
# at all counts as a failure.
echo "# systemd-analyze verify $copy"
set +e
out=$(systemd-analyze verify "$copy" 2>&1)
rc=$?
set -e
if [ $rc -ne 0 ] || [ -n "$out" ]; then
  printf '%s\n' "$out" >&2
  echo "FAIL: systemd-analyze verify exited $rc or printed warnings (above)" >&2
  exit 1
fi
echo "verify: clean"

if ! grep -qx 'LoadCredential=token:/etc/fieldgrip/token' "$unit"; then
  echo "FAIL: $unit lacks LoadCredential=token:/etc/fieldgrip/token, which the shipped" \
       "configuration's token_file = \${CREDENTIALS_DIRECTORY}/token needs" >&2
  exit 1
fi
echo "credential: token"

# No group of systemd's allows seccomp(2), so without it on an allow line fieldgrip-decode
# would run without its own, narrower filter under the unit (EPERM from seccomp).
if ! grep -E '^SystemCallFilter=[^~]' "$unit" | grep -qw seccomp; then
  echo "FAIL: $unit does not allow seccomp, which fieldgrip-decode needs for its own" \
       "system call filter" >&2
  exit 1
fi
echo "system calls: seccomp allowed"

echo "# systemd-analyze security --offline=true $unit"
set +e
sec=$(systemd-analyze security --offline=true --no-pager "$unit" 2>&1)
rc=$?
set -e
if [ $rc -ne 0 ]; then
  printf '%s\n' "$sec" >&2
  echo "FAIL: systemd-analyze security exited $rc" >&2
  exit 1
fi
# The last line reads "→ Overall exposure level for fieldgripd.service: 1.6 OK :-)".
exposure=$(printf '%s\n' "$sec" | sed -n 's/.*Overall exposure level for [^:]*: \([0-9][0-9]*\.[0-9]\).*/\1/p' | tail -n 1)
if [ -z "$exposure" ]; then
  printf '%s\n' "$sec" >&2
  echo "FAIL: no 'Overall exposure level' line in the output of systemd-analyze security" >&2
  exit 1
fi
# Show what is still exposed (lines marked ✗, or - in a non-UTF-8 locale) for whoever tightens it next.
printf '%s\n' "$sec" | grep -E '^(✗|- )' || true
echo "exposure=$exposure max=$MAX_EXPOSURE"
if awk -v e="$exposure" -v m="$MAX_EXPOSURE" 'BEGIN { exit !(e > m) }'; then
  echo "FAIL: exposure $exposure is above $MAX_EXPOSURE" >&2
  exit 1
fi
echo "ok"
