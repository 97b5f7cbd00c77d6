#!/usr/bin/env bash
# Prepares a hardware run on a lent GPU machine (Linux x86-64, NVIDIA driver, no Rust): builds the
# workspace, then puts into .devbin/ (git-ignored) the stripped, gzipped binaries that
# tools/device/run.sh uses — the CLI, the Bevy side-by-side (`versus`), `fragment_vs_compute` and
# five of the library's GPU test binaries — and the Vulkan loader packages into .gl/. Gzipped,
# the bundle is about 45 MB; with the tracked tree (about 16 MB) that stays under the 64 MiB a
# working tree may carry there (unstripped, the versus binary alone is 92 MB; more test
# binaries do not fit). Run from the project's root, then on the GPU machine:
#     bash .devbin/run.sh OUTPUT_DIR
# See docs/RESULTS.md "On hardware" for what a run on an NVIDIA H200 gave.
set -euo pipefail
[ -f Cargo.toml ] || { echo "run this from the project's root" >&2; exit 1; }
for d in /.gl/ /.devbin/; do grep -qxF "$d" .git/info/exclude 2>/dev/null || echo "$d" >> .git/info/exclude; done
# The workspace build (one feature set for wgpu and Bevy: building one package alone would
# rebuild them with another).
cargo build --release --workspace --all-targets
rm -rf .devbin && mkdir -p .devbin/t
pack() { cp "$1" "$2" && strip "$2" && gzip -9 -f "$2"; }
pack target/release/crepuscular .devbin/crepuscular
pack target/release/examples/versus .devbin/versus
pack target/release/examples/fragment_vs_compute .devbin/fvc
for t in passes closed_form shadowed mirror encode; do
  f=$(ls -t target/release/deps/"$t"-* | grep -v '\.d$' | head -1)
  pack "$f" .devbin/t/"$t"
done
cp tools/device/run.sh .devbin/run.sh
if ! ls .gl/libvulkan1_*.deb >/dev/null 2>&1; then
  mkdir -p .gl /tmp/amd64/partial
  o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
  apt-get $o update -qq
  (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
fi
du -sh .devbin .gl
echo "Ready: carry .gl and .devbin; on the GPU machine run  bash .devbin/run.sh OUTPUT_DIR"
