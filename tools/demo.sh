#!/usr/bin/env bash
# The main job on a generated example stage: generate the stage, solve it, show what changed.
set -euo pipefail
out=${1:-build/demo}
here=$(cd "$(dirname "$0")/.." && pwd)
py="$here/.venv/bin/python"
cli="$here/.venv/bin/mocapedit"
mkdir -p "$out"

echo "== generating the example stages into $out"
"$py" "$here/example_stages/make_stages.py" --out "$out"

stage="$out/${DEMO_STAGE:-demo_shot.usda}"
echo
echo "== mocapedit solve $(basename "$stage")"
echo "   (a Z-up centimetre crowd: one walk bent 30 degrees by a pinned last frame, another held"
echo "    at its start, collision avoidance on; see example_stages/stages_demo.py)"
"$cli" solve "$stage" -o "$out/demo.edits.usda" --composed "$out/demo.edited.usda" \
  --report "$out/demo.report.json"

echo
echo "== result"
"$py" - "$out" <<'PY'
import json, sys
out = sys.argv[1]
report = json.load(open(f"{out}/demo.report.json"))
s = report["stats"]
print(f"agents read: {s['agents']}, edited: {s['editedAgents']}, clips read: {s['clips']}, "
      f"constraints: {s['constraints']}")
for name, seconds in report["timings"].items():
    print(f"  {name:<14} {seconds * 1000:8.1f} ms")
for c in report["constraints"]:
    print(f"  {c.get('prim')}: residual {c.get('residual', 0.0):.2e}")
PY
echo
echo "== mocapedit report demo.edits.usda"
"$cli" report "$out/demo.edits.usda"

echo
echo "== mocapedit preview demo.edited.usda"
"$cli" preview "$out/demo.edited.usda" -o "$out/demo.top.png"
"$cli" preview "$out/demo.edited.usda" -o "$out/demo.top.exr" -q

echo
echo "== path edits: mocapedit solve path_edit.usda (a 10 m walk dragged 1 m sideways at its middle)"
"$cli" solve "$out/path_edit.usda" -o "$out/path_edit.edits.usda" --composed "$out/path_edit.edited.usda" \
  --report "$out/path_edit.report.json" -q
"$py" - "$out" <<'PY'
import json, sys
report = json.load(open(f"{sys.argv[1]}/path_edit.report.json"))
for c in report["constraints"]:
    print(f"  {c['prim']}: {c['kind']} residual {c['residual']:.1e} ({'met' if c['met'] else 'not met'})")
for path, a in sorted(report["agents"].items()):
    if a.get("edited"):
        print(f"  {path}: path length x{a['lengthRatio']:.4f}, solver {a['solver']}")
PY

echo
echo "edits layer:    $out/demo.edits.usda"
echo "composed stage: $out/demo.edited.usda   (open it in usdview; PXR_PLUGINPATH_NAME=\$($cli plugin-path))"
echo "top view (EXR): $(cd "$out" && pwd)/demo.top.exr"
echo "top view (PNG): $(cd "$out" && pwd)/demo.top.png"
