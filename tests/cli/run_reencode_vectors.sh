#!/usr/bin/env bash
# Every valid conformance vector (formats 1.0 to 1.3, every structure and
# codec, the hand-made ones included) re-encoded by `ivol convert IN.ivol
# OUT.ivol`, into the structure convert chooses and into an octree: the
# reference reader's dense export (spec §12.2, stored bits) of the new file
# equals that of the vector, byte for byte. $IVOL is the binary under test,
# $IVOLREF the reference reader.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
: "${IVOLREF:?set IVOLREF to format-spec/reference-reader/ivolref.py}"
vectors=$(cd "$(dirname "$0")/../../format-spec/vectors/valid" && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
source "$(dirname "$0")/cases.sh"

same_voxels() {  # same_voxels VECTOR STRUCTURE-ARGUMENTS...
  local vector=$1
  shift
  "$IVOL" -q convert "$vector" "$work/again.ivol" -f "$@" || return 1
  /usr/bin/python3 "$IVOLREF" dense "$vector" -o "$work/want.dense" || return 1
  /usr/bin/python3 "$IVOLREF" dense "$work/again.ivol" -o "$work/got.dense" || return 1
  cmp "$work/want.dense" "$work/got.dense"
}
count=0
for vector in "$vectors"/*.ivol; do
  name=$(basename "$vector" .ivol)
  check "$name" same_voxels "$vector"
  check "$name as an octree" same_voxels "$vector" --structure octree
  count=$((count + 1))
done
# The vectors are the test: an empty folder would pass vacuously.
[ "$count" -ge 50 ] || { echo "FAIL only $count vectors found in $vectors"; failed=$((failed + 1)); }
finish
