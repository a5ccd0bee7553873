#!/usr/bin/env bash
# The README's first command ends here: fieldgrip's whole loop on this machine, with no CLIP
# weights and no hardware, driven through the HTTP API exactly as a robot stack drives it.
#
#   1. builds (meson, in build/) unless that is done already;
#   2. renders two tabletop layouts with fieldgrip-scenegen (RGB-D views with per-patch
#      features; the objects stand elsewhere in the second) and starts fieldgrip-sim, which
#      plays the robot controller and the Robotiq gripper on 127.0.0.1:1502 in the physics
#      cell of the second layout (MuJoCo), and a camera on the robot's tool on 127.0.0.1:1503
#      whose intrinsics, distortion and mount fieldgripd is not told, with a calibration
#      board on the table;
#   3. starts fieldgripd with config/demo.conf and, printing every curl command it runs:
#      uploads the first layout's frames, trains, records two demos (how to pick up the box
#      and the ball); then from the bare cell: calibrates the camera (the robot takes 30
#      views of the board: intrinsics and mount), scans the table with it (30 viewpoints,
#      trained in the same job), asks "where is the mug?" (heatmap PLY and PNG), asks for a
#      grasp of the box by query, executes it in the physics cell and prints the gripper's
#      report and what physics says: the box lifted and by how much, or the miss; puts the
#      box back, and does the same for the ball, asked for by its task;
#   4. keeps the daemon and the simulator running for you to explore; Ctrl-C stops both.
#
# With [clip] in the configuration the questions are texts ("a mug") and the daemon computes
# the frames' CLIP features itself; without it they are the scan's class embeddings (the
# vectors its features were made of), which is what a feature extractor without a text
# encoder leaves you with.
#
# With --clear-table, step 3 ends differently: "pick up everything", as a robot stack drives
# it. A bin stands on the table beside the workspace; for each object, asked for by its
# question: a grasp, the pick, a place over the bin (physics drops what was lifted into it),
# a new scan of the changed cell (a new capture: what physics left, objects pushed or tilted
# included) and an update of the field from the current one (--update-steps, default 200),
# then the next question; two tries an object. It ends with the objects cleared, the grasps
# per object, the failures by kind and the time per object, and a line
# "clear_table: layout=N objects=4 cleared=K ..." for scripts.
#
# Options: --exit (stop both processes after the loop and exit 0 if it ran through: the
# tests run it so), --steps N (training steps per scan, default 300), --clear-table,
# --update-steps N, --layout N (the cell's scenegen seed, default 0; not 1, the demos'),
# --views N (the robot's viewpoints for the calibration and for each scan, 4 to 60, default 30),
# --config FILE (default config/demo.conf; the daemon's address is its [http] listen, the
# simulator's its [robot] host and port, its camera's [camera wrist] source's), --out DIR
# (default demo-out: scans, heatmaps, logs), --build DIR (take the programs from that meson
# build folder as they are, instead of building build/).
# Needs curl and jq. Exit status: 0 when the loop ran through, 1 on any failed step (the
# message says which; the daemon's log is in OUT/fieldgripd.log).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

steps=300
clear=0
update_steps=200
n_views=30
layout_seed=0
config=config/demo.conf
out=demo-out
build=
stay=1
while [ $# -gt 0 ]; do
  case "$1" in
    --exit) stay=0 ;;
    --steps) steps=${2:?--steps needs a number}; shift ;;
    --config) config=${2:?--config needs a file}; shift ;;
    --out) out=${2:?--out needs a folder}; shift ;;
    --build) build=${2:?--build needs a folder}; shift ;;
    --clear-table) clear=1 ;;
    --update-steps) update_steps=${2:?--update-steps needs a number}; shift ;;
    --layout) layout_seed=${2:?--layout needs a seed}; shift ;;
    --views) n_views=${2:?--views needs a number}; shift ;;
    -h|--help) awk 'NR > 1 && !/^#/ { exit } NR > 1 { sub(/^# ?/, ""); print }' "$0"; exit 0 ;;
    *) echo "demo: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
  shift
done

# the calibration takes 4 to 60 viewpoints (the scans up to 200): refused here, not after the
# trainings
if ! [[ "$n_views" =~ ^[0-9]+$ ]] || [ "$n_views" -lt 4 ] || [ "$n_views" -gt 60 ]; then
  echo "demo: --views wants a number from 4 to 60, got '$n_views'" >&2
  exit 2
