"""Loading an exported policy file (TorchScript, docs/interfaces.md (the exported policy)), with one-line errors.

Kept apart from the training code: the Drake systems load the exported file
through this module and never import the model classes.
"""

from __future__ import annotations

import os
import pathlib
import zipfile

from rtcohand_drake.errors import InputError

REQUIRED = ("encode_context", "step", "feature_dim", "hidden_size", "latent_dim")


class PolicyFileError(InputError):
    """A model file (exported policy or training checkpoint) that cannot be used; one line naming the file."""


_NAMES = {"policy": "TorchScript policy", "checkpoint": "checkpoint"}


def torch_archive_kind(path: os.PathLike, expected: str) -> str:
    """"torchscript" or "pickle" for a PyTorch archive (the two model files), else a PolicyFileError.

    `expected` ("policy" or "checkpoint") names the file the caller wants, in the messages.
    """
    path = pathlib.Path(path)
    if path.is_dir():
        raise PolicyFileError(f"{path}: a folder, not a {expected} file")
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such {expected} file")
    if not zipfile.is_zipfile(path):
        raise PolicyFileError(f"{path}: not a {_NAMES[expected]} (not a PyTorch archive; truncated or corrupt?)")
    try:
        with zipfile.ZipFile(path) as archive:
            scripted = any(n.split("/", 1)[-1].startswith("code/") for n in archive.namelist())
            # Every entry against its CRC-32: a file damaged inside its weights would otherwise load and
            # run with wrong numbers.
            damaged = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError) as err:
        raise PolicyFileError(f"{path}: not a {_NAMES[expected]} (a damaged archive: {err})") from None
    if damaged is not None:
        raise PolicyFileError(f"{path}: a damaged {_NAMES[expected]} ({damaged.split('/', 1)[-1]} fails its "
                              "checksum); copy the file again")
    return "torchscript" if scripted else "pickle"


def check_policy_file(path: os.PathLike) -> None:
    """A PolicyFileError, as `load_policy` would raise it, for a policy file that is missing, not a
    TorchScript archive, or damaged; without loading it (no torch import): a check before work that
    loads the file later."""
    if torch_archive_kind(path, "policy") != "torchscript":
        raise PolicyFileError(f"{path}: not a TorchScript policy (a training checkpoint? export it with "
                              "python -m rtcohand_drake.export)")


def load_policy(path: os.PathLike):
    """Loads an exported policy; a missing, corrupt or wrong file is a PolicyFileError naming it."""
    import torch

    path = pathlib.Path(path)
    check_policy_file(path)
    try:
        module = torch.jit.load(str(path), map_location="cpu")
    except Exception as err:  # torch raises RuntimeError and others for a damaged archive
        text = str(err).strip().splitlines()
        raise PolicyFileError(f"{path}: not a TorchScript policy ({type(err).__name__}: "
                              f"{text[0][:160] if text else ''})") from None
    for name in REQUIRED:
        if not hasattr(module, name):
            raise PolicyFileError(f"{path}: TorchScript module lacks {name!r} (not a CCHP policy export)")
    from rtcohand_drake.data.hand_features import FEATURE_DIM, PATH_SHAPE_DIM

    if int(module.feature_dim) not in (FEATURE_DIM, FEATURE_DIM + PATH_SHAPE_DIM):
        raise PolicyFileError(f"{path}: policy reads {int(module.feature_dim)} features; the hand features are "
                              f"{FEATURE_DIM}, or {FEATURE_DIM + PATH_SHAPE_DIM} with the hand's path and shape")
    return module


def reads_path_shape(policy) -> bool:
    """Whether a policy file (a path, or a module `load_policy` gave) reads the hand's path and shape after
    the 36 hand-part velocities (`feature_dim` > 36, `learning.path_shape_policy`): its context pieces
    must then be loaded with them (`to_policy_clip(path_shape=True)`)."""
    from rtcohand_drake.data.hand_features import FEATURE_DIM

    module = load_policy(policy) if isinstance(policy, (str, os.PathLike)) else policy
    return int(module.feature_dim) > FEATURE_DIM
