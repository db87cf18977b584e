#!/usr/bin/env bash
# Regenerate the bundled bags (bags/*.mcap) from bags/scenes.yaml, bags/touch_scenes.yaml (known
# loads, touch ground truth), bags/slip_scenes.yaml (friction, slip ground truth; two of its
# scenes) and the artwork the project ships. Deterministic: the same inputs give the same bytes. Run through `make bags`
# (`source env.sh && bash tools/make_bags.sh`).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ART="$ROOT/src/tactile_sl_sim/artwork/pattern.png"
if [ ! -f "$ART" ] || [ ! -f "$ART.yaml" ]; then
  echo "make_bags: $ART (and its .yaml sidecar) missing; render it with" \
       "'tactile-sl pattern render PATTERN.yaml --png $ART'" >&2
  exit 1
fi
tactile-sl synth "$ROOT/bags/scenes.yaml" -o "$ROOT/bags" --artwork "$ART"
tactile-sl synth "$ROOT/bags/touch_scenes.yaml" -o "$ROOT/bags" --artwork "$ART"
for bag in "$ROOT"/bags/*.mcap; do
  size=$(stat -c %s "$bag")
  if [ "$size" -ge 5000000 ]; then
    echo "make_bags: $bag is $size bytes (limit 5 MB)" >&2
    exit 1
  fi
done
# Slip scenes (issue 24): only the two bag scenes of bags/slip_scenes.yaml (the others are
# the slip benchmark's, rendered by tools/bench_touch.py), < 2.5 MB each.
tactile-sl synth "$ROOT/bags/slip_scenes.yaml" -o "$ROOT/bags" --artwork "$ART" \
  --only slip_halfspace --only slip_two_contacts
for bag in "$ROOT"/bags/slip_*.mcap; do
  size=$(stat -c %s "$bag")
  if [ "$size" -ge 2500000 ]; then
    echo "make_bags: $bag is $size bytes (limit 2.5 MB for slip bags)" >&2
    exit 1
  fi
done
# Robustness scenes (issue 11: nuisances of real sensors), small: < 2 MB each.
tactile-sl synth "$ROOT/bags/robust_scenes.yaml" -o "$ROOT/bags" --artwork "$ART"
for bag in "$ROOT"/bags/robust_*.mcap; do
  size=$(stat -c %s "$bag")
  if [ "$size" -ge 2000000 ]; then
    echo "make_bags: $bag is $size bytes (limit 2 MB for robustness bags)" >&2
    exit 1
  fi
done