fi

for tool in curl jq; do
  command -v "$tool" >/dev/null || { echo "demo: needs $tool (apt-get install $tool)" >&2; exit 1; }
done

bold=; dim=; reset=
if [ -t 1 ]; then bold=$'\e[1m'; dim=$'\e[2m'; reset=$'\e[0m'; fi

say() { printf '\n%s== %s%s\n' "$bold" "$*" "$reset"; }
die() { printf 'demo: %s\n' "$*" >&2; exit 1; }
# A check of the answers against the scans' ground truth. The scans' own class embeddings
# must pass it; CLIP's features of these plain renders are your weights' business, so with
# [clip] a miss is reported and the loop goes on.
miss() {
  if [ "$clip" -eq 1 ]; then printf 'demo: note: %s\n' "$*"; else die "$*"; fi
}

# ---------------------------------------------------------------- build

if [ -z "$build" ]; then
  build=build
  if [ ! -f build/build.ninja ]; then
    say "Configuring the build (meson setup build)"
    meson setup build >/dev/null
  fi
  say "Building (meson compile -C build)"
  meson compile -C build >/dev/null || die "the build failed: run 'meson compile -C build' to see why"
fi

daemon=$build/daemon/fieldgripd
scenegen=$build/tests/scenegen/fieldgrip-scenegen
sim=$build/sim/fieldgrip-sim
for prog in "$daemon" "$scenegen" "$sim"; do
  [ -x "$prog" ] || die "no $prog: build first (meson compile -C $build)"
done

# ---------------------------------------------------------------- the configuration

