#!/usr/bin/env bash
# The ivol command line, case by case: each case gives the command, the exit
# code it must return, and a text its output must contain (zstd's
# tests/cli-tests style). $IVOL is the binary under test.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
passed=0
failed=0

# case NAME EXPECTED_EXIT EXPECTED_TEXT -- COMMAND...
case_() {
  local name=$1 want_exit=$2 want_text=$3
  shift 4
  local out
  out=$("$@" 2>&1)
  local got=$?
  if [ "$got" -ne "$want_exit" ]; then
    echo "FAIL $name: exit $got, expected $want_exit"; echo "$out" | sed 's/^/    /' | head -20
    failed=$((failed + 1)); return
  fi
  if [ -n "$want_text" ] && ! grep -qF -- "$want_text" <<<"$out"; then
    echo "FAIL $name: output lacks '$want_text'"; echo "$out" | sed 's/^/    /' | head -20
    failed=$((failed + 1)); return
  fi
  echo "ok   $name"
  passed=$((passed + 1))
}

case_ help               0 "Subcommands:"            -- "$IVOL" --help
case_ version            0 "ivol 0."                 -- "$IVOL" --version
case_ no-subcommand      1 "subcommand"              -- "$IVOL"
case_ unknown-subcommand 1 "bogus"                   -- "$IVOL" bogus
case_ unknown-option     1 "--frobnicate"            -- "$IVOL" info --frobnicate x.ivol
case_ info-help          0 "--json"                  -- "$IVOL" info --help
case_ verify-help        0 "FILE"                    -- "$IVOL" verify --help
case_ demo-help          0 "--size"                  -- "$IVOL" demo --help
case_ demo-size-range    1 "--size"                  -- "$IVOL" demo --size 4
case_ demo-bad-object    1 "teapot"                  -- "$IVOL" demo --object teapot
case_ info-missing       2 "cannot open"             -- "$IVOL" info "$work/missing.ivol"
case_ demo               0 "octree"                  -- "$IVOL" demo --size 32 --object board -o "$work/demo"
case_ demo-quiet         0 ""                        -- "$IVOL" -q demo --size 16 -o "$work/quiet"
case_ verify-ok          0 "OK"                      -- "$IVOL" verify "$work/demo/demo-octree.ivol" "$work/demo/demo-lossless.ivol"
case_ info-text          0 "32 x 32 x 32 voxels"     -- "$IVOL" info "$work/demo/demo-octree.ivol"
case_ info-json          0 '"dimensions": ['         -- "$IVOL" info --json "$work/demo/demo-octree.ivol"
"$IVOL" info --json "$work/demo/demo-octree.ivol" > "$work/info.json"
case_ info-json-parses   0 "32"                      -- python3 -c "import json,sys; d=json.load(open('$work/info.json')); print(d['dimensions'][0]); sys.exit(0 if d['value_encoding']=='binary16' else 1)"

cp "$work/demo/demo-octree.ivol" "$work/damaged.ivol"
size=$(stat -c %s "$work/damaged.ivol")
printf '\x5a' | dd of="$work/damaged.ivol" bs=1 seek=$((size / 2)) conv=notrunc status=none
case_ verify-damaged     2 "DAMAGED"                 -- "$IVOL" verify "$work/damaged.ivol"
case_ verify-names-block 2 "checksum: "              -- "$IVOL" verify "$work/damaged.ivol"
head -c $((size - 7)) "$work/demo/demo-octree.ivol" > "$work/truncated.ivol"
case_ verify-truncated   2 "truncated"               -- "$IVOL" verify "$work/truncated.ivol"
echo "hello" > "$work/text.ivol"
case_ verify-not-ivol    2 "not-ivol"                -- "$IVOL" verify "$work/text.ivol"
case_ info-not-ivol      2 "signature"               -- "$IVOL" info "$work/text.ivol"
case_ verify-mixed       2 "OK"                      -- "$IVOL" verify "$work/demo/demo-octree.ivol" "$work/text.ivol"

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
