#!/usr/bin/env bash
# The browser check of `softtouch report`: render a report page in headless Chromium
# (Debian's `chromium` package) to a PNG, and fail if the page logs anything to the
# console (the page has no scripts, so any console line is an error: a blocked or
# failed load, a parse problem).
#
#   scripts/report-screenshot.sh [OUT.png] [REPORT.html] [WIDTH] [HEIGHT]
#
# Without REPORT.html it makes one first: a 300-sample simulated collection, a dataset,
# two tiny models and the result CSVs in docs/bench/, in a temporary folder, with the
# release binary (built if missing). Defaults: OUT.png = report.png, 1280×2400 px.
# Without Chromium it says so and exits 0 (CI without a browser skips the check).
set -euo pipefail

out=${1:-report.png}
page=${2:-}
width=${3:-1280}
height=${4:-2400}
root=$(cd "$(dirname "$0")/.." && pwd)

browser=$(command -v chromium || command -v chromium-browser || true)
if [[ -z $browser ]]; then
    echo "report-screenshot: skipped, no chromium on this machine (Debian: apt-get install -y chromium)"
    exit 0
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

if [[ -z $page ]]; then
    bin=$root/target/release/softtouch
    [[ -x $bin ]] || (cd "$root" && cargo build --release --bin softtouch)
    (
        cd "$work"
        "$bin" db init >/dev/null
        "$bin" collect --samples 300 --seed 1 >/dev/null 2>&1
        "$bin" dataset create land-v1 --runs 1 >/dev/null
        for kind in svae convnet; do
            "$bin" train --dataset land-v1 --model "$kind" --size 16 --width 4 --latent 8 \
                --epochs 4 --patience 0 >/dev/null 2>&1
        done
        "$bin" report --out report.html \
            --sweep "$root/docs/bench/sweep-alpha.csv" \
            --sweep "$root/docs/bench/sweep-latent.csv" \
            --bench-collection "$root/docs/bench/collection-sweep.csv"
    )
    page=$work/report.html
fi
[[ -f $page ]] || { echo "report-screenshot: no page at $page" >&2; exit 2; }
page=$(cd "$(dirname "$page")" && pwd)/$(basename "$page")

# --no-sandbox: CI and these machines run as root, where Chromium's sandbox refuses.
log=$work/chromium.log
timeout 120 "$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
    --enable-logging=stderr --v=0 --window-size="$width,$height" \
    --screenshot="$work/shot.png" "file://$page" >"$log" 2>&1 || {
    cat "$log" >&2
    echo "report-screenshot: chromium failed" >&2
    exit 1
}
if grep -q ':CONSOLE' "$log"; then
    grep ':CONSOLE' "$log" >&2
    echo "report-screenshot: the page logged to the browser console" >&2
    exit 1
fi
[[ -s $work/shot.png ]] || { echo "report-screenshot: no screenshot written" >&2; exit 1; }
cp "$work/shot.png" "$out"
echo "report-screenshot: $page rendered to $out (${width}×${height}), no console output"
