"""Shared fixtures."""

import importlib.util
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def load_script():
    """Import a script of the repository that is not part of the package (benchmarks/, experiments/)
    by its path from the repository's root; each is loaded once per session."""
    loaded = {}

    def load(relative: str):
        if relative not in loaded:
            path = REPO / relative
            spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            loaded[relative] = module
        return loaded[relative]

    return load


@pytest.fixture(scope="session")
def small_policy_file(tmp_path_factory):
    """A real TorchScript export of a (randomly initialised, small) CCHP model."""
    import torch

    from rtcohand_drake.learning.export import script_policy
    from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig

    torch.manual_seed(0)
    model = Cchp(CchpConfig(hidden_size=32, aggregate_sizes=[32, 32], latent_trunk_sizes=[32, 32],
                            latent_dim=8, key_size=16, output_hidden=[32]))
    path = tmp_path_factory.mktemp("policy") / "policy.pt"
    torch.jit.save(script_policy(model), str(path))
    return path


@pytest.hookimpl(wrapper=True)
def pytest_report_header(config, start_path):
    """The session header names the repository, not the folder it was checked out in: a soak's
    output is kept in docs/results/soak/ (docs/safety.md), and results hold no machine's paths."""
    headers = yield
    root = str(config.rootpath)
    relative = lambda line: line.replace(root, ".") if line.startswith("rootdir: ") else line  # noqa: E731
    return [[relative(line) for line in lines] if isinstance(lines, list) else relative(lines) for lines in headers]
