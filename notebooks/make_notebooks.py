"""Writes the notebooks from their cell sources (run after editing a notebook's text here).

    python notebooks/make_notebooks.py

Notebooks are documentation that runs: tests/test_notebooks.py executes each
one with RTCOHAND_NOTEBOOK_SHORT=1 (short simulated durations, tiny training).
They are committed without outputs.
"""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

SHORT = '''import os
SHORT = os.environ.get("RTCOHAND_NOTEBOOK_SHORT") == "1"  # the tests run every notebook in a short mode'''

BUILD = [
    new_markdown_cell("""# Building the diagram, step by step

The product is one Drake diagram. This notebook builds it piece by piece from
the scenario file, tests one system alone, then runs the whole thing and
looks at the run log. Open the Meshcat URL printed below to watch."""),
    new_code_cell(SHORT + '''
import numpy as np
import matplotlib.pyplot as plt
from pydrake.geometry import Meshcat, MeshcatParams
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from rtcohand_drake.scenario import load_scenario
scenario = load_scenario("inspection")
print(scenario.name, "| plant step", scenario.plant_time_step_s, "s | IK period", scenario.control_period_s, "s")'''),
    new_markdown_cell("""## 1. The station
`make_sim_station` returns a Diagram with a MultibodyPlant (Gen3, gripper,
workpiece, table, mold, glass, inspector) and named ports. The hardware
station serves the same port names."""),
    new_code_cell('''from rtcohand_drake.stations.sim import make_sim_station
station = make_sim_station(scenario)
for i in range(station.num_input_ports()):
    print("in ", station.get_input_port(i).get_name())
for i in range(station.num_output_ports()):
    print("out", station.get_output_port(i).get_name())
ctx = station.CreateDefaultContext()
print("workpiece at start (resting in the mold):", station.GetOutputPort("workpiece.pose").Eval(ctx)[:3].round(3))'''),
    new_markdown_cell("""## 2. One system alone: the differential IK
Fix its input ports and evaluate one discrete update: the joint velocities
that lift the workpiece straight up at 5 cm/s."""),
    new_code_cell('''from rtcohand_drake.systems.diff_ik import make_twist_to_joint_velocity
ik = make_twist_to_joint_velocity(scenario)  # Drake's DifferentialInverseKinematicsSystem inside
ik_ctx = ik.CreateDefaultContext()
ik.GetInputPort("twist_command").FixValue(ik_ctx, [0, 0, 0.05, 0, 0, 0])
ik.GetInputPort("gen3.position_measured").FixValue(ik_ctx, scenario.robot.q0_rad)
update = ik.EvalUniquePeriodicDiscreteUpdate(ik_ctx)
print("joint velocity command (rad/s):", update.get_vector(0).get_value().round(4))'''),
    new_markdown_cell("""## 3. The whole run
`build_run_diagram` wires source -> safety supervisor -> diff IK -> station,
adds the log sinks and, with a Meshcat, the visualiser and overlay. Here the
source is the scenario's scripted twist sequence; `python -m rtcohand_drake.run`
uses the gesture source and the CCHP policy in the same way."""),
    new_code_cell('''from rtcohand_drake.diagram import build_run_diagram, collect_run_log
meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
print("Meshcat:", meshcat.web_url())
run = build_run_diagram(scenario, meshcat=meshcat)
simulator = Simulator(run.diagram)
simulator.AdvanceTo(4.0 if SHORT else 40.0)
log = collect_run_log(run, simulator.get_context(), scenario)
print(len(log.robot_time), "robot samples;", len(log.events), "events")'''),
    new_code_cell('''fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
axes[0].plot(log.command_time, log.command_twist[:, :3]); axes[0].set_ylabel("commanded v (m/s)")
axes[0].legend(["vx", "vy", "vz"], loc="upper right")
axes[1].plot(log.robot_time, log.robot_workpiece_pose[:, :3]); axes[1].set_ylabel("workpiece xyz (m)")
axes[1].set_xlabel("time (s)")
plt.tight_layout()'''),
    new_markdown_cell("""## 4. The diagram, drawn from the code
The same drawing is in `diagrams/` (`python -m rtcohand_drake.draw_diagrams`)."""),
    new_code_cell('''from IPython.display import SVG, display
import shutil, subprocess
from pathlib import Path
import rtcohand_drake
dot = run.diagram.GetGraphvizString(max_depth=1)
if shutil.which("dot"):
    display(SVG(subprocess.run(["dot", "-Tsvg"], input=dot.encode(), capture_output=True).stdout))
else:  # no Graphviz here: the committed drawing of the same diagram
    print("Graphviz (dot) is not installed; showing the committed diagrams/run_scripted.svg")
    display(SVG(filename=str(Path(rtcohand_drake.__file__).parents[1] / "diagrams" / "run_scripted.svg")))'''),
]

