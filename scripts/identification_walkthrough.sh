#!/bin/bash
# The identification walk-through of docs/identify.md in one go: launch the graph (IPAnema 3 Mini,
# composed, default mismatched plant, force control), run each identification program while
# `cdpr bag record` records, identify from those bags, load the friction into the graph, and draw
# the figures of docs/img/identify_*.png.
#
#   source .venv/bin/activate; scripts/identification_walkthrough.sh [OUTDIR (default bags/ident)] [IMGDIR (default docs/img)]
#
# On an idle two-core machine the three runs take a few minutes (the graph records at a real-time
# factor of about 0.3-0.7); every step stops the script when it fails.
set -euo pipefail
OUT=${1:-bags/ident}
IMG=${2:-docs/img}
TOPICS="/joint_command/mode /winch/state /winch/command /ground_truth/cable_forces /ground_truth/pose /setpoint"
mkdir -p "$OUT" "$IMG"

cdpr launch cdpr_tools/cdpr_tools/graphs/closed_loop.yaml > "$OUT/launch.log" 2>&1 &
LAUNCH=$!
RECORDER=
stop() {
    [ -n "$RECORDER" ] && kill -INT "$RECORDER" 2>/dev/null && wait "$RECORDER" || true
    kill -INT "$LAUNCH" 2>/dev/null && wait "$LAUNCH" || true
    cdpr daemon stop > /dev/null 2>&1 || true     # started by `cdpr param load`
}
trap stop EXIT

record() {  # record NAME PROGRAM: the program's run into $OUT/NAME
    rm -rf "${OUT:?}/$1"
    cdpr bag record -o "$OUT/$1" $TOPICS > "$OUT/$1.log" 2>&1 &
    RECORDER=$!
    # the program starts once the recorder has subscribed to every topic
    for topic in $TOPICS; do
        until grep -q "subscribed to $topic \[" "$OUT/$1.log"; do
            kill -0 "$RECORDER" 2>/dev/null || { cat "$OUT/$1.log"; exit 1; }
            sleep 0.5
        done
    done
    cdpr program run "$2" --server-timeout 300 --timeout 3600
    kill -INT "$RECORDER"
    wait "$RECORDER"
    RECORDER=
}

record friction friction_identification_mini
record circle circle_load_identification
record stiffness stiffness_identification_mini

cdpr identify friction "$OUT/friction" -o "$OUT/friction.yaml" --plot "$IMG/identify_friction_fit.png"
cdpr identify drive "$OUT/friction" --plot "$IMG/identify_drive_fit.png"
cdpr identify mass "$OUT/circle" --friction "$OUT/friction.yaml" --plot "$IMG/identify_mass_fit.png"
cdpr identify stiffness "$OUT/stiffness" --friction "$OUT/friction.yaml" -o "$OUT/robot.yaml"
cdpr param load /friction_compensation "$OUT/friction.yaml"
cdpr param get /friction_compensation mu
cdpr analyze energy "$OUT/friction" --robot ipanema3_mini
python scripts/plot_identification.py "$OUT/friction" "$OUT/stiffness" "$OUT/friction.yaml" "$OUT/robot.yaml" --out "$IMG"
