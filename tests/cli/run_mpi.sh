#!/usr/bin/env bash
# ivol recon under mpirun (docs/distributed.md): 2 and 4 ranks on this one
# machine must give the single process's file byte for byte (dense, --keep
# otsu with its distributed preview, --structure octree and nested), the
# ranks other than 0 must build the octree subtrees of their slabs (keep,
# octree) and compress blocks of it, or turn their slabs into a bricked
# grid's stored values (dense), rank 0 must receive fewer bytes than the
# float32 slabs, and a rank that fails (while reconstructing, building or
# compressing) must end the whole run with its message, a non-zero exit and
# nothing left behind. --structure octree: every rank fills and builds the
# writer's slabs it owns, and the file is the same with coarse leaves that
# reach across several ranks' slabs. $IVOL is the binary under
# test, $MPIEXEC mpirun.
set -u
: "${IVOL:?set IVOL to the ivol binary}"
: "${MPIEXEC:?set MPIEXEC to mpirun}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1  # CI runs as root
export OMPI_MCA_btl=self,vader                                   # one machine: shared memory only
export SOURCE_DATE_EPOCH=1700000000                              # the same "created" in every file
# In the sanitizer build: OpenMPI's own allocations at exit (libmpi and its
# dlopen'ed components, "<unknown module>" once unloaded) are reported as
# leaks that no suppression can name. Leaks of ivol's code are checked by
# every other test of that build.
export ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
passed=0
failed=0
ok() { echo "ok   $1"; passed=$((passed + 1)); }
fail() {
  echo "FAIL $1"
  [ -f "$work/log" ] && sed 's/^/    /' "$work/log" | head -20
  failed=$((failed + 1))
}
# No output file and no temporary of it.
nothing_left() { ! ls -A "$work" | grep -q -e "^$1\$" -e "^\.$1\.tmp-"; }

"$IVOL" -q phantom shepp-logan --views 24 --detector 48 --radius 20 -o "$work/p.h5" || {
  echo "FAIL phantom"
  exit 1
}
recon=("$IVOL" -q recon "$work/p.h5" --geometry "$work/p.xml" --pitch 1.835 --size 24 --voxel 1.6)
cd "$work" || exit 1
# A file records the command that wrote it (provenance.command): the single
# process's reference runs the very same command, in a folder of its own.
mkdir "$work/single"
reference() { (cd "$work/single" && "$@" >/dev/null); }
modes=(dense keep octree nested)
declare -A mode_args=([dense]="" [keep]="--keep threshold=otsu,margin=2" [octree]="--structure octree"
  [nested]="--structure nested --nested-cell 8")
# Thin slabs (several per rank) on the ranks.
for ranks in 2 4; do
  for mode in "${modes[@]}"; do
    name="mpi$ranks-$mode"
    # shellcheck disable=SC2206
    args=("${recon[@]}" ${mode_args[$mode]} --slab-slices 3 -o "$name.ivol")
    if reference "${args[@]}" && "$MPIEXEC" --oversubscribe -np "$ranks" "${args[@]}" >"$work/log" 2>&1 &&
      cmp "single/$name.ivol" "$name.ivol" >>"$work/log" 2>&1; then
      ok "$name same bytes as one process"
    else
      fail "$name same bytes as one process"
    fi
  done
done

# A larger octree whose coarse leaves (up to 16 slices tall) reach across
# the slabs of several ranks, on 3 ranks: every rank fills and builds the
# slabs it owns from the bricks they meet (recon_built_structure.hpp).
"$IVOL" -q phantom thin-pipe --views 48 --detector 64 -o "$work/t.h5" || echo "FAIL phantom thin-pipe"
tall=("$IVOL" -q recon "$work/t.h5" --geometry "$work/t.xml" --pitch 6.973 --size 64 --voxel 3.2 --structure octree
  --slab-slices 4 -o tall.ivol)
reference "${tall[@]}"
if "$MPIEXEC" --oversubscribe -np 3 "${tall[@]}" >"$work/log" 2>&1 && cmp single/tall.ivol tall.ivol >>"$work/log" 2>&1 &&
  "$IVOL" verify -q tall.ivol >>"$work/log" 2>&1; then
  ok "mpi3-octree-tall-leaves same bytes as one process"
else
  fail "mpi3-octree-tall-leaves same bytes as one process"
fi

