#!/usr/bin/env bash
# The README's first command, end to end: scripts/demo.sh --exit on a throwaway state folder
# and free loopback ports, with the programs of this build, in one of three parts (the first
# argument), each a test of its own so that they run side by side:
#   loop   the command as the README gives it. The script itself stops at the first step that
#          goes wrong (a non-2xx answer, a calibration refused, a scan that fails, a best
#          heatmap voxel off the mug, a query that retrieves another task than the box's, no
#          grasp, a pick that does not end done, a gripper that holds nothing, an object
#          physics did not lift); here we check that it ran through, that it printed every
#          step's curl command and the files it names, and that it left no process behind;
#   clip   with [clip] (a tiny random model in CLIP's layout): the questions are then texts
#          and the frames go up without features;
#   clear  with --clear-table: at least 3 of the 4 objects end in the bin, as the simulator's
#          report says, each place through the gate with its key and each rescan updating the
#          field.
# argv: the part, demo.sh, build folder, gen_clip, CLIP's BPE vocabulary.
set -euo pipefail

part=$1
demo=$2
build=$3
gen_clip=$4
vocab=$5
case $part in loop | clip | clear) ;; *) echo "unknown part '$part'" >&2; exit 2 ;; esac
tmp=$(mktemp -d)
out_log=$tmp/out.log
trap 'rm -rf "$tmp"' EXIT

fail() { echo "FAIL: $*" >&2; echo "--- demo output:" >&2; cat "$out_log" >&2; echo "--- daemon log (tail):" >&2; tail -n 40 "$tmp/out/fieldgripd.log" >&2 || true; exit 1; }

