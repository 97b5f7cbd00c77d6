#!/usr/bin/env bash
# Hardware run (this session): the Bevy side-by-side at 1920x1080 first, then the bench presets at
# 1920x1080 with per-pass GPU timestamps. Each step's output is packed into one archive in
# OUTPUT_DIR as soon as it ends, so a run cut short keeps what finished.
set -u
OUT=${1:?usage: run.sh OUTPUT_DIR}
mkdir -p "$OUT"
T0=$SECONDS
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
export XDG_RUNTIME_DIR=/tmp/xdg; mkdir -p "$XDG_RUNTIME_DIR"; chmod 700 "$XDG_RUNTIME_DIR"
for z in .devbin/*.gz; do gunzip -k -f "$z" && chmod +x "${z%.gz}"; done
B=.devbin/crepuscular
W=/tmp/work; mkdir -p "$W"
{
  echo "date: $(date -u +%FT%TZ)"; nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>&1
  echo "adapter: $($B adapter 2>&1)"; nproc; 
} 2>&1 | tee "$OUT/summary.txt"
pack() {  # one archive per step; of versus's pictures only the side-by-side and a few (16 MiB a file)
  (cd "$W/$1" && find . -name '*.png' ! -name 'side-by-side.png' ! -name '*64-steps.png' ! -name '*1024-steps*.png' ! -name '*epipolar-balanced*.png' -delete 2>/dev/null)
  tar -czf "$OUT/$1.tar.gz" -C "$W" "$1" 2>/dev/null
}
step() {  # name, seconds, command...
  local name=$1 secs=$2; shift 2
  mkdir -p "$W/$name"
  local t0=$SECONDS
  timeout "$secs" "$@" >"$W/$name/log.txt" 2>&1
  local rc=$?
  echo "$name: exit $rc in $((SECONDS - t0)) s (at $((SECONDS - T0)) s)" | tee -a "$OUT/summary.txt"
  pack "$name"
}
step versus-1080p 270 .devbin/versus --size 1920x1080 --frames 15 --output "$W/versus-1080p"
ls -la "$OUT"

step klehm-table1 45 "$B" bench --backend gpu --reference-steps 0 --flicker-frames 0 --preset klehm-table1 --output "$W/klehm-table1"
step engelhardt-fig10 40 "$B" bench --backend gpu --reference-steps 0 --flicker-frames 0 --preset engelhardt-fig10 --output "$W/engelhardt-fig10"
step lights 40 "$B" bench --backend gpu --reference-steps 0 --flicker-frames 0 --preset lights --output "$W/lights"
ls -la "$OUT"
