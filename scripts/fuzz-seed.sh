#!/usr/bin/env bash
# Seeds the fuzz targets' corpora from the shared meshes (KAC_TEST_DATA, default ../shared/data): every file of a
# reader's format (by extension) into fuzz/corpus/TARGET/, which is git-ignored (the meshes are never copied into
# the repository), plus the regression inputs for every target. Then `cd fuzz && cargo fuzz run ply` starts from
# real files instead of an empty corpus.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${KAC_TEST_DATA:-${KAC_DATA_DIR:-$(cd .. && pwd)/shared/data}}"
[ -d "$DATA" ] || { echo "no shared data at $DATA (set KAC_TEST_DATA)"; exit 1; }
declare -A EXT=( [obj]=obj [off]=off [ply]=ply [stl]=stl [gltf]="gltf glb" [medit]=mesh [gmsh]=msh [vtk]=vtk
                 [xyz]=xyz [csv]=csv [json]=json [mtx]=mtx )
total=0
for target in "${!EXT[@]}"; do
  mkdir -p "fuzz/corpus/$target"
  for ext in ${EXT[$target]}; do
    while IFS= read -r -d '' f; do
      cp "$f" "fuzz/corpus/$target/$(basename "$f")"
      total=$((total + 1))
    done < <(find "$DATA" -type f -name "*.$ext" -print0)
  done
  cp fuzz/regressions/* "fuzz/corpus/$target/" 2> /dev/null || true
done
echo "seeded $total files from $DATA into fuzz/corpus/"