# The daemon's address and the simulator's port, read from the configuration file's
# [http] listen and [robot] port (the demo configuration: 127.0.0.1:7070 and 1502).
ini_get() { # FILE SECTION KEY
  awk -v sec="[$2]" -v key="$3" '
    /^[ \t]*\[/ { insec = ($0 ~ "^[ \t]*" "\\" sec) }
    insec && $0 ~ "^[ \t]*" key "[ \t]*=" { sub(/^[^=]*=[ \t]*/, ""); sub(/[ \t]*(;.*)?$/, ""); print; exit }
  ' "$1"
}
[ -f "$config" ] || die "no configuration file $config"
listen=$(ini_get "$config" http listen)
listen=${listen:-127.0.0.1:7070}
sim_port=$(ini_get "$config" robot port)
sim_host=$(ini_get "$config" robot host)
[ -n "$sim_port" ] && [ -n "$sim_host" ] || die "$config has no [robot] host and port for the simulator"
token=$(ini_get "$config" http token)
# the simulator's camera serves what [camera wrist] fetches
camera=$(ini_get "$config" "camera wrist" source)
camera=${camera#http://}
camera=${camera%%/*}
[ -n "$camera" ] || die "$config has no [camera wrist] source (http://HOST:PORT/rgb.png) for the simulator's camera"
api="http://$listen"

mkdir -p "$out"
out=$(cd "$out" && pwd)

# ---------------------------------------------------------------- processes

pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
}
trap cleanup EXIT
trap 'exit 130' INT TERM

port_busy() { (exec 3<>"/dev/tcp/$1/$2") 2>/dev/null; }

# ---------------------------------------------------------------- curl, shown

# Every request goes through api_curl, which prints the command (as you would type it) and
# leaves the body in $reply (or, with `-o FILE` as its third and fourth arguments, in FILE)
# and the status in $status.
auth=()
[ -z "$token" ] || auth=(-H "Authorization: Bearer $token")

quote() { # prints its arguments as a shell would need them typed
  local a out=
  for a in "$@"; do
    if [[ "$a" =~ ^[A-Za-z0-9_./:@=,+-]+$ ]]; then out+=" $a"; else out+=" '${a//\'/\'\\\'\'}'"; fi
  done
  printf '%s' "${out# }"
}

show=1
api_curl() { # METHOD PATH [curl arguments...]
  local method=$1 path=$2
  shift 2
  if [ "$show" -eq 1 ]; then
    local shown=(curl -s -X "$method" "$api$path" "$@")
    [ -z "$token" ] || shown=(curl -s -H "Authorization: Bearer \$TOKEN" -X "$method" "$api$path" "$@")
    printf '%s$ %s%s\n' "$dim" "$(quote "${shown[@]}")" "$reset"
  fi
  local tmp file=
  tmp=$(mktemp)
  if [ "${1:-}" = -o ]; then file=$2; shift 2; fi
  status=$(curl -s -o "$tmp" -w '%{http_code}' "${auth[@]}" -X "$method" "$api$path" "$@") || status=000
  if [ -n "$file" ] && [ "$status" = 200 ]; then
    mv "$tmp" "$file"
    reply=
  else
    reply=$(cat "$tmp")
    rm -f "$tmp"
  fi
}

api_json() { # METHOD PATH BODY [-o FILE]: a JSON request
  api_curl "$1" "$2" "${@:4}" -H 'Content-Type: application/json' -d "$3"
}

expect() { # STATUS...: the last request answered one of them, else stop with its error
  local s
  for s in "$@"; do [ "$status" = "$s" ] && return 0; done
  die "the daemon answered $status: $reply"
}

# ---------------------------------------------------------------- scans

say "Rendering two tabletop scans (fieldgrip-scenegen)"
# One feature space (--embedding-seed) for both, as frames of one feature extractor share it;
# the objects stand elsewhere in the second (seed 0, or --layout's: scan0, the cell's) than
# in the first (seed 1: scan1, the demos').
[[ "$layout_seed" =~ ^[0-9]+$ ]] && [ "$layout_seed" != 1 ] ||
  die "--layout wants a seed other than 1 (the demos' layout), got '$layout_seed'"
for layout in 1 0; do
  seed=$layout
  [ "$layout" = 1 ] || seed=$layout_seed
  args=(--out "$out/scan$layout" --seed "$seed" --embedding-seed 7 --views 30 --width 160
        --height 120 --dim 32 --patch 4 --holdout 0 --depth png)
  echo "${dim}\$ $(quote "$scenegen" "${args[@]}")${reset}"
  "$scenegen" "${args[@]}" >/dev/null
done

# the grasp of object NAME in scan LAYOUT, as its gt.json gives it
object_grasp() { jq -c --arg n "$2" '.objects[] | select(.name == $n) | .grasp' "$out/scan$1/gt.json"; }

# ---------------------------------------------------------------- simulator and daemon

say "Starting the robot and gripper simulator on $sim_host:$sim_port"
port_busy "$sim_host" "$sim_port" && die "$sim_host:$sim_port is taken: is a simulator or robot already there?"
# The physics cell of the second scan (MuJoCo): its table and objects, the gripper and what
# every command did to them, in $out/physics.jsonl
# and its camera on the tool: 640 x 480 with a little barrel distortion, 6 cm behind the TCP
# and turned 5 degrees, a ChArUco board on the table to the right of the objects, motions at
# ten times real time
sim_args=(--listen "$sim_host:$sim_port" --scene "$out/scan0/cell.xml" --report "$out/physics.jsonl"
          --camera-listen "$camera" --camera "604 602 323.5 236.5 640 480 -0.06 0.02 0.0004 -0.0003"
          --camera-mount "0.03 -0.02 -0.06 0.9990482 0.0436194 0 0"
          --board "7 5 0.03 0.022 DICT_5X5_100 0.15 -0.45 0 0" --camera-patch 16 --time-scale 0.1)
# clearing the table: the bin beside the workspace (y 0.46 to 0.80 inside), within the
# robot's reach and [robot] limits
bin_xy=(0.45 0.63)
[ "$clear" -eq 0 ] || sim_args+=(--bin "${bin_xy[0]},${bin_xy[1]}")
echo "${dim}\$ $(quote "$sim" "${sim_args[@]}") &${reset}   (the second scan's table and objects in physics)"
"$sim" "${sim_args[@]}" >"$out/sim.log" 2>&1 &
pids+=($!)

say "Starting fieldgripd on $api"
port_busy "${listen%:*}" "${listen##*:}" && die "$listen is taken: is fieldgripd already running? Stop it first."
echo "${dim}\$ $(quote "$daemon" --config "$config") &${reset}   (log: $out/fieldgripd.log)"
"$daemon" --config "$config" >"$out/fieldgripd.log" 2>&1 &
daemon_pid=$!
pids+=("$daemon_pid")
for _ in $(seq 600); do
  curl -sf "$api/v1/health" >/dev/null 2>&1 && break
  kill -0 "$daemon_pid" 2>/dev/null || die "fieldgripd exited: $(tail -n 5 "$out/fieldgripd.log")"
  sleep 0.1
done
api_curl GET /v1/health
expect 200
echo "$reply"

# CLIP configured? Then questions are texts and the daemon computes the features.
show=0
api_json POST /v1/embed/text '{"text": "a mug"}'
show=1
clip=0
[ "$status" = 200 ] && clip=1
if [ "$clip" -eq 1 ]; then
  echo "[clip] is configured: questions are texts, features are CLIP's"
else
  echo "no [clip] in $config: questions are the scan's class embeddings"
fi

# ---------------------------------------------------------------- scenes

workspace='{"min": [0.10, -0.45, 0.005], "max": [0.80, 0.45, 0.35]}'
upload_scan() { # SCENE LAYOUT
  local scene=$1 dir="$out/scan$2" n i meta f first=1
  say "Scene $scene: a fresh scene, then the scan's $(jq '.frames | length' "$dir/transforms.json") RGB-D frames"
  show=0
  api_curl DELETE "/v1/scenes/$scene"
  show=1
  api_json POST /v1/scenes "{\"name\": \"$scene\", \"workspace\": $workspace, \"voxel_size\": 0.01}"
  expect 201
  n=$(jq '.frames | length' "$dir/transforms.json")
  for ((i = 0; i < n; i++)); do
    meta=$(jq -c --argjson i "$i" '{transform_matrix: .frames[$i].transform_matrix,
             camera: {fl_x, fl_y, cx, cy, w, h}, depth_scale: .depth_unit_scale_factor}' \
             "$dir/transforms.json")
    f=$(jq -r --argjson i "$i" '.frames[$i] | [.file_path, .features_path, .depth_file_path] | @tsv' \
          "$dir/transforms.json")
    IFS=$'\t' read -r image features depth <<<"$f"
    local form=(-F "image=@$dir/$image" -F "depth=@$dir/$depth" -F "meta=$meta")
    [ "$clip" -eq 1 ] || form+=(-F "features=@$dir/$features")
    api_curl POST "/v1/scenes/$scene/frames" "${form[@]}"
    expect 201 200
    if [ "$first" -eq 1 ]; then
      echo "$reply"
      echo "(and so on for frames 1 to $((n - 1)), without printing them)"
      first=0
      show=0
    fi
  done
  show=1
}

follow() { # WHAT: the job of the last reply, its progress as Server-Sent Events, drawn as a bar
  local what=$1 job line state= step total phase shown= views
  views=$(jq -r '.viewpoints // 0' <<<"$reply")
  job=$(jq -r .job <<<"$reply")
  echo "$reply"
  echo "${dim}\$ $(quote curl -sN "$api/v1/jobs/$job/events")${reset}"
  local bar_format='  [%-40s] %5d/%d %-9s %s\n'
  [ -z "$bold" ] || bar_format='\r  [%-40s] %5d/%d %-9s %s  '
  while IFS= read -r line; do
    line=${line%$'\r'}
    [[ "$line" == data:* ]] || continue
    data=${line#data: }
    read -r state step total phase < <(jq -r '"\(.state) \(.step // 0) \(.steps) \(.phase // "-")"' <<<"$data")
    [ "$phase" != scanning ] || total=$views
    # a bar redrawn in place on a terminal, else a line per tenth of the steps and per phase
    local tenth=$((step * 10 / (total > 0 ? total : 1)))
    if [ -n "$bold" ] || [ "$phase $tenth" != "$shown" ]; then
      shown="$phase $tenth"
      printf "$bar_format" "$(printf '%*s' $((tenth * 4)) '' | tr ' ' '#')" "$step" "$total" \
        "$phase" "$(jq -r 'if .phase == "scanning" or .phase == "capturing" or .phase == "calibrating"
          then "\(.frames // 0) kept, \(.skipped // 0) out of reach  \(.elapsed_s // 0 | floor) s"
          else "loss \(.loss // "-" | tostring | .[0:6])  \(.elapsed_s // 0 | floor) s" end' <<<"$data")"
    fi
    case "$state" in done|failed|cancelled) break ;; esac
  done < <(curl -sN "${auth[@]}" "$api/v1/jobs/$job/events")
  [ -z "$bold" ] || echo
  [ "$state" = done ] || die "$what ended '$state': $(jq -r '.error // .' <<<"$data")"
}

train() { # SCENE
  local scene=$1
  say "Training $scene's feature field ($steps steps)"
  api_json POST "/v1/scenes/$scene/train" "{\"steps\": $steps, \"seed\": 0}"
  expect 202
  follow "the training of $scene"
  echo "$data" | jq -c '{state, step, psnr, samples_per_s, elapsed_s}'
}

upload_scan tabletop-demos 1
train tabletop-demos

# ---------------------------------------------------------------- demos

# A demo is the gripper's pose where it holds the object (here gt.json's grasp of it, as a
# person would show it by jogging the robot there), the scene it is in, and the width the
# gripper opens to before it closes: all of the 2F-85's 85 mm, since a briefly trained
# field's surfaces stand a little proud of the objects' and a tighter opening collides. The
# query points are the default: spread over what the fingers close on, between the pads
# (inside a box the features are the same everywhere, so its pose shows only in the points
# that reach its faces, 3 cm from the TCP).
demo() { # TASK OBJECT
  local body
  body=$(object_grasp 1 "$2" | jq -c --arg s tabletop-demos '{scene: $s,
           pose: {position: .position, quaternion: .quaternion}, width: 0.085}')
  api_json POST "/v1/tasks/$1/demos" "$body"
  expect 201 200
  jq -c '{demo: {id: .demo.id, scene: .demo.scene}, task: {name: .task.name, kind: .task.kind, n_demos: .task.n_demos}}' <<<"$reply"
}
tasks=(box ball)
[ "$clear" -eq 0 ] || tasks=(box ball mug bowl)
say "Recording demos on tabletop-demos: how to pick up a $(IFS=,; echo "${tasks[*]}" | sed 's/,/, a /g')"
for task in "${tasks[@]}"; do
  show=0; api_curl DELETE "/v1/tasks/$task"; show=1
done
for task in "${tasks[@]}"; do demo "$task" "$task"; done

# ---------------------------------------------------------------- the questions

# ---------------------------------------------------------------- the cell

# The camera on the robot's tool, from a bare cell: fieldgripd knows where the board lies on
# the table (roughly: its centre within a few centimetres) and where the camera sits on the
# tool as a ruler gives it, and finds its intrinsics, its distortion and its mount itself.
say "Calibrating the camera on the tool: the robot takes $n_views views of the board on the table"
api_json POST /v1/cameras/wrist/calibrate "{\"kind\": \"both\", \"drive\": {\"target\": [0.255, -0.45, 0], \"viewpoints\": $n_views,
  \"mount\": {\"position\": [0.03, -0.02, -0.06], \"quaternion\": [1, 0, 0, 0]}, \"settle_ms\": 100}}"
expect 202
follow "the calibration"
api_curl GET /v1/cameras/wrist
expect 200
jq -c '{intrinsics: .intrinsics | {fl_x, fl_y, cx, cy, k1, k2}, T_tcp_cam: .T_tcp_cam | {position, quaternion},
        calibration: .calibration | {intrinsics: .intrinsics.rms_px, mount: .mount | {rms_px, spread_mm, spread_deg}}}' <<<"$reply"

# The table scanned by the robot with the calibrated camera, and trained in the same job
say "Scanning the table: the robot moves the camera through $n_views viewpoints, then trains ($steps steps)"
show=0
api_curl DELETE /v1/scenes/tabletop
show=1
api_json POST /v1/scenes "{\"name\": \"tabletop\", \"workspace\": $workspace, \"voxel_size\": 0.01}"
expect 201
api_json POST /v1/scenes/tabletop/scan "{\"camera\": \"wrist\", \"viewpoints\": $n_views, \"radius_m\": 0.5,
  \"elevations_deg\": [40, 75], \"settle_ms\": 100, \"train\": {\"steps\": $steps, \"seed\": 0}}"
expect 202
follow "the scan of tabletop"
echo "$data" | jq -c '{state, frames, skipped, step, psnr, elapsed_s}'

# A question as JSON members: a text with CLIP, else the class's embedding (rounded to 4
# decimals to keep the commands short) with the other classes as negatives
question() { # CLASS
  if [ "$clip" -eq 1 ]; then
    printf '"text": "a %s"' "$1"
  else
    jq -r --arg c "$1" '"\"embedding\": \(.classes[] | select(.name == $c) | .embedding
        | map(. * 10000 | round / 10000) | tojson), \"negative_embeddings\": \([.classes[]
        | select(.name != $c) | .embedding | map(. * 10000 | round / 10000)] | tojson)"' \
      "$out/scan0/gt.json"
  fi
}

say "Where is the mug? (a heatmap over the workspace's voxels)"
mug=$(question mug)
api_json POST /v1/scenes/tabletop/heatmap "{$mug, \"format\": \"ply\", \"min_score\": 0.5}" \
  -o "$out/mug-heatmap.ply"
expect 200
echo "voxels scoring 0.5 or more, coloured by score (binary PLY): $out/mug-heatmap.ply"
api_json POST /v1/scenes/tabletop/heatmap "{$mug, \"max_points\": 1}"
expect 200
jq -c '{occupied, best}' <<<"$reply"
inside=$(jq -n --argjson p "$(jq -c .best.position <<<"$reply")" \
              --argjson b "$(jq -c '.objects[] | select(.name == "mug") | .aabb' "$out/scan0/gt.json")" \
         '[range(3) as $i | $p[$i] >= $b.min[$i] - 0.01 and $p[$i] <= $b.max[$i] + 0.01] | all')
[ "$inside" = true ] || miss "the best voxel is not on the mug (its box in gt.json: $(jq -c '.objects[] | select(.name == "mug") | .aabb' "$out/scan0/gt.json"))"
[ "$inside" = true ] && echo "the best voxel is on the mug (within its box in the scan's ground truth)"

# The same question in a view from above the table
cam='{"transform_matrix": [[1,0,0,0.45],[0,1,0,0],[0,0,1,0.9],[0,0,0,1]], "fl_x": 300, "fl_y": 300, "cx": 160, "cy": 120, "w": 320, "h": 240}'
api_json POST /v1/scenes/tabletop/render "{\"camera\": $cam, \"output\": \"heatmap\", $mug}" \
  -o "$out/mug-heatmap.png"
expect 200
echo "the view from above with the score's colours over it (PNG): $out/mug-heatmap.png"

# The end: where things are, and the daemon left running unless --exit.
finish() {
  say "Done: the loop ran through"
  echo "scans, heatmaps and logs: $out"
  # The same in the web viewer: the scan as points, the mug's heatmap, the box task's grasps
  if [ "$clip" -eq 1 ]; then
    link_query="text=a+mug"
  else
    link_query="embedding=$(jq -r '.classes[] | select(.name == "mug") | .embedding
        | map(. * 10000 | round / 10000 | tostring) | join(",")' "$out/scan0/gt.json")"
  fi
  echo "in a browser: $api/?scene=tabletop&$link_query&task=box${token:+   (it asks for the token)}"
  if [ "$stay" -eq 0 ]; then
    exit 0
  fi
  echo "fieldgripd keeps running on $api (see README.md, \"Trying the API\"); Ctrl-C stops it and the simulator."
  wait "$daemon_pid"
  exit 0
}

# ---------------------------------------------------------------- clearing the table

# The objects as the last physics report has them: "NAME IN_BIN" lines.
objects_now() { grep '"command"' "$out/physics.jsonl" | tail -n 1 | jq -r '.objects[] | "\(.name) \(.in_bin)"'; }

clear_table() {
  local queue=(box ball mug bowl) obj round=0 grasp lifted outcome t0 t1 secs left
  local -A tries=() failures=()
  local cleared_list=() grasps=0 total_s=0
  say "Clearing the table: every object into the bin at (${bin_xy[0]}, ${bin_xy[1]}), a new scan and an update of $update_steps steps after each pick"
  while [ ${#queue[@]} -gt 0 ]; do
    obj=${queue[0]}
    queue=("${queue[@]:1}")
    round=$((round + 1))
    tries[$obj]=$((${tries[$obj]:-0} + 1))
    t0=$(date +%s.%N)
    say "Round $round: pick up the $obj (try ${tries[$obj]})"
    api_json POST /v1/scenes/tabletop/grasps "{$(question "$obj"), \"top_k\": 1, \"seed\": 0}"
    expect 200
    jq -c '{task, grasp: .grasps[0] | {id, score, position: .pose.position}}' <<<"$reply"
    grasp=$(jq -r '.grasps[0].id // empty' <<<"$reply")
    outcome=
    if [ -z "$grasp" ]; then
      outcome=no_grasp
    else
      grasps=$((grasps + 1))
      api_curl POST "/v1/scenes/tabletop/grasps/$grasp/execute" -H 'Content-Type: application/json' \
        -H "Idempotency-Key: clear-$round-$grasp" -d '{"dry_run": false}'
      if [[ "$status" == 4* ]]; then # refused by the gate (limits, reach): say why, go on
        echo "the pick was refused: $(jq -c .error <<<"$reply")"
        outcome=refused
      elif [ "$status" != 200 ]; then # the robot faulted: an operator must make the cell safe
        die "the pick failed ($status): $(jq -c .error <<<"$reply")"
      elif [ "$(jq -r .state <<<"$reply")" != done ]; then
        outcome=robot_$(jq -r .state <<<"$reply")
      fi
      lifted=$(grep '"command"' "$out/physics.jsonl" | tail -n 1 | jq -r '.lifted // empty')
      echo "physics: $(grep '"command"' "$out/physics.jsonl" | tail -n 1 | jq -c '{command, lifted, lift_m, moved: [.moved[].name]}')"
      if [ -z "$outcome" ] && [ -z "$lifted" ]; then outcome=missed; fi
      if [ -n "$lifted" ]; then
        [ "$lifted" = "$obj" ] || outcome=wrong_object
        say "Into the bin: a place over it, through the same gate as every motion"
        api_json POST /v1/robot/commands "{\"command\": \"place\", \"pose\": {\"position\": [${bin_xy[0]}, ${bin_xy[1]}, 0.20],
          \"quaternion\": [0, 1, 0, 0]}, \"width\": 0.085}" -H "Idempotency-Key: clear-place-$round"
        expect 200
        [ "$(jq -r .state <<<"$reply")" = done ] || die "the place ended $(jq -r .state <<<"$reply"): $reply"
        [ "$(objects_now | awk -v o="$lifted" '$1 == o { print $2 }')" = true ] || outcome=${outcome:-dropped}
      fi
    fi
    cleared_list=($(objects_now | awk '$2 == "true" { print $1 }'))
    [ -n "$outcome" ] && failures[$outcome]=$((${failures[$outcome]:-0} + 1))
    # what is still to clear: the queue's objects not in the bin, and this one again after a
    # failed try (two tries an object)
    left=()
    for o in "${queue[@]}"; do [[ " ${cleared_list[*]} " == *" $o "* ]] || left+=("$o"); done
    if [[ " ${cleared_list[*]} " != *" $obj "* ]] && [ "${tries[$obj]}" -lt 2 ]; then left+=("$obj"); fi
    queue=("${left[@]}")
    echo "round $round: the $obj ${outcome:-cleared}; in the bin: ${cleared_list[*]:-nothing}"
    if [ ${#queue[@]} -gt 0 ]; then
      say "A new scan of the changed table, and an update of the field from the current one"
      api_json POST /v1/scenes/tabletop/scan "{\"camera\": \"wrist\", \"viewpoints\": $n_views, \"radius_m\": 0.5,
        \"elevations_deg\": [40, 75], \"settle_ms\": 100, \"train\": {\"steps\": $update_steps, \"seed\": 0, \"init\": \"current\"}}"
      expect 202
      follow "the scan and update of tabletop"
      echo "$data" | jq -c '{state, frames, step, psnr, elapsed_s}'
    fi
    t1=$(date +%s.%N)
    secs=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.1f", b - a }')
    total_s=$(awk -v a="$total_s" -v b="$secs" 'BEGIN { printf "%.1f", a + b }')
  done
  local n=4 k=${#cleared_list[@]} kinds=
  for o in "${!failures[@]}"; do kinds+="${kinds:+,}$o:${failures[$o]}"; done
  say "The table: $k of $n objects in the bin (${cleared_list[*]:-none}), $grasps grasps executed in $round rounds, $total_s s"
  echo "failures by kind: ${kinds:-none}"
  echo "clear_table: layout=$layout_seed objects=$n cleared=$k grasps=$grasps rounds=$round" \
    "failures=${kinds:-none} seconds=$total_s seconds_per_object=$(awk -v s="$total_s" -v n="$n" 'BEGIN { printf "%.1f", s / n }')" \
    "update_steps=$update_steps steps=$steps"
}

if [ "$clear" -eq 1 ]; then
  clear_table
  finish
fi

# ---------------------------------------------------------------- the grasp

say "Pick up the box: a grasp by query (the task whose demos look most like it)"
api_json POST /v1/scenes/tabletop/grasps "{$(question box), \"top_k\": 1, \"seed\": 0}"
expect 200
jq -c '{task, retrieval, grasp: .grasps[0] | {id, score, width, position: .pose.position, quaternion: .pose.quaternion}}' <<<"$reply"
grasp=$(jq -r '.grasps[0].id // empty' <<<"$reply")
if [ -z "$grasp" ] && [ "$clip" -eq 1 ]; then
  miss "no grasp by text: $(jq -r '.reason // .' <<<"$reply"); asking by the task's name instead"
  api_json POST /v1/scenes/tabletop/grasps '{"task": "box", "top_k": 1, "seed": 0}'
  expect 200
  jq -c '{task, grasp: .grasps[0] | {id, score, width, position: .pose.position, quaternion: .pose.quaternion}}' <<<"$reply"
  grasp=$(jq -r '.grasps[0].id // empty' <<<"$reply")
fi
[ -n "$grasp" ] || die "no grasp found: $(jq -r '.reason // .' <<<"$reply")"
[ "$(jq -r .task <<<"$reply")" = box ] || miss "the question retrieved task $(jq -r .task <<<"$reply"), not box"
off_mm=$(jq -n --argjson a "$(jq -c '.grasps[0].pose.position' <<<"$reply")" \
              --argjson b "$(object_grasp 0 box | jq -c .position)" \
         '[range(3) as $i | ($a[$i] - $b[$i]) | . * .] | add | sqrt * 1000 | . * 10 | round / 10')
echo "its TCP is $off_mm mm from the box's grasp in the scan's ground truth"

# What physics says of the simulator's last motion: the object OBJECT lifted, or the miss.
physics_says() { # OBJECT
  local last lifted
  last=$(grep '"command"' "$out/physics.jsonl" | tail -n 1)
  jq -c '{command, outcome, fingers, objects: [.objects[] | select(.touched or .moved or .lifted)
          | {name, held, lifted, dz_m, moved, knocked_over}]}' <<<"$last"
  lifted=$(jq -r '[.objects[] | select(.lifted) | .name] | join(",")' <<<"$last")
  if [ "$lifted" = "$1" ]; then
    echo "the $1 was lifted by $(jq -r --arg o "$1" '.objects[] | select(.name == $o) | .dz_m' <<<"$last") m, held between the fingers"
  elif [ -n "$lifted" ]; then
    miss "physics: the pick lifted the $lifted, not the $1"
  else
    miss "physics: the pick lifted nothing ($(jq -c '[.objects[] | select(.moved or .knocked_over) | .name]' <<<"$last") moved)"
  fi
}

execute() { # GRASP_ID OBJECT: the pick through fieldgripd, the gripper's report, physics's
  say "Executing it: a pick through the robot controller and the gripper (the simulator)"
  api_curl POST "/v1/scenes/tabletop/grasps/$1/execute" -H 'Content-Type: application/json' \
    -H "Idempotency-Key: demo-$1" -d '{"dry_run": false}'
  expect 200
  jq -c '{id, command, state, stage, seq, width, force}' <<<"$reply"
  [ "$(jq -r .state <<<"$reply")" = done ] || die "the pick ended $(jq -r .state <<<"$reply"): $reply"
  say "The gripper's report"
  api_curl GET /v1/gripper
  expect 200
  jq -c '{connected, activated, width, object_detected, fault}' <<<"$reply"
  [ "$(jq -r .object_detected <<<"$reply")" = true ] || miss "the gripper holds nothing: $reply"
  say "What physics says (the simulator's report of the last motion)"
  physics_says "$2"
}

box_pose=$(jq -c '.grasps[0].pose | {position, quaternion}' <<<"$reply")
execute "$grasp" box

say "Putting the box back: a place at the pose it was picked from"
api_json POST /v1/robot/commands "{\"command\": \"place\", \"pose\": $box_pose, \"width\": 0.085}" \
  -H "Idempotency-Key: demo-place-$grasp"
expect 200
jq -c '{id, command, state, stage, seq}' <<<"$reply"
[ "$(jq -r .state <<<"$reply")" = done ] || die "the place ended $(jq -r .state <<<"$reply"): $reply"

say "Pick up the ball: a grasp by the task's name"
api_json POST /v1/scenes/tabletop/grasps '{"task": "ball", "top_k": 1, "seed": 0}'
expect 200
jq -c '{task, grasp: .grasps[0] | {id, score, width, position: .pose.position, quaternion: .pose.quaternion}}' <<<"$reply"
grasp=$(jq -r '.grasps[0].id // empty' <<<"$reply")
[ -n "$grasp" ] || die "no grasp of the ball found: $(jq -r '.reason // .' <<<"$reply")"
execute "$grasp" ball

finish