TRAIN = [
    new_markdown_cell("""# Training and evaluating a small CCHP model

Generate a small population of simulated users, train CCHP for a few
hundred steps, evaluate it on the paper's six settings, and export it as the
TorchScript policy the diagram loads. The full runs are documented commands in
docs/policy.md; this is the same code at toy scale."""),
    new_code_cell(SHORT + '''
import json, subprocess, sys, tempfile
from pathlib import Path
work = Path(tempfile.mkdtemp())
py = sys.executable
users = 3 if SHORT else 15
subprocess.run([py, "-m", "rtcohand_drake.data.generate", "--out", str(work / "gestures.h5"),
                "--users", str(users), "--seed", "0"], check=True)'''),
    new_code_cell('''steps = 20 if SHORT else 400
subprocess.run([py, "-m", "rtcohand_drake.train", "--data", str(work / "gestures.h5"), "--out", str(work / "cchp"),
                "--model", "cchp", "--steps", str(steps), "--seed", "0", "--quiet"], check=True)
print(sorted(p.name for p in (work / "cchp").iterdir()))'''),
    new_code_cell('''from IPython.display import Image, display
curve = work / "cchp" / "training_curve.png"
if curve.exists():
    display(Image(filename=str(curve)))'''),
    new_code_cell('''subprocess.run([py, "-m", "rtcohand_drake.evaluate", "--data", str(work / "gestures.h5"),
                "--checkpoint", str(work / "cchp" / "checkpoint.pt"), "--out", str(work / "eval")]
               + (["--max-episodes", "5"] if SHORT else ["--noise-sweep", "--spectrum", "--attention"]), check=True)
results = json.loads((work / "eval" / "results.json").read_text())
print(json.dumps(results, indent=1)[:1500])'''),
    new_code_cell('''subprocess.run([py, "-m", "rtcohand_drake.export", "--checkpoint", str(work / "cchp" / "checkpoint.pt"),
                "--out", str(work / "policy.pt")], check=True)
from rtcohand_drake.learning.policy_file import load_policy
policy = load_policy(work / "policy.pt")
print("exported: hidden", int(policy.hidden_size), "latent", int(policy.latent_dim))'''),
]

NEW_USER = [
    new_markdown_cell("""# Customising the policy for a new user

CCHP is not retrained per person: it reads a new user's own labelled clips as
context. Here a user the policy never saw in training (an out-sample user of
the simulated population) records their clips, we look at them, and then the
run uses them as context while the built-in simulated person, acting as that user,
inspects the part."""),
    new_code_cell(SHORT + '''
import subprocess, sys, tempfile
from pathlib import Path
from rtcohand_drake.data.dataset import read_dataset, write_dataset
from rtcohand_drake.data.population import GeneratorConfig, simulate_user
from rtcohand_drake.systems.gestures.simulated_person import population_user_ids
work = Path(tempfile.mkdtemp())
groups = population_user_ids()
user_id = [u for u, g in groups.items() if g == "out-sample"][-1]
print("new user:", user_id, "(", groups[user_id], ")")'''),
    new_code_cell('''# The user's own labelled clips: each is one dominant motion, shown with the gesture this user chose.
profile, clips, _ = simulate_user(GeneratorConfig(), int(user_id[1:]), groups[user_id], seed=0)
write_dataset(work / "my_clips.h5", clips)
print(len(clips), "labelled clips written to", work / "my_clips.h5")
for c in clips[:4]:
    print(c.name, "active dims", list(c.active_dims), "|", c.description[:80])'''),
    new_code_cell('''%matplotlib inline
from IPython.display import display
from rtcohand_drake.data.plots import clip_figure
display(clip_figure(read_dataset(work / "my_clips.h5")[0]))'''),
    new_markdown_cell("""Before the session: how well does the policy read each of this user's gestures?
Each clip is played through the policy with the user's other clips as context (held out, as in
the run). A gain of 1 moves the part at the speed the labels say; a gesture read well below half
its size is worth re-recording, or replacing by a more distinct one
(`python -m rtcohand_drake.context_reading --context-file my_clips.h5` prints the same table)."""),
    new_code_cell('''from rtcohand_drake.analysis.context_reading import clips_from_file, held_out_readings, motion_table
from rtcohand_drake.cell.robot_files import models_dir
from rtcohand_drake.learning.policy_file import load_policy, reads_path_shape
from rtcohand_drake.scenario import load_scenario
model = models_dir() / load_scenario("inspection").policy.model  # the run's own policy file
mine, _ = clips_from_file(work / "my_clips.h5", user_id, rate_hz=10.0, path_shape=reads_path_shape(model))
if SHORT:
    mine = mine[::6]  # a quick look in the short mode
readings = held_out_readings(load_policy(model), mine, folds=3)
for motion, n, gain, word in motion_table(readings):
    print(f"{motion}: reading gain {gain:+.2f} over {n} clip(s): {word}")'''),
    new_code_cell('''duration = "10" if SHORT else "120"
out = subprocess.run([sys.executable, "-m", "rtcohand_drake.run", "--scenario", "inspection", "--no-meshcat",
                      "--realtime-rate", "0", "--duration", duration, "--user", user_id,
                      "--context-file", str(work / "my_clips.h5"), "--context-user", user_id,
                      "--log", str(work / "run.h5")], capture_output=True, text=True)
print(out.stdout or out.stderr)
assert out.returncode == 0'''),
]


def write(name, cells):
    nb = new_notebook(cells=cells, metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                                            "language": "python"}})
    nbformat.write(nb, HERE / name)


if __name__ == "__main__":
    write("01_build_the_diagram.ipynb", BUILD)
    write("02_train_and_evaluate.ipynb", TRAIN)
    write("03_new_user.ipynb", NEW_USER)
    print("wrote the notebooks")
