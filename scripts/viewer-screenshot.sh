#!/usr/bin/env bash
# Open a recording in the real rerun viewer on a virtual display and save a
# screenshot of what a person would see (the stored layout, at the last step).
#
#   scripts/viewer-screenshot.sh RECORDING.rrd OUT.png
#
# Environment: WAIT (seconds to let the viewer load and draw, default 25),
# SIZE (screen and window, default 1600x1000), WIDTH (width of the saved
# PNG, default 1280; the screenshot is downscaled with ImageMagick).
#
# Needs the viewer of the crate's rerun version (`pip install
# rerun-sdk==0.36.3`), Xvfb and ImageMagick, and a Vulkan driver: with no
# GPU, Mesa's software one (Debian: `apt-get install xvfb
# mesa-vulkan-drivers imagemagick`). The GL backend fails here ("Adapter
# does not support drawing to texture format R32Float") and without the
# Composite extension the screenshot is black. When something is missing
# the script says so and exits 0 without a screenshot. With xdotool
# installed the pointer is moved out of the way first.
set -u

if [ $# -ne 2 ]; then
    echo "usage: $0 RECORDING.rrd OUT.png" >&2
    exit 2
fi
rrd=$1
out=$2
wait=${WAIT:-25}
size=${SIZE:-1600x1000}
width=${WIDTH:-1280}

for cmd in rerun Xvfb import convert setsid; do
    if ! command -v "$cmd" >/dev/null 2>&1; then
        echo "skipped: \`$cmd\` not found (pip install rerun-sdk==0.36.3; apt-get install xvfb mesa-vulkan-drivers imagemagick)"
        exit 0
    fi
done
if [ ! -f "$rrd" ]; then
    echo "no such recording: $rrd" >&2
    exit 2
fi

# A display number nobody uses.
d=99
while [ -e "/tmp/.X$d-lock" ] || [ -e "/tmp/.X11-unix/X$d" ]; do
    d=$((d + 1))
done
work=$(mktemp -d)
xvfb=
viewer=
cleanup() {
    # The viewer runs in its own process group (the pip launcher starts the
    # binary as a child): end the whole group, then the display.
    [ -n "$viewer" ] && kill -- "-$viewer" 2>/dev/null
    [ -n "$xvfb" ] && kill "$xvfb" 2>/dev/null
    rm -rf "$work"
}
trap cleanup EXIT

Xvfb ":$d" -screen 0 "${size}x24" -extension Composite >"$work/xvfb.log" 2>&1 &
xvfb=$!
sleep 2
if ! kill -0 "$xvfb" 2>/dev/null; then
    echo "skipped: Xvfb did not start on :$d ($(tail -1 "$work/xvfb.log"))"
    exit 0
fi

# The viewer keeps its state (layouts included) under $XDG_DATA_HOME/rerun:
# a fresh one makes the screenshot show the recording's own layout and
# leaves the user's state alone.
DISPLAY=":$d" WGPU_BACKEND=vulkan XDG_DATA_HOME="$work/data" setsid rerun --new --window-size "$size" "$rrd" >"$work/viewer.log" 2>&1 &
viewer=$!
sleep "$wait"
if ! kill -0 "$viewer" 2>/dev/null; then
    echo "skipped: the viewer stopped before the screenshot; its log:"
    tail -5 "$work/viewer.log"
    exit 0
fi
if grep -q "Adapter does not support\|No suitable graphics adapter" "$work/viewer.log"; then
    echo "skipped: no usable Vulkan adapter (apt-get install mesa-vulkan-drivers); the viewer's log:"
    tail -5 "$work/viewer.log"
    exit 0
fi

# The pointer starts in the middle of the screen, where it would hover
# (and highlight) whatever lies there: park it in a corner when xdotool is
# installed.
if command -v xdotool >/dev/null 2>&1; then
    DISPLAY=":$d" xdotool mousemove 0 "${size#*x}" 2>/dev/null
    sleep 2
fi
DISPLAY=":$d" import -window root "$work/shot.png"
# 256 colours keep a screenshot of a scene with thousands of points
# near 200 kB.
convert "$work/shot.png" -resize "${width}x" -strip -colors 256 "PNG8:$out"
echo "screenshot: $out ($(du -k "$out" | cut -f1) kB) of $rrd"
