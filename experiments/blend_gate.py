"""Which people a policy file that blends a read fitted to the person should read with it: a sweep of
`--min-gain` (`path_shape_policy`, `ridge_blend_policy`) on development people.

    python experiments/blend_gate.py --data POPULATION.h5 --file FILE.pt [--core models/cchp_default.pt]
        [--every 8] [--gates 0 0.02 0.05 0.1 0.2] [--out FILE.json]

FILE must be built with `--min-gain 0` (the blend as fitted for everyone), over CORE (the CCHP, or
for a ridge blend the file it wraps). Each chosen episode is stepped with FILE and with CORE alone
(`learning.evaluate.stepped_policy_mse`); the file's mean is linear in its blend (the inner file is
fed its own mean), so the read with blend 0 is CORE's. For each gate G the
person's read is FILE's where the fitted blend removed at least G of the CCHP's error over their own
clips (`blend_choice`), else the CCHP's. Prints each gate's share of the zero twist's error.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv=None) -> int:
    import torch

    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.data.sampling import evaluation_episodes, pack_context
    from rtcohand_drake.learning.evaluate import stepped_policy_mse
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.learning.path_shape_policy import encode_fitted
    from rtcohand_drake.learning.train import load_clips

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True)
    p.add_argument("--file", required=True)
    p.add_argument("--core", default="models/cchp_default.pt")
    p.add_argument("--setting", default="Own")
    p.add_argument("--every", type=int, default=8)
    p.add_argument("--gates", type=float, nargs="+", default=[0.0, 0.02, 0.05, 0.1, 0.2, 0.3])
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    wide, core = load_policy(args.file), load_policy(args.core)
    narrow_eps = evaluation_episodes(load_clips(args.data, 10.0, path_shape=False), args.setting, 0)[::args.every]
    wide_eps = evaluation_episodes(load_clips(args.data, 10.0, path_shape=True), args.setting, 0)[::args.every]
    rows = []
    for i, (e_n, e_w) in enumerate(zip(narrow_eps, wide_eps)):
        e_f = e_w if int(wide.feature_dim) > FEATURE_DIM else e_n  # the episode as FILE reads it
        x_c, y_c, mask = (torch.from_numpy(a) for a in pack_context(e_f.context))
        keys = encode_fitted(wide, x_c, y_c, mask)[0]
        used, fitted, gain = (float(v) for v in wide.blend_choice(keys)[:3])
        rows.append({"episode": i, "a_used": used, "a_fitted": fitted, "gain": gain,
                     "zero": float(np.mean(np.asarray(e_n.target.labels, np.float64) ** 2)),
                     "core": stepped_policy_mse(core, [e_w if int(core.feature_dim) > FEATURE_DIM else e_n])["mse"],
                     "file": stepped_policy_mse(wide, [e_f])["mse"]})
        r = rows[-1]
        print(f"  episode {i}: A {fitted:.3f}, gain {gain:.3f}; core {r['core'] / r['zero']:.3f}, "
              f"file {r['file'] / r['zero']:.3f}", flush=True)
    zero = np.mean([r["zero"] for r in rows])
    result = {"data": args.data, "file": args.file, "core": args.core, "every": args.every, "rows": rows, "gates": {}}
    print(f"{args.data}: {len(rows)} {args.setting} episodes; the CCHP alone "
          f"{np.mean([r['core'] for r in rows]) / zero:.4f} of zero twist")
    for g in args.gates:
        mse = np.mean([r["file"] if r["gain"] >= g else r["core"] for r in rows])
        kept = sum(r["gain"] >= g for r in rows)
        result["gates"][str(g)] = {"share_of_zero": mse / zero, "kernel_people": kept}
        print(f"  gate {g:.2f}: {mse / zero:.4f} of zero twist ({kept} of {len(rows)} episodes with the kernel read)")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
