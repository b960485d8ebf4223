# Salvage of a cut file (format 1.3 framed blocks, spec §18): extract
# --salvage writes what survived, fills the rest from coarser levels and
# lists it (exit 3); plain extract refuses the cut file as truncated; info and
# verify say what could be salvaged and still fail; a cut 1.2 file (no
# framing) cannot be salvaged, and extract says why.
# (an octree of small blocks: what is lost is filled from its stored averages)
"$IVOL" -q convert "$work/v.raw" "$work/salvage-whole.ivol" --dims 16,16,16 --block-size 512 --structure octree
whole=$(stat -c %s "$work/salvage-whole.ivol")
head -c $((whole * 2 / 3)) "$work/salvage-whole.ivol" > "$work/salvage-cut.ivol"
"$IVOL" -q convert "$work/v.raw" "$work/salvage-v12.ivol" --dims 16,16,16 --format-version 1.2
head -c 2000 "$work/salvage-v12.ivol" > "$work/salvage-v12-cut.ivol"
bad salvage-extract-cut     3 "were not found"         -- "$IVOL" extract "$work/salvage-cut.ivol" --salvage --box 0,0,0,16,16,16 -o "$work/salvaged.raw"
bad salvage-extract-size    0 ""                       -- test "$(stat -c %s "$work/salvaged.raw")" -eq 16384
bad salvage-extract-plain   2 "truncated"              -- "$IVOL" extract "$work/salvage-cut.ivol" --box 0,0,0,16,16,16 -o "$out/x.raw"
bad salvage-verify-cut      2 "complete down to level of detail" -- "$IVOL" verify "$work/salvage-cut.ivol"
bad salvage-info-cut        2 "salvaged from its blocks" -- "$IVOL" info "$work/salvage-cut.ivol"
bad salvage-unframed        2 "not framed"             -- "$IVOL" extract "$work/salvage-v12-cut.ivol" --salvage --box 0,0,0,16,16,16 -o "$out/x.raw"
bad salvage-format-version  1 "--format-version"       -- "$IVOL" convert "$work/v.raw" "$out/x.ivol" --dims 16,16,16 --format-version 1.1
