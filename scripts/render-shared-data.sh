#!/usr/bin/env bash
# Renders every asset in ../shared/data (files nobody here authored) with the one command the
# README documents for it, and prints a table: file, method, wall time, mean linear luminance
# and dark-pixel fraction (from each render's JSON line). A black or failed render shows as
# such; the images are left in OUT for a look.
#
#   bash scripts/render-shared-data.sh [OUT=out/shared-data] [WIDTH=320] [HEIGHT=240]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/shared-data}
W=${2:-320}
H=${3:-240}
D=../shared/data
[ -d "$D" ] || { echo "error: $D not found (the shared data sits beside the project)" >&2; exit 1; }
mkdir -p "$OUT"
cargo build --release --quiet --bin valgi
VALGI=target/release/valgi
SIZE="--width $W --height $H --auto-exposure"

# name | valgi arguments (a scene file and what it needs: lights, camera, method)
JOBS=(
  "bunny|render --scene $D/bunny/bun_zipper.ply --light headlight:2"
  "bunny-res2|render --scene $D/bunny/bun_zipper_res2.ply --light headlight:2"
  "bunny-res4|render --scene $D/bunny/bun_zipper_res4.ply --light headlight:2"
  "damaged-helmet|render --scene $D/gltf-samples/DamagedHelmet/DamagedHelmet.glb --light headlight:30"
  "metal-rough-spheres|render --scene $D/gltf-samples/MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb --method direct --light headlight:30"
  "specular-test|render --scene $D/gltf-samples/SpecularTest/SpecularTest.glb --light headlight:30"
  "emissive-strength|render --scene $D/gltf-samples/EmissiveStrengthTest/EmissiveStrengthTest.glb"
  "environment-test|render --scene $D/gltf-samples/EnvironmentTest/glTF/EnvironmentTest.gltf --light sun:-0.3,-0.6,-1,3"
  "clear-coat|render --scene $D/gltf-samples/ClearCoatTest/ClearCoatTest.glb --light headlight:30"
  "sponza|render --scene $D/sponza/Sponza.gltf --light sun:-0.3,-1,-0.2,5 --camera-eye -11,1.8,-0.4 --camera-target 10,3.5,-0.4 --fov 60"
  "veach-ajar|render --scene $D/veach-ajar/scene.xml"
  "cornell-measured|render --scene $D/cornell-measured/cbox.xml"
  "cornell-measured-rgb|render --scene $D/cornell-measured/cbox-rgb.xml"
  "cornell-measured-spectral|render --scene $D/cornell-measured/cbox-spectral.xml"
)

printf '| file | command | wall (s) | mean luminance | dark pixels |\n|---|---|---|---|---|\n'
failed=0
for job in "${JOBS[@]}"; do
  name=${job%%|*}
  args=${job#*|}
  start=$(date +%s.%N)
  # shellcheck disable=SC2086 # the argument strings are split on purpose
  if $VALGI $args $SIZE --out "$OUT/$name.png" >"$OUT/$name.json" 2>"$OUT/$name.log"; then
    wall=$(echo "$(date +%s.%N) - $start" | bc)
    mean=$(sed -n 's/.*"mean_luminance":\[\([^],]*\).*/\1/p' "$OUT/$name.json")
    dark=$(sed -n 's/.*"dark_fraction":\[\([^],]*\).*/\1/p' "$OUT/$name.json")
    printf '| %s | `valgi %s` | %.1f | %s | %s |\n' "$name" "$args" "$wall" "$mean" "$dark"
  else
    failed=$((failed + 1))
    printf '| %s | `valgi %s` | failed | see %s | |\n' "$name" "$args" "$OUT/$name.log"
  fi
done

# The depth-sensor frames: a virtual object lit by the real room (mixed_reality/README.md).
start=$(date +%s.%N)
if $VALGI mr --rgbd "$D/rgbd/RGBD" --intrinsics "$D/rgbd/camera_primesense.json" --scale 2.5 \
    --light point:-1.5,1.2,2.0:1.5 --out "$OUT/mr" >"$OUT/mr.json" 2>"$OUT/mr.log"; then
  printf '| rgbd | `valgi mr --rgbd %s/rgbd/RGBD …` | %.1f | (composites in %s/mr) | |\n' \
    "$D" "$(echo "$(date +%s.%N) - $start" | bc)" "$OUT"
else
  failed=$((failed + 1))
  printf '| rgbd | `valgi mr --rgbd …` | failed | see %s/mr.log | |\n' "$OUT"
fi
exit $((failed > 0))