# The JSON report of a distributed run names every rank, what it sent and
# how many of the file's blocks it compressed: every rank compresses some
# (dense: the whole file is compressed after the last slab arrives; octree:
# likewise; nested: as slabs finish, the others join once their slabs are
# sent, so only the total is checked). The nested grid's voxel updates are
# the single process's, not N times them (each rank counts its own); the
# octree's at least the single process's (tall leaves on several ranks).
for mode in dense keep octree nested; do
  for ranks in 2 4; do
    # shellcheck disable=SC2086
    "$MPIEXEC" --oversubscribe -np "$ranks" "${recon[@]}" ${mode_args[$mode]} --slab-slices 3 --json \
      -o "json-$mode-$ranks.ivol" >"$work/report.json" 2>"$work/log"
    # shellcheck disable=SC2086
    [ "$mode" = dense ] || [ "$mode" = keep ] || "${recon[@]}" ${mode_args[$mode]} --json -f -o "json-one-$mode.ivol" >"$work/one.json"
    if MODE=$mode RANKS=$ranks /usr/bin/python3 -c "
import json, os, sys, subprocess
mode, ranks = os.environ['MODE'], int(os.environ['RANKS'])
report = json.load(open('$work/report.json'))
r = report['ranks']
info = json.loads(subprocess.run(['$IVOL', 'info', '--json', 'json-%s-%d.ivol' % (mode, ranks)],
                                 capture_output=True, check=True).stdout)
blocks = info['blocks']
checks = [len(r) == ranks, r[1]['bytes_sent'] > 0,
          sum(k['bytes_sent'] for k in r[1:]) == r[0]['bytes_received']]
if mode == 'dense':
    # a bricked grid: the ranks send their slabs' stored 16-bit values, and
    # rank 0's writer encodes the bricks on its own threads
    checks += [info['structure'] == 'bricked', report['structure'] == 'bricked',
               sum(k['blocks_compressed'] for k in r) == 0]
else:
    # every block but the metadata block, compressed somewhere
    checks += [info['structure'] != 'bricked', sum(k['blocks_compressed'] for k in r) == blocks - 1,
               all(k['block_bytes_sent'] > 0 and k['blocks_compressed'] > 0 for k in r[1:]) or mode == 'nested']
if mode in ('dense', 'keep', 'octree'):
    # every rank built its writer slabs (the subtrees of an octree's, a
    # bricked grid's stored values), and every slice was built once
    checks += [all(k['slabs_built'] > 0 and k['build_seconds'] > 0 for k in r),
               sum(k['slices_built'] for k in r) == 24]
if mode in ('octree', 'nested'):
    one = json.load(open('$work/one.json'))
    checks += [abs(report['gups'] - sum(k['gups'] for k in r)) < 1e-9]
    if mode == 'nested':
        checks += [report['voxel_updates'] == one['voxel_updates']]
    else:
        # each rank reconstructs the bricks its slabs meet, whole: a coarse
        # leaf taller than a slab on every rank whose slab it meets
        checks += [one['voxel_updates'] <= report['voxel_updates'] <= ranks * one['voxel_updates'],
                   report['seconds']['building'] > 0]
print(checks)
sys.exit(0 if all(checks) else 1)" >>"$work/log" 2>&1; then
      ok "json-ranks-$mode-$ranks"
    else
      fail "json-ranks-$mode-$ranks"
    fi
  done
done

# What rank 0 receives: built subtrees (binary16 values and node words), or
# a bricked grid's binary16 values, fewer bytes than the float32 slices they
# were built from. The writer's own
# slabs (16 slices here, two of them): with thin slabs of tiny subtrees the
# subtrees' records would outweigh their voxels.
for mode in dense keep; do
  # shellcheck disable=SC2206
  args=("${recon[@]}" ${mode_args[$mode]} --json -o "bytes-$mode.ivol")
  reference "${args[@]}"
  "$MPIEXEC" --oversubscribe -np 2 "${args[@]}" >"$work/report.json" 2>"$work/log"
  if cmp "single/bytes-$mode.ivol" "bytes-$mode.ivol" >>"$work/log" 2>&1 && /usr/bin/python3 -c "
import json, sys
r = json.load(open('$work/report.json'))['ranks']
float32 = 24 * 24 * 4 * r[1]['slices_built']
checks = [r[1]['slabs_built'] > 0, 0 < r[0]['slab_bytes_received'] < float32,
          r[0]['slab_bytes_received'] == r[1]['slab_bytes_sent']]
print(checks, r[0]['slab_bytes_received'], float32)
sys.exit(0 if all(checks) else 1)" >>"$work/log" 2>&1; then
    ok "built-subtrees-fewer-bytes-$mode"
  else
    fail "built-subtrees-fewer-bytes-$mode"
  fi
done

