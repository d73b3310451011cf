"""The study on the distributed engine: its runs, its statistics and the joystick operator it compares against."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from rtcohand_drake.analysis import study
from rtcohand_drake.analysis.engine import distributed_available, run_tasks
from rtcohand_drake.analysis.study_stats import bootstrap_ci, compare, person_time, sign_flip_p
from rtcohand_drake.interfaces import INTENDED_TWIST, TWIST_REQUEST
from rtcohand_drake.run_log import read_run_log
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.systems.joystick import ROTATION, TRANSLATION, Joystick, JoystickMapper, joystick_twist

needs_dask = pytest.mark.skipif(not distributed_available(), reason="the distributed extra is not installed")


# --- the joystick operator's semantics -------------------------------------------------------------------------


def test_joystick_pushes_the_largest_axes_at_the_fixed_speed():
    cfg = Joystick()
    # Translation wanted most (0.1/0.2 = 0.5 of full, against 0.1/0.5 = 0.2): three linear axes wished,
    # the two largest pushed fully, with their signs; the rotation waits.
    mode, twist = joystick_twist(np.array([0.1, -0.06, 0.02, 0.1, 0, 0]), ROTATION, cfg)
    assert mode == TRANSLATION
    np.testing.assert_allclose(twist, [0.2, -0.2, 0, 0, 0, 0])
    # Rotation wanted most: pushed at the angular speed.
    mode, twist = joystick_twist(np.array([0.01, 0, 0, 0, 0, -0.4]), TRANSLATION, cfg)
    assert mode == ROTATION
    np.testing.assert_allclose(twist, [0, 0, 0, 0, 0, -0.5])


def test_joystick_deadband_and_axis_count():
    cfg = Joystick(max_axes=1, deadband=0.15)
    # Below the deadband (0.14 of full speed on every axis): nothing moves, the mode stays.
    mode, twist = joystick_twist(np.array([0.028, 0, 0, 0.07, 0, 0]), ROTATION, cfg)
    assert mode == ROTATION and not twist.any()
    # One axis at a time.
    _, twist = joystick_twist(np.array([0.1, 0.15, 0.12, 0, 0, 0]), TRANSLATION, cfg)
    np.testing.assert_allclose(twist, [0, 0.2, 0, 0, 0, 0])
    # A second axis under the deadband is not pushed even when two are allowed.
    _, twist = joystick_twist(np.array([0.1, 0.02, 0, 0, 0, 0]), TRANSLATION, Joystick())
    np.testing.assert_allclose(twist, [0.2, 0, 0, 0, 0, 0])
    # NaN wishes read as none.
    _, twist = joystick_twist(np.array([np.nan, 0.1, 0, 0, 0, 0]), TRANSLATION, Joystick())
    np.testing.assert_allclose(twist, [0, 0.2, 0, 0, 0, 0])


def _mapper_output(intent, cfg: Joystick, until_s: float):
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.asarray(intent, float)))
    mapper = builder.AddSystem(JoystickMapper(cfg))
    builder.Connect(source.get_output_port(), mapper.GetInputPort(INTENDED_TWIST))
    sink = builder.AddSystem(VectorLogSink(6, publish_period=cfg.period_s))
    builder.Connect(mapper.GetOutputPort(TWIST_REQUEST), sink.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(until_s)
    log = sink.FindLog(simulator.get_context())
    return log.sample_times(), log.data().T


def test_joystick_mode_toggle_dwells_before_moving():
    cfg = Joystick(toggle_dwell_s=0.6, period_s=0.02)
    # The mapper starts in translation: a rotation wish costs a toggle, and nothing moves for 0.6 s.
    t, twist = _mapper_output([0, 0, 0, 0, 0.3, 0], cfg, 1.0)
    moving = np.abs(twist[:, 4]) > 0
    assert not moving[t < 0.6 - 1e-9].any()
    assert moving[t > 0.6 + cfg.period_s + 1e-9].all()
    np.testing.assert_allclose(twist[t > 0.65, 4], 0.5)
    # A translation wish in the starting mode moves at once (from the first update).
    t, twist = _mapper_output([0, 0, 0.1, 0, 0, 0], cfg, 0.2)
    assert (twist[t >= cfg.period_s - 1e-9, 2] == 0.2).all()


# --- each person is their own operator -------------------------------------------------------------------------


def _delay(population: int, user: str = "u10", seed: int = 0) -> float:
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person

    person, _ = make_builtin_person(load_scenario("inspection"), seed=seed, user=user, population_seed=population)
    return person.CreateDefaultContext().get_abstract_state(0).get_value().delay_s


def test_the_person_and_not_only_the_run_seed_sets_the_rhythm():
    from rtcohand_drake.data.population import DEFAULT_SEED

    delays = {p: _delay(p) for p in (101, 102, 103)}
    assert len(set(delays.values())) == 3  # u10 of three populations: three operators
    assert _delay(101, seed=1) != delays[101]
    assert _delay(101) == delays[101]  # deterministic
    # The benchmark population keeps its key (its runs and figures are unchanged): population_seed None.
    from rtcohand_drake.cell.plant import eye_position
    from rtcohand_drake.data.population import GeneratorConfig, simulate_user
    from rtcohand_drake.systems.gestures.simulated_person import SimulatedPerson, population_user_ids

    scenario = load_scenario("inspection")
    generator = GeneratorConfig()
    ids = population_user_ids(generator)
    profile, _, _ = simulate_user(generator, list(ids).index("u10"), ids["u10"], DEFAULT_SEED)
    old = SimulatedPerson(profile, scenario.cell.user_frame.to_rigid_transform(), eye_position(scenario.cell),
                          rate_hz=scenario.policy.rate_hz, seed=0)
    assert old.CreateDefaultContext().get_abstract_state(0).get_value().delay_s == _delay(DEFAULT_SEED)


# --- statistics -----------------------------------------------------------------------------------------------


def _run(t: float | None) -> dict:
    return {"completed": t is not None, "completion_s": t, "faces": 6 if t is not None else 3}


def test_paired_ratios_count_slow_people_at_the_cap_and_leave_out_failed_runs():
    cap = 100.0
    results = {
        "a": {"responsive": {0: _run(30.0), 1: _run(50.0)}, "joystick": {0: _run(20.0), 1: _run(20.0)}},
        "b": {"responsive": {0: _run(None), 1: _run(60.0)}, "joystick": {0: _run(40.0), 1: _run(None)}},
        "c": {"responsive": {0: _run(25.0), 1: None}, "joystick": {0: _run(25.0), 1: _run(25.0)}},
        "d": {"responsive": {0: _run(10.0), 1: _run(10.0)}, "joystick": {0: _run(40.0), 1: _run(40.0)}},
    }
    assert person_time(results["b"]["responsive"], cap) == 80.0
    assert person_time(results["c"]["responsive"], cap) is None
    c = compare(results, "responsive", "joystick", cap, n_boot=500)
    # a: 40/20 = 2; b: (100+60)/2 / ((40+100)/2) = 80/70; d: 10/40; c left out (a failed run).
    expected = {"a": 2.0, "b": 80.0 / 70.0, "d": 0.25}
    assert c.ratios.keys() == expected.keys()
    for person, r in expected.items():
        assert c.ratios[person] == pytest.approx(r)
    assert c.median == pytest.approx(80.0 / 70.0)
    assert c.mean == pytest.approx(np.mean(list(expected.values())))
    assert c.failed_people == ["c"]
    assert c.not_done == {"responsive": 1, "joystick": 1}
    assert c.runs == {"responsive": 6, "joystick": 6}
    # Exact sign-flip test over 3 people: every one of the 8 sign patterns, counted here independently.
    d = np.log(list(expected.values()))
    count = sum(abs(np.dot(s, d)) / 3 >= abs(d.mean()) - 1e-12 for s in itertools.product((1, -1), repeat=3))
    assert c.p_value == pytest.approx(count / 8)
    assert "left out for a failed run: 1 (c)" in c.line()


def test_sign_flip_p_values():
    assert sign_flip_p([1.0, 1.0, 1.0]) == pytest.approx(2 / 8)  # all same sign: the two extreme patterns
    assert sign_flip_p([0.3, 0.1, 0.2, 0.4, 0.5]) == pytest.approx(2 / 32)
    assert sign_flip_p([1.0, -1.0]) == 1.0
    # Many people, a clear effect: the random patterns give a small p-value, never 0.
    rng = np.random.default_rng(0)
    p = sign_flip_p(rng.normal(0.5, 0.3, 40))
    assert 0 < p < 0.001
    # No effect: not significant.
    assert sign_flip_p(rng.normal(0.0, 1.0, 40)) > 0.01


def test_bootstrap_interval_matches_the_normal_theory_for_a_mean():
    rng = np.random.default_rng(1)
    x = rng.normal(1.5, 0.4, 400)
    lo, hi = bootstrap_ci(x, np.mean, n_boot=4000, seed=3)
    half = 1.96 * x.std(ddof=1) / np.sqrt(len(x))
    assert lo == pytest.approx(x.mean() - half, abs=0.15 * half)
    assert hi == pytest.approx(x.mean() + half, abs=0.15 * half)
    # A median's interval holds the median and lies within the data.
    lo, hi = bootstrap_ci(x, np.median, n_boot=2000)
    assert x.min() < lo < np.median(x) < hi < x.max()
    assert bootstrap_ci([2.0, 2.0, 2.0]) == (2.0, 2.0)


# --- the engine ----------------------------------------------------------------------------------------------


def _strip(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "log"}


TINY = [(101, "u10"), (102, "u10")]  # two people: the same user id in two populations


@pytest.mark.slow
@needs_dask
def test_a_two_worker_cluster_gives_the_in_process_results(tmp_path):
    def tasks(folder):
        return [((p, u, c, 0), (p, u, c, str(tmp_path / folder), 0, 2.0)) for p, u in TINY
                for c in ("joystick", "responsive")]

    here = run_tasks(study.run_condition, tasks("here"), workers=0, progress=False)
    cluster = run_tasks(study.run_condition, tasks("cluster"), workers=2, progress=False)
    assert here.engine == "in-process" and cluster.engine.startswith("dask") and cluster.workers == 2
    assert [o.key for o in here.outcomes] == [o.key for o in cluster.outcomes]
    for a, b in zip(here.outcomes, cluster.outcomes):
        assert a.ok and b.ok, (a.error, b.error)
        assert a.attempts == b.attempts == 1
        assert _strip(a.value) == _strip(b.value)
        log_a, log_b = read_run_log(a.value["log"]), read_run_log(b.value["log"])
        np.testing.assert_array_equal(log_a.command_twist, log_b.command_twist)
    # Each person is their own operator: the same user id at the joystick, two populations, two commands.
    joystick = {o.key[0]: read_run_log(o.value["log"]).command_twist for o in here.outcomes if o.key[2] == "joystick"}
    assert joystick[101].shape != joystick[102].shape or not np.array_equal(joystick[101], joystick[102])


@pytest.mark.parametrize("workers", [0, pytest.param(2, marks=needs_dask)])
def test_a_run_that_raises_is_retried_once_then_reported(tmp_path, workers):
    # u99 is no user of the population: the intent run raises the one-line input error each time.
    tasks = [(("bad",), (101, "u99", "intent", str(tmp_path), 0, 1.0)),
             (("good",), (101, "u10", "intent", str(tmp_path), 0, 1.0))]
    report = run_tasks(study.run_condition, tasks, workers=workers, progress=False)
    bad, good = report.outcomes
    assert not bad.ok and bad.attempts == 2 and "unknown user 'u99'" in bad.error
    assert good.ok and good.attempts == 1 and good.value["completed"] is False
    assert report.failed == [bad]
    # Each run reports its process's peak resident memory (a worker's grows with its runs: docs/studies.md).
    assert good.peak_memory_gb > 0.05 and report.peak_memory_gb() == max(
        o.peak_memory_gb for o in report.outcomes if o.peak_memory_gb is not None)
    if workers == 0:  # this process: no more than the kernel's own high-water mark, read after the run
        status = Path("/proc/self/status")
        if status.exists():
            hwm_kb = int(next(line.split()[1] for line in status.read_text().splitlines() if line.startswith("VmHWM:")))
            assert good.peak_memory_gb <= hwm_kb / 1e6 + 1e-9


def test_the_study_command_reports_failures_and_writes_its_files(tmp_path, capsys, monkeypatch):
    # In this process: a person whose runs fail is reported with the error, and the exit status says so.
    # (An unknown user id is refused before any run; here u13's runs raise as a broken run would.)
    from rtcohand_drake.errors import InputError

    run_condition = study.run_condition

    def failing_for_u13(population, user, *rest):
        if user == "u13":
            raise InputError("a run that fails")
        return run_condition(population, user, *rest)

    monkeypatch.setattr(study, "run_condition", failing_for_u13)
    out = tmp_path / "study"
    status = study.main(["--populations", "101", "--users", "u10", "u13", "--conditions", "joystick", "intent",
                         "--cap", "1", "--workers", "0", "--bootstrap", "200", "--out", str(out)])
    assert status == 1
    text = (out / "study.md").read_text()
    assert "Runs failed with an error after a retry (2):" in text
    assert "p101/u13 joystick run seed 0" in text and "a run that fails" in text
    data = json.loads((out / "study.json").read_text())
    run = data["results"]["p101/u10"]["joystick"]["0"]
    assert run["completed"] is False and run["completion_s"] is None and 0 <= run["faces"] < 6  # capped at 1 s
    assert data["results"]["p101/u13"]["intent"]["0"] is None
    assert [c["condition"] for c in data["comparisons"]] == ["intent"]
    assert (out / "study.png").stat().st_size > 0
    assert "Engine: in-process" in text and "largest peak memory of a process that ran them:" in text
    # --resume: the runs with a log are summarised, not run again; only the failed person's runs are.
    logs = out / "logs"
    stamp = {p.name: p.stat().st_mtime_ns for p in logs.glob("*.h5")}
    assert sorted(stamp) == ["p101_u10_intent_s0.h5", "p101_u10_joystick_s0.h5"]
    status = study.main(["--populations", "101", "--users", "u10", "u13", "--conditions", "joystick", "intent",
                         "--cap", "1", "--workers", "0", "--bootstrap", "200", "--out", str(out), "--resume"])
    assert status == 1 and {p.name: p.stat().st_mtime_ns for p in logs.glob("*.h5")} == stamp
    again = json.loads((out / "study.json").read_text())
    assert again["results"]["p101/u10"] == data["results"]["p101/u10"]
    assert "2 more runs summarised from earlier logs" in (out / "study.md").read_text()



def test_the_study_runs_its_gesture_conditions_with_the_policy_file_given(tmp_path):
    """--model: the gesture conditions' runs read that file (their logs say so and carry its stem);
    the joystick's do not, so their logs are shared with a study of the scenario's file."""
    import pathlib

    from rtcohand_drake.run_log import read_run_log

    model = pathlib.Path(__file__).resolve().parents[1] / "models" / "cchp_path_shape.pt"
    out = tmp_path / "study"
    status = study.main(["--populations", "101", "--users", "u10", "--conditions", "responsive", "joystick",
                         "--cap", "1", "--workers", "0", "--bootstrap", "200", "--out", str(out),
                         "--model", str(model)])
    assert status == 0
    logs = out / "logs"
    assert sorted(p.name for p in logs.glob("*.h5")) == ["p101_u10_joystick_s0.h5",
                                                         "p101_u10_responsive_mcchp_path_shape_s0.h5"]
    assert pathlib.Path(read_run_log(str(logs / "p101_u10_responsive_mcchp_path_shape_s0.h5")).model).name == \
        "cchp_path_shape.pt"
    assert "cchp_path_shape.pt" not in read_run_log(str(logs / "p101_u10_joystick_s0.h5")).model
    # The committed summary names the file relative to the repository, not where it was checked out.
    assert json.loads((out / "study.json").read_text())["model"] == "models/cchp_path_shape.pt"
    assert "read the policy file" in (out / "study.md").read_text()
    from rtcohand_drake.errors import InputError

    with pytest.raises(InputError, match="no such policy file"):  # before any run
        study.main(["--model", str(tmp_path / "none.pt"), "--out", str(out)])

@needs_dask
def test_address_joins_an_existing_cluster(tmp_path):
    # A cluster started elsewhere (here: in this test, as `dask scheduler` / `dask worker` would);
    # the study's runs go to it by its address, and the cluster outlives them.
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        report = run_tasks(study.run_condition, [(("p101", "intent"), (101, "u10", "intent", str(tmp_path), 0, 1.0))],
                           address=cluster.scheduler_address, progress=False)
        assert report.engine == f"dask ({cluster.scheduler_address})" and report.workers == 1
        assert report.outcomes[0].ok and report.outcomes[0].value["completed"] is False
        with Client(cluster.scheduler_address) as client:  # still up, its worker still there
            assert len(client.scheduler_info()["workers"]) == 1


@needs_dask
def test_runs_per_worker_restarts_the_workers_between_batches():
    # os.getpid as the task: which process ran it. With one run per worker and 2 workers, the second
    # batch runs in fresh processes; with no restarts, the 4 runs share the 2 workers.
    import os

    tasks = [(i, ()) for i in range(4)]
    recycled = run_tasks(os.getpid, tasks, workers=2, progress=False, runs_per_worker=1)
    assert all(o.ok for o in recycled.outcomes)
    first, second = {o.value for o in recycled.outcomes[:2]}, {o.value for o in recycled.outcomes[2:]}
    assert first.isdisjoint(second) and os.getpid() not in first | second
    kept = run_tasks(os.getpid, tasks, workers=2, progress=False)
    assert len({o.value for o in kept.outcomes}) <= 2
    with pytest.raises(ValueError, match="runs_per_worker"):
        run_tasks(os.getpid, tasks, workers=2, progress=False, runs_per_worker=-1)


def test_two_studies_compare_person_by_person(load_script, tmp_path, capsys):
    """benchmarks/compare_studies.py: the second study's condition against the first's, paired by person,
    with a person who did not finish counted at the cap; studies of other people are refused."""
    def run(t):
        return {"completed": t is not None, "completion_s": t, "faces": 6 if t else 3}

    people = {"p1/u10": (30.0, 40.0, 20.0), "p1/u11": (60.0, 50.0, 25.0), "p2/u10": (None, 90.0, 30.0)}
    first = {"populations": [1, 2], "run_seeds": [0], "cap_s": 180.0, "model": None,
             "results": {p: {"responsive": {"0": run(b)}, "joystick": {"0": run(j)}}
                         for p, (_, b, j) in people.items()}}
    second = dict(first, model="/x/cchp_path_shape.pt",
                  results={p: {"responsive": {"0": run(a)}} for p, (a, _, _) in people.items()})
    (tmp_path / "a.json").write_text(json.dumps(first))
    (tmp_path / "b.json").write_text(json.dumps(second))
    script = load_script("benchmarks/compare_studies.py")
    assert script.main(["--first", str(tmp_path / "a.json"), "--second", str(tmp_path / "b.json"),
                        "--bootstrap", "200"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| responsive, second")]
    # ratios 30/40, 60/50, 180/90 (not done: the cap): median 1.2; against the joystick 1.5, 2.4, 6.0.
    assert "responsive, first study (the scenario file) | 3 | 1.200 (" in rows[0]
    assert "| 1/3 against 0/3 | 0 |" in rows[0]
    assert "| joystick | 3 | 2.400 (" in rows[1]
    (tmp_path / "c.json").write_text(json.dumps(dict(second, populations=[1])))
    assert script.main(["--first", str(tmp_path / "a.json"), "--second", str(tmp_path / "c.json")]) == 2


def test_the_progress_line_of_a_finished_run_says_done_not_failed(capsys):
    """A run that succeeded, with no describer, is reported as done; a failed one as failed, with its error."""
    from rtcohand_drake.analysis.engine import Outcome, _Progress

    progress = _Progress(2, "runs", True, None)
    progress.finished(Outcome(key="u10", value={"completed": True}, attempts=1))
    progress.finished(Outcome(key="u11", error="ValueError: bad", attempts=2))
    progress.close()
    lines = [line.strip() for line in capsys.readouterr().err.replace("\r", "\n").splitlines()]
    assert "u10: done" in lines and not any(line.startswith("u10: failed") for line in lines)
    assert "u11: failed after 2 attempts: ValueError: bad" in lines
