"""`python -m rtcohand_drake.run`: build the diagram for a scenario, simulate it, log it.

    python -m rtcohand_drake.run --scenario inspection [--duration S]
        [--realtime-rate R] [--no-meshcat] [--seed N] [--log PATH.h5] [--html PATH.html]

Prints the Meshcat URL (unless --no-meshcat), then a summary: faces
inspected, completion time, peak workpiece speeds and events. Bad input exits
with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Sequence

from rtcohand_drake.errors import InputError, run_cli


class _ArgumentParser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line, status 2
        raise InputError(f"command line: {message}")


def make_parser() -> argparse.ArgumentParser:
    p = _ArgumentParser(prog="python -m rtcohand_drake.run", description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="inspection", help="built-in scenario name or path to a YAML file")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the scenario's)")
    p.add_argument("--realtime-rate", type=float, default=None,
                   help="target real-time rate; 0 = as fast as possible (default 1 with Meshcat, 0 without)")
    p.add_argument("--no-meshcat", action="store_true", help="run headless")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--log", type=Path, default=None, help="write the run log (HDF5, contracts §2)")
    p.add_argument("--html", type=Path, default=None,
                   help="save the Meshcat animation as a standalone HTML file (default: beside --log)")
    return p


def _check_args(args) -> None:
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"command line: --duration must be a positive number of seconds, got {args.duration}")
    if args.realtime_rate is not None and not (math.isfinite(args.realtime_rate) and args.realtime_rate >= 0):
        raise InputError(f"command line: --realtime-rate must be >= 0, got {args.realtime_rate}")
    for path in (args.log, args.html):
        if path is not None and not (path.parent if str(path.parent) else Path(".")).is_dir():
            raise InputError(f"{path}: directory {path.parent} does not exist")


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    _check_args(args)
    from rtcohand_drake.scenario import load_scenario

    scenario = load_scenario(args.scenario)

    # Imports that load pydrake and the models come after the argument checks.
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.diagram import build_run_diagram, collect_run_log, peak_speeds
    from rtcohand_drake.inspection import measure_inspection
    from rtcohand_drake.run_log import write_run_log
    from rtcohand_drake.station import eye_position

    meshcat = None
    if not args.no_meshcat:
        from pydrake.geometry import Meshcat, MeshcatParams

        meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
        print(f"Meshcat: {meshcat.web_url()}", flush=True)
    run = build_run_diagram(scenario, meshcat=meshcat)
    duration = args.duration if args.duration is not None else scenario.duration_s
    rate = args.realtime_rate if args.realtime_rate is not None else (1.0 if meshcat else 0.0)

    simulator = Simulator(run.diagram)
    simulator.set_target_realtime_rate(rate)
    if run.visualizer is not None:
        run.visualizer.StartRecording(set_transforms_while_recording=True)
    simulator.Initialize()
    wall_start = time.perf_counter()
    try:
        simulator.AdvanceTo(duration)
    except KeyboardInterrupt:
        print("interrupted: stopping the run and writing what was recorded", file=sys.stderr)
    wall = time.perf_counter() - wall_start
    root = simulator.get_context()
    sim_time = root.get_time()

    log = collect_run_log(run, root, scenario)
    result = measure_inspection(log.robot_time, log.robot_workpiece_pose, eye_position(scenario))
    log.completed, log.faces_inspected, log.completion_time = (
        result.completed, result.faces_inspected, result.completion_time)
    log.extra_attrs["seed"] = args.seed
    log.extra_attrs["sim_duration_s"] = sim_time
    if args.log is not None:
        write_run_log(args.log, log)
    html = args.html or (args.log.with_suffix(".html") if args.log is not None else None)
    if run.visualizer is not None:
        run.visualizer.StopRecording()
        run.visualizer.PublishRecording()
        if html is not None:
            html.write_text(meshcat.StaticHtml())

    v_peak, w_peak = peak_speeds(log.robot_time, log.robot_workpiece_pose)
    completion = f"{log.completion_time:.1f} s" if log.completed else "not completed"
    print(f"scenario {scenario.name}: {sim_time:.1f} s simulated in {wall:.1f} s "
          f"({sim_time / max(wall, 1e-9):.1f}x real time)")
    print(f"faces inspected: {log.faces_inspected}/6, completion: {completion}")
    print(f"peak workpiece speed: {v_peak:.3f} m/s, {w_peak:.3f} rad/s")
    kinds = {}
    for e in log.events:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    print("events: " + (", ".join(f"{k} x{n}" for k, n in sorted(kinds.items())) or "none"))
    if args.log is not None:
        print(f"run log: {args.log}")
    if html is not None and run.visualizer is not None:
        print(f"animation: {html}")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.run"))


if __name__ == "__main__":
    entry_point()
