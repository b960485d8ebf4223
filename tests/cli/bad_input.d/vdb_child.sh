# OpenVDB input is read by libopenvdb in a child process (issue 17): a
# 10 KB file whose blosc block header claims 64 GiB (found by fuzz_vdb) makes
# libopenvdb allocate it. The child's address-space limit refuses it (twice
# --memory, default 2 x 2048 MiB): limit-exceeded naming the file and the
# grid, the child's limit named (the error came from there, not from this
# process, which runs under a 2 GiB cap here), nothing written.
vdb_child_here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
vdb_child_findings="$vdb_child_here/../../fuzz/regressions/vdb"
cp "$vdb_child_findings/vdb-blosc-64gib-density-allocation" "$work/vdb-child-density.vdb"
cp "$vdb_child_findings/vdb-blosc-64gib-allocation" "$work/vdb-child-tiles.vdb"
if [ "${IVOL_SANITIZED:-0}" != 1 ]; then
  bad vdb-child-blosc-64gib 2 "(limit-exceeded): $work/vdb-child-density.vdb: grid 'density': libopenvdb could not allocate" -- \
    timeout 60 prlimit --as=2147483648 "$IVOL" convert "$work/vdb-child-density.vdb" "$out/x.ivol"
  bad vdb-child-limit-default 2 "the process that runs the library may allocate 4096 MiB" -- \
    timeout 60 "$IVOL" convert "$work/vdb-child-density.vdb" "$out/x.raw"
  bad vdb-child-limit-memory 2 "the process that runs the library may allocate 128 MiB" -- \
    timeout 60 "$IVOL" convert "$work/vdb-child-tiles.vdb" "$out/x.ivol" --memory 64
else
  # ASan's operator new aborts on the request: the child dies, which is an
  # error naming the file, not the end of ivol.
  bad vdb-child-blosc-64gib 2 "$work/vdb-child-density.vdb" -- \
    timeout 60 "$IVOL" convert "$work/vdb-child-density.vdb" "$out/x.ivol"
fi
# A 19 KB grid whose blosc block makes libopenvdb 10 write past its buffer
# (found by fuzz_converters, 2026-12-02; under valgrind: an invalid write in
# bloscFromStream; in a release build glibc aborts on the damaged heap). In
# the child that is an error naming the file, and nothing is written.
cp "$vdb_child_here/../../fuzz/regressions/libopenvdb/vdb-blosc-heap-overflow" "$work/vdb-child-overflow.vdb"
bad vdb-child-heap-overflow 2 "$work/vdb-child-overflow.vdb: libopenvdb crashed" -- \
  timeout 60 "$IVOL" convert "$work/vdb-child-overflow.vdb" "$out/x.raw"
