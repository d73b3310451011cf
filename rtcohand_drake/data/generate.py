"""Generate a simulated gesture dataset (docs/interfaces.md, the gesture dataset file).

    python -m rtcohand_drake.data.generate --out PATH.h5 [--users 15] [--seed N] [--fps 30]
        [--single-stroke-share P] [--repeated-rhythm-share P] [--recorded-tracking]

Bad arguments or an unwritable output exit with status 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

from rtcohand_drake.data.dataset import write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.data.population.config import RECORDED_TRACKING
from rtcohand_drake.errors import non_negative_int


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, status 2
        sys.stderr.write(f"{self.prog}: error: {' '.join(message.split())}\n")
        sys.exit(2)


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _share(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1], got {text}")
    return value


def _fps(text: str) -> float:
    value = float(text)
    if not value >= 5.0:
        raise argparse.ArgumentTypeError(f"must be at least 5 Hz, got {text}")
    return value


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m rtcohand_drake.data.generate", description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="output dataset file (.h5)")
    parser.add_argument("--users", type=_positive_int, default=15, help="number of users (2/3 in-sample)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="random seed")
    parser.add_argument("--fps", type=_fps, default=GeneratorConfig.fps, help="keypoint frame rate, Hz")
    parser.add_argument("--single-stroke-share", type=_share, default=GeneratorConfig.p_single_stroke,
                        help="share of users who make each move or turn as one stroke out and partly back, "
                             "as recorded people do (default 0)")
    parser.add_argument("--repeated-rhythm-share", type=_share, default=GeneratorConfig.p_repeated_rhythm,
                        help="share of users who gesture in repeated strokes (default "
                             f"{GeneratorConfig.p_repeated_rhythm}); 0: every user moves steadily while gesturing")
    parser.add_argument("--direct-share", type=_share, default=GeneratorConfig.p_direct,
                        help="share of users who make every motion the direct way: a move of the hand along its "
                             "axis, a turn of the wrist about its axis (default 0)")
    parser.add_argument("--recorded-tracking", action="store_true",
                        help="track the hands as recorded people's were: steadier frame to frame, with glitches of "
                             "centimetres now and then (GeneratorConfig's RECORDED_TRACKING; default: the "
                             "simulated camera's Gaussian jitter)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)

    config = replace(GeneratorConfig(), fps=args.fps, p_single_stroke=args.single_stroke_share,
                     p_repeated_rhythm=args.repeated_rhythm_share, p_direct=args.direct_share,
                     **(RECORDED_TRACKING if args.recorded_tracking else {}))
    start = time.perf_counter()

    def progress(done: int, total: int, user) -> None:
        if not args.quiet:
            print(f"user {done}/{total} ({user.user_id}, {user.group}): {user.describe()}", flush=True)

    clips = generate_population(config, n_users=args.users, seed=args.seed, progress=progress)
    try:
        write_dataset(args.out, clips, generator=config.to_json())
    except OSError as err:
        sys.stderr.write(f"{args.out}: cannot write: {' '.join(str(err).split())}\n")
        return 2
    if not args.quiet:
        print(f"wrote {len(clips)} clips of {args.users} users to {args.out} in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
