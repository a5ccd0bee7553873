#!/usr/bin/env bash
# fieldgrip benchmarks. Not part of `meson test`; run them by hand or with `ninja -C BUILD bench`.
#
# Usage: tests/bench/run.sh BUILD_DIR [import] [health] [memory] [train] [throughput]
#                           [busy] [clip] [heatmap] [robot] [grasp] [grasp_physics]
#                           [geometry] [depth_throughput] [fox] [http_idle] [load] [soak]
#                           [viewer] [calibration] [scan] [update] [first_grasp]
#                           [clear_table]
#   (no names: all of them but fox, grasp_physics, update and clear_table; train takes about 6 minutes,
#   throughput about 3; grasp several, most of them in the PyTorch peer; grasp_physics about
#   30)
#   import  wall-clock time of POST /v1/scenes/{s}/import of the 100 lego frames (800x800
#           RGBA PNG, downscaled to 400 px) through HTTP, fresh daemon and state dir
#           (target <= 3 s)
#   health  GET /v1/health under wrk -t2 -c32 -d10s on loopback: requests/s and p99 latency
#           (targets >= 20000 req/s, p99 <= 5 ms). Needs wrk: apt-get install wrk
#   memory  VmRSS / VmHWM of an idle daemon after start and a few requests (target <= 30 MB)
#   train   lego at 400 px, white background, every 10th frame held out, trained in-process
#           (bench_train) for 5 minutes of wall time on 2 threads: held-out PSNR at 1, 2 and
#           5 minutes (target >= 30 dB at 5), a timed 400x400 render (target <= 1 s) and
#           peak resident memory (target <= 1.5 GB)
#   throughput  training samples/s on a generated tabletop with 512-d features, with and
#           without the feature branch, next to a plain PyTorch CPU implementation of the
#           same model (tests/bench/peer_field.py, Debian's python3-torch) on the same
#           threads in the same run (targets: >= 10x PyTorch, >= 1 M RGB samples/s), and the
#           peak memory with 512-d features (target <= 3 GB)
#   busy    GET /v1/health and GET /v1/scenes under wrk -t2 -c32 while the daemon trains
#           lego on every core: p99 latency (target <= 50 ms). Needs wrk
#   clip    CLIP with random weights of ViT-B/16 size (written by gen_clip, about 600 MB in
#           the temp dir): dense MaskCLIP images/s at 224x224 and at a 640x360 frame (224x398),
#           text embeddings/s, against OpenBLAS SGEMM 2048^3 and a PyTorch CPU run of the
#           same model and weights (tests/bench/peer_clip.py) on the same threads in the same
#           run (targets: dense >= 1.2x PyTorch, >= 50% of SGEMM), and peak memory over the
#           weights with F32 and with F16 weights (target <= 300 MB). BENCH_CLIP_SECONDS
#           (default 10) sets each figure's measuring time
#   heatmap  the SPEC.md tabletop workspace (0.70 x 0.90 x 0.35 m at 1 cm: 220,500 voxels)
#           with 512-d features: a generated tabletop (fieldgrip-scenegen --dim 512) trained
#           through the daemon for BENCH_HEATMAP_STEPS steps (default 200), then the first
#           heatmap's seconds through HTTP (it builds the voxel feature cache; target <= 3 s),
#           BENCH_HEATMAP_N (default 60) more json heatmaps of the mug's class embedding
#           timed with curl: p50 and p90 ms (target p50 <= 50 ms), the reply's points, the
#           same at alpha_threshold 0.01 (more points), and the cache's bytes from the
#           scene's "voxel_cache"
#   robot   POST /v1/robot/commands round trips to fieldgrip-sim on loopback with zero ack
#           delay (bench_robot): BENCH_ROBOT_N (default 1000) move commands with
#           "wait": true in a row over one kept-alive connection, client-side p50 / p90 /
#           p99 / max ms and the daemon's ack_ms (target p99 <= 5 ms), then 200 with
#           "wait": false (answered at the acknowledgement) and, for comparison, GET
#           /v1/robot and dry-run moves (HTTP without Modbus); every command's seq checked
#           against the simulator's request log: each one once and consecutive, none lost
#           or duplicated, the logged words equal to the reply's registers.robot.words
#   grasp   a grasp request (issue 12) on the SPEC.md tabletop workspace (220,500 voxels) with
#           512-d features: a generated tabletop (fieldgrip-scenegen --dim 512 --views 40)
#           trained in-process on 2 threads for BENCH_GRASP_STEPS steps (default 300), its
#           voxel cache built (seconds and bytes reported apart: not part of a request), one
#           demo each of the mug's and the box's gt.json grasp, then BENCH_GRASP_RUNS (default
#           5) rounds of both tasks' requests as the daemon does them (grasp field + search,
#           default options, Robotiq 2F-140 at 0.11 m): p50/min/max seconds, candidates,
#           rotations, poses scored and optimised, iterations, evaluations, lookups and the
#           extra peak memory (targets p50 <= 1 s, <= 300 MB); then the same optimisation in
#           PyTorch (tests/bench/peer_grasp.py, F3RM's way: full 512-d features, autograd,
#           Adam; no collision check) on the same threads from bench_grasp --dump, and the
#           ratio of the peer's seconds to ours (reported, no target). Quick checks at tiny
#           sizes: BENCH_GRASP_DIM, BENCH_GRASP_VIEWS (default 40), BENCH_GRASP_ROTATIONS
#           (default 24), BENCH_GRASP_SAMPLES (samples per training step, default the
#           trainer's 2^17) and BENCH_GRASP_VOXEL_SIZE (default 0.01; a coarser grid finds
#           candidates after fewer steps) change the run; pass is only meaningful at the
#           defaults. ratio_per_evaluation compares the seconds per cost evaluation, since
#           the peer, without collision checks, may optimise more poses than ours
#   grasp_physics  inferred grasps executed in the MuJoCo cell of sim/cell.h
#           (bench_grasp_physics; about 30 minutes on 2 cores): BENCH_GRASP_PHYSICS_LAYOUTS
#           (default 10) question layouts, scenegen seeds 101 up, demos on seeds 1 and 3, each
#           trained in-process as tests/quality's layouts for BENCH_GRASP_PHYSICS_STEPS steps
#           (default 1200), with and without depth maps (BENCH_GRASP_PHYSICS_DEPTH both, with
#           or without). Per object of each layout the top grasp by task and by language query,
#           each picked by the Robotiq 2F-85 in a fresh cell; success = the object held 5 cm
#           up and nothing knocked over. The success rate overall, per object, per kind and
#           with and without depth, the control (every ground-truth grasp, must be near
#           100 %), failures by cause, p50 and mean seconds per grasp request; one
#           grasp_physics_grasp line per pick for studying failures. Targets: rate with depth
#           >= 0.90, control >= 0.95. A smoke run: BENCH_GRASP_PHYSICS_LAYOUTS=1
#           BENCH_GRASP_PHYSICS_STEPS=100
#   geometry  issue 13: a scenegen tabletop with 16-bit PNG depth maps (36 views at 240x180,
#           every 10th held out), trained in-process (bench_geometry, BENCH_GEOMETRY_STEPS
#           steps, default 2000, the trainer's 2^17 samples per step, 2 threads) four ways
#           side by side: no geometry loss, distortion loss only, depth loss only, both.
#           Each: held-out PSNR, median and p90 depth error on held-out object pixels (mm),
#           the share of points 6 mm inside the mug's and the bowl's cavity that are free
#           (alpha < 0.1 at 1 cm), the containers' heatmap IoU with the cavity counted,
#           samples/s. Targets (the depth variant): PSNR >= 30 dB, depth median <= 2 mm,
#           cavities >= 95 % free, IoU >= 0.6
#   depth_throughput  training samples/s on a depth tabletop with the depth loss on and off,
#           60 s each (target: on >= 90 % of off)
#   http_idle  GET /v1/health on new connections while BENCH_IDLE_N (default 10000) idle
#           connections are open (bench_http_idle): BENCH_IDLE_REQUESTS (default 200)
#           requests, p50 / p99 / max ms, twice: with [http] max_connections above N (every
#           idle connection held) and at the default 1024 (the oldest shed as new ones come).
#           Target p99 <= 50 ms
#   load    GET /v1/health (4 clients), POST /v1/scenes/{s}/heatmap (2) and POST
#           /v1/scenes/{s}/grasps (1), each client a closed loop over one kept-alive
#           connection (bench_load), for BENCH_LOAD_SECONDS (default 30) while another scene
#           trains on [train] threads 2; the scene is a scenegen tabletop (30 views, 32-d
#           features, 2 cm voxels) trained 60 steps with one demo. Per endpoint: requests,
#           req/s, p50 / p99 / max ms, errors (non-2xx or transport); the training job's
#           steps/s with and without the load. Targets: zero errors, health p99 <= 50 ms,
#           the training still running at the end. About a minute
#   soak    BENCH_SOAK_FRAMES (default 10000) uploads of a 64x48 PNG with a 6x8x16 features
#           .npy over one kept-alive connection, the scene deleted and created again every
#           100 (no endpoint deletes one frame), the daemon's VmRSS every 500 uploads
#           (bench_soak): the series, and the growth from 1000 uploads to the end (target
#           <= 4096 kB). About a minute and a half
#   viewer  the web viewer in Debian's headless Chromium with software WebGL (bench_viewer; about
#           two minutes): from navigation to the first frame with the point cloud and with a
#           deep link's heatmap on a scenegen tabletop at 1 cm, the first load after training
#           (the daemon builds its caches), BENCH_VIEWER_LOADS (default 5) with the browser's
#           cache disabled and as many with it on (median, max); then the frame rate while
#           the view turns with 200,000 points of a 5 mm scene. Targets: cold heatmap
#           median <= 2000 ms, >= 30 fps (headless Chromium paces frames at 60 Hz)
#   calibration  camera and hand-eye calibration on synthetic views (bench_calibration):
#           errors of the intrinsics and the mount against the truth for 8, 12 and 20 views
#           and for robot pose noise of 0.5 mm / 0.05 deg to 2 mm / 0.2 deg at 20 views,
#           median and worst of BENCH_CALIBRATION_TRIALS (default 10) draws, and the time of a
#           calibration (targets at 20 views: focal <= 0.5 %, principal point <= 1 px, mount
#           <= 1 mm and 0.2 deg)
#   scan    a scan the robot drives in the simulator (bench_scan): 30 viewpoints on a cap
#           0.45 m from the workspace's centre with the default settle_ms (300), from the
#           request to the job's end:
#           seconds, per viewpoint, frames stored and skipped, and the worst frame pose error
#           against the simulator's truth (targets: per view <= 1 s, <= 2 mm, <= 0.3 deg)
#   update  a changed scene (bench_update): the same scenegen layout with the mug taken away
#           and the box moved 10 cm, its field updated from the old one (without and with
#           BENCH_UPDATE_FOCUS percent of its rays where the views changed, default 50) against
#           trained from scratch, looked at every 50 steps, with and without depth: steps and
#           seconds to the update test's quality (the mug's voxels >= 95 % free, the box's
#           heatmap IoU within 0.05 of the scratch field's at 1500 steps) and their ratios
#           (target: the update meets it in fewer steps). About 10 minutes alone (626 s
#           on 2026-12-06)
#   first_grasp  time to first grasp after a 30-view RGB-D scan in the simulator
#           (bench_first_grasp, BENCH_FIRST_GRASP_STEPS steps, default 500): scan, load,
#           training, save, the first grasp (voxel cache, grasp field, search) and a second
#           search, seconds each; then the first grasp executed in the physics cell: its
#           distance from the box's true grasp and what it lifted (target: from the last
#           frame to the first grasp <= 60 s, and the box lifted)
#   fox     instant-ngp's fox (50 phone photos, OPENCV lens), read from $FG_FOX_DIR (the
#           repository's data/nerf/fox; not shipped here), through the daemon's API as a
#           user would: a scene of +-1.5 m with its field settings on auto, the import,
#           trainings of 3000 steps (BENCH_FOX_STEPS) at [train] max_image_side 400 with
#           every 10th photo held out, without and with the distortion loss
#           (BENCH_FOX_DISTORTION, default 0.002): held-out PSNR (target >= 23 dB) and the
#           field the settings chose
#   clear_table  scripts/demo.sh --clear-table on scenegen layouts the tests never use
#           (BENCH_CLEAR_SEEDS, default 200 to 209; BENCH_CLEAR_STEPS 300 per scan,
#           BENCH_CLEAR_UPDATE_STEPS 200 per update): a line per layout, then the share of
#           objects in the bin (target >= 0.9), grasps per object, the failures by kind and
#           the seconds per object (a rescan and an update each). Several minutes a layout
#
# Output: one line per benchmark of space-separated key=value pairs, e.g.
#   bench=import frames=100 skipped=0 seconds=1.234 target_max_seconds=3 pass=yes
# The exit status is 1 if a benchmark missed its target or could not run, 0 otherwise.
# The data set is read from $FG_SHARED_DATA/lego (default: ../shared/data beside the
# repository). Set BENCH_WRK_DURATION (default 10s) to shorten the wrk run.
set -euo pipefail

