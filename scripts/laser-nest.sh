#!/bin/bash
# A 2-D laser contour nest as a fast laser would cut it: Mr Beam's `Focus_Tool_Mr_Beam_Laser_1
# .svg.5x.gco` (public, from their OctoPrint plugin's test fixtures: 310 contours of an SVG, 3,562
# G1 lines of median 0.41 mm, each contour cut twice, the beam switched with M3/M5 and a G4 P0
# between passes), downloaded at a pinned commit and checked. Made a LinuxCNC program: its user
# M-code M100 (a compressor, not in LinuxCNC) dropped, comment lines cut to LinuxCNC's line
# length, every feed set to FEED mm/min (default 12000: 200 mm/s; the file's F200 is a diode
# laser's), M2 at the end. Then scripts/program.sh plans each of its runs with the default and
# the reachability planner at configs/nurbs-sim's limits (V 1000 A 1e4 J 1e5) with G64 P TOL
# (default 0.01 mm), and one LinuxCNC 2.9 runs the whole program with the same G64 P (compare
# its moving time with our summed motion).
# Usage: [NEST=file.gco] scripts/laser-nest.sh [FEED_MM_MIN [TOL]]  (after `cargo build
# --release --bin nurbs-plan`; as root, needs linuxcnc-uspace; NEST: the file fetched before,
# else it is downloaded)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
feed=${1:-12000} tol=${2:-0.01}
commit=5900693368dfc1ebf8622c8a7d169d9213c45c68
sha=fb01f345944529befd4d423fb341f6df564e90e88721e4bed8bff75bef3efbab
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ -n "${NEST:-}" ]; then
  cp "$NEST" "$work/nest.gco"  # a copy fetched before (no network here)
else
  curl -fsSL -o "$work/nest.gco" \
    "https://raw.githubusercontent.com/mrbeam/MrBeamPlugin/$commit/cypress/fixtures/Focus_Tool_Mr_Beam_Laser_1.svg.5x.gco"
fi
echo "$sha  $work/nest.gco" | sha256sum -c --quiet
awk -v feed="$feed" '
  /^M100/ { next }
  /^;/ { print substr($0, 1, 200); next }
  { gsub(/F[0-9.]+/, "F" feed); print }
  END { print "M2" }' "$work/nest.gco" >"$work/nest.ngc"
G64=$tol PLANNERS="erwinski reach" TP=program "$here/program.sh" "$work/nest.ngc"
