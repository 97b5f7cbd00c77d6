#!/usr/bin/env bash
# Runs on the GPU machine (copied into .devbin/ by tools/device/prepare.sh), about 4 minutes on
# an NVIDIA H200: the Bevy side-by-side at 1920x1080, the bench presets at 1920x1080 with
# per-pass GPU timestamps, fragment against compute throughput, and the library's GPU tests
# (CREPUSCULAR_REQUIRE_GPU=1). Each step's output is packed into one archive in OUTPUT_DIR as
# soon as it ends (at most 8 files come back from such a machine; a run cut short keeps what
# finished). Unpack them into docs/results/<device>-<date>/ and write the figures into
# docs/RESULTS.md with the device name and driver.
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
for z in .devbin/*.gz .devbin/t/*.gz; do gunzip -k -f "$z" && chmod +x "${z%.gz}"; done
B=.devbin/crepuscular
W=/tmp/work; mkdir -p "$W"
{
  echo "date: $(date -u +%FT%TZ)"; nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>&1
  echo "adapter: $($B adapter 2>&1)"
} 2>&1 | tee "$OUT/summary.txt"
pack() {  # one archive per step; of versus's pictures only the side-by-side and a few (16 MiB a file)
  (cd "$W/$1" && find . -name '*.png' ! -name 'side-by-side.png' ! -name '*64-steps.png' \
     ! -name '*1024-steps*.png' ! -name '*epipolar-balanced*.png' ! -name 'temporal.png' -delete 2>/dev/null)
  tar -czf "$OUT/$1.tar.gz" -C "$W" "$1" 2>/dev/null
}
step() {  # name, seconds, command...
  local name=$1 secs=$2; shift 2
  mkdir -p "$W/$name"
  local t0=$SECONDS
  timeout "$secs" "$@" >"$W/$name/log.txt" 2>&1
  echo "$name: exit $? in $((SECONDS - t0)) s (at $((SECONDS - T0)) s)" | tee -a "$OUT/summary.txt"
}
bench() { local name=$1 secs=$2; shift 2
  step "$name" "$secs" "$B" bench --backend gpu --reference-steps 0 --flicker-frames 0 --output "$W/$name" "$@"; }
step versus-1080p 260 .devbin/versus --size 1920x1080 --frames 15 --temporal --output "$W/versus-1080p"; pack versus-1080p
bench default-1080p 60 --sizes 1920x1080 --repeat 10 --warmup 3
for p in engelhardt-timings klehm-scenes toth-interleaving klehm-table1 engelhardt-fig10 lights; do bench "$p" 45 --preset "$p"; done
mkdir -p "$W/presets"
for p in default-1080p engelhardt-timings klehm-scenes toth-interleaving klehm-table1 engelhardt-fig10 lights; do mv "$W/$p" "$W/presets/"; done
pack presets
step fvc 60 .devbin/fvc 1920x1080 16,64,256,1024; cp "$W/fvc/log.txt" "$OUT/fragment_vs_compute.md"
export CREPUSCULAR_REQUIRE_GPU=1
mkdir -p "$W/tests"
for t in passes closed_form shadowed mirror encode; do
  step "tests/$t" 60 .devbin/t/"$t" --test-threads 4
done
pack tests
ls -la "$OUT"
