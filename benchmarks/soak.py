"""Soak benchmark: the ROS 2 graph with the detector for a long run; memory of every node, messages lost.

Runs plant, valve, controllers, recorder and the fault detector (``phfdi launch
--detector --record``, started by the same launcher) for a long scenario, and
measures while it runs:

* resident memory of each node process, from /proc/<pid>/status every
  ``--sample-s`` s of wall time: VmRSS and its parts RssAnon (the heap: where a
  leak shows), RssFile (mapped libraries) and RssShmem (Fast DDS shared
  memory). Start = first sample after the graph connected, middle = the sample
  nearest the middle of the run (wall, connected to the plant's last sample),
  end = the last sample before the plant's last sample (nodes still running).
  Growth = (end - middle) / middle of VmRSS;
* messages lost, per topic: published (each node counts what its publishers
  sent and prints it on exit) minus recorded (in the bag); for the topics with
  one message per sample, the simulated stamps in the bag are checked against
  the sample grid 0..N-1 (missing, duplicated); the detector's received
  counts (measurements, controller outputs) against what was published; and
  the lock-step ring (every sample completed: it stalls if one message is lost);
* bag size (sampled while it grows), wall time, the load average throughout.

Writes <out>/<name>.json (everything), <name>_rss.csv (the samples) and
<name>_rss.png (resident memory per node against wall time), and prints a
table. Acceptance (issue 15): growth under 10 % from middle to end for every
node, 0 messages lost.

    .venv/bin/python benchmarks/soak.py --sim-s 100000                    # lock-step, 100 000 s simulated
    .venv/bin/python benchmarks/soak.py --pace 1 --wall-s 3600 --load 2   # 1 h real time, + 2 busy processes
    .venv/bin/python benchmarks/soak.py --sim-s 2000 --out /tmp/soak      # a quick check (about 30 s)
    .venv/bin/python benchmarks/soak.py --sim-s 100000 --results          # into the committed results

The results go to out/soak/ unless ``--out`` says otherwise; ``--results`` writes them into
benchmarks/results/soak/, the committed measurements docs/results.md cites (a run there replaced them without a
word before). An existing <name>.json is kept unless ``--overwrite``.

``--load N`` starts N busy-loop processes (nice ``--load-nice``) for the whole
run, on top of whatever else runs on the machine; the load average is
recorded either way.
"""

from __future__ import annotations

import argparse
import csv
import ctypes
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from phfdi.bagio import bag_parts
from wavelet_fdi import alarm_messages

#: /proc/<pid>/status fields sampled (kB)
MEMORY_FIELDS = ("VmRSS", "RssAnon", "RssFile", "RssShmem", "VmHWM")
GROWTH_LIMIT = 0.10  # issue 15: under 10 % from middle to end

#: where a run's files go by default, and with --results (the committed measurements)
SCRATCH_OUT = "out/soak"
RESULTS_OUT = "benchmarks/results/soak"


