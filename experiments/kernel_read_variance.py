"""Would the kernel read's own predictive variance tell a recorded person's known gestures from
unknown ones better than the CCHP's (the `read_variance` the file for real hands reports)?

    python experiments/kernel_read_variance.py --data PEOPLE.h5 --people s02 s04 ... [--unknown]

For each person, their held-out clips back to back (as `benchmarks/back_to_back_read.py` reads
them) through `models/cchp_path_shape.pt`: the CCHP's variance factor v_i, the kernel read's
v_k = 1 + (1 - k' M k) / lambda over its anchors (M = (G + lambda I)^-1: the Bayesian linear read's
factor written with the kernel), their blend by the person's A, and the supervisor's mean confidence
scale of each over the steps with a gesture under way. With `--unknown`, each of the person's first
6 held-out clips is read again with a context lacking every clip of its motion.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks"))

MODEL = "models/cchp_path_shape.pt"
UNKNOWN_CLIPS = 6


def variances(module, context, features, keypoints):
    """(v_i (T,), v_k (T,), A) over a stream read with `context` [(features, labels)]."""
    import torch

    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.path_shape_policy import encode_fitted
    from rtcohand_drake.learning.rest_release import fit_rest_release, guard_stream

    x_c, y_c, mask = pack_context(context)
    with torch.no_grad():
        keys, values, z, _ = encode_fitted(module, torch.from_numpy(x_c), torch.from_numpy(y_c),
                                           torch.from_numpy(mask))
        stream = guard_stream(fit_rest_release(context), np.nan_to_num(features), keypoints, 10.0)
        extras = module._extras(keys)
        anchors = module._anchors(keys.size(0))
        m_inv = module._anchor_part(keys, 0, anchors).double()
        blend = float(module.blend_choice(keys)[0])
        hidden = torch.zeros(int(module.hidden_size))
        cell, y = torch.zeros_like(hidden), torch.zeros(6)
        v_i, v_k = [], []
        for x in stream:
            x_t = torch.from_numpy(x).float()
            y, _, hidden, cell, _, v, _ = module.step_read(x_t, y, hidden, cell, keys, values, z)
            k = module._kernel(module._standardise(x_t[36:], extras), keys, extras).double()
            v_i.append(float(v[0]))
            v_k.append(1.0 + max(1.0 - float(k @ m_inv @ k.T), 0.0) / float(module.kernel_lambda))
    return np.array(v_i), np.array(v_k), blend


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", required=True, help="a recorded people's dataset file (the importer's)")
    p.add_argument("--people", nargs="+", required=True)
    p.add_argument("--unknown", action="store_true", help="also read gestures the context lacks")
    args = p.parse_args(argv)

    import torch

    import back_to_back_read
    from rtcohand_drake.data.dataset import read_dataset, to_policy_clip
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.systems.safety.config import Safety
    from rtcohand_drake.systems.safety.rules import confidence_scale

    torch.set_num_threads(1)
    clips, module, safety = read_dataset(args.data), load_policy(MODEL), Safety()
    scale = lambda v: float(np.mean([confidence_scale(x, safety) for x in v]))
    for user in args.people:
        streams = back_to_back_read.person_streams(clips, user, 10.0, True)
        if streams is None:
            continue
        context, _, (features, labels, keypoints) = streams
        v_i, v_k, blend = variances(module, context, features, keypoints)
        on = np.abs(labels).max(1) > 0
        v_b = 1.0 + (1.0 - blend) * (v_i - 1.0) + blend * (v_k - 1.0)
        print(f"{user} A {blend:.2f}; in gestures: v_i {np.median(v_i[on]):.2f} (confidence {scale(v_i[on]):.2f}), "
              f"v_k {np.median(v_k[on]):.2f} ({scale(v_k[on]):.2f}), blended {np.median(v_b[on]):.2f} "
              f"({scale(v_b[on]):.2f})", flush=True)
        if not args.unknown:
            continue
        own = [c for c in clips if c.user == user and c.object_velocity is not None]
        motion = lambda c: tuple(np.nonzero(np.abs(c.object_velocity).max(0) > 0)[0])
        found_i, found_k = [], []
        for test in [c for c in own if c.split == "test"][:UNKNOWN_CLIPS]:
            lacking = [to_policy_clip(c, 10.0, True) for c in own if c.split == "train" and motion(c) != motion(test)]
            _, single, _ = back_to_back_read.person_streams([test] + [c for c in own if c.split == "train"],
                                                            user, 10.0, True)
            features, labels, keypoints = single[0]
            v_i, v_k, _ = variances(module, [(c.features, c.labels) for c in lacking], features, keypoints)
            on = np.abs(labels).max(1) > 0
            found_i.append(scale(v_i[on]))
            found_k.append(scale(v_k[on]))
        print(f"{user} a gesture the context lacks: confidence v_i {np.mean(found_i):.2f}, v_k {np.mean(found_k):.2f}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
