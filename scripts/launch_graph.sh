#!/usr/bin/env bash
# Start the node graph from the shell, as `phfdi launch` does: every node its own
# process (python -m <package>.node), LOCALHOST discovery, a ROS domain of its own.
#
#   scripts/launch_graph.sh [--scenario NAME|FILE.yaml] [--fault NAME] [--onset S]
#                           [--record BAG.mcap] [--pace FACTOR] [--detector] [--set KEY=VALUE ...]
#
#   scripts/launch_graph.sh --fault backlash --record bags/run.mcap
#   scripts/launch_graph.sh --fault backlash --detector --pace 50     # + the fault detector (/fault_alarm)
#   scripts/launch_graph.sh --pace 20 --set duration_s=2000 --set setpoints.ph.changes.0.at_s=1000
#
# Ctrl-C or SIGTERM stops the plant first, then the controllers and the valve, then
# the detector, then the recorder (the bag stays readable). Node logs go to the terminal. Overrides are
# simple KEY=VALUE pairs here (no commas); use phfdi launch for list-valued ones.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PHFDI_VENV:-.venv}/bin/python
unset _ROS_WHEELS_BOOTSTRAP_COMPLETE || true

scenario=paper fault="" onset=-1.0 record="" pace=0.0 detector="" overrides=()
while [ $# -gt 0 ]; do
  case "$1" in
    --scenario) scenario=$2; shift 2 ;;
    --fault) fault=$2; shift 2 ;;
    --onset) onset=$2; shift 2 ;;
    --record) record=$2; shift 2 ;;
    --pace) pace=$2; shift 2 ;;
    --set) overrides+=("$2"); shift 2 ;;
    --detector) detector=1; shift ;;
    -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "launch_graph.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
case "$onset" in *.*) ;; *) onset="$onset.0" ;; esac   # ROS double parameters need a decimal point
case "$pace" in *.*) ;; *) pace="$pace.0" ;; esac

export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST     # DDS stays on this machine
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$("$PY" -m phfdi_base.ros.env)}
nodes="controllers,valve,plant${record:+,recorder}${detector:+,detector}"
common=(-p "scenario:=$scenario" -p "fault:='$fault'" -p "fault_onset_s:=$onset" -p "graph_nodes:=[$nodes]")
if [ ${#overrides[@]} -gt 0 ]; then
  common+=(-p "overrides:=[$(IFS=,; echo "${overrides[*]}")]")
fi
echo "launch_graph.sh: ROS domain $ROS_DOMAIN_ID, nodes $nodes" >&2

# Each node in a session of its own (Ctrl-C reaches this script only, which stops
# them in order) that gets SIGTERM if this script dies.
start() { setsid setpriv --pdeathsig TERM "$PY" -m "$@" & }
rec=""; if [ -n "$record" ]; then start phfdi.ros.recorder --ros-args "${common[@]}" -p "path:=$record"; rec=$!; fi
start pi_controllers.node --ros-args "${common[@]}"; ctl=$!
start valve_actuator.node --ros-args "${common[@]}"; valve=$!
det=""
if [ -n "$detector" ]; then  # the multichannel detector with the physics reference shipped for the scenario
  ref=$("$PY" -c 'import sys; from phfdi.replay import shipped_physics_name; from phfdi.scenario import load_scenario
print(shipped_physics_name(load_scenario(sys.argv[1])))' "$scenario")
  start wavelet_fdi.learned_node --ros-args "${common[@]}" -p "reference:=$ref" -p loop:=ph -p loop_graph_topics:=true
  det=$!
fi
start ph_plant_sim.node --ros-args "${common[@]}" -p "pace:=$pace" -p progress:=false; plant=$!

stop() {  # plant first (no new samples), the loop, the detector (last alarms), the recorder (finishes the bag)
  for group in "$plant" "$ctl $valve" "$det" "$rec"; do
    for pid in $group; do kill -TERM "$pid" 2>/dev/null || true; done
    for pid in $group; do wait "$pid" 2>/dev/null || true; done
  done
}
trap 'stop; exit 130' INT TERM
status=0
wait "$plant" || status=$?
stop
[ -n "$record" ] && "$PY" -m phfdi.cli bag info "$record"
exit $status
