#!/usr/bin/env bash
# The code's shape, as the README's "Repository layout" describes it:
#   - daemon/ is in rooms, lowest first: conf, decoder, metrics, state, robot, http, api. A file
#     of a room includes its own room's headers by their bare names, and another room's as
#     "room/name.h", of a room before its own only; at the top, only main.c and notify.[ch];
#   - nothing under lib/ includes a daemon header: a bare name must be a header beside the file,
#     anything else a lib/ path;
#   - no file under daemon/, lib/ or sim/ (the simulator ships with the daemon) passes 900 lines.
# Every offence is printed; the exit status is 1 if there was one.
# argv: the source root.
set -uo pipefail
root=$1
rooms=(conf decoder metrics state robot cell http api)
bad=0
offence() { echo "FAIL: $*"; bad=1; }

rank() { # ROOM: its place in rooms, or -1
  local i
  for i in "${!rooms[@]}"; do [ "${rooms[$i]}" = "$1" ] && { echo "$i"; return; }; done
  echo -1
}

# quoted includes of FILE, one per line
includes() { sed -n 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*"\([^"]*\)".*/\1/p' "$1"; }

cd "$root" || exit 2
[ -d daemon ] && [ -d lib ] || { echo "FAIL: $root has no daemon/ and lib/"; exit 2; }

for f in daemon/*; do
  case $f in
    daemon/main.c | daemon/notify.c | daemon/notify.h | daemon/meson.build) ;;
    *) [ -d "$f" ] && [ "$(rank "${f#daemon/}")" -ge 0 ] ||
         offence "$f: daemon/ holds rooms (${rooms[*]}), main.c and notify.[ch] only" ;;
  esac
done

for room in "${rooms[@]}"; do
  [ -d "daemon/$room" ] || { offence "daemon/$room: a room is missing"; continue; }
  mine=$(rank "$room")
  for f in "daemon/$room"/*.[ch]; do
    while IFS= read -r inc; do
      [ -n "$inc" ] || continue
      case $inc in
        config.h) ;;
        */*)
          r=$(rank "${inc%%/*}")
          if [ "$r" -gt "$mine" ]; then
            offence "$f includes \"$inc\": $room may include only rooms before it (${rooms[*]:0:$mine})"
          elif [ "$r" -eq "$mine" ]; then
            offence "$f includes \"$inc\": a header of its own room goes by its bare name"
          elif [ "$r" -lt 0 ] && [ ! -f "lib/$inc" ]; then
            offence "$f includes \"$inc\", which is neither a room's header nor under lib/"
          fi ;;
        *) [ -f "daemon/$room/$inc" ] ||
             offence "$f includes \"$inc\", which is not in daemon/$room/ (another room's header goes as \"room/$inc\")" ;;
      esac
    done < <(includes "$f")
  done
done

while IFS= read -r f; do
  dir=${f%/*}
  while IFS= read -r inc; do
    [ -n "$inc" ] || continue
    case $inc in
      config.h) ;;
      */*) [ -f "lib/$inc" ] || offence "$f includes \"$inc\", which is not under lib/" ;;
      *) [ -f "$dir/$inc" ] || offence "$f includes \"$inc\", which is not beside it" ;;
    esac
  done < <(includes "$f")
done < <(find lib -name '*.[ch]' -o -name '*.cc' -o -name '*.cpp' -o -name '*.hpp')

while IFS= read -r f; do
  n=$(wc -l < "$f")
  [ "$n" -le 900 ] || offence "$f has $n lines (at most 900)"
done < <(find daemon lib sim -name '*.[ch]' -o -name '*.cc' -o -name '*.cpp' -o -name '*.hpp')

[ "$bad" -eq 0 ] && echo "ok: ${#rooms[@]} rooms in order, lib/ apart, every file within 900 lines"
exit "$bad"
