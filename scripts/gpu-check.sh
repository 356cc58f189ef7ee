#!/usr/bin/env bash
# The Taichi kernels on a GPU in one command: their tests against the NumPy twins, the kernel benchmarks on the GPU
# and on this machine's CPU, and the paper-000 report on each with its numbers compared.  docs/benchmarks.md,
# "Checking the kernels on a GPU".
#
#   scripts/gpu-check.sh [--arch cuda|vulkan|cpu] [--out DIR] [--wheels DIR] [--size quick|full]
#                        [--report-size quick|full] [--rtol R] [--work DIR] [--deadline SECONDS] [--dry-run]
#
#   --arch      the arch under test (default cuda; cpu stands in for it on a machine without a GPU)
#   --out       where the logs and gpu-check.json go (default: $OUT if set, else ./gpu-check-out)
#   --wheels    a folder of wheels: pip install --no-index --find-links DIR taichi dill, then the project with
#               pip install --no-index --no-deps --no-build-isolation -e . (skipped where they already import)
#   --size      quick (default: the quick benchmark and report sizes, ~5 minutes on 2 cores) or full
#   --report-size  the paper-000 reports' size alone (default: --size's): full runs the full report
#   --rtol      relative tolerance of the report comparison (default 1e-6, see docs/benchmarks.md)
#   --work      where the benchmark JSON and the two report folders go (default: a new temporary folder)
#   --deadline  seconds for the whole run (default 450); a step that would start past it is not run
#   --dry-run   print the steps' commands and run nothing
#
# Steps, each logged to OUT/<step>.log, its status, exit and seconds in OUT/gpu-check.json:
#   install, tests, kernels-<arch>, kernels-cpu, report-<arch>, report-cpu, compare
# Exit status 0 when every step passed and the two reports agree, 1 otherwise.  At most 8 files go into OUT (the
# device tool brings back 8), everything bulky into the work folder.
set -u
{  # the whole script is read before it runs: an edit while it runs cannot change what it does

ARCH=cuda
OUT_DIR=${OUT:-gpu-check-out}
WHEELS=
SIZE=quick
REPORT_SIZE_ARG=
RTOL=1e-6
WORK=
DEADLINE=450
DRY=0

value() { [ $# -ge 2 ] && [ "${2#--}" = "$2" ]; }  # an option's value follows it, not another option
die() { echo "gpu-check: error: $*" >&2; exit 2; }

while [ $# -gt 0 ]; do
    case "$1" in
        --arch) value "$@" || die "--arch needs a value"; ARCH=$2; shift 2 ;;
        --out) value "$@" || die "--out needs a value"; OUT_DIR=$2; shift 2 ;;
        --wheels) value "$@" || die "--wheels needs a value"; WHEELS=$2; shift 2 ;;
        --size) value "$@" || die "--size needs a value"; SIZE=$2; shift 2 ;;
        --report-size) value "$@" || die "--report-size needs a value"; REPORT_SIZE_ARG=$2; shift 2 ;;
        --rtol) value "$@" || die "--rtol needs a value"; RTOL=$2; shift 2 ;;
        --work) value "$@" || die "--work needs a value"; WORK=$2; shift 2 ;;
        --deadline) value "$@" || die "--deadline needs a value"; DEADLINE=$2; shift 2 ;;
        --dry-run) DRY=1; shift ;;
        -h|--help) sed -n '2,/^set -u/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done
case "$ARCH" in cuda|vulkan|cpu) ;; *) die "--arch must be cuda, vulkan or cpu, not '$ARCH'" ;; esac
case "$SIZE" in quick|full) ;; *) die "--size must be quick or full, not '$SIZE'" ;; esac
case "${REPORT_SIZE_ARG:-$SIZE}" in quick|full) ;; *) die "--report-size must be quick or full, not '$REPORT_SIZE_ARG'" ;; esac
[[ "$DEADLINE" =~ ^[0-9]+$ ]] || die "--deadline must be a whole number of seconds, not '$DEADLINE'"
[[ "$RTOL" =~ ^[0-9.]+([eE][-+]?[0-9]+)?$ ]] || die "--rtol must be a number, not '$RTOL'"
[ -z "$WHEELS" ] || [ "$DRY" = 1 ] || [ -d "$WHEELS" ] || die "--wheels folder '$WHEELS' does not exist"

