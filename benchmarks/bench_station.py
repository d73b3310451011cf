"""Real-time factor of the inspection station with differential IK, headless.

    python benchmarks/bench_station.py [--repeats 5] [--duration 40]

Builds the run diagram (scripted twist -> diff-IK -> simulated Gen3 station,
with the run-log sinks), simulates the scenario as fast as possible and prints
the median simulated-seconds per wall-second over the repeats. Diagram
construction is not timed.
"""

import argparse
import statistics
import time

from pydrake.systems.analysis import Simulator

from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.scenario import load_scenario


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="inspection")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--duration", type=float, default=40.0)
    args = p.parse_args()
    scenario = load_scenario(args.scenario)
    factors = []
    for _ in range(args.repeats):
        run = build_run_diagram(scenario)
        simulator = Simulator(run.diagram)
        simulator.Initialize()
        start = time.perf_counter()
        simulator.AdvanceTo(args.duration)
        factors.append(args.duration / (time.perf_counter() - start))
    print(f"station + diff-IK, {args.duration:.0f} s of '{scenario.name}', "
          f"plant step {scenario.plant_time_step_s * 1e3:.0f} ms, IK period {scenario.control_period_s * 1e3:.0f} ms")
    print(f"real-time factor: median {statistics.median(factors):.1f}x "
          f"(min {min(factors):.1f}x, max {max(factors):.1f}x, {args.repeats} runs)")


if __name__ == "__main__":
    main()
