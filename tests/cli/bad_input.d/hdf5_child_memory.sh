# recon's HDF5 projections are read in libhdf5's child process, which may
# allocate recon's --memory (it had a fixed 1 GiB whatever --memory said;
# issue 17, item 14): 4 views of 4x4 stored in one gzip chunk of 256 MiB
# (a 1.2 MB file) end in limit-exceeded naming the file under --memory 64,
# and reconstruct under the default --memory 1024.
chunked="$work/chunked"
mkdir -p "$chunked"
if [ "${IVOL_SANITIZED:-0}" = 1 ]; then
  echo "skipped recon-hdf5-child-memory: the libhdf5 child has no address-space limit in the sanitizer build"
elif /usr/bin/python3 "$(dirname "${BASH_SOURCE[0]}")/make_huge_chunk_scan_h5.py" "$chunked/scan-chunk.h5" 256; then
  chunk_recon=(recon "$chunked/scan-chunk.h5" --sid 600 --sdd 1200 --pitch 1.5 --size 4 --voxel 1.5)
  bad recon-hdf5-chunk-limit   2 "error (limit-exceeded): $chunked/scan-chunk.h5: dataset /exchange/data" -- \
    timeout 60 "$IVOL" "${chunk_recon[@]}" --memory 64 -o "$out/x.ivol"
  bad recon-hdf5-chunk-names-limit 2 "may allocate 64 MiB" -- timeout 60 "$IVOL" "${chunk_recon[@]}" --memory 64 -o "$out/x.ivol"
  bad recon-hdf5-chunk-within-memory 0 "4x4x4 voxels from 4 views" -- \
    timeout 60 "$IVOL" "${chunk_recon[@]}" -o "$chunked/x.ivol"
else
  echo "FAIL recon-hdf5-child-memory: cannot make the file (h5py)"
  failed=$((failed + 1))
fi
rm -rf "$chunked"
