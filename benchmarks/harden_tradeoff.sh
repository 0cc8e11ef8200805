#!/usr/bin/env bash
# Issue 29: the trade-off of each hardening try (each round's weights): nominal survival on the validation seeds
# paired with v9, against a quick roll screen on the before/after audit's 50 images (seed 0), paired with v9 too.
#
#   nominal  benchmarks/detector_protocol.py --split validation --compare v9 (2040 approaches, exact McNemar)
#   screen   reproduce spatial-1d --methods georobust-av --max-evals 30 --grid-step 1 (the roll boxes ±2…±30°, 30
#            evaluations per box and a 1° reference grid over ±30°): far fewer evaluations than the full before/after
#            audit (benchmarks/measure_harden.sh), so it finds fewer breaches — a ranking of the tries, not their
#            robustness figures. v9 is screened the same way.
# The tries: `vbl-robust harden $COMMON <the try's options> --out <its folder>` (TRIES below; try1 is the
# pre-registered run of benchmarks/measure_harden.sh). Outputs in results/harden/tradeoff/ (TRY_rN_nominal.txt,
# TRY_rN_validation.json, screen_TRY_rN_compare.md); a try whose outputs are all there is skipped, so a new checkout
# runs only the tries it lacks (training included: harden resumes its rounds). Stores stay in runs/harden/tradeoff/.
# Run it alone on the machine: bash benchmarks/harden_tradeoff.sh
set -euo pipefail
export OMP_NUM_THREADS=1 YOLO_OFFLINE=1 YOLO_VERBOSE=False MPLBACKEND=Agg
VR=${VR:-.venv/bin/vbl-robust}
PY=${PY:-.venv/bin/python}
OUT=${OUT:-runs/harden/tradeoff}
RES=${RES:-results/harden/tradeoff}
mkdir -p "$OUT" "$RES"
SCREEN=(spatial-1d --images 50 --methods georobust-av --max-evals 30 --grid-step 1 --workers 2 -q)
V9_PROTOCOL=results/detector_candidates/protocol_v9_validation.json
COMMON=(--rounds 2 --k 8 --epochs 2 --n-train 300 --n-val 60)
TRIES=(  # name|training folder|the try's own harden options
  "try1|train_runs/harden_roll30|--perturb roll_deg=-30,30 --threads 1"
  "try2|train_runs/harden_roll30_shipped|--perturb roll_deg=-30,30 --data shipped --threads 2"
  "try3|train_runs/harden_roll15_shipped|--perturb roll_deg=-15,15 --data shipped --threads 2"
)

for spec in "${TRIES[@]}"; do
  IFS='|' read -r name dir opts <<< "$spec"
  todo=0
  for r in 0 1; do
    for f in "${name}_r${r}_validation.json" "screen_${name}_r${r}_compare.md"; do [ -f "$RES/$f" ] || todo=1; done
  done
  [ $todo = 1 ] || { echo "$name: done (outputs in $RES)"; continue; }
  # shellcheck disable=SC2086
  $VR harden $opts "${COMMON[@]}" --out "$dir"
  $VR reproduce "${SCREEN[@]}" --model default --out "$OUT/screen_v9"
  for r in 1 0; do
    tag=${name}_r$r
    W=$($PY -c "import json, os, sys; print(os.path.abspath(json.load(open(sys.argv[1]))['weights']))" "$dir/round0$r/round.json")
    [ -f "$RES/${tag}_validation.json" ] || (cd benchmarks && ../$PY detector_protocol.py --model "$W" --split validation \
      --json "../$RES/${tag}_validation.json" --compare "../$V9_PROTOCOL") > "$RES/${tag}_nominal.txt"
    $VR reproduce "${SCREEN[@]}" --model "$W" --trust-model --detector twostage --out "$OUT/screen_$tag"
    $VR report "$OUT/screen_v9" --format md --compare "$OUT/screen_$tag" > "$RES/screen_${tag}_compare.md"
    echo "$tag: $(grep '^| pooled' "$RES/${tag}_nominal.txt")"
    grep -E '^\| georobust-av \| ±(2|15|30)° \| all ' "$RES/screen_${tag}_compare.md" || true
  done
done
