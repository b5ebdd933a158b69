#!/usr/bin/env bash
# Blender tier (CTest blender_glb_test): imports every kind of .glb artex exports into Blender
# in background mode (tests/blender/check_glb.py) - the template, an animated template and a
# tracked.glb with exact correctives and texture - checks bones, frame range, texture and shape
# keys, and renders one frame. Exits 77 (skipped) when no `blender` is on PATH.
#   tests/blender/blender_test.sh ARTEX_BINARY [WORK_DIR]
set -euo pipefail
ARTEX="$1"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if ! command -v blender >/dev/null 2>&1; then
  echo "blender_glb_test: skipped: Blender is not installed (apt-get install blender to run it)"
  exit 77
fi
WORK="${2:-$(mktemp -d)}"
mkdir -p "$WORK"
check() { blender -b --factory-startup --python-exit-code 1 --python "$HERE/check_glb.py" -- "$@"; }

"$ARTEX" template make --resolution 0 -o "$WORK/template.glb" >/dev/null
check "$WORK/template.glb" --joints 17

"$ARTEX" synth --motion walk --frames 8 --seed 1 --subject-resolution 0 --texture-size 256 \
  --color-width 200 --color-height 254 -o "$WORK/seq" >/dev/null
"$ARTEX" track "$WORK/seq" -o "$WORK/run" -q --set texture.atlas_size=256 >/dev/null
check "$WORK/run/tracked.glb" --joints 17 --frames 8 --fps 30 --texture --shape-keys 8 \
  --render "$WORK/frame.png"
test -s "$WORK/frame.png"
echo "blender_glb_test: OK ($WORK)"
