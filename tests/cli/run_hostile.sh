#!/usr/bin/env bash
# Hostile .ivol files (issue 17, tests/support/hostile_files.hpp): every
# reading command on each, under a 2 GiB address-space limit and a 60 s
# timeout. None may crash (exit >= 128), hang (timeout) or leave output
# behind when it fails; files a reader must refuse exit 2, valid ones 0.
# $IVOL is the binary under test, $MAKE_HOSTILE the files' maker.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
: "${MAKE_HOSTILE:?set MAKE_HOSTILE to make_hostile_files}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
out="$work/out"
mkdir -p "$out"
passed=0
failed=0

limit=(prlimit --as=2147483648 --)
# Sanitizers reserve terabytes of address space: no limit there.
[ "${IVOL_SANITIZED:-0}" = 1 ] && limit=()

# run NAME WANT TEXT -- COMMAND...: COMMAND exits WANT (any exit below 128
# when WANT is "any") and prints TEXT; a failing command leaves $out empty.
run() {
  local name=$1 want=$2 text=$3
  shift 4
  local log got start seconds
  start=$(date +%s)
  log=$(timeout 60 "${limit[@]}" "$@" 2>&1)
  got=$?
  seconds=$(($(date +%s) - start))
  if [ "$got" -eq 124 ]; then
    echo "FAIL $name: no answer in 60 s"; failed=$((failed + 1))
  elif [ "$got" -ge 128 ]; then
    echo "FAIL $name: killed by signal $((got - 128))"; echo "$log" | tail -5 | sed 's/^/    /'
    failed=$((failed + 1))
  elif [ "$want" != any ] && [ "$got" -ne "$want" ]; then
    echo "FAIL $name: exit $got, expected $want"; echo "$log" | tail -5 | sed 's/^/    /'
    failed=$((failed + 1))
  elif ! grep -qF -- "$text" <<<"$log"; then
    echo "FAIL $name: output lacks '$text'"; echo "$log" | tail -5 | sed 's/^/    /'
    failed=$((failed + 1))
  elif [ "$got" -ne 0 ] && [ "$got" -ne 3 ] && [ -n "$(ls -A "$out")" ]; then
    echo "FAIL $name: exit $got but left $(ls -A "$out" | tr '\n' ' ')"; failed=$((failed + 1))
  else
    echo "ok   $name (exit $got, ${seconds} s)"; passed=$((passed + 1))
  fi
  rm -rf "${out:?}"/* "${out:?}"/.[!.]*
}

"$MAKE_HOSTILE" "$work" || { echo "FAIL: make_hostile_files"; exit 1; }

while read -r name verdict _; do
  f="$work/$name.ivol"
  # Refused files exit 2 from every command, valid ones 0; the text is what
  # the refusal must say.
  text=""
  case $name in
    deep_json_*) text="nested deeper than 128" ;;
    dag_octree) text="breadth-first order requires" ;;
    zstd_block_4gib) text="the largest zstd frame" ;;
    index_6gib) text="footer: index_size" ;;
  esac
  want=0
  [ "$verdict" = refused ] && want=2
  info_want=$want verify_want=$want read_want=$want
  extract_want=$want extract_text=$text
  case $name in
    # info reads no node; one voxel's path has one node per level, which
    # the DAG does not break.
    dag_octree) info_want=0 extract_want=0 extract_text="" ;;
    unknown_stream_2gib) verify_want=2 ;;  # only verify checks the ignorable block's CRC
    salvage_zeroed) verify_want=2 read_want=any extract_want=any ;;  # depends on the blocks a read meets
    # A slice of 2^29 x 2^29 voxels is the request's size, not the file's:
    # refused or failed cleanly, but not read.
    rectilinear_2p29) read_want=any ;;
  esac
  info_text=$text
  [ "$info_want" = 0 ] && info_text=""
  run "$name: info" "$info_want" "$info_text" -- "$IVOL" info "$f"
  run "$name: verify" "$verify_want" "$text" -- "$IVOL" verify "$f"
  run "$name: slice x" "$read_want" "$text" -- "$IVOL" -q slice "$f" --axis x --index 0 -o "$out/s.png"
  run "$name: extract" "$extract_want" "$extract_text" -- "$IVOL" -q extract "$f" --box 0,0,0,1,1,1 -o "$out/e.raw"
  # The whole volume, except for the two valid grids of 2 GiB and 2^87 voxels.
  if [ "$name" != regular_grid_2gib ] && [ "$name" != rectilinear_2p29 ]; then
    run "$name: convert" "$read_want" "$text" -- "$IVOL" -q convert "$f" "$out/c.raw"
    run "$name: re-encode" "$read_want" "$text" -- "$IVOL" -q convert "$f" "$out/c.ivol"
    # Salvaging reads past what it can: any exit, but no crash or hang; an
    # unreadable metadata block is a loss it names (exit 3), not defaults
    # passed off as the input's.
    salvage_want=any salvage_text=""
    case $name in deep_json_*) salvage_want=3 salvage_text="metadata, which cannot be read" ;; esac
    run "$name: re-encode --salvage" "$salvage_want" "$salvage_text" -- "$IVOL" -q convert "$f" "$out/c.ivol" --salvage
  fi
done < <("$MAKE_HOSTILE" --list)

# Levels of detail of large grids: the output and one layer of sums.
# (Each sums the 2^28 full-resolution voxels of 256 slices: seconds.)
f="$work/regular_grid_2gib.ivol"
run "regular_grid_2gib: extract --level 8" 0 "" -- "$IVOL" -q extract "$f" --box 0,0,1,4,4,2 --level 8 -o "$out/e.raw"
run "regular_grid_2gib: slice --level 8" 0 "" -- "$IVOL" -q slice "$f" --axis z --index 1 --level 8 -o "$out/s.png"
f="$work/rectilinear_2p29.ivol"
# A level of detail of a grid sums the full-resolution voxels under it (spec
# §12.3): 2^27 of them for these 8 voxels of level 8, in memory for 8.
run "rectilinear_2p29: extract --level 8" 0 "" -- "$IVOL" -q extract "$f" --box 0,0,0,2,2,2 --level 8 -o "$out/e.raw"
run "rectilinear_2p29: extract --level 20" 2 "more than this reader's limit" -- \
  "$IVOL" -q extract "$f" --box 0,0,0,1,1,1 --level 20 -o "$out/e.raw"
run "rectilinear_2p29: convert (too large)" any "" -- "$IVOL" -q convert "$f" "$out/c.raw"
# Salvage: a bounded list, one entry per damaged block, not per voxel.
f="$work/salvage_zeroed.ivol"
run "salvage_zeroed: extract --salvage" 3 "from coarser levels because blocks are damaged" -- \
  "$IVOL" -q extract "$f" --box 0,0,0,160,160,160 --salvage -o "$out/e.raw"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
