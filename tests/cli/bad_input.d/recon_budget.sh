# recon's memory budget (issue 23): parts that cannot fit their share of
# --memory are refused with limit-exceeded, naming the bytes: the detection
# preview's ring and packed mask (before any reconstruction), the
# structure's values in flight even with one-slice slabs (--device-memory
# keeps the device's slabs out of the budget, so that the window decides).
bad recon-budget-preview-floor 2 "detection preview: its memory budget of 262144 bytes is below the" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 1024 --voxel 0.02 --structure octree --memory 1 --no-disk-check -o "$out/x.ivol"
bad recon-budget-preview-floor-sizes 2 "4 slices of 512x512 cells, a need mask of 1 bit per cell: 16777216 bytes" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 1024 --voxel 0.02 --structure octree --memory 1 --no-disk-check -o "$out/x.ivol"
bad recon-budget-value-window 2 "(limit-exceeded): FDK: the structure's values and tasks in flight need 572384 bytes with one-slice slabs and the writer's slabs of 8 slices, over their memory budget of" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 64 --voxel 0.4 --structure octree --memory 1 --device-memory 8 -o "$out/x.ivol"
# A device budget too small for one slice: limit-exceeded naming the options
# that set it (it was a bare error with no class, naming neither).
bad recon-budget-one-slice 2 "(limit-exceeded): FDK: even one slice of 128x128 voxels needs 1312512 bytes" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 128 --voxel 0.1 --device-memory 1 -o "$out/x.ivol"
bad recon-budget-one-slice-options 2 "allowed (--device-memory; a CPU device's share of --memory)" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 128 --voxel 0.1 --device-memory 1 -o "$out/x.ivol"
