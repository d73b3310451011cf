"""The package's layout and extension points: what a newcomer relies on when adding a box."""

import ast
import inspect
import json
import pathlib
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import rtcohand_drake
from rtcohand_drake import interfaces
from rtcohand_drake.scenario import load_scenario

PACKAGE = pathlib.Path(rtcohand_drake.__file__).resolve().parent
REPO = PACKAGE.parent


def _modules(folder: pathlib.Path):
    for path in sorted(folder.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield ".".join(parts)


# Modules that must run where Drake is not installed (training machines, the arm's own session).
DRAKE_FREE = [*_modules(PACKAGE / "learning"), "rtcohand_drake.stations.kortex_session",
              "rtcohand_drake.data.dataset", "rtcohand_drake.data.sampling", "rtcohand_drake.data.population",
              "rtcohand_drake.data.hand_features", "rtcohand_drake.data.generate", "rtcohand_drake.cell.geometry"]


def test_learning_and_session_modules_import_no_drake():
    """Each module is imported in a fresh interpreter; the first that brings pydrake in is named."""
    script = (
        "import importlib, json, sys\n"
        f"mods = {json.dumps(DRAKE_FREE)}\n"
        "for m in mods:\n"
        "    importlib.import_module(m)\n"
        "    if any(k == 'pydrake' or k.startswith('pydrake.') for k in sys.modules):\n"
        "        print(m); sys.exit(3)\n"
        "print('clean')\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"imports pydrake: {proc.stdout.strip()} {proc.stderr[-400:]}"
    assert proc.stdout.strip() == "clean"
    assert len([m for m in DRAKE_FREE if m.startswith("rtcohand_drake.learning")]) >= 8


def _is_thin_entry(path: pathlib.Path) -> bool:
    """A few lines that keep a documented `python -m rtcohand_drake.X` command, calling into a folder."""
    tree = ast.parse(path.read_text())
    code = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
    return len(code) <= 2 and all(isinstance(n, (ast.ImportFrom, ast.If)) for n in code)


def test_top_level_holds_at_most_ten_modules_of_substance():
    top = [p for p in PACKAGE.glob("*.py") if p.name != "__init__.py"]
    substantive = sorted(p.name for p in top if not _is_thin_entry(p))
    thin = sorted(p.stem for p in top if _is_thin_entry(p))
    assert len(substantive) <= 10, substantive
    assert set(thin) == {"train", "evaluate", "export", "context_reading", "initial_pose", "study"}
    for folder in ("systems", "stations", "cell", "learning", "data", "analysis"):
        assert (PACKAGE / folder / "__init__.py").is_file(), folder


def test_every_package_folder_is_installed():
    """pyproject's package list names every folder with an __init__.py (else a fresh install misses it)."""
    text = (REPO / "pyproject.toml").read_text()
    listed = set(text[text.index("packages = ["):text.index("]", text.index("packages = ["))].split('"')[1::2])
    found = {".".join(p.parent.relative_to(REPO).parts) for p in PACKAGE.rglob("__init__.py")}
    assert found <= listed, sorted(found - listed)


def test_no_citation_of_a_document_outside_the_repository():
    offenders = []
    for path in list(REPO.glob("rtcohand_drake/**/*.py")) + list(REPO.glob("tests/*.py")) + \
            list(REPO.glob("benchmarks/*.py")) + [REPO / "README.md", REPO / "pyproject.toml"]:
        if ("contracts " + "\u00a7") in path.read_text():
            offenders.append(str(path.relative_to(REPO)))
    assert not offenders
    assert (REPO / "docs" / "interfaces.md").is_file()


def test_no_system_reads_the_whole_scenario():
    """Each Drake system takes its own config (the scenario composes them)."""
    from pydrake.systems.framework import LeafSystem

    import importlib

    checked = 0
    for name in _modules(PACKAGE / "systems"):
        module = importlib.import_module(name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ != name or not issubclass(cls, LeafSystem):
                continue
            params = inspect.signature(cls.__init__).parameters
            assert "scenario" not in params, f"{name}.{cls.__name__} takes the whole scenario"
            checked += 1
    assert checked >= 9


def test_run_command_offers_exactly_the_registered_gesture_sources():
    from rtcohand_drake.run import make_parser
    from rtcohand_drake.systems.gestures.registry import GESTURE_SOURCES

    import importlib

    action = next(a for a in make_parser()._actions if "--gesture-source" in a.option_strings)
    assert tuple(action.choices) == tuple(GESTURE_SOURCES)
    for name, entry in GESTURE_SOURCES.items():
        factory = getattr(importlib.import_module(entry.module), entry.factory)
        assert list(inspect.signature(factory).parameters) == ["options", "scenario"], name


def test_a_registered_gesture_source_drives_a_run(monkeypatch, tmp_path):
    """Registering one row is all a new source needs: the run command builds and logs it."""
    from rtcohand_drake import run as run_module
    from rtcohand_drake.run_log import read_run_log
    from rtcohand_drake.systems.gestures import registry

    module = tmp_path / "still_hand_source.py"
    module.write_text(
        "import numpy as np\n"
        "from rtcohand_drake.systems.gestures.registry import GestureSetup\n"
        "from rtcohand_drake.systems.scripted_twist import ScriptedTwist\n"
        "from rtcohand_drake.systems.scripted_twist import TwistSegment\n"
        "def from_options(options, scenario):\n"
        "    return GestureSetup(ScriptedTwist([TwistSegment(0.5, [0, 0, 0.02, 0, 0, 0])]))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(registry.GESTURE_SOURCES, "still_hand",
                        registry.GestureSourceEntry("still_hand_source", "a test source", uses_policy=False))
    log = tmp_path / "run.h5"
    assert run_module.main(["--gesture-source", "still_hand", "--no-meshcat", "--duration", "0.6",
                            "--log", str(log)]) == 0
    run = read_run_log(log)
    assert run.gesture_source == "still_hand"
    assert np.max(run.command_twist[:, 2]) > 0.01  # the source's twist reached the controller


def test_safety_rules_table_names_every_intervention_once():
    from rtcohand_drake.systems.safety.rules import RULES, Intervention

    flags = [rule.flag for rule in RULES]
    events = [rule.event for rule in RULES]
    assert len(set(flags)) == len(flags) and len(set(events)) == len(events)
    # The two mode flags are logged as mode events (pause, watchdog), every other one by the table.
    assert set(flags) == set(Intervention) - {Intervention.NONE, Intervention.WATCHDOG, Intervention.PAUSED}


def test_a_new_zone_rule_is_one_function_and_one_row(monkeypatch):
    """A rule added to the table acts in the supervisor and becomes its own run-log event."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.diagram import build_run_diagram, collect_run_log
    from rtcohand_drake.scenario import TwistSegment
    from rtcohand_drake.systems.safety import rules

    def no_climbing(twist_U, v_W, p_W, zones):  # a toy rule: never move up
        if v_W[2] > 0:
            v_W = v_W * np.array([1.0, 1.0, 0.0])
            return twist_U, v_W, True
        return twist_U, v_W, False

    flag = rules.Intervention(1 << 10)
    monkeypatch.setattr(rules, "RULES", rules.RULES + (rules.Rule(flag, "no_climbing", no_climbing),))
    scenario = load_scenario("inspection")
    scenario.scripted_motion = [TwistSegment(1.0, [0.0, 0.0, 0.05, 0.0, 0.0, 0.0])]
    run = build_run_diagram(scenario)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(0.6)
    log = collect_run_log(run, simulator.get_context(), scenario)
    assert np.max(np.abs(log.command_twist[:, 2])) < 1e-9  # the rule held the part down
    assert any(e.kind == "no_climbing" for e in log.events)


def test_a_run_stopped_between_two_publishes_still_gives_a_consistent_log():
    """Ctrl-C can land after one sink of a clock has published and before the next has:
    the run log cuts that clock's logs to the samples they all hold, and scores."""
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.analysis.inspection import score_run_log
    from rtcohand_drake.diagram import build_run_diagram, collect_run_log

    scenario = load_scenario("inspection")
    run = build_run_diagram(scenario)
    simulator = Simulator(run.diagram)
    simulator.AdvanceTo(0.25)
    root = simulator.get_context()
    full = collect_run_log(run, root, scenario)
    for name in ("robot_q", "command_twist", "gesture_status"):  # one sink ahead of the others on its clock
        sink_log = run.loggers[name].FindMutableLog(root)
        sink_log.AddData(sink_log.sample_times()[-1] + 0.01, sink_log.data()[:, -1])
    torn = collect_run_log(run, root, scenario)
    assert len(torn.robot_time) == len(torn.robot_q) == len(torn.robot_workpiece_pose) == len(full.robot_time)
    assert len(torn.command_time) == len(torn.command_twist) == len(torn.command_speed_scale) == len(full.command_time)
    assert len(torn.gesture_time) == len(torn.gesture_keypoints) == len(full.gesture_time)
    np.testing.assert_array_equal(torn.robot_q, full.robot_q)
    score_run_log(full, scenario)
    score_run_log(torn, scenario)
    assert (torn.completed, torn.faces_inspected) == (full.completed, full.faces_inspected)


def _mold_cavity_half_xy(sdf: pathlib.Path) -> tuple[float, float]:
    """The cavity's half extents from the mold's wall boxes (inner faces)."""
    walls = {}
    for collision in ET.parse(sdf).getroot().iter("collision"):
        name = collision.get("name")
        if name.startswith("wall_"):
            pose = [float(v) for v in collision.find("pose").text.split()]
            size = [float(v) for v in collision.find("geometry/box/size").text.split()]
            walls[name] = (pose, size)
    x = walls["wall_px"][0][0] - walls["wall_px"][1][0] / 2
    y = walls["wall_py"][0][1] - walls["wall_py"][1][1] / 2
    assert x == pytest.approx(-(walls["wall_nx"][0][0] + walls["wall_nx"][1][0] / 2))
    assert y == pytest.approx(-(walls["wall_ny"][0][1] + walls["wall_ny"][1][1] / 2))
    return x, y


def test_mold_corridor_covers_the_cavity_of_the_mold_model():
    from rtcohand_drake.cell.robot_files import models_dir

    half_x, half_y = _mold_cavity_half_xy(models_dir() / "cell" / "mold.sdf")
    configured = load_scenario("inspection").safety.mold_exit_half_xy_m
    assert configured[0] >= half_x - 1e-9 and configured[1] >= half_y - 1e-9
    assert (half_x, half_y) == pytest.approx((0.083, 0.033))


def test_port_names_live_in_one_place():
    """No module of the diagram or the stations spells a shared port name as a literal."""
    shared = {v for k, v in vars(interfaces).items() if k.isupper() and isinstance(v, str)}
    offenders = []
    for path in list((PACKAGE / "systems").rglob("*.py")) + list((PACKAGE / "stations").rglob("*.py")) + \
            [PACKAGE / "diagram.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", "").endswith(
                    ("InputPort", "OutputPort", "ExportInput", "ExportOutput")):
                for arg in node.args:
                    if isinstance(arg, ast.Constant) and arg.value in shared:
                        offenders.append(f"{path.name}:{node.lineno} {arg.value}")
    assert not offenders
