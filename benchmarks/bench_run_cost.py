"""What one headless run costs: start-up against simulation, in a fresh process and in a study's worker.

    python benchmarks/bench_run_cost.py [--repeats 3] [--compare-to OTHER_CHECKOUT] [--out FILE.json]

The run is the default one (`python -m rtcohand_drake.run --scenario
inspection --realtime-rate 0 --no-meshcat`: the built-in person u10 of
population 0, the shipped policy, until the hold after the sixth face).

- **Fresh process**: the command itself, `--repeats` times. The total wall
  time, the simulation's wall time (the run's own "simulated in" line), and
  the rest: imports, parsing the models, building the diagram, scoring,
  writing.
- **Warm worker**: `run.main` called `--repeats` times in one process, as a
  study's worker calls it for run after run. The first call pays the
  imports; the others show what start-up still costs once they are done.

The figures are medians over the repeats. The real-time factor is
simulated seconds per wall second of the simulation alone.
`--compare-to DIR` measures another checkout (its `rtcohand_drake` first
on the path), interleaved with this one, so the ratio comes from one run on
the same machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RUN = ["-m", "rtcohand_drake.run", "--scenario", "inspection", "--realtime-rate", "0", "--no-meshcat"]
SIMULATED = re.compile(r"([0-9.]+) s simulated in ([0-9.]+) s")

WORKER = r"""
import contextlib, io, json, re, sys, time
from rtcohand_drake.run import main
rows = []
for i in range(int(sys.argv[1])):
    out = io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(out):
        status = main(["--scenario", "inspection", "--realtime-rate", "0", "--no-meshcat"])
    total = time.perf_counter() - t
    m = re.search(r"([0-9.]+) s simulated in ([0-9.]+) s", out.getvalue())
    rows.append({"status": status, "total_s": total, "sim_s": float(m.group(1)), "sim_wall_s": float(m.group(2))})
print(json.dumps({"rows": rows}))
"""


def _env(checkout: Path) -> dict:
    """The environment that runs `checkout`'s code with `checkout`'s model files: its `rtcohand_drake`
    first on the path, and its `models/` as the models package (`rtcohand_drake_models`, which an
    editable install otherwise maps to the installed checkout's), through a link in a folder of its own."""
    env = dict(os.environ)
    links = Path(tempfile.gettempdir()) / f"bench_run_cost_models_{hashlib.sha1(str(checkout).encode()).hexdigest()[:12]}"
    link = links / "rtcohand_drake_models"
    if not link.exists():
        links.mkdir(exist_ok=True)
        link.symlink_to(checkout / "models", target_is_directory=True)
    env["PYTHONPATH"] = os.pathsep.join([str(checkout), str(links)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def check_checkout(checkout: Path) -> None:
    """Fails unless `checkout`'s run would load its own code and its own model files."""
    probe = ("import rtcohand_drake; from rtcohand_drake.cell.robot_files import models_dir; "
             "print(rtcohand_drake.__file__); print(models_dir())")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=_env(checkout), cwd=checkout)
    found = [Path(line).resolve() for line in done.stdout.split()]
    if done.returncode or len(found) != 2 or not all(f.is_relative_to(checkout.resolve()) for f in found):
        raise SystemExit(f"error: {checkout} would not run its own code and models: {found or done.stderr.strip()}")


def fresh(checkout: Path) -> dict:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *RUN], capture_output=True, text=True, env=_env(checkout), cwd=checkout)
    total = time.perf_counter() - t0
    if done.returncode:
        raise SystemExit(f"error: the run failed in {checkout}: {(done.stderr.strip().splitlines() or [''])[-1]}")
    m = SIMULATED.search(done.stdout)
    return {"total_s": total, "sim_s": float(m.group(1)), "sim_wall_s": float(m.group(2))}


def warm(checkout: Path, repeats: int) -> list[dict]:
    done = subprocess.run([sys.executable, "-c", WORKER, str(repeats)], capture_output=True, text=True,
                          env=_env(checkout), cwd=checkout)
    if done.returncode:
        raise SystemExit(f"error: the worker failed in {checkout}: {(done.stderr.strip().splitlines() or [''])[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])["rows"]


def summary(rows: list[dict]) -> dict:
    med = lambda k: statistics.median(r[k] for r in rows)  # noqa: E731
    return {"total_s": med("total_s"), "sim_wall_s": med("sim_wall_s"), "startup_s": med("total_s") - med("sim_wall_s"),
            "sim_s": med("sim_s"), "realtime_factor": statistics.median(r["sim_s"] / r["sim_wall_s"] for r in rows)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--compare-to", type=Path, default=None, help="another checkout, measured interleaved")
    p.add_argument("--out", type=Path, default=None, help="write the figures as JSON")
    args = p.parse_args(argv)
    from rtcohand_drake.repo_paths import checkout_commit

    checkouts = {"this": REPO} | ({"other": args.compare_to.resolve()} if args.compare_to else {})
    for path in checkouts.values():
        check_checkout(path)
    rows = {name: {"fresh": [], "warm": []} for name in checkouts}
    for _ in range(args.repeats):
        for name, path in checkouts.items():
            rows[name]["fresh"].append(fresh(path))
    for name, path in checkouts.items():
        rows[name]["warm"] = warm(path, args.repeats + 1)
    result = {}
    print("| code | fresh process: total | of it simulating | start-up and the rest | real-time factor "
          "| warm worker: total (runs 2..) | start-up and the rest |")
    print("|---|---|---|---|---|---|---|")
    for name, path in checkouts.items():
        f = summary(rows[name]["fresh"])
        w = summary(rows[name]["warm"][1:])
        # The checkout by its commit: the results file is committed, and its folder means nothing elsewhere.
        result[name] = {"checkout": checkout_commit(path), "fresh": f, "warm_after_first": w, "warm_first": rows[name]["warm"][0],
                        "rows": rows[name]}
        print(f"| {name} ({path.name}) | {f['total_s']:.1f} s | {f['sim_wall_s']:.2f} s ({f['sim_s']:.1f} s simulated) "
              f"| {f['startup_s']:.1f} s | {f['realtime_factor']:.1f}x | {w['total_s']:.1f} s | {w['startup_s']:.1f} s |")
    if "other" in result:
        a, b = result["this"], result["other"]
        print(f"ratios this / other: fresh total {a['fresh']['total_s'] / b['fresh']['total_s']:.2f}, "
              f"start-up {a['fresh']['startup_s'] / b['fresh']['startup_s']:.2f}, warm worker total "
              f"{a['warm_after_first']['total_s'] / b['warm_after_first']['total_s']:.2f}")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
