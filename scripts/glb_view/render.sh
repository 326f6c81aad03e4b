#!/bin/sh
# Dev-only: renders a GLB beside its legend.svg in headless Chromium with three.js (npm,
# installed into NODE_DIR) and writes a PNG. Usage:
#   scripts/glb_view/render.sh surface.glb legend.svg out.png [NODE_DIR] [flip|-] [ZOOM]
# NODE_DIR (default /tmp/glbview) needs `npm install three gltf-validator`.
set -eu
glb=$(realpath "$1"); legend=$(realpath "$2"); png=$(realpath -m "$3")
node_dir=${4:-/tmp/glbview}
here=$(dirname "$(realpath "$0")")
dir=$(mktemp -d)
cp "$here/view.html" "$dir/"
ln -s "$node_dir/node_modules" "$dir/node_modules"
cp "$glb" "$dir/surface.glb"; cp "$legend" "$dir/legend.svg"
port=$((20000 + $$ % 10000))
python3 -m http.server "$port" --bind 127.0.0.1 --directory "$dir" >/dev/null 2>&1 &
server=$!
trap 'kill $server; rm -rf "$dir"' EXIT
sleep 1
query="?zoom=${6:-1}"
[ "${5:-}" = flip ] && query="$query&flip=1"
chromium --headless --no-sandbox --use-angle=swiftshader --enable-unsafe-swiftshader \
  --window-size=1400,900 --virtual-time-budget=20000 --screenshot="$png" \
  "http://127.0.0.1:$port/view.html$query" 2>/dev/null
echo "$png"
