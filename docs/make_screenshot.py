"""Screenshots the inspection cell in Meshcat during a scripted run (README picture).

    python docs/make_screenshot.py --time 20 --out docs/images/inspection_cell.png

Needs Chromium (`apt-get install -y chromium`).
"""

import argparse

from pydrake.geometry import Meshcat, MeshcatParams
from pydrake.systems.analysis import Simulator

from rtcohand_drake.browser import screenshot
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.scenario import load_scenario


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="inspection")
    p.add_argument("--time", type=float, default=20.0, help="simulated seconds before the picture")
    p.add_argument("--camera", type=float, nargs=3, default=[1.9, 0.9, 1.1])
    p.add_argument("--target", type=float, nargs=3, default=[0.25, 0.25, 0.25])
    p.add_argument("--out", default="docs/images/inspection_cell.png")
    args = p.parse_args()
    meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
    run = build_run_diagram(load_scenario(args.scenario), meshcat=meshcat)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(args.time)
    run.diagram.ForcedPublish(simulator.get_context())
    meshcat.SetCameraPose(args.camera, args.target)
    print(f"wrote {screenshot(meshcat.web_url(), args.out)}")


if __name__ == "__main__":
    main()
