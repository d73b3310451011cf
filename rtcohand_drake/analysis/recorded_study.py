"""The study of recorded people in the closed loop (`python -m rtcohand_drake.study --recorded-people PEOPLE.h5`).

    python -m rtcohand_drake.study --recorded-people PEOPLE.h5 --out DIR [--people s03 s07 ...]
        [--conditions responsive intent] [--run-seeds 0] [--cap S] [--model PATH.pt] [--no-hand-sign]
        [--workers 2 | --address ...]

Each person of the gesture dataset file (the importer's: held-out `split =
test` repetitions, `split = train` context) runs the inspection with the
`recorded` gesture source (`systems.gestures.recorded_person`: the simulated
person's decisions, the person's own held-out gestures) in each condition:

- `responsive`: the policy file reads the recorded hand, with the person's
  `split = train` clips as context, through the responsive command filter;
  it goes through the run command's own code (`rtcohand_drake.run.main`);
- `paper`: the same with the paper's filter;
- `intent`: the same decisions and the same played gestures, with the label
  of each played frame commanded in place of the policy, 0.3 s late
  (`analysis.reference_policies.IntentPolicy`, as the study's intent
  reference of simulated people), through the same filter and safety layer.

Each run is one task of `analysis.engine.run_tasks`. `DIR/study.json` holds
`results[person][condition][run seed]`: `analysis.study.summarise`'s entry
plus `contacts` (the run log's mold and cell contact events: one for each of
the two it touched), `limits_exceeded` (which limits the run went beyond:
`analysis.inspection.limits_exceeded`), `wrong_way_share` and `drift_share`
(`analysis.gesture_following`) and, for a run that did not finish, `stuck`
(`gesture_following.stuck_motion`: the command gestured most in its last
60 s and the read's gain along it), or None for a run that failed with an
error (a person with no held-out recording of a motion the inspection asked
for).
`DIR/study.md` gives the table per person and the medians, and counts the
pauses the pause hand sign made (`sign_pauses`): neither the simulated nor
the recorded person means one, but some recorded gestures start or end in a
thumbs-up held still. `--no-hand-sign` runs a copy of the scenario with the
sign off.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.analysis.gesture_following import STUCK_WINDOW_S

CONDITIONS = ("responsive", "paper", "intent")
DEFAULT_CONDITIONS = ("responsive", "intent")


def log_name(person: str, condition: str, seed: int) -> str:
    return f"{person}_{condition}_s{seed}.h5"


def _scenario_path(folder: str, cap_s: float | None, hand_sign: bool = True, scenario: str = "inspection") -> str:
    """`scenario` (a built-in name or a YAML path), or a copy of it with its cap changed or its pause hand
    sign off."""
    import yaml

    from rtcohand_drake.scenario import resolve_scenario_path

    if cap_s is None and hand_sign:
        return scenario
    data = yaml.safe_load(resolve_scenario_path(scenario).read_text())
    if cap_s is not None:
        data["duration_s"] = float(cap_s)
    if not hand_sign:
        data.setdefault("hand_sign", {})["enabled"] = False
    path = Path(folder) / "inspection_capped.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


def _resolved_scenario(scenario: str | None) -> str:
    """The scenario the runs use: a built-in name as it is, a YAML path made absolute (the runs may be
    on other workers); checked here, so that a bad one is one error, not one per run."""
    from rtcohand_drake.scenario import load_scenario

    if scenario is None:
        return "inspection"
    load_scenario(scenario)  # raises ScenarioError (one line) for a missing or malformed file
    path = Path(scenario)
    return str(path.resolve()) if path.suffix in (".yaml", ".yml") or path.exists() else scenario


def run_recorded_condition(people_file: str, person: str, condition: str, out: str, seed: int = 0,
                           cap_s: float | None = None, model: str | None = None, hand_sign: bool = True,
                           scenario: str = "inspection") -> dict:
    """One run of `person` in `condition` under `scenario` (a built-in name or a YAML path), its log
    written to `out`; returns its entry (module doc). `hand_sign=False` runs with the scenario's pause
    hand sign off. Raises on a run that fails."""
    import contextlib
    import io
    import tempfile

    from rtcohand_drake.run_log import write_run_log
    from rtcohand_drake.scenario import load_scenario

    log = Path(out) / log_name(person, condition, seed)
    log.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder:
        scenario_path = _scenario_path(folder, cap_s, hand_sign, scenario)
        if condition == "intent":
            from rtcohand_drake.analysis.reference_policies import run_intent_with_source
            from rtcohand_drake.cell.plant import eye_position
            from rtcohand_drake.systems.gestures.recorded_person import RecordedPerson, load_recorded_person

            loaded = load_scenario(scenario_path)
            recordings = load_recorded_person(people_file, person, loaded.policy.rate_hz)
            source = RecordedPerson(recordings, loaded.cell.user_frame.to_rigid_transform(),
                                    eye_position(loaded.cell), rate_hz=loaded.policy.rate_hz, seed=seed)
            write_run_log(log, run_intent_with_source(loaded, source, seed=seed, stop_when_done=True,
                                                      gesture_source="recorded (intent)"))
        else:
            from rtcohand_drake.run import main

            args = ["--scenario", scenario_path, "--realtime-rate", "0", "--no-meshcat", "--gesture-source", "recorded",
                    "--gesture-file", str(people_file), "--clip", person, "--seed", str(seed), "--log", str(log),
                    "--filter-mode", condition] + (["--model", str(model)] if model else [])
            with contextlib.redirect_stdout(io.StringIO()):
                status = main(args)
            if status != 0:
                raise RuntimeError(f"{log.name}: the run exited with status {status}")
    return {**summarise_recorded(str(log), scenario), "log": str(log)}


def summarise_recorded(path: str, scenario: str = "inspection") -> dict:
    """`analysis.study.summarise` of a run log, plus contacts, limits exceeded and the following shares
    (the limits and the user frame of `scenario`, the one the run used)."""
    from rtcohand_drake.analysis.gesture_following import run_log_following_shares, stuck_motion
    from rtcohand_drake.analysis.inspection import limits_exceeded
    from rtcohand_drake.analysis.study import summarise
    from rtcohand_drake.run_log import read_run_log
    from rtcohand_drake.scenario import load_scenario

    loaded = load_scenario(scenario)
    log = read_run_log(path)
    R_WU = loaded.cell.user_frame.to_rigid_transform().rotation().matrix()
    wrong_way, drift = run_log_following_shares(log, R_WU)
    return {**summarise(path),
            "contacts": sum(e.kind in ("mold_contact", "cell_contact") for e in log.events),
            "limits_exceeded": limits_exceeded(loaded, log),
            "wrong_way_share": wrong_way, "drift_share": drift,
            "sign_pauses": sum(e.kind == "pause" and "hand sign" in e.detail for e in log.events),
            "stuck": None if log.completed else stuck_motion(log.gesture_time, log.gesture_intended, log.policy_time,
                                                             log.policy_mean)}


def people_of(path) -> list[str]:
    from rtcohand_drake.data.dataset import read_dataset

    return sorted({c.user for c in read_dataset(path)})


def _median(values) -> float | None:
    values = [v for v in values if v is not None]
    return float(np.median(values)) if values else None


def _pct(value) -> str:
    return "-" if value is None else f"{100 * value:.1f} %"


def markdown(results: dict, conditions: Sequence[str], cap_s: float, failed: Sequence[dict] = (),
             header: str = "") -> tuple[str, dict]:
    """The table per person and run seed, then the medians per condition; returns (text, medians)."""
    from rtcohand_drake.analysis.study_stats import person_time

    lines = [header, ""] if header else []
    lines += ["| person | condition | run seed | completed safely | faces | time | time / intent | wrong way | drift "
              "| contacts | limits exceeded | sign pauses |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    medians = {}
    for c in conditions:
        ok, ratios, times, wrong, drift, n = 0, [], [], [], [], 0
        for person, runs in results.items():
            intent = person_time(runs.get("intent", {}), cap_s) if "intent" in runs else None
            mine = person_time(runs.get(c, {}), cap_s)
            for seed, r in sorted(runs.get(c, {}).items()):
                n += 1
                if r is None:
                    lines.append(f"| {person} | {c} | {seed} | failed | - | - | - | - | - | - | - | - |")
                    continue
                safe = r["completed"] and not r["contacts"] and not r["limits_exceeded"]
                ok += safe
                ratio = (f"{mine / intent:.2f}" if c != "intent" and mine is not None and intent else "-")
                time = f"{r['completion_s']:.1f} s" if r["completed"] else "not done"
                lines.append(f"| {person} | {c} | {seed} | {'yes' if safe else 'no'} | {r['faces']}/6 | {time} | {ratio} "
                             f"| {_pct(r['wrong_way_share'])} | {_pct(r['drift_share'])} | {r['contacts']} "
                             f"| {', '.join(r['limits_exceeded']) or 'none'} | {r.get('sign_pauses', 0)} |")
                times.append(r["completion_s"] if r["completed"] else cap_s)
                wrong.append(r["wrong_way_share"])
                drift.append(r["drift_share"])
            if c != "intent" and mine is not None and intent:
                ratios.append(mine / intent)
        medians[c] = {"runs": n, "completed_safely": ok, "median_time_s": _median(times),
                      "median_time_over_intent": _median(ratios) if c != "intent" else None,
                      "median_wrong_way_share": _median(wrong), "median_drift_share": _median(drift)}
    lines += ["", "Medians over the runs (a run not finished counts at the cap, "
                  f"{cap_s:g} s; time / intent: per person, over the people with both):", ""]
    for c, m in medians.items():
        ratio = "" if m["median_time_over_intent"] is None else f", time / intent {m['median_time_over_intent']:.2f}"
        time = "-" if m["median_time_s"] is None else f"{m['median_time_s']:.1f} s"
        lines.append(f"- **{c}**: completed safely {m['completed_safely']}/{m['runs']}, time {time}{ratio}, "
                     f"wrong way {_pct(m['median_wrong_way_share'])}, drift {_pct(m['median_drift_share'])}")
    stuck = [(person, c, seed, r["stuck"]) for c in conditions for person, runs in results.items()
             for seed, r in sorted(runs.get(c, {}).items()) if r is not None and r.get("stuck")]
    if stuck:
        lines += ["", "Runs not finished: the command the person gestured most in the run's last "
                      f"{STUCK_WINDOW_S:g} s, the share of that time, and the read's gain along it (1: the "
                      "gesture's size; about 0: the part is not asked to move):", ""]
        lines += [f"- {person} {c} run seed {seed}: {s['motion']} ({100 * s['time_share']:.0f} % of the time), "
                  f"gain {s['gain']:+.2f}" for person, c, seed, s in stuck]
    if failed:
        lines += ["", f"Runs failed with an error after a retry ({len(failed)}):", ""]
        lines += [f"- {f['person']} {f['condition']} run seed {f['run_seed']}: {f['error']}" for f in failed]
    return "\n".join(lines) + "\n", medians


def main_recorded(args) -> int:
    """The study's `--recorded-people` mode (`analysis.study.main` parses the flags)."""
    from rtcohand_drake.analysis.engine import run_tasks
    from rtcohand_drake.analysis.study import engine_summary, plot
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.scenario import load_scenario

    path = args.recorded_people
    if not Path(path).is_file():
        raise InputError(f"{path}: no such file (--recorded-people: a gesture dataset file of recorded people)")
    conditions = list(args.conditions or DEFAULT_CONDITIONS)
    bad = [c for c in conditions if c not in CONDITIONS]
    if bad:
        raise InputError(f"command line: --recorded-people runs the conditions {', '.join(CONDITIONS)}; "
                         f"not {', '.join(bad)}")
    everyone = people_of(path)
    people = args.people or everyone
    unknown = [p for p in people if p not in everyone]
    if unknown:
        raise InputError(f"{path}: no person named {', '.join(unknown)} (people: {', '.join(everyone)})")
    seeds = args.run_seeds or [args.seed if args.seed is not None else 0]
    scenario = _resolved_scenario(args.scenario)
    cap = args.cap if args.cap is not None else load_scenario(scenario).duration_s
    model = str(args.model.resolve()) if args.model is not None else None
    logs = (args.logs or args.out / "logs").resolve()
    logs.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    keys = [(p, c, s) for p in people for s in seeds for c in conditions]

    def describe(o) -> str:
        person, c, seed = o.key
        v = o.value
        state = f"{v['completion_s']:.1f} s" if v["completed"] else f"not done ({v['faces']}/6)"
        return f"{person} {c} run seed {seed}: {state} ({o.seconds:.0f} s wall)"

    report = run_tasks(run_recorded_condition,
                       [(k, (str(path), k[0], k[1], str(logs), k[2], args.cap, model, not args.no_hand_sign, scenario))
                        for k in keys],
                       workers=args.workers, address=args.address, label="recorded study", describe=describe,
                       runs_per_worker=args.runs_per_worker)
    results: dict = {p: {c: {} for c in conditions} for p in people}
    failed = []
    for o in report.outcomes:
        person, c, seed = o.key
        results[person][c][seed] = o.value if o.ok else None
        if not o.ok:
            failed.append({"person": person, "condition": c, "run_seed": seed, "attempts": o.attempts,
                           "error": o.error})
    if args.model:
        chosen = str(args.model)
    else:  # the run's own choice for this file's hands (run._resolve_model)
        from rtcohand_drake.scenario import load_scenario
        from rtcohand_drake.systems.gestures.registry import policy_model_name, reads_real_hands

        policy = load_scenario(scenario).policy
        chosen = f"the scenario's, {policy_model_name(policy, reads_real_hands('recorded', path))}"
    header = (f"Recorded people of `{path}`; scenario {args.scenario or 'inspection'}; policy file: {chosen}; "
              f"run seeds {', '.join(map(str, seeds))}; the pause hand sign {'off' if args.no_hand_sign else 'on'}.")
    text, medians = markdown(results, conditions, cap, failed, header)
    text += "\n" + engine_summary(report) + "\n"
    print(text)
    (args.out / "study.md").write_text(text)
    summary = {"recorded_people": str(path), "scenario": args.scenario or "inspection", "people": people,
               "run_seeds": seeds, "cap_s": cap,
               "hand_sign": not args.no_hand_sign,
               "conditions": conditions, "model": model,
               "results": {p: {c: {str(s): r for s, r in runs.items()} for c, runs in by_c.items()}
                           for p, by_c in results.items()},
               "medians": medians, "failed": failed}
    (args.out / "study.json").write_text(json.dumps(summary, indent=1))
    plot(results, conditions, cap, args.out / "study.png")
    print(f"wrote {args.out / 'study.md'}, study.json and study.png", file=sys.stderr)
    return 1 if failed else 0