# ---- measuring ---------------------------------------------------------------------------------
def proc_memory(pid: int) -> dict[str, int] | None:
    """Memory of a live process in kB (MEMORY_FIELDS) and its thread count; None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    out = {}
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key in MEMORY_FIELDS:
            out[key] = int(value.split()[0])
        elif key == "Threads":
            out["Threads"] = int(value)
    return out if "VmRSS" in out else None


class Sampler(threading.Thread):
    """Samples the memory of every node process of a running launcher, the load average and the bag size."""

    def __init__(self, launcher, period_s: float, bag: Path | None, csv_path: Path) -> None:
        super().__init__(name="soak-sampler", daemon=True)
        self.launcher, self.period_s, self.bag = launcher, period_s, bag
        self.rows: list[dict] = []  # one per node and sample
        self.system: list[dict] = []  # one per sample: load average, bag size
        self.t0 = time.monotonic()
        self.stop_event = threading.Event()
        self._csv = open(csv_path, "w", newline="")
        self._writer = csv.DictWriter(self._csv, ["wall_s", "node", "pid", *MEMORY_FIELDS, "Threads",
                                                  "load1", "bag_bytes"])
        self._writer.writeheader()

    def run(self) -> None:
        try:
            while not self.stop_event.is_set():
                self.sample()
                self.stop_event.wait(self.period_s)
        finally:
            self._csv.close()

    def sample(self) -> None:
        now = time.monotonic() - self.t0
        load1 = os.getloadavg()[0]
        try:
            bag_bytes = sum(p.stat().st_size for p in bag_parts(self.bag)) if self.bag is not None else 0
        except OSError:
            bag_bytes = 0
        self.system.append({"wall_s": now, "load1": load1, "bag_bytes": bag_bytes})
        for name, proc in list(self.launcher.procs.items()):
            mem = proc_memory(proc.popen.pid)
            if mem is None or proc.popen.poll() is not None:
                continue
            row = {"wall_s": round(now, 3), "node": name, "pid": proc.popen.pid, **mem, "load1": load1,
                   "bag_bytes": bag_bytes}
            self.rows.append(row)
            self._writer.writerow(row)
        self._csv.flush()

    def stop(self) -> None:
        self.stop_event.set()
        self.join()


def memory_summary(rows: list[dict], t_connected: float, t_done: float) -> dict[str, dict]:
    """Per node: VmRSS (and its parts) at start, middle and end of the run (see the module docstring)."""
    t_mid = 0.5 * (t_connected + t_done)
    out = {}
    for name in dict.fromkeys(r["node"] for r in rows):
        mine = [r for r in rows if r["node"] == name and t_connected <= r["wall_s"] <= t_done]
        if not mine:
            out[name] = {"samples": 0}
            continue
        start, end = mine[0], mine[-1]
        mid = min(mine, key=lambda r: abs(r["wall_s"] - t_mid))
        second = [r for r in mine if r["wall_s"] >= mid["wall_s"]]
        entry = {"pid": start["pid"], "samples": len(mine),
                 "start_s": start["wall_s"], "middle_s": mid["wall_s"], "end_s": end["wall_s"]}
        for f in ("VmRSS", "RssAnon", "RssFile", "RssShmem"):
            entry[f] = {"start_kb": start[f], "middle_kb": mid[f], "end_kb": end[f],
                        "max_kb": max(r[f] for r in mine)}
        entry["growth_middle_to_end"] = (end["VmRSS"] - mid["VmRSS"]) / mid["VmRSS"]
        entry["anon_growth_middle_to_end"] = ((end["RssAnon"] - mid["RssAnon"]) / mid["RssAnon"]
                                              if mid["RssAnon"] else math.nan)
        entry["rss_slope_kb_per_h"] = _slope_per_hour(second)
        entry["threads_end"] = end.get("Threads")
        out[name] = entry
    return out


def _slope_per_hour(rows: list[dict]) -> float:
    """Least-squares slope of VmRSS over the rows (kB per hour of wall time)."""
    if len(rows) < 3:
        return math.nan
    import numpy as np

    t = np.array([r["wall_s"] for r in rows])
    y = np.array([r["VmRSS"] for r in rows], dtype=float)
    if np.ptp(t) <= 0:
        return math.nan
    return float(np.polyfit(t, y, 1)[0] * 3600.0)


def stamp_check(bags: list[Path], topics: list[str], n_samples: int, dt_ns: int) -> dict[str, dict]:
    """For topics with one message per sample: stamps in the bag (all its files) against the grid 0..n_samples-1."""
    import numpy as np
    from mcap.reader import make_reader

    stamps: dict[str, list[int]] = {t: [] for t in topics}
    for bag in bags:
        with open(bag, "rb") as f:
            for _schema, channel, message in make_reader(f).iter_messages(topics=topics, log_time_order=False):
                stamps[channel.topic].append(message.log_time)
    out = {}
    for topic, s in stamps.items():
        a = np.asarray(s, dtype=np.int64)
        on_grid = a[a % dt_ns == 0] // dt_ns
        valid = on_grid[(on_grid >= 0) & (on_grid < n_samples)]
        distinct = np.unique(valid)
        out[topic] = {"messages": int(len(a)), "off_grid": int(len(a) - len(valid)),
                      "missing_stamps": int(n_samples - len(distinct)),
                      "duplicate_stamps": int(len(valid) - len(distinct)),
                      "in_order": bool(np.all(np.diff(a) > 0)) if len(a) > 1 else True}
    return out


def detector_counts(done: dict) -> dict:
    """The detector node's input counts from its final report, in the physics node's names: its own counters, or
    the multichannel node's channel map (the measured pH stands for /plant/measurement, the valve command for
    /controller/output)."""
    if "diagnostics" in done:
        return done["diagnostics"]
    counts = done["channel_map"]["counts"]
    ph, command = counts["ph_measured"], counts["valve_command_pct"]
    return {"measurements": ph["received"], "controller_outputs": command["received"],
            "commands_missing": command["missing"], "late_controller_outputs": command["late"]}


def message_summary(result, n_samples: int, dt_ns: int) -> dict:
    """Messages lost: published vs recorded per topic, stamps of per-sample topics, the detector's inputs."""
    from phfdi_base.topics import BY_NAME, CONTROLLER, MEASUREMENT

    recorded = {t["topic"]: t["count"] for t in (result.bag or {}).get("topics", [])}
    topics = {}
    for topic in dict.fromkeys([*recorded, *result.published]):
        pub = result.published.get(topic, 0)
        if topic not in recorded and pub == 0:
            continue  # e.g. /clock: nobody subscribes, nothing published
        rec = recorded.get(topic, 0) if topic in BY_NAME else None
        topics[topic] = {"published": pub, "recorded": rec, "lost": None if rec is None else pub - rec}
    per_sample = [t for t in recorded if t in BY_NAME and BY_NAME[t].per_sample]
    files = [Path(p) for p in result.bag.get("parts", [result.bag["path"]])] if result.bag else []
    stamps = stamp_check(files, per_sample, n_samples, dt_ns) if files else {}
    for topic, s in stamps.items():
        topics[topic].update(s)
    done = [e for e in result.node_events.get("detector", []) if e.get("event") == "detector_done"]
    detector = {}
    if done:
        diag = detector_counts(done[-1])
        detector = {"measurements_received": diag.get("measurements"),
                    "controller_outputs_received": diag.get("controller_outputs"),
                    "samples_processed": done[-1]["samples"],
                    "commands_missing": diag.get("commands_missing"),
                    "late_controller_outputs": diag.get("late_controller_outputs"),
                    "alarms": [{k: a.get(k) for k in ("onset_time", "detection_time", "fault_class", "confidence")}
                               for a in alarm_messages.from_summaries(done[-1]["alarms"])],
                    "lag": done[-1].get("lag")}
        detector["measurements_lost"] = result.published.get(MEASUREMENT.name, 0) - (detector["measurements_received"] or 0)
        detector["controller_outputs_lost"] = (result.published.get(CONTROLLER.name, 0)
                                               - (detector["controller_outputs_received"] or 0))
    lost_bag = sum(max(0, t["lost"]) for t in topics.values() if t["lost"] is not None)
    lost_stamps = sum(s["missing_stamps"] for s in stamps.values())
    lost_detector = (max(0, detector.get("measurements_lost", 0)) + max(0, detector.get("controller_outputs_lost", 0))
                     if detector else None)
    ring_complete = result.samples_done == n_samples and result.status == 0
    return {"topics": topics, "detector": detector, "ring_complete": ring_complete,
            "samples": n_samples, "samples_done": result.samples_done,
            "lost_recorder": lost_bag, "lost_stamps": lost_stamps, "lost_detector": lost_detector,
            "lost_total": lost_bag + lost_stamps + (lost_detector or 0) + (0 if ring_complete else 1)}