# Two ports below the kernel's ephemeral range (which the other tests' port-0 listeners and
# all outgoing connections draw from), nothing listening on either.
free_port() {
  local p
  while :; do
    p=$((20000 + RANDOM % 12000))
    (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null || { echo "$p"; return; }
  done
}
http_port=$(free_port)
modbus_port=$(free_port)
while [ "$modbus_port" = "$http_port" ]; do modbus_port=$(free_port); done
camera_port=$(free_port)
while [ "$camera_port" = "$http_port" ] || [ "$camera_port" = "$modbus_port" ]; do
  camera_port=$(free_port)
done

cat >"$tmp/demo.conf" <<CONF
[http]
listen = 127.0.0.1:$http_port
[state]
dir = $tmp/state
[train]
threads = 2
[gripper]
model = robotiq-2f85
[robot]
timeout_ms = 5000
transport = tcp
host = 127.0.0.1
port = $modbus_port
limit_min = -0.30 -1.00 -0.05
limit_max = 1.00 1.00 1.00
reach_m = 0.85
speed_mps = 0.25
[gripper.modbus]
timeout_ms = 5000
transport = tcp
host = 127.0.0.1
port = $modbus_port
[calibration]
squares_x = 7
squares_y = 5
square_m = 0.03
marker_m = 0.022
dictionary = DICT_5X5_100
[camera wrist]
source = http://127.0.0.1:$camera_port/rgb.png
depth_source = http://127.0.0.1:$camera_port/depth.png
features_source = http://127.0.0.1:$camera_port/features.npy
timeout_ms = 60000
CONF

run_demo() { # CONFIG [demo.sh options]: runs it into $tmp/out, output in $out_log
  local rc=0 conf=$1
  shift
  rm -rf "$tmp/out"
  bash "$demo" --exit --build "$build" --config "$conf" --out "$tmp/out" "$@" >"$out_log" 2>&1 || rc=$?
  [ "$rc" -eq 0 ] || fail "demo.sh exited $rc"
}
ports_closed() { # after a run: nothing listens on any of its ports any more
  local p
  for p in "$http_port" "$modbus_port" "$camera_port"; do
    if (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then fail "something still listens on $p"; fi
  done
}

if [ "$part" = loop ]; then
  # a bad --views is refused before anything runs
  rc=0
  bash "$demo" --exit --build "$build" --views 3 >"$out_log" 2>&1 || rc=$?
  [ "$rc" -eq 2 ] && grep -q -- '--views wants a number from 4 to 60' "$out_log" ||
    fail "--views 3 was not refused (exit $rc)"

  run_demo "$tmp/demo.conf"

  grep -q '^== Done: the loop ran through' "$out_log" || fail "no final line"
  grep -q '"object_detected":true' "$out_log" || fail "no gripper report with an object"
  grep -q '"task":"box"' "$out_log" || fail "the grasp's task is not printed"
  grep -q '^the box was lifted by 0\.[0-9]* m' "$out_log" || fail "physics did not lift the box"
  grep -q '^the ball was lifted by 0\.[0-9]* m' "$out_log" || fail "physics did not lift the ball"
  # every request it made is shown as a command to copy, with the daemon's address
  for path in /v1/health /v1/scenes /v1/scenes/tabletop-demos/frames /v1/scenes/tabletop-demos/train \
              /v1/cameras/wrist/calibrate /v1/cameras/wrist /v1/scenes/tabletop/scan \
              /v1/robot/commands \
              /v1/tasks/box/demos /v1/scenes/tabletop/heatmap /v1/scenes/tabletop/render \
              /v1/scenes/tabletop/grasps /v1/gripper; do
    grep -Eq "^\\\$ curl .*http://127.0.0.1:$http_port$path( |'|\$)" "$out_log" ||
      fail "no curl command for $path"
  done
  grep -q "^\$ curl -sN http://127.0.0.1:$http_port/v1/jobs/j[0-9a-f-]*/events" "$out_log" ||
    fail "no event stream command"
  grep -Eq '^  \[#{40}\] +300/300 ' "$out_log" || fail "no full progress bar"
  grep -Eq '^  \[#{40}\] +30/30 calibrating' "$out_log" || fail "no calibration that took its 30 views"
  grep -q '"T_tcp_cam":{"position"' "$out_log" || fail "the calibrated mount is not shown"

  ply=$tmp/out/mug-heatmap.ply
  png=$tmp/out/mug-heatmap.png
  grep -qF "$ply" "$out_log" && grep -qF "$png" "$out_log" || fail "the heatmap files' paths are not printed"
  [ "$(head -c 3 "$ply")" = ply ] || fail "$ply is not a PLY file"
  grep -aq '^element vertex [1-9]' "$ply" || fail "$ply has no vertices"
  [ "$(head -c 8 "$png" | od -An -tx1 | tr -d ' \n')" = 89504e470d0a1a0a ] || fail "$png is not a PNG"

  # the viewer's deep link to the same scene, question and task
  link=$(sed -n 's/^in a browser: \([^ ]*\).*/\1/p' "$out_log")
  [[ $link == "http://127.0.0.1:$http_port/?scene=tabletop&embedding="*"&task=box" ]] ||
    fail "no viewer link to the mug's embedding: '$link'"
  emb=${link#*embedding=}
  emb=${emb%%&*}
  [ "$(tr ',' '\n' <<<"$emb" | grep -Ec '^-?[0-9.e-]+$')" = \
    "$(jq '.classes[] | select(.name == "mug") | .embedding | length' "$tmp/out/scan0/gt.json")" ] ||
    fail "the viewer link's embedding is not the mug's: $emb"

  ports_closed
  echo "ok: the demo ran through in $SECONDS s"
fi

if [ "$part" = clip ]; then
  # With [clip]: texts, and CLIP computes the frames' features in the trainings
  "$gen_clip" "$tmp/clip.safetensors" --preset tiny >/dev/null
  # (the camera then sends its images only: the daemon computes the scan's features with CLIP)
  { grep -v '^features_source' "$tmp/demo.conf"
    printf '[clip]\nweights = %s\nvocab = %s\n' "$tmp/clip.safetensors" "$vocab"; } \
    >"$tmp/clip.conf"
  start=$SECONDS
  # A random tiny model's features find nothing in particular, so the trainings need not be
  # long, nor the calibration and the scan as thorough: the run checks the path through CLIP, not
  # the answers (the loop part does).
  run_demo "$tmp/clip.conf" --steps 100 --views 16
  grep -q '^== Done: the loop ran through' "$out_log" || fail "[clip]: no final line"
  grep -q '^\[clip\] is configured' "$out_log" || fail "[clip] was not noticed"
  grep -q "/v1/scenes/tabletop/heatmap .*-d '{\"text\": \"a mug\"" "$out_log" || fail "[clip]: no text heatmap query"
  grep -q '"features":null' "$out_log" || fail "[clip]: frames were uploaded with features"
  if grep -q 'features=@' "$out_log"; then fail "[clip]: frames were uploaded with features"; fi
  grep -q '"state":"done","stage":"finished"' "$out_log" || fail "[clip]: the pick did not finish"
  grep -q "^in a browser: http://127.0.0.1:$http_port/?scene=tabletop&text=a+mug&task=box" "$out_log" ||
    fail "[clip]: no viewer link with the text"

  echo "ok: with [clip] in $((SECONDS - start)) s"
  ports_closed
fi

if [ "$part" = clear ]; then
  # --clear-table: every object into the bin, a rescan and an update of the field from the
  # current one after each pick. Short trainings and 16 viewpoints a scan (of which about 11 are
  # within reach): the loop and physics are under test here (tests/bench/run.sh clear_table
  # measures the share on ten layouts at full length).
  start=$SECONDS
  run_demo "$tmp/demo.conf" --clear-table --steps 150 --update-steps 60 --views 16
  line=$(grep '^clear_table: ' "$out_log") || fail "--clear-table: no summary line"
  echo "$line"
  cleared=$(sed -n 's/.* cleared=\([0-9]*\) .*/\1/p' <<<"$line")
  [ "${cleared:-0}" -ge 3 ] || fail "--clear-table: $cleared of 4 objects in the bin"
  # what physics says, not the script: the last report has them in the bin
  [ "$(grep '"command"' "$tmp/out/physics.jsonl" | tail -n 1 | jq '[.objects[] | select(.in_bin)] | length')" = "$cleared" ] ||
    fail "--clear-table: the simulator's last report does not have $cleared objects in the bin"
  # each place into the bin went through the gate with a key, and each rescan updated the field
  [ "$(grep -c "^\$ curl .*/v1/robot/commands .*Idempotency-Key: clear-place-" "$out_log")" -ge "$cleared" ] ||
    fail "--clear-table: places without the gate's key"
  grep -q '"init": "current"' "$out_log" || fail "--clear-table: no update from the current field"
  [ "$(jq -s '[.[] | select(.command == "place" and .outcome == "done")] | length' "$tmp/out/physics.jsonl")" -ge "$cleared" ] ||
    fail "--clear-table: fewer places done than objects cleared"
  echo "ok: --clear-table, $cleared of 4 objects in the bin in $((SECONDS - start)) s"
  ports_closed
fi
