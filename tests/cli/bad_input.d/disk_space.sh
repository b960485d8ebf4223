# Disk space (README, "Disk a run needs"): a conversion or reconstruction
# whose disks lack the room estimated from the volume is refused before any
# work, naming the directory, the bytes needed and the bytes available; a
# spill directory that cannot be used is refused too. IVOL_TEST_FREE_BYTES
# stands for every filesystem's free bytes; a small tmpfs checks the real
# statvfs where one can be mounted.
ds="$work/disk_space"
mkdir -p "$ds"
# 16^3 float32 as an octree (--structure octree; auto would write a bricked
# grid, which has no spill): 16 KiB of values for the file and as much for
# the spill.
bad disk-space-convert 2 "$out: not enough free disk for this run: it needs about 32.0 KiB (32768 bytes: the output" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --structure octree
bad disk-space-convert-free 2 "its filesystem has 1000 bytes (1000 bytes) available" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --structure octree
bad disk-space-convert-temp-hint 2 "available (--temp-dir puts the temporary files on another disk; --no-disk-check" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --structure octree
bad disk-space-recon 2 "$out: not enough free disk for this run" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel 0.4 -o "$out/x.ivol"
# A dense recon writes a bricked grid: no spill, no temporary files, so no
# --temp-dir to suggest.
bad disk-space-recon-no-temp-hint 2 "bytes) available (--no-disk-check skips this estimate)" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel 0.4 -o "$out/x.ivol"
bad disk-space-recon-structure 2 "not enough free disk" -- \
  env IVOL_TEST_FREE_BYTES=1000 "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel 0.4 --structure octree -o "$out/x.ivol"
bad temp-dir-missing-convert 2 "$ds/nowhere: cannot write the octree writer's spill file there" -- \
  "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --structure octree --temp-dir "$ds/nowhere"
# (--keep: an octree; a dense recon without it is a bricked grid, with no spill)
bad temp-dir-missing-recon 2 "$ds/nowhere: cannot write the octree writer's spill file there" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 16 --voxel 0.4 --keep threshold=otsu,margin=2 -o "$out/x.ivol" \
  --temp-dir "$ds/nowhere"
bad tmpdir-missing-convert 2 "$ds/nowhere: cannot write the octree writer's spill file there" -- \
  env TMPDIR="$ds/nowhere" "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --structure octree
# The real free space: a 256 KiB tmpfs as the spill directory of a 256 KiB
# (64^3 u16) octree; --no-disk-check lets the same run fail on the full disk
# instead, leaving nothing.
ds_small="$ds/small"
mkdir -p "$ds_small"
if mount -t tmpfs -o size=256k tmpfs "$ds_small" 2>/dev/null; then
  head -c $((2 * 64 * 64 * 64)) /dev/urandom > "$ds/noise16.raw"
  bad disk-space-tmpfs-spill 2 "$ds_small: not enough free disk for this run: it needs about 512.0 KiB (524288 bytes: the octree writer" -- \
    "$IVOL" convert "$ds/noise16.raw" "$out/x.ivol" --dims 64,64,64 --type u16 --structure octree --temp-dir "$ds_small"
  bad disk-space-tmpfs-unchecked 2 "No space left" -- \
    "$IVOL" convert "$ds/noise16.raw" "$out/x.ivol" --dims 64,64,64 --type u16 --structure octree --temp-dir "$ds_small" --no-disk-check
  # The detection preview's cells beyond its quarter of a 4 MiB --memory
  # spill (compressed) to the same full tmpfs: an io error naming the
  # directory, no output, nothing left in the tmpfs.
  rm -f "$out/x.ivol"
  bad disk-space-tmpfs-preview-spill 2 "error (io): the detection preview's cells: writing the temporary file in '$ds_small' failed: No space left on device" -- \
    "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 256 --voxel 0.09 --structure octree --memory 4 -o "$out/x.ivol" --temp-dir "$ds_small" --no-disk-check
  if [ -e "$out/x.ivol" ]; then
    echo "FAIL disk-space-tmpfs-preview-output: $out/x.ivol was left behind"
    failed=$((failed + 1))
  fi
  if [ -n "$(ls -A "$ds_small")" ]; then
    echo "FAIL disk-space-tmpfs-clean: the spill directory holds $(ls -A "$ds_small" | tr '\n' ' ')"
    failed=$((failed + 1))
  fi
  umount "$ds_small"
else
  echo "skipped disk-space tmpfs cases: cannot mount a tmpfs here (needs root or CAP_SYS_ADMIN)"
fi
