#!/usr/bin/env bash
# Frame times of two builds side by side: `harmonic-lab frame-time` of each case, the two
# binaries alternating run by run, at 1 and 2 threads; prints each side's median and the ratio.
#   bash benches/lab/frame_time.sh OLD_LAB_BINARY NEW_LAB_BINARY [RUNS] [CASES...]
set -euo pipefail
old=$1
new=$2
runs=${3:-7}
shift $(($# < 3 ? $# : 3))
cases=("$@")
[ ${#cases[@]} -gt 0 ] || cases=(chain cloth16 stiff128 cloth1024)
median() { sort -g | awk '{a[NR] = $1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }
printf '| case | threads | old (s/frame) | new (s/frame) | new/old | spread old | spread new |\n'
printf '|---|---|---|---|---|---|---|\n'
for case in "${cases[@]}"; do
    for threads in 1 2; do
        o=() n=()
        for _ in $(seq "$runs"); do
            o+=("$(RAYON_NUM_THREADS=$threads "$old" frame-time --case "$case" | cut -f2)")
            n+=("$(RAYON_NUM_THREADS=$threads "$new" frame-time --case "$case" | cut -f2)")
        done
        mo=$(printf '%s\n' "${o[@]}" | median)
        mn=$(printf '%s\n' "${n[@]}" | median)
        # The spread: (max - min) / median of each side's runs.
        so=$(printf '%s\n' "${o[@]}" | sort -g | awk -v m="$mo" 'NR == 1 {lo = $1} {hi = $1} END {printf "%.1f %%", 100 * (hi - lo) / m}')
        sn=$(printf '%s\n' "${n[@]}" | sort -g | awk -v m="$mn" 'NR == 1 {lo = $1} {hi = $1} END {printf "%.1f %%", 100 * (hi - lo) / m}')
        ratio=$(awk -v a="$mn" -v b="$mo" 'BEGIN {printf "%.4f", a / b}')
        printf '| %s | %s | %.4e | %.4e | %s | %s | %s |\n' "$case" "$threads" "$mo" "$mn" "$ratio" "$so" "$sn"
    done
done
