#!/bin/sh
# Speed of a commit against main with airspeed velocity: each commit installed in its own
# virtualenv (.asv/env), the benchmarks of benchmarks/asv/ctrplan_benchmarks run for both, and a
# benchmark more than 15 % slower is flagged (exit status 1; 2 when a benchmark fails, without the
# table: asv compare prints it from the stored results). Commit the working tree first.
#   sh benchmarks/asv/compare_with_main.sh [BASE [HEAD]]      (default: main HEAD)
set -e
cd "$(dirname "$0")/../.."
exec asv --config benchmarks/asv/asv.conf.json continuous --factor 1.15 --split --show-stderr \
    "${1:-main}" "${2:-HEAD}"
