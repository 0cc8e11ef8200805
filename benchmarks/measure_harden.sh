#!/usr/bin/env bash
# Issue 29: harden the shipped detector (v9) against camera roll, then measure it before / after, paired per image.
#
# Fixed before any hardening run (2026-12-03, session 32), so that no choice is made on the figures it produces:
#   training   roll ±30° (the largest 1-D box the audit reads), worst of k = 8 per image (plus the image's previous
#              worst), 2 rounds × 2 epochs, 300 approaches of detect.protocol.HARDEN_SEED (their own airports) with
#              their clean views, 60 clean validation approaches, v9's own recipe (detect.train.FINE_TUNE); the
#              weights of the last round.
#   nominal    benchmarks/detector_protocol.py on every seed (the model card's figures need the test seeds); the
#              four validation seeds (2040 approaches) paired with v9's committed results (exact McNemar): the goal
#              is p >= 0.05 and no worse than -1 point. Then shipped beside v9 (ship --as hardened; it replaces
#              nothing) and audited as --model hardened.
#   spatial-1d the paper's experiment (roll ±2…±30°, georobust / georobust-av / random / apgd, dense-grid truth) on
#              the first 50 images of seed 0 with the hardened model; "before" is the paper run's v9 store on the
#              same images (runs/paper/spatial-1d, unpacked from its committed bundle results/paper on a new checkout).
#   2-D box    roll ±15° × contrast [0.7, 1.4], the four methods, 200 evaluations with early stop, 50 images of
#              seed 0, both models.
#   transfer   brightness [-0.2, 0.2] (never trained on), the same way, both models.
# Every step resumes when the script is run again (the stores and the harden rounds are resumable), on this checkout
# or a new one: each audit's store is packed into results/harden/audits/<run>/ (`vbl-robust bundle --stores`, after
# each step, and by hand before a session stops: the KEEP line below) and a checkout without the run restores it from
# there (`vbl-robust merge`). One thread per process; run it alone on the machine (it is CPU-bound for hours).
#   bash benchmarks/measure_harden.sh
#   .venv/bin/vbl-robust bundle runs/harden/audits --out results/harden/audits --stores   # KEEP: pack what is done
set -euo pipefail
export OMP_NUM_THREADS=1 YOLO_OFFLINE=1 YOLO_VERBOSE=False MPLBACKEND=Agg
VR=${VR:-.venv/bin/vbl-robust}
PY=${PY:-.venv/bin/python}
H=${H:-train_runs/harden_roll30}
OUT=${OUT:-runs/harden/audits}
KEEP=${KEEP:-results/harden/audits}
RES=results/harden
N=50
METHODS=georobust,georobust-av,random,apgd
mkdir -p "$OUT" "$KEEP"
# seed a run directory of this checkout from its packed store ($1: packed store, $2: run directory) when it has none
restore() { if [ -f "$1" ] && [ ! -f "$2/results.sqlite" ]; then $VR merge "$1" --into "$2"; fi; }
keep() { $VR bundle "$OUT" --out "$KEEP" --stores; }

# 1.-2. training, nominal accuracy on every protocol seed (the validation seeds paired with v9), shipped beside v9 as
# `hardened` version 1; skipped where the model is shipped and measured ($RES/protocol_all.json, $RES/nominal.txt)
if [ ! -f src/vbl_robust/models/hardened/runway_yolov8n_pose.pt ] || [ ! -f "$RES/protocol_all.json" ]; then
  $VR harden --perturb roll_deg=-30,30 --rounds 2 --k 8 --epochs 2 --n-train 300 --n-val 60 --threads 1 --out "$H"
  # the last round's weights, as an absolute path (round.json may hold either; the protocol runs from benchmarks/)
  W=$($PY -c "import json, os, sys; print(os.path.abspath(json.load(open(sys.argv[1]))['weights']))" "$H/round01/round.json")
  (cd benchmarks && ../$PY detector_protocol.py --model "$W" --split all --json "../$RES/protocol_all.json" \
    --compare ../results/detector_candidates/protocol_v9_validation.json) | tee "$RES/nominal.txt"
  $VR ship "$W" --as hardened --version 1 --epochs 52 --protocol "$RES/protocol_all.json" --trust-model
fi
HARDENED=(--model hardened)
# "before": the paper run's v9 store of spatial-1d, unpacked from its committed bundle on a checkout without it
restore results/paper/spatial-1d/results.sqlite.xz runs/paper/spatial-1d
for run in spatial-1d box2d_v9 box2d_hardened transfer_v9 transfer_hardened; do
  restore "$KEEP/$run/results.sqlite.xz" "$OUT/$run"
done

# 3. spatial-1d, hardened, on the paper run's first 50 images; compared with the paper run's v9 rows
$VR reproduce spatial-1d --images $N "${HARDENED[@]}" --out "$OUT/spatial-1d" -q
keep
$VR report runs/paper/spatial-1d --compare "$OUT/spatial-1d" --out "$KEEP/spatial-1d"   # compare.html
$VR report runs/paper/spatial-1d --format md --compare "$OUT/spatial-1d" | tee "$RES/spatial1d_compare.md"

# 4. one 2-D box and 5. the transfer family: both models, the same images and seeds
for case in "box2d:--roll 15 --contrast 0.7,1.4" "transfer:--roll none --perturb brightness=-0.2,0.2"; do
  name=${case%%:*}; args=${case#*:}
  # shellcheck disable=SC2086
  $VR audit --images $N $args --methods $METHODS --no-landscape --model default --out "$OUT/${name}_v9" -q
  # shellcheck disable=SC2086
  $VR audit --images $N $args --methods $METHODS --no-landscape "${HARDENED[@]}" --out "$OUT/${name}_hardened" -q
  keep
  $VR report "$OUT/${name}_v9" --compare "$OUT/${name}_hardened" --out "$KEEP/${name}_hardened"
  $VR report "$OUT/${name}_v9" --format md --compare "$OUT/${name}_hardened" | tee "$RES/${name}_compare.md"
done