absolute() { case "$1" in ''|/*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }  # paths as the caller meant them
OUT_DIR=$(absolute "$OUT_DIR"); WHEELS=$(absolute "$WHEELS"); WORK=$(absolute "$WORK")
cd "$(dirname "$0")/.." || die "cannot enter the repository root"
if [ -n "${PYTHON:-}" ]; then PY=$PYTHON
elif [ -x .venv/bin/python ]; then PY=.venv/bin/python
else PY=python3
fi
if [ -z "$WORK" ]; then
    if [ "$DRY" = 1 ]; then WORK='$WORK'; else WORK=$(mktemp -d "${TMPDIR:-/tmp}/gpu-check-work.XXXXXX"); fi
fi
export MPLBACKEND=Agg PYTHONUNBUFFERED=1

if [ "$SIZE" = quick ]; then BENCH_SIZE=--quick; else BENCH_SIZE=; fi
if [ "${REPORT_SIZE_ARG:-$SIZE}" = quick ]; then REPORT_SIZE=--quick; else REPORT_SIZE=--full; fi
# the other arch: the CPU beside the GPU (with --arch cpu the second report checks that a rerun gives the same)
if [ "$ARCH" = cpu ]; then OTHER=cpu-again; else OTHER=cpu; fi
WB="$PY -m workbench.cli"
TESTS="tests/test_kernels.py tests/test_crpf_kernel.py"

kernels_cmd() {  # on an arch: the method-C kernel at N = 1e5, 1e6 x M = 1e3, 1e4, the CRPF step per particle,
                # then the method-C weight-kernel group (tbd-pf's) of the benchmark with its limits
    echo "$PY scripts/gpu_check_compare.py method-c --arch $1 --json $WORK/method-c-$1.json" \
         "&& $PY scripts/gpu_check_compare.py crpf-step --arch $1 --json $WORK/crpf-$1.json" \
         "&& $WB bench $BENCH_SIZE --only tbd-weights --arch $1 --json $WORK/bench-$1.json"
}
report_cmd() {  # $1 arch, $2 folder name
    echo "rm -rf $WORK/report-$2 && $WB report --paper 000 $REPORT_SIZE --arch $1 --out $WORK/report-$2 --no-progress"
}

STEP_NAMES=()
STEP_CMDS=()
STEP_CAPS=()
add() { STEP_NAMES+=("$1"); STEP_CMDS+=("$2"); STEP_CAPS+=("$3"); }

if [ -n "$WHEELS" ]; then
    add install "if $PY -c 'import taichi, dill, workbench_papers.paper000' 2>/dev/null; then echo 'taichi, dill and the project already import: nothing installed'; else $PY -m pip install --no-index --find-links $WHEELS taichi dill && $PY -m pip install --no-index --no-deps --no-build-isolation -e .; fi" 180
fi
add tests "WORKBENCH_TEST_ARCH=$ARCH $PY -m pytest -q -rs $TESTS -k 'on_test_arch or taichi-$ARCH'" 180
add "kernels-$ARCH" "$(kernels_cmd "$ARCH")" 240
[ "$ARCH" = cpu ] || add kernels-cpu "$(kernels_cmd cpu)" 240
add "report-$ARCH" "$(report_cmd "$ARCH" "$ARCH")" 240
add "report-$OTHER" "$(report_cmd cpu "$OTHER")" 240
add compare "$PY scripts/gpu_check_compare.py compare $WORK/report-$ARCH $WORK/report-$OTHER --rtol $RTOL --json $WORK/compare.json" 60

if [ "$DRY" = 1 ]; then
    echo "# gpu-check: arch $ARCH, size $SIZE, report size ${REPORT_SIZE#--}, out $OUT_DIR, work $WORK, deadline ${DEADLINE}s, rtol $RTOL"
    for i in "${!STEP_NAMES[@]}"; do
        echo "${STEP_NAMES[$i]}: ${STEP_CMDS[$i]}  > $OUT_DIR/${STEP_NAMES[$i]}.log"
    done
    echo "summary: $PY scripts/gpu_check_compare.py summary --out $OUT_DIR --work $WORK --arch $ARCH --size $SIZE --rtol $RTOL"
    exit 0
fi

mkdir -p "$OUT_DIR" "$WORK" || die "cannot create '$OUT_DIR' or '$WORK'"
: > "$WORK/steps.tsv"
START=$SECONDS
FAILED=0
for i in "${!STEP_NAMES[@]}"; do
    name=${STEP_NAMES[$i]}; cmd=${STEP_CMDS[$i]}; cap=${STEP_CAPS[$i]}
    left=$(( DEADLINE - (SECONDS - START) - 15 ))  # 15 s kept for the summary
    limit=$(( cap < left ? cap : left ))
    log="$OUT_DIR/$name.log"
    echo "== $name (at most ${limit}s): $cmd" | tee "$log"
    t0=$(date +%s.%N)
    if [ "$limit" -lt 20 ]; then
        echo "not run: the deadline of ${DEADLINE}s is too near" | tee -a "$log"
        rc=124; status="not run"
    else
        timeout -k 10 "$limit" bash -c "$cmd" >> "$log" 2>&1
        rc=$?
        if [ $rc = 0 ]; then status=ok; elif [ $rc = 124 ] || [ $rc = 137 ]; then status="timed out"; else status=failed; fi
    fi
    secs=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
    printf '%s\t%s\t%s\t%s\t%s\n' "$name" "$status" "$rc" "$secs" "$cmd" >> "$WORK/steps.tsv"
    echo "== $name: $status (exit $rc, ${secs}s)" | tee -a "$log"
    [ $rc = 0 ] || FAILED=1
done

$PY scripts/gpu_check_compare.py summary --out "$OUT_DIR" --work "$WORK" --arch "$ARCH" --size "$SIZE" --rtol "$RTOL" \
    || FAILED=1
if [ ! -s "$OUT_DIR/gpu-check.json" ]; then  # the summary could not run: the bare records, still as JSON
    python3 - "$OUT_DIR" "$WORK" "$ARCH" <<'EOF' || printf '{"ok": false, "error": "no Python to write the summary"}\n' > "$OUT_DIR/gpu-check.json"
import json, sys
out, work, arch = sys.argv[1:]
steps = [dict(zip(("name", "status", "exit", "seconds", "command"), l.split("\t", 4)))
         for l in open(f"{work}/steps.tsv").read().splitlines()]
json.dump({"arch": arch, "ok": False, "error": "the summary helper failed", "steps": steps},
          open(f"{out}/gpu-check.json", "w"), indent=1)
EOF
fi
echo "gpu-check: $( [ $FAILED = 0 ] && echo 'every step passed' || echo 'SOME STEPS FAILED' ); $OUT_DIR/gpu-check.json (work: $WORK, $((SECONDS - START))s)"
exit $FAILED
}
