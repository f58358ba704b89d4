#!/usr/bin/env bash
# study.sh FIRMWARE_CHECKOUT [OUT_DIR]: the whole Crazyflie firmware in the loop, one command.
#
# Builds the SITL firmware with hamflight as its controller (build.sh), builds the plant
# (host-train's firmware_sitl_plant example), then flies, through the whole firmware with cflib's
# full-state setpoints at 100 Hz and a perfect motion-capture pose at 100 Hz:
#   - the scenarios of tools/bitcraze-loop's table (cf-hover-lag50, cf-calm-spiral,
#     cf-paper-spiral, cf-rotor-loss, cf-hover-wind, gust-spiral);
#   - a hover flown by the firmware's high-level commander (take-off, go-to, land, stop);
#   - a figure of eight uploaded to the high-level commander's trajectory memory and flown by it
#     (--pilot trajectory: 10 poly4d pieces, 10 s, relative to the hover point);
#   - a lost radio link 5 s into a hover (setpoints and pose stop);
#   - an estimator reset 5 s into a hover (kalman.resetEstimation = 1 over CRTP);
# and prints a markdown table (also OUT_DIR/table.md), each flight's files in OUT_DIR/<name>/.
# The flights run in lock-step with the firmware (patches/cf-lockstep.patch, the plant's
# --lockstep): one firmware tick per plant millisecond, repeatable, 1-3 s of wall clock per 20 s
# flight; the whole study takes about 30 s after the build. STUDY_TIMING=wall-clock flies them
# paced by the wall clock instead (the firmware on its own timer, 20-40 s each, not repeatable).
# Exit 1 if a flight crashed or failed, after the table.
set -euo pipefail

usage() {
    sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'
    echo
    echo "usage: $(basename "$0") FIRMWARE_CHECKOUT [OUT_DIR]   (default OUT_DIR: target/firmware-sitl/study)"
}
case "${1:-}" in
    -h | --help) usage; exit 0 ;;
    "") usage >&2; exit 2 ;;
esac
checkout=$1
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${2:-$root/target/firmware-sitl/study}
command -v python3 >/dev/null || { echo "study.sh: python3 is needed for the table" >&2; exit 2; }

"$root/tools/firmware-sitl/build.sh" "$checkout"
(cd "$root" && cargo build --release -p host-train --example firmware_sitl_plant)
fw=$root/target/firmware-sitl/cmake/cf2_sitl/cf2
plant=${CARGO_TARGET_DIR:-$root/target}/release/examples/firmware_sitl_plant
mkdir -p "$out"
case "${STUDY_TIMING:-lockstep}" in
    lockstep) timing=(--lockstep) ;;
    wall-clock) timing=() ;;
    *) echo "study.sh: STUDY_TIMING is lockstep or wall-clock" >&2; exit 2 ;;
esac

failed=0
fly() { # name scenario [extra args]
    local name=$1 scenario=$2
    shift 2
    echo "== $name"
    if ! (cd "$root" && "$plant" --firmware "$fw" --scenario "scenarios/$scenario.toml" \
        --window-s 5 --out "$out/$name" "${timing[@]}" "$@" >"$out/$name.log" 2>&1); then
        echo "   FAILED (exit $?): $out/$name.log" >&2
        failed=1
    fi
    grep -E "hold, from|trajectory \(vs|CRASHED|link lost|estimator reset" "$out/$name.log" | sed 's/^/   /' || true
}
for s in cf-hover-lag50 cf-calm-spiral cf-paper-spiral cf-rotor-loss cf-hover-wind gust-spiral; do
    fly "$s" "$s"
done
fly high-level hover --pilot high-level
fly trajectory hover --pilot trajectory
fly link-loss hover --link-loss-s 5
fly estimator-reset hover --estimator-reset-s 5

commit=$(git -C "$checkout" rev-parse --short=12 HEAD 2>/dev/null || echo unknown)
python3 - "$out" "$commit" "${STUDY_TIMING:-lockstep}" <<'EOF' | tee "$out/table.md"
import json, os, sys
out, commit, timing = sys.argv[1], sys.argv[2], sys.argv[3]
def load(name):
    p = os.path.join(out, name, "summary.json")
    return json.load(open(p)) if os.path.exists(p) else None
def num(x, fmt="{:.2f}"):
    return "—" if x is None else fmt.format(x)
print(f"Firmware `{commit}` (CrazySim SITL) with hamflight's app (the shim's default law), "
      "cflib full-state setpoints at 100 Hz, perfect pose at 100 Hz, "
      + ("lock-step timing (one firmware tick per plant millisecond).\n" if timing == "lockstep"
         else "real-time pacing.\n"))
print("| scenario | RMSE t ≥ 5 s into the hold (cm) | max (cm) | take-off / landing RMSE (cm) | crashed |")
print("| --- | --- | --- | --- | --- |")
for s in ["cf-hover-lag50", "cf-calm-spiral", "cf-paper-spiral", "cf-rotor-loss", "cf-hover-wind", "gust-spiral"]:
    j = load(s)
    if j is None:
        print(f"| {s} | no result | | | |")
        continue
    print(f"| {s} | {num(j['hold_rmse_cm'])} | {num(j['hold_max_cm'])} | "
          f"{num(j['takeoff_rmse_cm'])} / {num(j['landing_rmse_cm'])} | {j['crashed'] or 'no'} |")
print()
j = load("high-level")
if j:
    print(f"The high-level commander (take-off, go-to, land, stop, no streamed setpoint): hover RMSE "
          f"{num(j['hold_rmse_cm'])} cm from 5 s into the hold, touch-down at {num(j['touchdown_m_s'])} m/s, "
          f"crashed: {j['crashed'] or 'no'}.")
j = load("trajectory")
if j and j.get("trajectory"):
    t = j["trajectory"]
    print(f"An uploaded trajectory (a {t['size_m'][0]:.1f} × {t['size_m'][1]:.1f} m figure of eight, "
          f"{t['pieces']} poly4d pieces, {t['duration_s']:.0f} s, {t['writes']} memory writes, "
          f"{t['repeats']} repeated) flown by the high-level commander: RMSE {num(t['rmse_cm'])} cm "
          f"against its polynomial (max {num(t['max_cm'])}), touch-down at {num(j['touchdown_m_s'])} m/s, "
          f"crashed: {j['crashed'] or 'no'}.")
j = load("link-loss")
if j and j.get("link_loss"):
    l = j["link_loss"]
    print(f"Link lost 5 s into a hover: the motors stopped {num(l['motors_off_after_s'], '{:.3f}')} s later "
          f"(the supervisor's 2 s watchdog), drift until then {num(l['drift_cm'])} cm, the vehicle reached "
          f"the ground at {num(l['ground_speed_m_s'])} m/s, tilt {num(l['ground_tilt_deg'], '{:.0f}')}°.")
j = load("estimator-reset")
if j and j.get("estimator_reset"):
    r = j["estimator_reset"]
    print(f"Estimator reset 5 s into a hover: echoed after {num(r['echoed_after_s'], '{:.3f}')} s, "
          f"peak error to the hold's end {num(r['peak_cm'])} cm.")
EOF
exit $failed
