#!/usr/bin/env bash
# Runs every fuzz target of a fuzz build for a bounded time:
#   fuzz/run_fuzzers.sh BUILD_DIR SECONDS_PER_TARGET DATA_DIR
# Seeds (fuzz_seeds: small files of every encoding, the heads of the scans in DATA_DIR,
# the URDFs) go to BUILD_DIR/seeds; each target's working corpus, BUILD_DIR/corpus/NAME,
# is kept between runs and grows. The inputs of fuzz/regressions/NAME (each once found a
# failure, since fixed) are replayed first. Any crash, sanitizer report, uncaught
# exception, input slower than TIMEOUT seconds (a hang) or use of more than RSS_MB fails
# the run; the input is saved in BUILD_DIR/artifacts/NAME/.
set -uo pipefail
build=${1:?build dir}
seconds=${2:?seconds per target}
data=${3:?data dir}
here=$(cd "$(dirname "$0")" && pwd)
timeout_s=${TIMEOUT:-30}
rss_mb=${RSS_MB:-2048}
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
# One third-party leak, documented in docs/reliability.md ("Fuzzing"): urdfdom 3.0.1 leaks
# the links of a URDF whose joints form a loop when it then fails to parse the file.
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$here/lsan.supp}

urdfs=("$here/../tests/data/test_arm.urdf:base_link:tool"
       "$here/../tests/data/test_arm.urdf:world:sensor_mount")
bullet=$(cd "$here/.." && .venv/bin/python -c "import pybullet_data; print(pybullet_data.getDataPath())" 2>/dev/null || true)
if [ -n "$bullet" ]; then
  urdfs+=("$bullet/kuka_iiwa/model.urdf:lbr_iiwa_link_0:lbr_iiwa_link_7"
          "$bullet/franka_panda/panda.urdf:panda_link0:panda_hand")
fi
"$build/fuzz/fuzz_seeds" "$build/seeds" "$data" "${urdfs[@]}" || exit 1

declare -A max_len=([pcd_fuzzer]=16384 [pcd_ascii_fuzzer]=80 [ply_fuzzer]=16384 [urdf_fuzzer]=32768 [align_fuzzer]=2048 [depth_fuzzer]=20000)
declare -A seeds=([pcd_fuzzer]=pcd [pcd_ascii_fuzzer]=pcd_ascii [ply_fuzzer]=ply [urdf_fuzzer]=urdf [align_fuzzer]=align [depth_fuzzer]=depth)
failed=()
for name in pcd_fuzzer pcd_ascii_fuzzer ply_fuzzer urdf_fuzzer align_fuzzer depth_fuzzer; do
  corpus="$build/corpus/$name"
  artifacts="$build/artifacts/$name"
  mkdir -p "$corpus" "$artifacts"
  common=(-timeout="$timeout_s" -rss_limit_mb="$rss_mb" -max_len="${max_len[$name]}"
          -artifact_prefix="$artifacts/")
  if [ -d "$here/regressions/$name" ] && [ -n "$(ls -A "$here/regressions/$name")" ]; then
    echo "== $name: regressions"
    if ! "$build/fuzz/$name" "${common[@]}" "$here/regressions/$name"/*; then
      failed+=("$name (regressions)")
      continue
    fi
  fi
  echo "== $name: ${seconds} s"
  start=$(date +%s)
  if ! "$build/fuzz/$name" "${common[@]}" -max_total_time="$seconds" -print_final_stats=1 \
      "$corpus" "$build/seeds/${seeds[$name]}" 2> "$build/$name.log"; then
    tail -n 60 "$build/$name.log"
    failed+=("$name")
  else
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb|^Done|cov:" "$build/$name.log" | tail -n 3
  fi
  echo "   $(( $(date +%s) - start )) s, corpus $(ls "$corpus" | wc -l) inputs"
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: FAILED: ${failed[*]} (inputs in $build/artifacts)"
  exit 1
fi
echo "fuzz: every target ran ${seconds} s without a failure"
