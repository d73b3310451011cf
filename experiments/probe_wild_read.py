"""How much of a wild read (a context without the gesture's motion) does the safety layer's confidence scaling take out?

    python experiments/probe_wild_read.py [--data out/population15_s0.h5] [--model models/cchp_default.pt]
        [--settings D+U+ D-U+ D-U- Unseen Own] [--max-episodes 120]
        [--confidence-floor F] [--confidence-floor-variance V]   (other values than the scenario's, to compare)

For the first episodes of each evaluation setting, the exported policy is
played over the target clip (`context_reading.play_clip`: its own mean fed back, z the mean of q(z|C)),
and each step's mean and read variance factor v = 1 + phi^T A phi are kept.
Per setting it prints the squared error as a share of commanding zero twist:
of the policy's mean, and of the mean scaled by the supervisor's confidence
scale of v (`systems.safety.rules.confidence_scale` with the scenario's
keys), and the share of steps the scaling slows (v above its full-speed
level), with v's median and 90th percentile. Analysis only: the supervisor's
other limits (speed, workspace, corridor) come after the scaling.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from rtcohand_drake.analysis.context_reading import play_clip
from rtcohand_drake.data.dataset import load_policy_clips
from rtcohand_drake.data.sampling import evaluation_episodes
from rtcohand_drake.learning.batching import collate_context
from rtcohand_drake.learning.policy_file import load_policy
from rtcohand_drake.repo_paths import repo_relative
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.systems.safety.rules import confidence_scale

REPO = Path(__file__).resolve().parents[1]


def run_episode(policy, episode):
    """The policy's mean over the episode's target (the module's own mean fed back) and each step's v."""
    x_c, y_c, mask = collate_context(episode.context)
    with torch.no_grad():
        keys, values, z_mu, _ = policy.encode_context(x_c, y_c, mask)
    x = episode.target_features if episode.target_features is not None else episode.target.features
    vs: list = []
    means = play_clip(policy, x, keys, values, z_mu, correction_weight=1.0, variances=vs)
    return means, np.array(vs)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", type=Path, default=REPO / "out" / "population15_s0.h5")
    p.add_argument("--model", type=Path, default=REPO / "models" / "cchp_default.pt")
    p.add_argument("--settings", nargs="+", default=["D+U+", "D-U+", "D-U-", "Unseen", "Own"])
    p.add_argument("--max-episodes", type=int, default=120)
    p.add_argument("--confidence-floor", type=float, default=None, help="default: the scenario's")
    p.add_argument("--confidence-floor-variance", type=float, default=None, help="default: the scenario's")
    args = p.parse_args()
    safety = load_scenario("inspection").safety
    if args.confidence_floor is not None:
        safety.confidence_floor = args.confidence_floor
    if args.confidence_floor_variance is not None:
        safety.confidence_floor_variance = args.confidence_floor_variance
    policy = load_policy(args.model)
    clips = load_policy_clips(args.data)
    print(f"policy {repo_relative(args.model)}; confidence scale: 1 up to v = {safety.confidence_full_variance}, "
          f"{safety.confidence_floor} from v = {safety.confidence_floor_variance}")
    print("| setting | episodes | mean, share of zero twist | scaled by confidence, share of zero twist "
          "| steps slowed | v median / 90th percentile |")
    print("|---|---|---|---|---|---|")
    for setting in args.settings:
        episodes = evaluation_episodes(clips, setting, seed=0)[: args.max_episodes]
        err = err_scaled = zero = 0.0
        all_v = []
        for ep in episodes:
            means, vs = run_episode(policy, ep)
            scale = np.array([confidence_scale(v, safety) for v in vs])[:, None]
            y = ep.target.labels
            err += float(((means - y) ** 2).sum())
            err_scaled += float(((means * scale - y) ** 2).sum())
            zero += float((y ** 2).sum())
            all_v.append(vs)
        v = np.concatenate(all_v)
        print(f"| {setting} | {len(episodes)} | {err / zero:.2f} | {err_scaled / zero:.2f} | "
              f"{np.mean(v > safety.confidence_full_variance):.0%} | {np.median(v):.2f} / {np.quantile(v, 0.9):.2f} |")


if __name__ == "__main__":
    main()
