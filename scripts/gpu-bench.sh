#!/usr/bin/env bash
# The whole benchmark suite in one run, for a machine with a GPU (and, smaller, for checking the
# script on the software driver): every part writes its own CSV and charts under OUT/<part>/,
# and OUT/suite.csv gathers them all in long form (part,file,row,column,value), one line per
# figure, so two machines' runs can be compared with one join. Sized to finish in a few minutes
# on a GPU; the device's name and the FMA peak of the same run are in every part's output.
#
#   bash scripts/gpu-bench.sh [OUT=out/gpu-bench] [SIZE=full|small]
#
# VALGI=path runs a valgi binary built elsewhere instead of building one (a machine without a
# Rust toolchain); SPONZA=file and RGBD=folder point at copies of the shared data; PARTS="a b"
# runs only the parts named (a rerun after a change).
#
# Parts:
#   table1   the paper's Table 1 grid (16k/64k/512k VALs × 4k/16k points) at 1920×1080, the
#            per-stage split (Table 2 rows), pairs/s and % of the FMA peak, brute force, and
#            the gather's VAL slices and tile size swept at 16k VALs
#   scenes   the gather's pair rate on the door room and on Sponza (sun, 256²), no brute force
#   lookup-switch, lookup-tree
#            the default frame (16k VALs, 4k points, W×H) with the gather's cluster-visibility
#            lookup as a switch and as a select tree (`--visibility-lookup`): `auto` takes the
#            switch on a GPU and the tree on a CPU device; these two say whether a GPU agrees
#   views    one lighting solution shared by 1–8 views against one view per solution
#   mr       one full 640×480 RGB-D frame (every pixel a VAL) lighting the bunny, per pass
#   negative seed 002's Table 1 (frame time per N+M on bunny-box)
#   eval     speed against indirect error of every method on cornell, corridor and the door
#            room (the Pareto charts), LPV against HO-LPV at the same grid and steps
# SIZE=small shrinks every image and grid so that the suite also finishes on lavapipe
# (it checks the script, not the device).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/gpu-bench}
SIZE=${2:-full}
case "$SIZE" in
full)
    W=1920 H=1080 VALS=16384,65536,524288 POINTS=4096,16384 SMALL=512 SLICES=1,16,64,256 TILES=64,256
    SCENE_W=256 VIEWS=1,2,4,8 LARGE=3840x2160 EVAL_W=256 EVAL_H=256 SPP=256
    ;;
small)
    W=160 H=90 VALS=4096 POINTS=1024 SMALL=64 SLICES=1,4 TILES=64
    SCENE_W=64 VIEWS=1,2 LARGE=320x180 EVAL_W=64 EVAL_H=64 SPP=16
    ;;
*)
    echo "gpu-bench: SIZE must be full or small, not '$SIZE'" >&2
    exit 2
    ;;
esac
mkdir -p "$OUT"
if [ -z "${VALGI:-}" ]; then
    cargo build --release --quiet --bin valgi
    VALGI=target/release/valgi
fi
SPONZA=${SPONZA:-../shared/data/sponza/Sponza.gltf}
RGBD=${RGBD:-../shared/data/rgbd/RGBD}
start=$(date +%s)

part() {
    local name=$1
    shift
    if [ -n "${PARTS:-}" ] && [[ " $PARTS " != *" $name "* ]]; then
        echo "== $name: skipped (not in PARTS)"
        return
    fi
    local t0
    t0=$(date +%s)
    echo "== $name: $*"
    if ! "$VALGI" "$@" >"$OUT/$name.log" 2>&1; then
        tail -5 "$OUT/$name.log" >&2
        echo "gpu-bench: part '$name' failed; its log is $OUT/$name.log" >&2
        exit 1
    fi
    # The figures, without the log lines (warnings, progress).
    grep -v '^\[' "$OUT/$name.log" || true
    echo "== $name: $(($(date +%s) - t0)) s"
}

part table1 bench --width "$W" --height "$H" --vals "$VALS" --points "$POINTS" \
    --small "$SMALL" --gather-slices "$SLICES" --tiles "$TILES" --out "$OUT/table1"
part door bench --scene door-room --width "$SCENE_W" --height "$SCENE_W" --vals 16384 \
    --points 4096 --small 64 --no-brute --out "$OUT/door"
if [ -f "$SPONZA" ]; then
    part sponza bench --scene "$SPONZA" --light sun:-0.3,-1,-0.2,5 \
        --camera-eye -11,1.8,-0.4 --camera-target 10,3.5,-0.4 --fov 60 \
        --width "$SCENE_W" --height "$SCENE_W" --vals 16384 --points 4096 --small 64 \
        --no-brute --out "$OUT/sponza"
else
    echo "== sponza: skipped ($SPONZA not found)"
fi
for lookup in switch tree; do
    part "lookup-$lookup" render --scene cornell --method sparse --sparse-points 4096 --rsm 160 \
        --width "$W" --height "$H" --frames 5 --no-write --visibility-lookup "$lookup"
done
part views bench --views "$VIEWS" --large "$LARGE" --width "$EVAL_W" --height "$EVAL_H" \
    --out "$OUT/views"
if [ -d "$RGBD" ]; then
    part mr mr --rgbd "$RGBD" --frames 0..3 --out "$OUT/mr"
    # What the full sensor frame is compared with: a 64k-VAL frame at the same size and
    # point count (cornell's spot light lights 60 % of its 328² RSM: 64,438 VALs).
    part mr64k render --scene cornell --method sparse --sparse-points 1024 --rsm 328 \
        --width 640 --height 480 --frames 4 --no-write --out "$OUT/mr64k"
else
    echo "== mr: skipped ($RGBD not found)"
fi
part negative negative-bench --width "$EVAL_W" --height "$EVAL_H" --frames 3 --out "$OUT/negative"
part eval eval --scenes cornell,corridor,door-room --width "$EVAL_W" --height "$EVAL_H" \
    --ref-spp "$SPP" --frames 3 --out "$OUT/eval" \
    --methods direct,sparse,sparse:occlusion=sum,brute,lpv:steps=16,holpv:steps=16,negative,reference

# Long form: part,file,row,column,value for every cell of every CSV (quoted fields kept whole).
{
    echo "part,file,row,column,value"
    find "$OUT" -mindepth 2 -name '*.csv' | sort | while read -r csv; do
        rel=${csv#"$OUT"/}
        awk -v part="${rel%%/*}" -v file="${rel#*/}" '
            function split_csv(line, out,    n, i, c, field, quoted) {
                n = 0; field = ""; quoted = 0
                for (i = 1; i <= length(line); i++) {
                    c = substr(line, i, 1)
                    if (c == "\"") { quoted = !quoted; field = field c }
                    else if (c == "," && !quoted) { out[++n] = field; field = "" }
                    else { field = field c }
                }
                out[++n] = field
                return n
            }
            NR == 1 { columns = split_csv($0, header); next }
            {
                n = split_csv($0, cell)
                for (i = 1; i <= n && i <= columns; i++)
                    if (cell[i] != "") print part "," file "," NR - 1 "," header[i] "," cell[i]
            }' "$csv"
    done
} >"$OUT/suite.csv"
echo "gpu-bench: $(($(wc -l <"$OUT/suite.csv") - 1)) figures in $OUT/suite.csv, charts:"
find "$OUT" -name '*.png' -path '*_pareto.png' -o -name '*.png' -path '*views*' | sort
echo "gpu-bench: $(($(date +%s) - start)) s in all"