if [ $# -lt 1 ]; then
  sed -n '2,127p' "$0" >&2
  exit 2
fi
build=$(realpath "$1")
shift
benches=("$@")
[ ${#benches[@]} -gt 0 ] || benches=(import health memory train throughput busy clip heatmap robot grasp geometry depth_throughput http_idle load soak viewer calibration scan first_grasp)

src=$(cd "$(dirname "$0")/../.." && pwd)
daemon=$build/daemon/fieldgripd
data=${FG_SHARED_DATA:-$src/../shared/data}
wrk_duration=${BENCH_WRK_DURATION:-10s}

if [ ! -x "$daemon" ]; then
  echo "error: no daemon at $daemon; build first (meson compile -C $1)" >&2
  exit 2
fi
command -v curl >/dev/null || { echo "error: curl is needed (apt-get install curl)" >&2; exit 2; }

tmp=$(mktemp -d)
pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do
    kill "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  done
  rm -rf "$tmp"
}
trap cleanup EXIT

# start_daemon NAME [CONF_LINES]: starts fieldgripd with a fresh state dir under $tmp/NAME
# (CONF_LINES, if given, appended to its configuration file) and sets $pid and $base
# (http://127.0.0.1:PORT) once it logs its listening line.
start_daemon() {
  local dir=$tmp/$1 port= i
  mkdir -p "$dir/state"
  {
    echo "[state]"
    # The shared data sets, and data sets generated into the temp dir.
    if [ -d "$data" ]; then echo "import_dirs = $(realpath "$data"):$tmp"; else echo "import_dirs = $tmp"; fi
    [ $# -lt 2 ] || printf '%s\n' "$2"
  } > "$dir/bench.conf"
  # The listening line is logged at level info, the default. The log file exists before the
  # daemon starts: the background job opens it only once it runs, after the loop below began.
  : > "$dir/stderr"
  "$daemon" --config "$dir/bench.conf" --listen 127.0.0.1:0 --state-dir "$dir/state" \
    2> "$dir/stderr" &
  pid=$!
  pids+=("$pid")
  for i in $(seq 1 200); do
    port=$(sed -n 's|.*listening on http://127\.0\.0\.1:\([0-9][0-9]*\).*|\1|p' "$dir/stderr" | head -n 1)
    [ -z "$port" ] || break
    if ! kill -0 "$pid" 2>/dev/null; then
      cat "$dir/stderr" >&2
      echo "error: fieldgripd exited at start-up" >&2
      return 1
    fi
    sleep 0.05
  done
  if [ -z "$port" ]; then
    cat "$dir/stderr" >&2
    echo "error: fieldgripd did not log its listening line within 10 s" >&2
    return 1
  fi
  base=http://127.0.0.1:$port
}

stop_daemon() {
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
}

now() { date +%s.%N; }

# json_int KEY < JSON: the first integer value of "KEY" (enough for the flat answers used here).
json_int() { sed -n "s/.*\"$1\"[[:space:]]*:[[:space:]]*\([0-9][0-9]*\).*/\1/p" | head -n 1; }

failed=0

bench_import() {
  local lego=$data/lego out t0 t1 seconds imported skipped pass code
  if [ ! -f "$lego/transforms_train.json" ]; then
    echo "bench=import error=no_data_set path=$lego pass=no"
    failed=1; return
  fi
  start_daemon import
  curl -sf -X POST "$base/v1/scenes" -H 'Content-Type: application/json' \
    -d '{"name":"lego","workspace":{"min":[-1.5,-1.5,-1.5],"max":[1.5,1.5,1.5]}}' >/dev/null
  out=$tmp/import.json
  t0=$(now)
  code=$(curl -s -o "$out" -w '%{http_code}' -X POST "$base/v1/scenes/lego/import" \
    -H 'Content-Type: application/json' \
    -d "{\"path\":\"$(realpath "$lego")\",\"transforms\":\"transforms_train.json\"}")
  t1=$(now)
  stop_daemon
  if [ "$code" != 200 ]; then
    echo "bench=import error=http_$code pass=no"
    cat "$out" >&2; echo >&2
    failed=1; return
  fi
  imported=$(json_int imported < "$out")
  skipped=$(json_int skipped < "$out")
  seconds=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.3f", b - a }')
  pass=$(awk -v s="$seconds" -v n="$imported" 'BEGIN { print (s <= 3 && n == 100) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=import frames=$imported skipped=$skipped seconds=$seconds target_max_seconds=3 pass=$pass"
}

# to_ms VALUE: wrk's latency ("812.00us", "1.23ms", "1.01s") in milliseconds.
to_ms() {
  awk -v v="$1" 'BEGIN {
    n = v + 0
    if (v ~ /us$/) n /= 1000; else if (v ~ /ms$/) n = n; else if (v ~ /m$/) n *= 60000; else if (v ~ /s$/) n *= 1000
    printf "%.3f", n }'
}

bench_health() {
  local out rps p99 p50 p99_ms p50_ms errors pass
  if ! command -v wrk >/dev/null 2>&1; then
    echo "bench=health error=wrk_not_installed hint=apt-get_install_wrk pass=no"
    failed=1; return
  fi
  start_daemon health
  out=$(wrk -t2 -c32 -d"$wrk_duration" --latency "$base/v1/health")
  stop_daemon
  rps=$(printf '%s\n' "$out" | awk '/^Requests\/sec:/ { printf "%.0f", $2 }')
  p50=$(printf '%s\n' "$out" | awk '$1 == "50%" { print $2 }')
  p99=$(printf '%s\n' "$out" | awk '$1 == "99%" { print $2 }')
  # wrk prints "Non-2xx or 3xx responses" and "Socket errors" only when there are some.
  errors=$(printf '%s\n' "$out" | awk '/Non-2xx/ { n += $NF } /Socket errors/ { gsub(",", ""); n += $4 + $6 + $8 + $10 } END { print n + 0 }')
  if [ -z "$rps" ] || [ -z "$p99" ]; then
    printf '%s\n' "$out" >&2
    echo "bench=health error=unparsed_wrk_output pass=no"
    failed=1; return
  fi
  p50_ms=$(to_ms "$p50"); p99_ms=$(to_ms "$p99")
  pass=$(awk -v r="$rps" -v p="$p99_ms" -v e="$errors" 'BEGIN { print (r >= 20000 && p <= 5 && e == 0) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=health threads=2 connections=32 duration=$wrk_duration requests_per_s=$rps p50_ms=$p50_ms p99_ms=$p99_ms errors=$errors target_min_requests_per_s=20000 target_max_p99_ms=5 pass=$pass"
}

bench_memory() {
  local i rss hwm pass
  start_daemon memory
  for i in 1 2 3 4 5; do
    curl -sf "$base/v1/health" >/dev/null
    curl -sf "$base/v1/scenes" >/dev/null
    curl -sf "$base/metrics" >/dev/null
  done
  sleep 0.2
  rss=$(awk '/^VmRSS:/ { print $2 }' "/proc/$pid/status")
  hwm=$(awk '/^VmHWM:/ { print $2 }' "/proc/$pid/status")
  stop_daemon
  pass=$(awk -v h="$hwm" 'BEGIN { print (h <= 30 * 1024) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=memory vmrss_kb=$rss vmhwm_kb=$hwm target_max_kb=$((30 * 1024)) pass=$pass"
}

# field KEY LINE: the value of KEY=... in a key=value line.
field() { printf '%s\n' "$2" | tr ' ' '\n' | sed -n "s/^$1=//p" | head -n 1; }

bench_train() {
  local lego=$data/lego out line psnr rss render pass
  if [ ! -f "$lego/transforms_train.json" ]; then
    echo "bench=train error=no_data_set path=$lego pass=no"
    failed=1; return
  fi
  out=$("$build/tests/bench/bench_train" --data "$lego/transforms_train.json" --threads 2 \
    --max-side 400 --holdout 10 --seconds 300 --eval-at 60,120,300 --background 1 1 1)
  printf '%s\n' "$out" | grep -E '^bench=train_(eval|load)'
  line=$(printf '%s\n' "$out" | grep '^bench=train ')
  psnr=$(field psnr "$line"); rss=$(field peak_rss_mb "$line")
  render=$(field seconds "$(printf '%s\n' "$out" | grep '^bench=train_render')")
  pass=$(awk -v p="$psnr" -v r="$rss" -v t="$render" \
    'BEGIN { print (p >= 30 && r <= 1536 && t <= 1) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "$line render_400_s=$render target_min_psnr=30 target_max_rss_mb=1536 target_max_render_s=1 pass=$pass"
}

bench_throughput() {
  local set=$tmp/tabletop512 c0 c512 p0 p512 ratio0 ratio512 rss pass
  "$build/tests/scenegen/fieldgrip-scenegen" --out "$set" --dim 512 --holdout 0 >/dev/null
  c0=$("$build/tests/bench/bench_train" --data "$set/transforms.json" --threads 2 --holdout 0 \
    --workspace 0.10 -0.45 0.005 0.80 0.45 0.35 --field-scale 2 --seconds 30 --no-features |
    grep '^bench=train ')
  c512=$("$build/tests/bench/bench_train" --data "$set/transforms.json" --threads 2 --holdout 0 \
    --workspace 0.10 -0.45 0.005 0.80 0.45 0.35 --field-scale 2 --seconds 30 |
    grep '^bench=train ')
  if ! /usr/bin/python3 -c 'import torch' 2>/dev/null; then
    echo "bench=throughput error=no_pytorch hint=apt-get_install_python3-torch pass=no"
    failed=1; return
  fi
  p0=$(/usr/bin/python3 "$src/tests/bench/peer_field.py" --threads 2 --seconds 20 --json |
    sed -n 's/.*"samples_per_s": *\([0-9.]*\).*/\1/p')
  p512=$(/usr/bin/python3 "$src/tests/bench/peer_field.py" --threads 2 --seconds 20 \
    --feature-dim 512 --json | sed -n 's/.*"samples_per_s": *\([0-9.]*\).*/\1/p')
  c0=$(field samples_per_s "$c0"); rss=$(field peak_rss_mb "$c512"); c512=$(field samples_per_s "$c512")
  ratio0=$(awk -v a="$c0" -v b="$p0" 'BEGIN { printf "%.1f", a / b }')
  ratio512=$(awk -v a="$c512" -v b="$p512" 'BEGIN { printf "%.1f", a / b }')
  pass=$(awk -v r0="$ratio0" -v r1="$ratio512" -v c="$c0" -v m="$rss" \
    'BEGIN { print (r0 >= 10 && r1 >= 10 && c >= 1000000 && m <= 3072) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=throughput threads=2 rgb_samples_per_s=$c0 pytorch_rgb_samples_per_s=$p0 ratio_rgb=$ratio0 feat512_samples_per_s=$c512 pytorch_feat512_samples_per_s=$p512 ratio_feat512=$ratio512 peak_rss_mb_feat512=$rss target_min_ratio=10 target_min_rgb_samples_per_s=1000000 target_max_rss_mb_feat512=3072 pass=$pass"
}

# wrk_p99 URL: "requests_per_s p99_ms" of wrk -t2 -c32 against URL.
wrk_p99() {
  local out
  out=$(wrk -t2 -c32 -d"$wrk_duration" --latency "$1")
  printf '%s\n' "$out" | awk '/^Requests\/sec:/ { printf "%.0f ", $2 }'
  to_ms "$(printf '%s\n' "$out" | awk '$1 == "99%" { print $2 }')"
}

bench_busy() {
  local lego=$data/lego job state health scenes pass
  if ! command -v wrk >/dev/null 2>&1; then
    echo "bench=busy error=wrk_not_installed hint=apt-get_install_wrk pass=no"
    failed=1; return
  fi
  start_daemon busy
  curl -sf -X POST "$base/v1/scenes" -H 'Content-Type: application/json' \
    -d '{"name":"lego","workspace":{"min":[-1.5,-1.5,-1.5],"max":[1.5,1.5,1.5]}}' >/dev/null
  curl -sf -X POST "$base/v1/scenes/lego/import" -H 'Content-Type: application/json' \
    -d "{\"path\":\"$(realpath "$lego")\",\"transforms\":\"transforms_train.json\"}" >/dev/null
  job=$(curl -sf -X POST "$base/v1/scenes/lego/train" -H 'Content-Type: application/json' \
    -d '{"steps":100000,"max_seconds":120}' | sed -n 's/.*"job" *: *"\([^"]*\)".*/\1/p')
  for _ in $(seq 1 100); do
    state=$(curl -sf "$base/v1/jobs/$job" | sed -n 's/.*"state" *: *"\([a-z]*\)".*/\1/p')
    [ "$state" = running ] && break
    sleep 0.1
  done
  sleep 3 # past the first steps
  health=$(wrk_p99 "$base/v1/health")
  scenes=$(wrk_p99 "$base/v1/scenes")
  state=$(curl -sf "$base/v1/jobs/$job" | sed -n 's/.*"state" *: *"\([a-z]*\)".*/\1/p')
  curl -sf -X DELETE "$base/v1/jobs/$job" >/dev/null || true
  stop_daemon
  pass=$(awk -v a="${health#* }" -v b="${scenes#* }" -v s="$state" \
    'BEGIN { print (a <= 50 && b <= 50 && s == "running") ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=busy training=$state health_requests_per_s=${health% *} health_p99_ms=${health#* } scenes_requests_per_s=${scenes% *} scenes_p99_ms=${scenes#* } target_max_p99_ms=50 pass=$pass"
}

bench_clip() {
  local secs=${BENCH_CLIP_SECONDS:-10} f32=$tmp/vitb16_f32.safetensors f16=$tmp/vitb16_f16.safetensors
  local c h p k cr pr ratio224 ratio640 pass
  "$build/tests/clip/gen_clip" "$f32" --preset vit-b-16 --dtype f32 >/dev/null
  c=$("$build/tests/bench/bench_clip" "$f32" --threads 2 --seconds "$secs" | grep '^bench=clip ')
  echo "$c"
  if ! /usr/bin/python3 -c 'import torch' 2>/dev/null; then
    echo "bench=clip_vs_pytorch error=no_pytorch hint=apt-get_install_python3-torch pass=no"
    failed=1; return
  fi
  p=$(/usr/bin/python3 "$src/tests/bench/peer_clip.py" "$f32" --threads 2 --seconds "$secs")
  echo "$p"
  rm -f "$f32"
  "$build/tests/clip/gen_clip" "$f16" --preset vit-b-16 --dtype f16 >/dev/null
  h=$("$build/tests/bench/bench_clip" "$f16" --threads 2 --seconds "$((secs / 2 + 1))" | grep '^bench=clip ')
  echo "$h"
  rm -f "$f16"
  # peer lines: "peer=torch case=dense224 images_per_s=1.93 ..."
  pcase() { printf '%s\n' "$p" | grep "case=$1 " | tr ' ' '\n' | sed -n "s/^$2=//p" | head -n 1; }
  ratio224=$(awk -v a="$(field dense224_images_per_s "$c")" -v b="$(pcase dense224 images_per_s)" 'BEGIN { printf "%.2f", a / b }')
  ratio640=$(awk -v a="$(field dense640x360_images_per_s "$c")" -v b="$(pcase dense640x360 images_per_s)" 'BEGIN { printf "%.2f", a / b }')
  k=$(awk -v a="$(field text77_per_s "$c")" -v b="$(pcase text77 texts_per_s)" 'BEGIN { printf "%.2f", a / b }')
  pass=$(awk -v r1="$ratio224" -v r2="$ratio640" -v s1="$(field dense224_of_sgemm "$c")" \
    -v s2="$(field dense640x360_of_sgemm "$c")" -v m1="$(field peak_over_weights_mb "$c")" \
    -v m2="$(field peak_over_weights_mb "$h")" \
    'BEGIN { print (r1 >= 1.2 && r2 >= 1.2 && s1 >= 0.5 && s2 >= 0.5 && m1 <= 300 && m2 <= 300) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=clip_summary threads=2 ratio_dense224=$ratio224 ratio_dense640x360=$ratio640 ratio_text77=$k of_sgemm_dense224=$(field dense224_of_sgemm "$c") of_sgemm_dense640x360=$(field dense640x360_of_sgemm "$c") f32_peak_over_weights_mb=$(field peak_over_weights_mb "$c") f16_peak_over_weights_mb=$(field peak_over_weights_mb "$h") f16_dense224_images_per_s=$(field dense224_images_per_s "$h") target_min_ratio=1.2 target_min_of_sgemm=0.5 target_max_over_weights_mb=300 pass=$pass"
}

# class_embedding NAME < gt.json: the class's embedding as a JSON array (gt.json writes one
# number per line).
class_embedding() {
  awk -v name="$1" '
    $0 ~ "\"name\": \"" name "\"" { found = 1 }
    found && /"embedding"/ { inside = 1; next }
    inside && /\]/ { exit }
    inside { gsub(/[ ,]/, ""); printf "%s%s", (n++ ? "," : "["), $0 }
    END { print "]" }'
}

bench_heatmap() {
  local set=$tmp/heatmap512 steps=${BENCH_HEATMAP_STEPS:-200} n=${BENCH_HEATMAP_N:-60}
  local job state emb body first t times p50 p90 points bytes voxels pass i points_dense p50_dense
  "$build/tests/scenegen/fieldgrip-scenegen" --out "$set" --dim 512 --views 40 --holdout 0 >/dev/null
  start_daemon heatmap
  # The default workspace is SPEC.md's tabletop.
  curl -sf -X POST "$base/v1/scenes" -H 'Content-Type: application/json' \
    -d '{"name":"tabletop"}' >/dev/null
  curl -sf -X POST "$base/v1/scenes/tabletop/import" -H 'Content-Type: application/json' \
    -d "{\"path\":\"$set\"}" >/dev/null
  job=$(curl -sf -X POST "$base/v1/scenes/tabletop/train" -H 'Content-Type: application/json' \
    -d "{\"steps\":$steps}" | sed -n 's/.*"job" *: *"\([^"]*\)".*/\1/p')
  for _ in $(seq 1 6000); do
    state=$(curl -sf "$base/v1/jobs/$job" | sed -n 's/.*"state" *: *"\([a-z]*\)".*/\1/p')
    case $state in done|failed|cancelled) break ;; esac
    sleep 0.2
  done
  if [ "$state" != done ]; then
    stop_daemon
    echo "bench=heatmap error=training_$state pass=no"
    failed=1; return
  fi
  emb=$(class_embedding mug < "$set/gt.json")
  body=$tmp/heatmap_query.json
  printf '{"embedding": %s}' "$emb" > "$body"
  first=$(curl -s -o "$tmp/heatmap_first.json" -w '%{http_code} %{time_total}' -X POST \
    "$base/v1/scenes/tabletop/heatmap" -H 'Content-Type: application/json' --data-binary "@$body")
  if [ "${first% *}" != 200 ]; then
    stop_daemon
    echo "bench=heatmap error=http_${first% *} pass=no"
    cat "$tmp/heatmap_first.json" >&2; echo >&2
    failed=1; return
  fi
  first=${first#* }
  times=$tmp/heatmap_times
  : > "$times"
  for i in $(seq 1 "$n"); do
    curl -s -o /dev/null -w '%{time_total}\n' -X POST "$base/v1/scenes/tabletop/heatmap" \
      -H 'Content-Type: application/json' --data-binary "@$body" >> "$times"
  done
  points=$(json_int returned < "$tmp/heatmap_first.json")
  # The same query at alpha_threshold 0.01: many more occupied voxels in the reply (the
  # JSON's cost grows with them), whatever the training made of the scene.
  printf '{"embedding": %s, "alpha_threshold": 0.01}' "$emb" > "$body.dense"
  curl -s -o "$tmp/heatmap_dense.json" -X POST "$base/v1/scenes/tabletop/heatmap" \
    -H 'Content-Type: application/json' --data-binary "@$body.dense"
  points_dense=$(json_int returned < "$tmp/heatmap_dense.json")
  : > "$times.dense"
  for i in $(seq 1 "$n"); do
    curl -s -o /dev/null -w '%{time_total}\n' -X POST "$base/v1/scenes/tabletop/heatmap" \
      -H 'Content-Type: application/json' --data-binary "@$body.dense" >> "$times.dense"
  done
  t=$(curl -sf "$base/v1/scenes/tabletop")
  bytes=$(printf '%s' "$t" | sed -n 's/.*"voxel_cache" *: *{[^}]*"bytes" *: *\([0-9]*\).*/\1/p')
  voxels=$(printf '%s' "$t" | sed -n 's/.*"voxel_cache" *: *{[^}]*"voxels" *: *\([0-9]*\).*/\1/p')
  stop_daemon
  p50=$(sort -g "$times" | awk '{ v[NR] = $1 } END { printf "%.2f", v[int((NR + 1) / 2)] * 1000 }')
  p90=$(sort -g "$times" | awk '{ v[NR] = $1 } END { printf "%.2f", v[int(NR * 0.9 + 0.5)] * 1000 }')
  p50_dense=$(sort -g "$times.dense" | awk '{ v[NR] = $1 } END { printf "%.2f", v[int((NR + 1) / 2)] * 1000 }')
  pass=$(awk -v f="$first" -v p="$p50" -v v="$voxels" \
    'BEGIN { print (f <= 3 && p <= 50 && v == 220500) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=heatmap voxels=$voxels dim=512 train_steps=$steps first_heatmap_s=$(printf '%.3f' "$first") heatmaps=$n p50_ms=$p50 p90_ms=$p90 points=$points p50_ms_alpha_0.01=$p50_dense points_alpha_0.01=$points_dense cache_bytes=$bytes cache_mb=$(awk -v b="$bytes" 'BEGIN { printf "%.1f", b / 1048576 }') target_max_first_s=3 target_max_p50_ms=50 pass=$pass"
}

bench_robot() {
  local dir=$tmp/robot sim=$build/sim/fieldgrip-sim bin=$build/tests/bench/bench_robot
  local n=${BENCH_ROBOT_N:-1000} sim_pid port= out rc=0 line p99 pass
  if [ ! -x "$sim" ] || [ ! -x "$bin" ]; then
    echo "bench=robot_execute error=not_built hint=meson_compile_bench_robot_fieldgrip-sim pass=no"
    failed=1; return
  fi
  mkdir -p "$dir"
  "$sim" --listen 127.0.0.1:0 --port-file "$dir/sim.port" --log "$dir/sim.log" \
    --ack-delay-ms 0 2> "$dir/sim.stderr" &
  sim_pid=$!
  pids+=("$sim_pid")
  for _ in $(seq 1 200); do
    [ ! -s "$dir/sim.port" ] || break
    kill -0 "$sim_pid" 2>/dev/null || break
    sleep 0.05
  done
  port=$(cat "$dir/sim.port" 2>/dev/null || true)
  if [ -z "$port" ]; then
    cat "$dir/sim.stderr" >&2
    echo "bench=robot_execute error=simulator_did_not_start pass=no"
    failed=1; return
  fi
  start_daemon robot "$(printf '[robot]\ntransport = tcp\nhost = 127.0.0.1\nport = %s' "$port")"
  out=$("$bin" "$base" "$dir/sim.log" "$n") || rc=$?
  stop_daemon
  kill "$sim_pid" 2>/dev/null || true
  wait "$sim_pid" 2>/dev/null || true
  line=$(printf '%s\n' "$out" | grep '^bench=robot_execute ' || true)
  if [ -z "$line" ]; then
    echo "bench=robot_execute error=bench_robot_exit_$rc pass=no"
    failed=1; return
  fi
  printf '%s\n' "$out" | grep -E '^bench=robot_execute_(nowait|baseline) ' || true
  p99=$(field p99_ms "$line")
  pass=$(awk -v p="$p99" -v r="$rc" -v c="$(field checks "$line")" \
    'BEGIN { print (p <= 5 && r == 0 && c == "pass") ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "$line target_max_p99_ms=5 pass=$pass"
}

bench_grasp() {
  local set=$tmp/grasp512 dump=$tmp/grasp_dump bin=$build/tests/bench/bench_grasp
  local dim=${BENCH_GRASP_DIM:-512} steps=${BENCH_GRASP_STEPS:-300} runs=${BENCH_GRASP_RUNS:-5}
  local views=${BENCH_GRASP_VIEWS:-40} rotations=${BENCH_GRASP_ROTATIONS:-24}
  local samples=${BENCH_GRASP_SAMPLES:-0} voxel=${BENCH_GRASP_VOXEL_SIZE:-0.01}
  local ours peer rc=0 ratio ratio_eval pass
  if [ ! -x "$bin" ]; then
    echo "bench=grasp error=not_built hint=meson_compile_bench_grasp pass=no"
    failed=1; return
  fi
  "$build/tests/scenegen/fieldgrip-scenegen" --out "$set" --dim "$dim" --views "$views" \
    --holdout 0 >/dev/null
  ours=$("$bin" --data "$set" --threads 2 --steps "$steps" --runs "$runs" \
    --rotations "$rotations" --samples "$samples" --voxel-size "$voxel" --dump "$dump") || rc=$?
  ours=$(printf '%s\n' "$ours" | grep '^bench=grasp ' || true)
  rm -rf "$set"
  if [ -z "$ours" ]; then
    echo "bench=grasp error=bench_grasp_exit_$rc pass=no"
    failed=1; return
  fi
  echo "$ours"
  [ "$(field pass "$ours")" = yes ] || failed=1
  if ! /usr/bin/python3 -c 'import torch, numpy' 2>/dev/null; then
    echo "bench=grasp_vs_peer error=no_pytorch hint=apt-get_install_python3-torch_python3-numpy pass=no"
    failed=1; return
  fi
  rc=0
  peer=$(/usr/bin/python3 "$src/tests/bench/peer_grasp.py" "$dump" --threads 2) || rc=$?
  peer=$(printf '%s\n' "$peer" | grep '^bench=grasp_peer ' || true)
  rm -rf "$dump"
  if [ -z "$peer" ]; then
    echo "bench=grasp_vs_peer error=peer_grasp_exit_$rc pass=no"
    failed=1; return
  fi
  echo "$peer"
  ratio=$(awk -v a="$(field seconds "$peer")" -v b="$(field p50_s "$ours")" \
    'BEGIN { printf "%.1f", a / b }')
  ratio_eval=$(awk -v a="$(field seconds "$peer")" -v b="$(field p50_s "$ours")" \
    -v ea="$(field evaluations "$peer")" -v eb="$(field evaluations "$ours")" \
    'BEGIN { printf "%.1f", (a / ea) / (b / eb) }')
  pass=$(field pass "$ours")
  echo "bench=grasp_vs_peer threads=2 dim=$dim seconds=$(field p50_s "$ours") peer_seconds=$(field seconds "$peer") ratio=$ratio ratio_per_evaluation=$ratio_eval evaluations=$(field evaluations "$ours") peer_evaluations=$(field evaluations "$peer") best_score_mug=$(field top_score_mug "$ours") peer_best_score_mug=$(field best_score_mug "$peer") best_score_box=$(field top_score_box "$ours") peer_best_score_box=$(field best_score_box "$peer") peer_cost_check_max_abs=$(field cost_check_max_abs "$peer") target_ratio=report_only pass=$pass"
}

bench_geometry() {
  local steps=${BENCH_GEOMETRY_STEPS:-2000} out line v pass=yes
  out=$("$build/tests/bench/bench_geometry" --scenegen "$build/tests/scenegen/fieldgrip-scenegen" \
    --steps "$steps" --threads 2) || { echo "bench=geometry error=bench_geometry_failed pass=no"; failed=1; return; }
  printf '%s\n' "$out" | grep -v '^bench=geometry variant=depth '
  line=$(printf '%s\n' "$out" | grep '^bench=geometry variant=depth ')
  v=$(awk -v p="$(field psnr_db "$line")" -v d="$(field depth_object_median_mm "$line")" \
    -v m="$(field mug_cavity_free "$line")" -v b="$(field bowl_cavity_free "$line")" \
    -v mi="$(field mug_iou "$line")" -v bi="$(field bowl_iou "$line")" \
    'BEGIN { print (p >= 30 && d <= 2 && m >= 0.95 && b >= 0.95 && mi >= 0.6 && bi >= 0.6) ? "yes" : "no" }')
  [ "$v" = yes ] || { pass=no; failed=1; }
  echo "$line target_min_psnr_db=30 target_max_depth_median_mm=2 target_min_cavity_free=0.95 target_min_iou=0.6 pass=$pass"
}

bench_depth_throughput() {
  local set=$tmp/tabletop_depth off on ratio pass
  "$build/tests/scenegen/fieldgrip-scenegen" --out "$set" --holdout 0 --depth png >/dev/null
  off=$("$build/tests/bench/bench_train" --data "$set/transforms.json" --threads 2 --holdout 0 \
    --workspace 0.10 -0.45 0.005 0.80 0.45 0.35 --field-scale 2 --seconds 60 --depth-weight 0 |
    grep '^bench=train ')
  on=$("$build/tests/bench/bench_train" --data "$set/transforms.json" --threads 2 --holdout 0 \
    --workspace 0.10 -0.45 0.005 0.80 0.45 0.35 --field-scale 2 --seconds 60 |
    grep '^bench=train ')
  rm -rf "$set"
  ratio=$(awk -v a="$(field samples_per_s "$on")" -v b="$(field samples_per_s "$off")" \
    'BEGIN { printf "%.3f", a / b }')
  pass=$(awk -v r="$ratio" 'BEGIN { print (r >= 0.9) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  echo "bench=depth_throughput samples_per_s_without=$(field samples_per_s "$off") samples_per_s_with=$(field samples_per_s "$on") ratio=$ratio target_min_ratio=0.9 pass=$pass"
}

bench_http_idle() {
  local bin=$build/tests/bench/bench_http_idle n=${BENCH_IDLE_N:-10000}
  local reqs=${BENCH_IDLE_REQUESTS:-200} cap out rc line p99 pass
  if [ ! -x "$bin" ]; then
    echo "bench=http_idle error=not_built hint=meson_compile_bench_http_idle pass=no"
    failed=1; return
  fi
  for cap in $((n + 100)) 1024; do
    start_daemon "http_idle_$cap" \
      "$(printf '[http]\nmax_connections = %s\nheader_timeout_s = 600' "$cap")"
    rc=0
    out=$("$bin" "$base" "$n" "$reqs") || rc=$?
    stop_daemon
    line=$(printf '%s\n' "$out" | grep '^bench=http_idle ' || true)
    if [ -z "$line" ] || [ $rc -ne 0 ]; then
      echo "${line:-bench=http_idle error=bench_http_idle_exit_$rc pass=no}"
      failed=1; continue
    fi
    p99=$(field p99_ms "$line")
    pass=$(awk -v p="$p99" 'BEGIN { print (p <= 50) ? "yes" : "no" }')
    [ "$pass" = yes ] || failed=1
    echo "$line max_connections=$cap target_max_p99_ms=50 pass=$pass"
  done
}

# Runs a benchmark program that checks its own target: NAME (bench_NAME), the pattern of its
# detail lines, the key of its summary line, then its arguments. Prints the details and the
# summary (which carries pass=); a missing summary is a failure.
run_self_checked() {
  local name=$1 details=$2 summary=$3 out rc=0 line
  local bin=$build/tests/bench/bench_$name
  shift 3
  if [ ! -x "$bin" ]; then
    echo "bench=$summary error=not_built hint=meson_compile_bench_$name pass=no"
    failed=1; return
  fi
  out=$("$bin" "$@") || rc=$?
  printf '%s\n' "$out" | grep -E "^bench=($details) " || true
  line=$(printf '%s\n' "$out" | grep "^bench=$summary " || true)
  if [ -z "$line" ]; then
    echo "bench=$summary error=bench_${name}_exit_$rc pass=no"
    failed=1; return
  fi
  echo "$line"
  [ "$(field pass "$line")" = yes ] || failed=1
}

bench_calibration() {
  run_self_checked calibration calibration_case calibration "${BENCH_CALIBRATION_TRIALS:-10}"
}

bench_grasp_physics() {
  run_self_checked grasp_physics 'grasp_physics_layout|grasp_physics_grasp|grasp_physics_depth' \
    grasp_physics --scenegen "$build/tests/scenegen/fieldgrip-scenegen" \
    --layouts "${BENCH_GRASP_PHYSICS_LAYOUTS:-10}" --steps "${BENCH_GRASP_PHYSICS_STEPS:-1200}" \
    --depth "${BENCH_GRASP_PHYSICS_DEPTH:-both}" --threads 2
}

bench_load() {
  run_self_checked load load load_summary "$daemon" "$build/tests/scenegen/fieldgrip-scenegen" \
    --seconds "${BENCH_LOAD_SECONDS:-30}"
}

bench_soak() {
  run_self_checked soak soak_sample soak "$daemon" --frames "${BENCH_SOAK_FRAMES:-10000}"
}

bench_viewer() {
  run_self_checked viewer 'viewer_load|viewer_fps' viewer "$daemon" \
    "$build/tests/scenegen/fieldgrip-scenegen" --loads "${BENCH_VIEWER_LOADS:-5}"
}

bench_scan() {
  FG_SOURCE_DIR=$src run_self_checked scan none scan "$daemon" "$build/sim/fieldgrip-sim" \
    "${BENCH_SCAN_VIEWPOINTS:-30}"
}

bench_update() {
  local bin=$build/tests/bench/bench_update out rc=0 line
  if [ ! -x "$bin" ]; then
    echo "bench=update error=not_built hint=meson_compile_bench_update pass=no"
    failed=1; return
  fi
  out=$("$bin" --scenegen "$build/tests/scenegen/fieldgrip-scenegen" \
    --focus "${BENCH_UPDATE_FOCUS:-50}") || rc=$?
  printf '%s\n' "$out" | grep -E '^bench=update_look ' || true
  if ! printf '%s\n' "$out" | grep -q '^bench=update '; then
    echo "bench=update error=bench_update_exit_$rc pass=no"
    failed=1; return
  fi
  while read -r line; do  # one line with depth maps, one without
    echo "$line"
    [ "$(field pass "$line")" = yes ] || failed=1
  done < <(printf '%s\n' "$out" | grep '^bench=update ')
}

bench_first_grasp() {
  FG_SOURCE_DIR=$src FG_BUILD_DIR=$build run_self_checked first_grasp none first_grasp \
    "$daemon" "$build/tests/scenegen/fieldgrip-scenegen" "$build/sim/fieldgrip-sim" \
    "${BENCH_FIRST_GRASP_STEPS:-500}"
}

# json_str KEY < JSON, json_num KEY < JSON: the first string or number value of "KEY".
json_str() { sed -n "s/.*\"$1\"[[:space:]]*:[[:space:]]*\"\([^\"]*\)\".*/\1/p" | head -n 1; }
json_num() { sed -n "s/.*\"$1\"[[:space:]]*:[[:space:]]*\([-0-9.eE+]*\).*/\1/p" | head -n 1; }

# The fox as a user gets it: imported and trained through the daemon's API with the scene's
# field settings on "auto" (which must find the cube of 4 and the learned background that
# instant-ngp's aabb_scale 4 asks for).
bench_fox() {
  local fox=${FG_FOX_DIR:-} v out job state psnr pass t0 t1 seconds
  if [ -z "$fox" ] || [ ! -f "$fox/transforms.json" ]; then
    echo "bench=fox error=no_data_set hint=set_FG_FOX_DIR_to_instant-ngp's_data/nerf/fox pass=no"
    failed=1; return
  fi
  cp -r "$(realpath "$fox")" "$tmp/fox" # import_dirs holds $tmp; a link out of it is refused
  start_daemon fox "$(printf '[train]\nthreads = 2\nmax_image_side = 400')"
  curl -sf -X POST "$base/v1/scenes" -H 'Content-Type: application/json' \
    -d '{"name":"fox","workspace":{"min":[-1.5,-1.5,-1.5],"max":[1.5,1.5,1.5]}}' >/dev/null
  curl -sf -X POST "$base/v1/scenes/fox/import" -H 'Content-Type: application/json' \
    -d "{\"path\":\"$tmp/fox\",\"transforms\":\"transforms.json\"}" >/dev/null
  for v in 0 "${BENCH_FOX_DISTORTION:-0.002}"; do
    t0=$(now)
    job=$(curl -sf -X POST "$base/v1/scenes/fox/train" -H 'Content-Type: application/json' \
      -d "{\"steps\":${BENCH_FOX_STEPS:-3000},\"holdout_every\":10,\"distortion_weight\":$v}" |
      json_str job)
    state=queued
    while [ "$state" = queued ] || [ "$state" = running ]; do
      sleep 2
      out=$(curl -sf "$base/v1/jobs/$job")
      state=$(printf '%s' "$out" | json_str state)
    done
    t1=$(now)
    psnr=$(printf '%s' "$out" | json_num psnr)
    seconds=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.1f", b - a }')
    pass=$(awk -v p="$psnr" -v s="$state" 'BEGIN { print (s == "done" && p >= 23) ? "yes" : "no" }')
    [ "$pass" = yes ] || failed=1
    echo "bench=fox state=$state steps=$(printf '%s' "$out" | json_int step) psnr=$psnr" \
      "frames=$(printf '%s' "$out" | json_int frames)" \
      "heldout=$(printf '%s' "$out" | json_int heldout_frames) distortion_weight=$v" \
      "field_scale=$(printf '%s' "$out" | json_num scale)" \
      "learn_background=$(printf '%s' "$out" | sed -n 's/.*"learn_background":\([a-z]*\).*/\1/p')" \
      "chosen_by=$(printf '%s' "$out" | json_str chosen_by | tr ' ' _) seconds=$seconds" \
      "target_min_psnr=23 pass=$pass"
  done
  stop_daemon
}

# Clear the table (scripts/demo.sh --clear-table) on layouts the tests never use: the share
# of objects that ended in the bin, grasps per object, failures by kind, time per object.
bench_clear_table() {
  local seeds=${BENCH_CLEAR_SEEDS:-"200 201 202 203 204 205 206 207 208 209"} s line conf
  local layouts=0 objects=0 cleared=0 grasps=0 seconds=0 kinds= share pass
  for s in $seeds; do
    # a state dir of its own: a robot stopped in one layout stays stopped there
    conf=$tmp/clear-$s.conf
    sed -e "s|^dir = .*|dir = $tmp/clear-$s-state|" \
        -e "s|^import_dirs = .*|import_dirs = $(realpath "$data")|" "$src/config/demo.conf" > "$conf"
    line=$("$src/scripts/demo.sh" --exit --clear-table --layout "$s" --config "$conf" \
             --out "$tmp/clear-$s" --build "$build" --steps "${BENCH_CLEAR_STEPS:-300}" \
             --update-steps "${BENCH_CLEAR_UPDATE_STEPS:-200}" 2>"$tmp/clear-$s.err" |
           grep '^clear_table: ' | tail -n 1) || true
    if [ -z "$line" ]; then
      echo "bench=clear_table_layout layout=$s error=demo_failed why=$(tail -n 1 "$tmp/clear-$s.err" | tr ' ' _)"
      failed=1
      continue
    fi
    line=${line#clear_table: }
    echo "bench=clear_table_layout $line"
    layouts=$((layouts + 1))
    objects=$((objects + $(field objects "$line")))
    cleared=$((cleared + $(field cleared "$line")))
    grasps=$((grasps + $(field grasps "$line")))
    seconds=$(awk -v a="$seconds" -v b="$(field seconds "$line")" 'BEGIN { print a + b }')
    [ "$(field failures "$line")" = none ] || kinds+="${kinds:+,}$(field failures "$line")"
  done
  share=$(awk -v c="$cleared" -v n="$objects" 'BEGIN { printf "%.3f", n ? c / n : 0 }')
  pass=$(awk -v s="$share" -v l="$layouts" 'BEGIN { print (l > 0 && s >= 0.9) ? "yes" : "no" }')
  [ "$pass" = yes ] || failed=1
  kinds=$(printf '%s' "$kinds" | tr ',' '\n' | awk -F: 'NF == 2 { n[$1] += $2 } END { for (k in n) printf "%s%s:%d", (i++ ? "," : ""), k, n[k] }')
  echo "bench=clear_table layouts=$layouts objects=$objects cleared=$cleared share=$share" \
    "grasps_per_object=$(awk -v g="$grasps" -v n="$objects" 'BEGIN { printf "%.2f", n ? g / n : 0 }')" \
    "failures=${kinds:-none} seconds_per_object=$(awk -v s="$seconds" -v n="$objects" 'BEGIN { printf "%.1f", n ? s / n : 0 }')" \
    "target_min_share=0.9 pass=$pass"
}

for b in "${benches[@]}"; do
  case $b in
    import) bench_import ;;
    health) bench_health ;;
    memory) bench_memory ;;
    train) bench_train ;;
    throughput) bench_throughput ;;
    busy) bench_busy ;;
    clip) bench_clip ;;
    heatmap) bench_heatmap ;;
    robot) bench_robot ;;
    grasp) bench_grasp ;;
    grasp_physics) bench_grasp_physics ;;
    geometry) bench_geometry ;;
    depth_throughput) bench_depth_throughput ;;
    fox) bench_fox ;;
    clear_table) bench_clear_table ;;
    http_idle) bench_http_idle ;;
    load) bench_load ;;
    soak) bench_soak ;;
    viewer) bench_viewer ;;
    calibration) bench_calibration ;;
    scan) bench_scan ;;
    update) bench_update ;;
    first_grasp) bench_first_grasp ;;
    *) echo "error: unknown benchmark '$b' (import, health, memory, train, throughput, busy, clip, heatmap, robot, grasp, grasp_physics, geometry, depth_throughput, fox, http_idle, load, soak, viewer, calibration, scan, update, first_grasp, clear_table)" >&2; exit 2 ;;
  esac
done
exit "$failed"
