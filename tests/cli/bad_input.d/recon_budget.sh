# recon's memory budget (issue 23): parts that cannot fit their share of
# --memory are refused with limit-exceeded, naming the bytes: the detection
# preview's ring and packed mask (before any reconstruction), the
# structure's values in flight even with one-slice slabs.
bad recon-budget-preview-floor 2 "detection preview: its memory budget of 262144 bytes is below the" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 1024 --voxel 0.02 --structure octree --memory 1 --no-disk-check -o "$out/x.ivol"
bad recon-budget-preview-floor-sizes 2 "6 slices of 512x512 cells, a need mask of 1 bit per cell: 16777216 bytes" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 1024 --voxel 0.02 --structure octree --memory 1 --no-disk-check -o "$out/x.ivol"
bad recon-budget-value-window 2 "with one-slice slabs and the writer's slabs of 16 slices, over their memory budget of 262144 bytes" -- \
  "$IVOL" recon "$work/p.raw" "${scan[@]}" --size 64 --voxel 0.4 --structure octree --memory 1 -o "$out/x.ivol"