# ---- load ------------------------------------------------------------------------------------------
def _die_with_parent() -> None:
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def start_load(n: int, niceness: int) -> list[subprocess.Popen]:
    """n busy-loop processes (pure CPU, no memory), niced; ended by stop_load (and with this process)."""
    def pre() -> None:  # absolute niceness (os.nice adds to the caller's, e.g. a soak run under nice -n 10)
        own = os.getpriority(os.PRIO_PROCESS, 0)
        os.setpriority(os.PRIO_PROCESS, 0, max(own, min(19, niceness)))
        _die_with_parent()

    return [subprocess.Popen([sys.executable, "-S", "-c", "while True: pass"], stdin=subprocess.DEVNULL,
                             preexec_fn=pre) for _ in range(n)]


def stop_load(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait()


# ---- report ------------------------------------------------------------------------------------------
def print_table(summary: dict) -> None:
    mem = summary["memory"]
    print(f"\nVmRSS in MiB\n{'node':12s} {'start':>10s} {'middle':>10s} {'end':>10s} {'max':>10s} {'mid->end':>9s} "
          f"{'anon mid->end':>14s} {'slope 2nd half':>15s}")
    for name, m in mem.items():
        if not m.get("samples"):
            print(f"{name:12s} (no sample during the run)")
            continue
        r = m["VmRSS"]
        print(f"{name:12s} {r['start_kb'] / 1024:10.1f} {r['middle_kb'] / 1024:10.1f} {r['end_kb'] / 1024:10.1f} "
              f"{r['max_kb'] / 1024:10.1f} {100 * m['growth_middle_to_end']:+8.2f}% "
              f"{100 * m['anon_growth_middle_to_end']:+13.2f}% {m['rss_slope_kb_per_h'] / 1024:+9.2f} MiB/h")
    msgs = summary["messages"]
    print(f"\n{'topic':22s} {'published':>10s} {'recorded':>10s} {'lost':>6s} {'missing stamps':>15s} "
          f"{'duplicates':>10s}")
    for topic, t in msgs["topics"].items():
        print(f"{topic:22s} {t['published']:10d} {t['recorded'] if t['recorded'] is not None else '-':>10} "
              f"{t['lost'] if t['lost'] is not None else '-':>6} {t.get('missing_stamps', '-'):>15} "
              f"{t.get('duplicate_stamps', '-'):>10}")
    d = msgs["detector"]
    if d:
        print(f"detector received {d['measurements_received']} measurements ({d['measurements_lost']} lost), "
              f"{d['controller_outputs_received']} controller outputs ({d['controller_outputs_lost']} lost); "
              f"core processed {d['samples_processed']} samples; alarms: "
              + (", ".join(f"{a['detection_time']:g} s {a['fault_class']}" for a in d["alarms"]) or "none"))
    w = summary["wall"]
    ld = summary["load"]
    print(f"ring: {msgs['samples_done']} of {msgs['samples']} samples; messages lost in all: {msgs['lost_total']}")
    print(f"wall: start-up {w['connect_s']:.1f} s, run {w['run_s']:.1f} s ({summary['sim_s'] / w['run_s']:.0f} x "
          f"real time), total {w['total_s']:.1f} s; bag {summary['bag_bytes'] / 1e6:.2f} MB "
          f"({summary['bag_messages']} messages, {summary.get('bag_files', 1)} files); load average "
          f"min {ld['load1_min']:.1f} median {ld['load1_median']:.1f} max {ld['load1_max']:.1f} on "
          f"{os.cpu_count()} cores (+{ld['busy_processes']} busy processes of ours)")
    v = summary["acceptance"]
    print(f"acceptance: growth < 10 % for every node: {'met' if v['memory'] else 'NOT met'}; 0 lost: "
          f"{'met' if v['no_loss'] else 'NOT met'}")


def plot(summary: dict, rows: list[dict], system: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = summary["wall"]["t_connected"]
    span = summary["wall"]["t_done"] - t0
    scale, unit = (60.0, "min") if span > 1200 else (1.0, "s")
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    for name in summary["memory"]:
        mine = [r for r in rows if r["node"] == name]
        ax.plot([(r["wall_s"] - t0) / scale for r in mine], [r["VmRSS"] / 1024 for r in mine], label=name)
    for key, label in (("t_mid", "middle"), ("t_done", "end")):
        x = (summary["wall"][key] - t0) / scale
        ax.axvline(x, color="0.5", ls="--", lw=0.8)
        ax.annotate(label, (x, 1.0), xycoords=("data", "axes fraction"), ha="right", va="top", fontsize=8)
    for a in summary.get("alarms_wall", []):
        x = (a["wall_s"] - t0) / scale
        ax.axvline(x, color="tab:red", ls=":", lw=0.8)
        ax.annotate(f"detector {a['kind']}", (x, 0.02), xycoords=("data", "axes fraction"), rotation=90,
                    ha="right", va="bottom", fontsize=7, color="tab:red")
    ax.set_ylabel("resident memory VmRSS (MiB)")
    ax.set_title(summary["title"], fontsize=10)
    ax.legend(fontsize=8, ncol=3)
    ax.grid(alpha=0.3)
    ax2.plot([(s["wall_s"] - t0) / scale for s in system], [s["load1"] for s in system], color="k", lw=0.8)
    ax2.set_ylabel("load average\n(1 min)")
    ax2.set_xlabel(f"wall time since the graph connected ({unit})")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- main ----------------------------------------------------------------------------------------------
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sim-s", type=float, default=None, help="simulated seconds to run (default 100000)")
    ap.add_argument("--wall-s", type=float, default=None, help="wall seconds to run at --pace (sim = wall x pace)")
    ap.add_argument("--pace", type=float, default=0.0, help="0: lock-step as fast as possible; F: F x real time")
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--fault", default="backlash", help="fault injected (default backlash; 'healthy' for none)")
    ap.add_argument("--onset-frac", type=float, default=0.7, help="fault onset as a fraction of the run (0.7)")
    ap.add_argument("--sample-s", type=float, default=1.0, help="memory sampling period (s, wall)")
    ap.add_argument("--load", type=int, default=0, help="start N busy-loop processes for the whole run")
    ap.add_argument("--load-nice", type=int, default=10,
                    help="niceness of the busy processes (default 10; never below this script's own)")
    ap.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default: a free one)")
    ap.add_argument("--out", default=None,
                    help=f"folder for the JSON, CSV, figure and bag (default {SCRATCH_OUT}; --results: {RESULTS_OUT})")
    ap.add_argument("--results", action="store_true",
                    help=f"write into {RESULTS_OUT} (the committed results) instead of {SCRATCH_OUT}")
    ap.add_argument("--overwrite", action="store_true", help="replace an earlier run's <name>.json of the same name")
    ap.add_argument("--name", default=None, help="file name stem (default soak_<lockstep|paceF>_<sim>s)")
    ap.add_argument("--keep-bag", action="store_true", help="keep the bag (default: deleted after measuring)")
    ap.add_argument("--split-s", type=float, default=0.0,
                    help="recorder: a new bag file every this many s of simulated time (0: one file)")
    ap.add_argument("--replot", metavar="RUN.json", default=None,
                    help="only redraw the figure and reprint the table of a finished run")
    args = ap.parse_args(argv)
    if args.wall_s is not None:
        if args.pace <= 0:
            ap.error("--wall-s needs --pace F > 0 (the simulated time is wall x pace)")
        args.sim_s = args.wall_s * args.pace
    if args.sim_s is None:
        args.sim_s = 100000.0
    if not (math.isfinite(args.sim_s) and args.sim_s >= 10):
        ap.error(f"--sim-s {args.sim_s}: give at least 10 s")
    if not 0.0 < args.onset_frac < 1.0:
        ap.error("--onset-frac: give a fraction between 0 and 1")
    if args.load < 0 or args.sample_s <= 0:
        ap.error("--load must be >= 0 and --sample-s > 0")
    if args.name is None:
        mode = "lockstep" if args.pace <= 0 else f"pace{args.pace:g}"
        args.name = f"soak_{mode}_{args.sim_s:g}s"
    if args.out is not None and args.results:
        ap.error("give --out DIR or --results, not both")
    args.out = args.out or (RESULTS_OUT if args.results else SCRATCH_OUT)
    return args


def replot(json_path: Path) -> None:
    """Redraw the figure and reprint the table of a finished run from its JSON and CSV."""
    summary = json.loads(json_path.read_text())
    stem = json_path.with_suffix("")
    with open(f"{stem}_rss.csv", newline="") as f:
        rows = [{k: (v if k == "node" else float(v)) for k, v in r.items()} for r in csv.DictReader(f)]
    system = list({r["wall_s"]: {"wall_s": r["wall_s"], "load1": r["load1"]} for r in rows}.values())
    print_table(summary)
    plot(summary, rows, system, Path(f"{stem}_rss.png"))
    print(f"wrote {stem}_rss.png")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.replot is not None:
        replot(Path(args.replot))
        return 0
    from phfdi.ros.launcher import Launcher, loop_graph
    from phfdi.scenario import load_scenario
    from phfdi_base.errors import UserError
    from phfdi_base.topics import sample_period_ns

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if (out / f"{args.name}.json").exists() and not args.overwrite:
        print(f"soak: error: {out / (args.name + '.json')} exists (an earlier run's results): give --overwrite, "
              f"another --name or another --out", file=sys.stderr)
        return 2
    bag = (out / f"{args.name}.mcap").resolve()
    if bag_parts(bag):
        print(f"soak: error: {bag} exists: remove it (and its parts {bag.stem}.N.mcap) or give another --name",
              file=sys.stderr)
        return 2
    fault = None if args.fault == "healthy" else args.fault
    overrides = [f"duration_s={args.sim_s}"]
    if args.scenario == "paper" and args.sim_s <= 5000:  # its setpoint step (5000 s) inside a short run
        overrides.append(f"setpoints.ph.changes.0.at_s={args.sim_s / 2}")
    onset = args.onset_frac * args.sim_s if fault else None
    try:
        spec = load_scenario(args.scenario, fault=args.fault, overrides=overrides, onset_s=onset)
    except UserError as exc:
        print(f"soak: error: {exc}", file=sys.stderr)
        return 2
    n = int(round(spec.duration_s / spec.sample_time_s)) + 1
    dt_ns = sample_period_ns(spec.sample_time_s)
    expect = f"about {args.sim_s / args.pace:.0f} s" if args.pace > 0 else "as fast as the graph runs"
    print(f"soak {args.name}: {spec.name}, {n} samples ({args.sim_s:g} s simulated), "
          + (f"pace {args.pace:g} x real time" if args.pace > 0 else "lock-step") + f", wall {expect}; "
          f"fault {args.fault} at {onset if onset is not None else '-'} s; load average now "
          f"{os.getloadavg()[0]:.1f}; {args.load} busy processes (nice {args.load_nice}) added", flush=True)

    nodes = loop_graph(args.scenario, args.fault, onset, overrides, bag, args.pace, detector={},
                       split_after_s=args.split_s)
    load = start_load(args.load, args.load_nice)
    load_nice = sorted({os.getpriority(os.PRIO_PROCESS, p.pid) for p in load})
    t_start = time.monotonic()
    marks: dict[str, float] = {}
    sampler_box: list[Sampler] = []

    def progress(fraction: float) -> None:
        now = time.monotonic()
        if fraction >= 1.0:
            marks.setdefault("done", now)
        s = sampler_box[0] if sampler_box else None
        mem = {}
        if s is not None:
            for r in reversed(s.rows[-20:]):
                mem.setdefault(r["node"], r["VmRSS"])
        elapsed = now - marks.get("connected", t_start)
        eta = elapsed * (1 - fraction) / fraction if fraction > 0 else math.nan
        print(f"[{100 * fraction:5.1f} %] {fraction * args.sim_s:9.0f} s simulated, {elapsed:7.0f} s wall, "
              f"ETA {eta:6.0f} s; load {os.getloadavg()[0]:.1f}; RSS MiB "
              + " ".join(f"{k} {v / 1024:.0f}" for k, v in mem.items()), flush=True)

    def status(text: str) -> None:
        if text.startswith("graph connected"):
            marks["connected"] = time.monotonic()
        print(f"soak: {text}", flush=True)

    alarms_at: list[dict] = []  # wall time of the detector's alarms and diagnoses (the isolation runs before)

    def on_event(node: str, event: dict) -> None:
        if event.get("event") == "fault_alarm" and event.get("kind") in ("alarm", "diagnosis"):
            alarms_at.append({"wall_s": time.monotonic() - t_start, "kind": event["kind"],
                              "time_s": event.get("time_s")})

    launcher = Launcher(nodes, domain_id=args.domain_id, log_dir=out / f"{args.name}_logs", progress=progress,
                        status=status, on_event=on_event)
    sampler = Sampler(launcher, args.sample_s, bag, out / f"{args.name}_rss.csv")
    sampler.t0 = t_start
    sampler_box.append(sampler)
    sampler.start()
    try:
        result = launcher.run()
    finally:
        sampler.stop()
        stop_load(load)
    t_end = time.monotonic()
    if result.status != 0 or "connected" not in marks:
        print(f"soak: the graph run failed: {result.failure or result.notes}; logs in {result.log_dir}",
              file=sys.stderr)
    t_connected = marks.get("connected", t_start) - t_start
    t_done = marks.get("done", t_end) - t_start
    messages = message_summary(result, n, dt_ns)
    memory = memory_summary(sampler.rows, t_connected, t_done)
    loads = sorted(s["load1"] for s in sampler.system) or [math.nan]
    summary = {
        "title": (f"soak: {args.sim_s:g} s simulated, "
                  + (f"pace {args.pace:g}" if args.pace > 0 else "lock-step")
                  + f", {spec.name}, +{args.load} busy processes"
                  + (f", a bag file every {args.split_s:g} s" if args.split_s > 0 else "")),
        "command": " ".join([Path(sys.argv[0]).as_posix(), *(argv if argv is not None else sys.argv[1:])]),
        "scenario": spec.name, "fault": args.fault, "onset_s": onset, "sim_s": args.sim_s, "pace": args.pace,
        "samples": n, "domain_id": result.domain_id, "status": result.status, "failure": result.failure,
        "notes": result.notes, "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
        "cores": os.cpu_count(),
        "wall": {"connect_s": result.connect_s, "run_s": result.run_wall_s, "total_s": t_end - t_start,
                 "t_connected": t_connected, "t_mid": 0.5 * (t_connected + t_done), "t_done": t_done},
        "load": {"busy_processes": args.load, "busy_nice": load_nice, "busy_pids": [p.pid for p in load], "load1_min": loads[0],
                 "load1_median": loads[len(loads) // 2], "load1_max": loads[-1]},
        "bag_bytes": sum(p.stat().st_size for p in bag_parts(bag)), "bag_files": len(bag_parts(bag)),
        "bag_messages": (result.bag or {}).get("messages"),
        "memory": memory, "messages": messages, "alarms_wall": alarms_at,
    }
    summary["acceptance"] = {
        "memory": bool(memory) and all(m.get("samples") and m["growth_middle_to_end"] < GROWTH_LIMIT
                                       for m in memory.values()),
        "no_loss": messages["lost_total"] == 0,
    }
    (out / f"{args.name}.json").write_text(json.dumps(summary, indent=1, default=str))
    print_table(summary)
    if sampler.rows:
        plot(summary, sampler.rows, sampler.system, out / f"{args.name}_rss.png")
    print(f"wrote {out / (args.name + '.json')}, {args.name}_rss.csv, {args.name}_rss.png")
    if not args.keep_bag:
        for part in bag_parts(bag):
            part.unlink()
    return 0 if result.status == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
