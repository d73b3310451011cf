"""The closed-loop read measure: exact on constructed signals, and calibrated by the intent reference."""

import numpy as np
import pytest

from rtcohand_drake.analysis.closed_loop_read import markdown, measure, read_figures


def test_read_figures_recover_a_known_lag_gain_and_rest_output():
    rng = np.random.default_rng(0)
    n, period = 400, 0.1
    intent = np.zeros((n, 6))
    for start in range(10, n - 30, 40):  # strokes on Tz and Rx, rest between them
        intent[start:start + 15, 2] = 0.1 * rng.uniform(0.5, 1.0)
        intent[start + 20:start + 30, 3] = -0.5 * rng.uniform(0.5, 1.0)
    output = np.zeros((n, 6))
    output[4:, 2] = 0.7 * intent[:-4, 2]
    output[4:, 3] = 1.2 * intent[:-4, 3]
    output[:, 5] = 0.02  # a steady drift on Rz, which the person never used
    lag, gains, rest_v, rest_w = read_figures(intent, output, period, max_lag=8)
    assert lag == pytest.approx(0.4)
    assert gains[2] == pytest.approx(0.7) and gains[3] == pytest.approx(1.2)
    assert all(np.isnan(gains[d]) for d in (0, 1, 4, 5))
    assert rest_v == pytest.approx(0.0) and rest_w == pytest.approx(0.02)


def test_still_figures_count_only_samples_a_second_after_the_intent_ended():
    from rtcohand_drake.analysis.closed_loop_read import still_figures

    intent = np.zeros((40, 6))
    intent[:10, 5] = 0.5
    command = np.zeros((40, 6))
    command[10:15, 5] = 0.3   # the loop's lag: within the first second, not counted
    command[30:, 3] = 0.02    # a creep while the hand rests
    v, w, share = still_figures(intent, command, 0.1, still_s=1.0)
    # Still from sample 19 on (ten idle samples, 10..19): 21 samples, 10 of them moving.
    assert v == 0.0 and w == pytest.approx(0.02 * 10 / 21) and share == pytest.approx(10 / 21)


def test_too_short_a_run_is_a_clear_error():
    with pytest.raises(ValueError, match="need more than"):
        read_figures(np.zeros((5, 6)), np.zeros((5, 6)), 0.1, max_lag=8)


def test_the_intent_reference_reads_at_gain_one_and_its_own_delay_in_closed_loop():
    from rtcohand_drake.analysis.reference_policies import IntentPolicy
    from rtcohand_drake.scenario import load_scenario

    scenario = load_scenario("inspection")
    r = measure(scenario, "u12", population_seed=0, seed=0, policy=IntentPolicy(scenario.policy.rate_hz, 0.3),
                duration_s=15.0)
    assert r.lag_s == pytest.approx(0.3)
    used = [g for g in r.gains if np.isfinite(g)]
    assert used and np.allclose(used, 1.0, atol=1e-9)
    assert r.rest_w_rad_s == pytest.approx(0.0, abs=1e-12)
    assert r.still_w_rad_s == pytest.approx(0.0, abs=1e-9) and r.still_moving_share == 0.0
    assert r.completion_s is None and r.duration_s == pytest.approx(15.0)  # 15 s is too short for six faces
    assert "| p0/u12 | not done | 300 ms |" in markdown([r])


def test_the_figures_come_from_a_run_log_as_from_the_signals(tmp_path):
    """`from_run_log`: the policy's output and the command sampled at the gesture's samples, up to the
    sixth face; the same figures as `read_figures` on the signals written into the log."""
    from rtcohand_drake.analysis.closed_loop_read import from_run_log
    from rtcohand_drake.errors import InputError
    from rtcohand_drake.run_log import RunLog, write_run_log

    n, period = 300, 0.1
    t = np.arange(n) * period
    intent = np.zeros((n, 6))
    for start in range(5, n - 20, 30):
        intent[start:start + 12, 0] = 0.12
    output = np.zeros((n, 6))
    output[3:, 0] = 0.5 * intent[:-3, 0]
    log = RunLog(model="m.pt", gesture_source="recorded", completed=True, faces_inspected=6, completion_time=20.0,
                 policy_time=t, policy_mean=output, command_time=t, command_twist=output,
                 gesture_time=t, gesture_intended=intent, extra_attrs={"seed": 3})
    (tmp_path / "runs").mkdir()
    path = write_run_log(tmp_path / "runs" / "s02.h5", log)
    r = from_run_log(path)
    keep = t <= 20.0 + 1e-9
    lag, gains, _, _ = read_figures(intent[keep], output[keep], period)
    assert r.user == "runs/s02" and r.seed == 3 and r.completion_s == 20.0
    assert r.lag_s == pytest.approx(lag) == pytest.approx(0.3) and r.gains[0] == pytest.approx(gains[0]) == pytest.approx(0.5)
    assert "| runs/s02 | 20.0 s | 300 ms | +0.50 |" in markdown([r])
    short = RunLog(policy_time=t[:3], policy_mean=output[:3], gesture_time=t[:3], gesture_intended=intent[:3])
    with pytest.raises(InputError, match="too short"):
        from_run_log(write_run_log(tmp_path / "short.h5", short))
    with pytest.raises(InputError, match="no intended twist"):
        from_run_log(write_run_log(tmp_path / "camera.h5", RunLog(policy_time=t, policy_mean=output)))
