"""Saving and loading training checkpoints, and building a model from one.

A checkpoint is a `torch.save` dictionary:
    format "rtcohand-policy-checkpoint", version 1, kind ("cchp", "ranp", "lstm"),
    model_config (dict), train_config (dict), state_dict, step, history, meta.
A missing, corrupt or foreign file raises `CheckpointError` naming the file.
"""

from __future__ import annotations

import json
import os
import pathlib
import pickle
import zipfile
from typing import Any, Dict, Optional, Sequence, Tuple

import torch
from torch import nn

from rtcohand_drake.errors import InputError
from rtcohand_drake.learning.policy_file import PolicyFileError, torch_archive_kind
from rtcohand_drake.learning.nets.cchp import Cchp, CchpConfig
from rtcohand_drake.learning.nets.lstm import DummyLstm, LstmConfig
from rtcohand_drake.learning.nets.ranp import Ranp, RanpConfig

CHECKPOINT_FORMAT = "rtcohand-policy-checkpoint"
CHECKPOINT_VERSION = 1

MODEL_KINDS = {
    "cchp": (Cchp, CchpConfig),
    "ranp": (Ranp, RanpConfig),
    "lstm": (DummyLstm, LstmConfig),
}


# One error class for model files, training checkpoints and exported policies alike.
CheckpointError = PolicyFileError


def build_model(kind: str, config: Optional[Dict[str, Any]] = None) -> nn.Module:
    if kind not in MODEL_KINDS:
        raise InputError(f"unknown model kind {kind!r} (expected one of {', '.join(MODEL_KINDS)})")
    model_cls, cfg_cls = MODEL_KINDS[kind]
    cfg = cfg_cls(**(config or {}))
    return model_cls(cfg)


def _plain(obj: Any) -> Any:
    """Plain JSON types only, so `torch.load(weights_only=True)` accepts the file."""
    return json.loads(json.dumps(obj, default=lambda o: o.item() if hasattr(o, "item") else str(o)))


def save_checkpoint(path: os.PathLike, model: nn.Module, train_config: Dict[str, Any], step: int,
                    history: Optional[Dict[str, Any]] = None, meta: Optional[Dict[str, Any]] = None) -> None:
    """Writes atomically (temporary file, then rename), so a killed run leaves the previous file intact."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "kind": model.kind,
        "model_config": model.cfg.to_dict(),
        "train_config": _plain(train_config),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "step": int(step),
        "history": _plain(history or {}),
        "meta": _plain(meta or {}),
    }
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)


def read_checkpoint(path: os.PathLike) -> Dict[str, Any]:
    """The checkpoint dictionary, checked; CheckpointError on any problem."""
    path = pathlib.Path(path)
    if torch_archive_kind(path, "checkpoint") == "torchscript":
        raise CheckpointError(f"{path}: is an exported TorchScript policy, not a training checkpoint")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, pickle.UnpicklingError, zipfile.BadZipFile, EOFError, OSError, ValueError, AttributeError,
            TypeError, KeyError, IndexError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(err).__name__}: {first[:160]})") from None
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not a {CHECKPOINT_FORMAT} file")
    if payload.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: unsupported checkpoint version {payload.get('version')!r}")
    for key in ("kind", "model_config", "state_dict"):
        if key not in payload:
            raise CheckpointError(f"{path}: checkpoint lacks {key!r}")
    return payload


def parse_overrides(items: Sequence[str]) -> dict:
    """`--set` options, ["KEY=JSON", ...] -> {KEY: value} (a bare word that is not JSON is a string),
    for `load_checkpoint`'s and `export --from-policy`'s overrides."""
    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise InputError(f"--set {item!r}: expected KEY=VALUE")
        try:
            out[key] = json.loads(text)
        except json.JSONDecodeError:
            out[key] = text
    return out


def load_checkpoint(path: os.PathLike, overrides: Optional[Dict[str, Any]] = None) -> Tuple[nn.Module, Dict[str, Any]]:
    """The model (in eval mode) and the checkpoint dictionary. `overrides` changes model options that
    hold no parameters (how the context is read); one that changes a weight's shape is refused."""
    payload = read_checkpoint(path)
    try:
        model = build_model(payload["kind"], {**payload["model_config"], **(overrides or {})})
        model.load_state_dict(payload["state_dict"])
    except (InputError, TypeError, RuntimeError, ValueError) as err:
        raise CheckpointError(f"{path}: checkpoint does not match its model ({str(err).splitlines()[0]})") from None
    model.eval()
    return model, payload


def load_model_file(path: os.PathLike, overrides: Optional[Dict[str, Any]] = None) -> Tuple[nn.Module, Dict[str, Any]]:
    """A training checkpoint, or an exported CCHP policy file rebuilt as the model it was made
    from (`export.cchp_from_policy`; the exported step computes what the model computes), with
    the checkpoint's payload or the policy's model card (kind "cchp")."""
    if torch_archive_kind(path, "checkpoint") == "torchscript":
        from rtcohand_drake.learning.export import cchp_from_policy  # export imports this module

        model, card = cchp_from_policy(path, overrides)
        return model, {**card, "kind": "cchp"}
    return load_checkpoint(path, overrides)
