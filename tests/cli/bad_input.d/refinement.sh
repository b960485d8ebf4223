# The refinement rule of `ivol recon --structure` (docs/refinement.md): an
# unknown rule is a bad command line, named, found before any work.
bad recon-refine-unknown    1 "--refine"               -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --structure octree --refine guess -o "$out/x.ivol"
bad recon-refine-factor     1 "--preview-factor"       -- "$IVOL" recon "$work/p.raw" "${scan[@]}" "${grid[@]}" --structure octree --refine detection --preview-factor 6 -o "$out/x.ivol"
