#!/usr/bin/env bash
# What ran on the H200 on 2026-12-04, in four device calls (this file joins them; each call
# unpacked the Vulkan loader from .gl/ and gunzipped the stripped binaries that .devbin/ carried:
# crepuscular, the versus example, fragment_vs_compute and eight test binaries).
#  1. the bench presets below (versus failed there: Bevy's screenshot had not landed after 10
#     frames; demo::capture now waits for the device between frames);
#  2. versus at 1920x1080, klehm-table1, engelhardt-fig10, lights;
#  3. fragment_vs_compute and the test binaries (CREPUSCULAR_REQUIRE_GPU=1);
#  4. the failing shadowed test again, twice, with --nocapture.
set -u
OUT=${1:?usage: run.sh OUTPUT_DIR}
B=.devbin/crepuscular
bench() { name=$1; shift; timeout 60 "$B" bench --backend gpu --reference-steps 0 --flicker-frames 0 --output "$OUT/$name" "$@" >"$OUT/$name.log" 2>&1; }
bench default-1080p --sizes 1920x1080 --repeat 10 --warmup 3
for p in engelhardt-timings klehm-scenes toth-interleaving klehm-table1 engelhardt-fig10 lights; do bench $p --preset $p; done
timeout 270 .devbin/versus --size 1920x1080 --frames 15 --output "$OUT/versus-1080p" >"$OUT/versus.log" 2>&1
.devbin/fvc 1920x1080 16,64,256,1024 >"$OUT/fragment_vs_compute.md"
export CREPUSCULAR_REQUIRE_GPU=1
for t in passes closed_form shadowed mirror encode projection lights temporal; do .devbin/t/$t --test-threads 4; done >"$OUT/gpu-tests.txt" 2>&1
