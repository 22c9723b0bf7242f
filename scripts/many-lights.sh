#!/usr/bin/env bash
# The Cornell box lit by N point lights on a 10×10×(N/100) lattice under the ceiling (one
# --light each), rendered by every method, with the default budgets (--shadow-memory,
# --max-vals): prints a table of wall time, GPU bytes and the render's mean luminance, and
# keeps each render's log (the budget warnings name how many lights lost resolution or
# shadows or RSM resolution). SPREAD > 1 makes the brightest light SPREAD times the dimmest
# (intensities geometric in the light's index, 0.5 W/sr in all), so the budgets share by power.
#
#   bash scripts/many-lights.sh [N=1000] [OUT=out/many-lights] [SIZE=128] [METHODS="direct sparse"] [SPREAD=1]
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-1000}
OUT=${2:-out/many-lights}
SIZE=${3:-128}
METHODS=${4:-direct sparse brute lpv negative}
SPREAD=${5:-1}
mkdir -p "$OUT"
cargo build --release --quiet --bin valgi
VALGI=target/release/valgi

# Lattice inside the box (x 0..0.556 m, z 0..0.559 m), 0.36–0.52 m high: above the blocks.
mapfile -t LIGHTS < <(awk -v n="$N" -v spread="$SPREAD" 'BEGIN {
  layers = int((n + 99) / 100)
  # Weights spread^(i/(n-1)), normalized to 0.5 W/sr in all.
  total = 0
  for (i = 0; i < n; i++) { w[i] = spread ^ (n > 1 ? i / (n - 1) : 0); total += w[i] }
  for (i = 0; i < n; i++) {
    a = i % 10; b = int(i / 10) % 10; c = int(i / 100)
    printf "--light\npoint:%.4f,%.4f,%.4f,%.6g\n", 0.05 + 0.05 * a, 0.36 + 0.16 * c / layers, 0.05 + 0.05 * b, 0.5 * w[i] / total
  }
}')

printf '| method | lights | wall (s) | GPU MB | mean luminance | budget notes |\n|---|---|---|---|---|---|\n'
failed=0
for method in $METHODS; do
  start=$(date +%s.%N)
  if RUST_LOG=info $VALGI render --scene cornell --method "$method" "${LIGHTS[@]}" \
      --width "$SIZE" --height "$SIZE" --auto-exposure --out "$OUT/$method.png" \
      >"$OUT/$method.json" 2>"$OUT/$method.log"; then
    wall=$(echo "$(date +%s.%N) - $start" | bc)
    mean=$(sed -n 's/.*"mean_luminance":\[\([^],]*\).*/\1/p' "$OUT/$method.json")
    bytes=$(sed -n 's/.*"gpu_bytes":\([0-9]*\).*/\1/p' "$OUT/$method.json")
    notes=$(grep -oE "[0-9]+ of [0-9]+ lights (are unshadowed|have shadow maps below[^,]*|get smaller RSMs by power \(down to [0-9]+²)" \
      "$OUT/$method.log" | sort -u | paste -sd ';' -)
    printf '| %s | %s | %.1f | %s | %s | %s |\n' "$method" "$N" "$wall" \
      "$(( ${bytes:-0} / 1000000 ))" "$mean" "$notes"
  else
    failed=$((failed + 1))
    printf '| %s | %s | failed | | | see %s |\n' "$method" "$N" "$OUT/$method.log"
  fi
done
exit $((failed > 0))
