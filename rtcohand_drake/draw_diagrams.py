"""Draws the project's Drake diagrams into diagrams/ from the code.

    python -m rtcohand_drake.draw_diagrams           # writes diagrams/*.dot and, with Graphviz, *.svg
    python -m rtcohand_drake.draw_diagrams --check   # exit 1 if a committed .dot is stale

Each diagram's Graphviz text comes from Drake's `GetGraphvizString`; system
ids are renumbered in order of appearance so the text does not depend on how
many systems a process built before. SVGs need Graphviz's `dot`
(`apt-get install -y graphviz`); the check compares the .dot files only.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Callable, Sequence

DIAGRAM_DIR = Path(__file__).resolve().parent.parent / "diagrams"


def canonical_dot(text: str) -> str:
    """Renumbers Drake's system ids (s123, cluster123..., clusters123in, _123) by first appearance, sorts the edges."""
    ids: dict[str, str] = {}

    def renumber(match: re.Match) -> str:
        prefix, number = match.group(1), match.group(2)
        ids.setdefault(number, str(len(ids) + 1))
        return prefix + ids[number]

    text = re.sub(r"\b(clusters|cluster|s|_)(\d+)", renumber, text)
    # Drake lists connections in no fixed order: sort each run of edge lines.
    lines, out, run = text.split("\n"), [], []
    for line in lines + [""]:
        if " -> " in line:
            run.append(line)
            continue
        out.extend(sorted(run))
        run = []
        out.append(line)
    return "\n".join(out[:-1])


def _scripted():
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.scenario import load_scenario

    return build_run_diagram(load_scenario("inspection")).diagram


def _gestures():
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.cell.robot_files import models_dir
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person
    from rtcohand_drake.systems.policy import CchpPolicy
    from rtcohand_drake.scenario import load_scenario

    from rtcohand_drake.learning.policy_file import reads_path_shape

    scenario = load_scenario("inspection")
    model = models_dir() / scenario.policy.model
    source, pieces = make_builtin_person(scenario, seed=0, path_shape=reads_path_shape(model))
    policy = CchpPolicy.from_scenario(model, pieces, scenario.policy)
    return build_run_diagram(scenario, source=source, policy=policy).diagram


def _station():
    from rtcohand_drake.scenario import load_scenario
    from rtcohand_drake.stations.sim import make_sim_station

    return make_sim_station(load_scenario("inspection"))


DIAGRAMS: dict[str, Callable] = {
    "run_gestures": _gestures,   # the product: gesture source -> policy -> filter -> safety -> diff IK -> station
    "run_scripted": _scripted,   # a scripted twist sequence through the same safety and diff IK
    "station": _station,         # inside the simulated station
}


def dot_texts() -> dict[str, str]:
    return {name: canonical_dot(build().GetGraphvizString(max_depth=1)) for name, build in DIAGRAMS.items()}


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m rtcohand_drake.draw_diagrams", description=__doc__.split("\n")[0])
    p.add_argument("--check", action="store_true", help="only check that diagrams/*.dot are current")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    texts = dot_texts()
    if args.check:
        stale = [n for n, t in texts.items()
                 if not (DIAGRAM_DIR / f"{n}.dot").is_file() or (DIAGRAM_DIR / f"{n}.dot").read_text() != t]
        if stale:
            print(f"stale diagrams: {', '.join(stale)}; run python -m rtcohand_drake.draw_diagrams", file=sys.stderr)
            return 1
        print("diagrams are current")
        return 0
    DIAGRAM_DIR.mkdir(exist_ok=True)
    dot = shutil.which("dot")
    for name, text in texts.items():
        path = DIAGRAM_DIR / f"{name}.dot"
        path.write_text(text)
        if dot:
            subprocess.run([dot, "-Tsvg", str(path), "-o", str(path.with_suffix(".svg"))], check=True)
        print(f"wrote {path}" + (" and .svg" if dot else " (no Graphviz: no .svg)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
