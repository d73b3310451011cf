"""Does a recorder session read a person as well as their generated clips do?

    python benchmarks/recorded_context.py [--users u10 u11 ...] [--population-seed 0] [--seed 0]

For each simulated person: records a session with `python -m rtcohand_drake.record
--simulated-user --repeats 1` (one round: 18 clips, labels the cue's twist shifted by the protocol's
label delay), then plays the person's
held-out generated clips (the odd-numbered half of their 72) through the
shipped policy with three contexts: the session's clips, the even-numbered
half of their generated clips (36, handler labels), and 18 of those (the
session's size). Prints the squared error as a share of commanding zero
twist and the ratio session / generated (the issue's bar: at most 1.25).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def _error(module, context, targets) -> float:
    import torch

    from rtcohand_drake.analysis.context_reading import play_clip
    from rtcohand_drake.data.sampling import pack_context

    x_c, y_c, mask = pack_context(context)
    with torch.no_grad():
        keys, values, z_mu, _ = module.encode_context(torch.from_numpy(x_c), torch.from_numpy(y_c),
                                                      torch.from_numpy(mask))
    err = sum(float(((play_clip(module, f, keys, values, z_mu) - y) ** 2).sum()) for f, y in targets)
    return err / sum(float((y ** 2).sum()) for _, y in targets)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--users", nargs="+", default=["u10", "u11", "u12", "u13", "u14"])
    p.add_argument("--population-seed", type=int, default=0)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    from rtcohand_drake.analysis.context_reading import builtin_clips
    from rtcohand_drake.data.dataset import load_policy_clips
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.cell.robot_files import policy_file_path

    module = load_policy(policy_file_path("cchp_default.pt"))
    print("| person | session context | generated, 36 clips | generated, 18 clips | ratio (vs 36) | ratio (vs 18) |")
    print("|---|---|---|---|---|---|")
    for user in args.users:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "session.h5"
            subprocess.run([sys.executable, "-m", "rtcohand_drake.record", "--out", str(path), "--user", "ME",
                            "--simulated-user", user, "--population-seed", str(args.population_seed),
                            "--seed", str(args.seed), "--no-meshcat", "--no-check", "--repeats", "1"],
                           check=True, capture_output=True)
            session = [(c.features, c.labels) for c in load_policy_clips(path, 10.0)]
        generated = builtin_clips(user, 10.0, args.population_seed)
        targets = [(c.features, c.labels) for c in generated[1::2]]
        own = [(c.features, c.labels) for c in generated[0::2]]
        e_session, e_36, e_18 = (_error(module, ctx, targets) for ctx in (session, own, own[:18]))
        print(f"| {user} | {e_session:.3f} | {e_36:.3f} | {e_18:.3f} | {e_session / e_36:.2f} | "
              f"{e_session / e_18:.2f} |", flush=True)


if __name__ == "__main__":
    main()