# A rank that fails (a failure injected for this test through the variable
# $1) ends the run with "rank K: $2: failure injected", where @ in $2 stands
# for K; rank 0 removes its temporary file. $3 names the case, the rest are
# the modes to try.
injected_failure() {
  local variable=$1 message=$2 name=$3
  shift 3
  for mode in "$@"; do
    for ranks in 2 4; do
      victim=$((ranks - 1))
      # shellcheck disable=SC2086
      env "$variable=$victim" "$MPIEXEC" --oversubscribe -np "$ranks" "${recon[@]}" \
        ${mode_args[$mode]} --slab-slices 3 -o "$name-fails-$mode.ivol" >"$work/log" 2>&1
      status=$?
      if [ "$status" -eq 2 ] &&
        grep -qF "ivol recon: error: rank $victim: ${message//@/$victim}: failure injected" "$work/log" &&
        nothing_left "$name-fails-$mode.ivol"; then
        ok "rank-$victim-$name-fails-$mode"
      else
        fail "rank-$victim-$name-fails-$mode (exit $status)"
      fi
    done
  done
}
# While building its subtrees (its stored values, for a bricked grid), and
# while compressing blocks for rank 0 (an octree's: a bricked grid's bricks
# are encoded by rank 0's writer).
injected_failure IVOL_TEST_FAIL_BUILD_RANK "building the subtrees of slab @" build keep octree
injected_failure IVOL_TEST_FAIL_BUILD_RANK "storing the values of slab @" build dense
injected_failure IVOL_TEST_FAIL_COMPRESSION_RANK "compressing blocks for rank 0" compression keep octree

# Rank 1 reads a copy of the scan whose compressed chunks are damaged: it
# fails while reconstructing its slabs, tells rank 0, which removes its
# temporary file and ends the run with rank 1's message.
mkdir -p a b c
h5repack -l /exchange/data:CHUNK=1x48x48 -f /exchange/data:GZIP=1 p.h5 a/p.h5
cp a/p.h5 b/p.h5
/usr/bin/python3 - <<'EOF'
import h5py
with h5py.File('b/p.h5', 'r') as f:
    d = f['/exchange/data']
    chunks = [d.id.get_chunk_info(i) for i in range(d.id.get_num_chunks())]
with open('b/p.h5', 'r+b') as g:
    for c in chunks:
        g.seek(c.byte_offset + c.size // 2)
        g.write(b'\xff' * 16)
EOF
recon_in=("$IVOL" recon p.h5 --geometry "$work/p.xml" --pitch 1.835 --size 24 --voxel 1.6 --slab-slices 3)
for mode in dense octree; do
  extra=()
  [ "$mode" = octree ] && extra=(--structure octree)
  "$MPIEXEC" --oversubscribe -np 1 --wdir "$work/a" "${recon_in[@]}" "${extra[@]}" -o "$work/bad-$mode.ivol" : \
    -np 1 --wdir "$work/b" "${recon_in[@]}" "${extra[@]}" -o "$work/bad-$mode.ivol" >"$work/log" 2>&1
  status=$?
  if [ "$status" -eq 2 ] && grep -q "ivol recon: error: rank 1: p.h5: .*cannot read" "$work/log" &&
    nothing_left "bad-$mode.ivol"; then
    ok "rank-1-read-fails-$mode"
  else
    fail "rank-1-read-fails-$mode (exit $status)"
  fi
done

# Rank 1 cannot open its scan at all (before any slab): it ends the run.
"$MPIEXEC" --oversubscribe -np 1 --wdir "$work/a" "${recon_in[@]}" -o "$work/missing.ivol" : \
  -np 1 --wdir "$work/c" "${recon_in[@]}" -o "$work/missing.ivol" >"$work/log" 2>&1
status=$?
if [ "$status" -eq 2 ] && grep -q "ivol recon: rank 1: error (io): p.h5: cannot open" "$work/log" &&
  nothing_left missing.ivol; then
  ok "rank-1-open-fails"
else
  fail "rank-1-open-fails (exit $status)"
fi

# Rank 1 killed outright: mpirun ends the others, nothing is left behind.
# A larger grid in slabs of one slice, so that the run lasts long enough.
recon_long=("$IVOL" -q recon p.h5 --geometry "$work/p.xml" --pitch 1.835 --size 64 --voxel 0.6 --slab-slices 1)
"$MPIEXEC" --oversubscribe -np 2 "${recon_long[@]}" -o killed.ivol >"$work/log" 2>&1 &
launcher=$!
victim=""
for _ in $(seq 100); do
  for p in $(pgrep -P "$launcher"); do
    tr '\0' '\n' <"/proc/$p/environ" 2>/dev/null | grep -q '^OMPI_COMM_WORLD_RANK=1$' && victim=$p
  done
  [ -n "$victim" ] && break
  sleep 0.05
done
[ -n "$victim" ] && sleep 0.3 && kill -9 "$victim" 2>/dev/null
wait "$launcher"
status=$?
if [ -z "$victim" ]; then
  fail "rank-1-killed: rank 1 never started"
elif [ "$status" -eq 0 ]; then
  echo "note rank-1-killed: the run ended before rank 1 could be killed; not checked"
elif nothing_left killed.ivol; then
  ok "rank-1-killed (exit $status)"
else
  fail "rank-1-killed (exit $status)"
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
