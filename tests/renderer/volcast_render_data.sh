#!/bin/sh
# volcast-render --data: a scene naming its volume relative to the server's data folders
# (as a scene saved from volcast-server does) renders given those folders, and the name is
# confined as the server confines it. Usage: volcast_render_data.sh VOLCAST_RENDER_EXE
set -u
exe=$1
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
mkdir -p "$dir/first" "$dir/data/ct" "$dir/scenes" "$dir/outside"
# A 2³ uint8 volume in the second folder; the first folder (searched first) lacks it.
{ printf 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n'; printf '\000\100\200\377\000\100\200\377'; } > "$dir/data/ct/v.nrrd"
cp "$dir/data/ct/v.nrrd" "$dir/outside/secret.nrrd"
ln -s "$dir/outside" "$dir/data/link"
scene() {   # scene NAME VOLUME: a scene file in scenes/, away from the data folders
  printf '{"volume": "%s", "transfer_function": {"preset": "micro_ct"}, "camera": {"eye": [0.5, 0.5, 8], "target": [0.5, 0.5, 0.5], "up": [0, 1, 0], "projection": "perspective", "fov_y_deg": 30}, "image": {"width": 8, "height": 8}}\n' "$2" > "$dir/scenes/$1.json"
}
failures=0
expect() {  # expect 0|fail "what" MESSAGE-PATTERN args...
  want=$1 what=$2 pattern=$3; shift 3
  "$exe" "$@" --reference -o "$dir/out.png" > "$dir/stdout" 2> "$dir/stderr"; rc=$?
  if [ "$want" = 0 ] && [ $rc -ne 0 ]; then echo "FAIL: $what: exit $rc: $(cat "$dir/stderr")"; failures=$((failures + 1)); return; fi
  if [ "$want" = fail ] && [ $rc -eq 0 ]; then echo "FAIL: $what: rendered, should have been refused"; failures=$((failures + 1)); return; fi
  if [ -n "$pattern" ] && ! grep -q -- "$pattern" "$dir/stderr" "$dir/stdout"; then
    echo "FAIL: $what: output lacks \"$pattern\": $(cat "$dir/stderr" "$dir/stdout")"; failures=$((failures + 1)); return; fi
  echo "ok: $what"
}
scene relative ct/v.nrrd
expect 0 "a server-relative name renders with --data (second folder of two)" '"dims":\[2,2,2\]' "$dir/scenes/relative.json" --data "$dir/first" --data "$dir/data"
expect fail "without --data the name is relative to the scene file: not there" "" "$dir/scenes/relative.json"
scene dotdot ../outside/secret.nrrd
expect fail "a .. component is refused" "must name a volume relative to the data folders" "$dir/scenes/dotdot.json" --data "$dir/data"
scene absolute "$dir/outside/secret.nrrd"
expect fail "an absolute name is refused" "must name a volume relative to the data folders" "$dir/scenes/absolute.json" --data "$dir/data"
scene link link/secret.nrrd
expect fail "a symbolic link out of the folder is refused" "resolves outside the data folder" "$dir/scenes/link.json" --data "$dir/data"
scene missing ct/none.nrrd
expect fail "a name in none of the folders says where it looked" "is in none of the --data folders" "$dir/scenes/missing.json" --data "$dir/data"
scene builtin builtin:sphere
expect 0 "builtin: volumes need no folder" "" "$dir/scenes/builtin.json" --data "$dir/data"
[ $failures -eq 0 ] || { echo "$failures check(s) failed"; exit 1; }
