"""Controller specs written from a training checkpoint (``.pt``, which needs torch to read)
and the constants of the rules it is shipped with. The three packaged specs in
``rabbit_policy/controllers`` are what ships (classic's and the recovery controller's were
written once from their constants; see git history): a change of a code default moves nothing
shipped."""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from rabbit_hzd_controller.controller import ControllerSettings
from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming
from rabbit_policy.spec.provenance import code_commit
from rabbit_policy.runtime.classic import DEFAULT_DECISION_WINDOW
from rabbit_policy.runtime.alpha_blend import BlendConfig
from rabbit_policy.runtime.memory import MemoryConfig
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS, OverlayConfig, RecoveryConfig
from rabbit_policy.runtime.speed_integral import decision_dt
from rabbit_policy.spec.files import PACKAGED, library_dir, library_hash, save_weights
from rabbit_policy.spec.schema import (SPEC_VERSION, ControllerSection, ControllerSpec, DecisionSpec,
                                       LibrarySpec, NetworkSpec, ResidualSpec, WeightsSpec,
                                       dump_spec, load_spec, parse_spec)
from rabbit_sim.physics.model import model_sha256

RESIDUAL_BOUNDS_MARGIN = 0.15
"""rad: ``actions.residual_sum_bounds``' margin on the classic base (what the checkpoints ran with)."""
RESIDUAL_KD_BOUNDS = (20.0, 150.0)
"""N m s/rad: ``actions.ActionBounds.from_library``' Kd range (what the checkpoints ran with)."""


def _library(source: str, base: Path, mode: str = "interpolate") -> LibrarySpec:
    return LibrarySpec(source, library_hash(library_dir(source, base)), mode)


def _settings(values: dict) -> ControllerSection:
    """The controller section a checkpoint ran with: ``values`` over ``ControllerSettings``'
    defaults, for the packaged robot model."""
    return ControllerSection(**replace(ControllerSettings(), **values).settings(), model_sha256=model_sha256())


def network_arrays(checkpoint) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, np.ndarray]]:
    """(weight matrices, bias vectors, the buffers offset/scale/low/high) of a checkpoint's
    ``HZDPolicyNet`` state dict."""
    state = {k: np.asarray(v.detach().numpy() if hasattr(v, "detach") else v, dtype=np.float32)
             for k, v in checkpoint.state_dict.items()}
    layers = sorted({int(k.split(".")[1]) for k in state if k.startswith("body.") and k.endswith(".weight")})
    return ([state[f"body.{i}.weight"] for i in layers], [state[f"body.{i}.bias"] for i in layers],
            {k: state[k] for k in ("offset", "scale", "low", "high")})


def learned_spec(checkpoint, out_dir: Path, name: str = "learned", source: str = PACKAGED,
                 decision: DecisionTiming = OWN, provenance: dict | None = None) -> ControllerSpec:
    """The spec of a learned policy from its checkpoint (``PolicyCheckpoint``), its weights
    written beside it in ``out_dir`` (:func:`checkpoint_spec`)."""
    weights, biases, buffers = network_arrays(checkpoint)
    file, sha = save_weights(weights, biases, out_dir, name)
    return checkpoint_spec(checkpoint.info, (weights, biases), buffers, WeightsSpec(file, sha), name, source, out_dir,
                           decision, provenance)


def checkpoint_spec(info: dict, layers: tuple[list, list], buffers: dict, weights: WeightsSpec,
                    name: str = "learned", source: str = PACKAGED, base: Path = Path("."),
                    decision: DecisionTiming = OWN, provenance: dict | None = None) -> ControllerSpec:
    """The spec of a network trained as a checkpoint's ``info`` records it (what
    ``train.py`` and ``ship_policy.py`` write): its ``layers`` (weight matrices, bias
    vectors) and ``buffers`` (offset, scale, low, high) with the memory, the residual and its
    base as recorded. The constants a checkpoint does not record are today's code defaults,
    written down here: the recovery rule's (``RecoveryConfig``) for a residual on it or an
    overlay, the overlay's policy blend (the controller's default blend) and the controller's
    at-once settings. ``decision``: as trained (own: the period the checkpoint's config
    records), once per step (an overlay then drops: the rule acts within the step) or N
    ticks. Nothing is written."""
    weights_list, _ = layers
    residual = None
    residual_base = info.get("residual_base", "classic")
    if info.get("action", "direct") == "residual":
        residual = ResidualSpec(residual_base, tuple(float(v) for v in info["residual_scale"]),
                                RESIDUAL_BOUNDS_MARGIN if residual_base == "classic" else None, RESIDUAL_KD_BOUNDS)
    network = NetworkSpec(info.get("features", "paper"), int(weights_list[0].shape[1]),
                          tuple(int(w.shape[0]) for w in weights_list[:-1]), int(weights_list[-1].shape[0]),
                          info.get("output", "sigmoid"), _floats(buffers["offset"]), _floats(buffers["scale"]),
                          _floats(buffers["low"]), _floats(buffers["high"]), residual, weights)
    integral = None
    memory = info.get("memory")
    decision_period = decision.resolve(int(info.get("config", {}).get("decision_period", 0)))
    if memory is not None:  # its dt is the time between decisions, at the timing asked for
        integral = replace(MemoryConfig.from_dict(memory).integral, dt=decision_dt(decision_period))
    overlay = blend = rule = None
    settings: dict = {}
    if residual is not None and residual_base != "classic":
        rule, settings = RecoveryConfig(), CONTROLLER_SETTINGS
    if info.get("recovery_overlay") is not None and decision_period:
        values = info["recovery_overlay"]
        overlay = OverlayConfig(float(values["fast_gate"]), float(values["hold"]), float(values.get("rise_until", 1.0)))
        if values.get("policy_blend"):
            defaults = ControllerSettings()
            blend = BlendConfig(defaults.within_step_blend, defaults.within_step_until)
        rule = RecoveryConfig()
        settings = CONTROLLER_SETTINGS if values.get("at_once") else {}
    return ControllerSpec(SPEC_VERSION, name, "learned", _library(source, base),
                          DecisionSpec(decision_period, DEFAULT_DECISION_WINDOW), integral, network, blend, rule,
                          overlay, _settings(settings), provenance or {})


def _floats(values) -> tuple[float, ...]:
    """float32 numbers as the shortest decimals that read back as the same float32 (the
    network casts them so): 0.1, not 0.10000000149011612."""
    return tuple(float(str(v)) for v in np.asarray(values, dtype=np.float32))


def upgrade_spec(path: str | Path) -> ControllerSpec:
    """Rewrite the spec file ``path`` of ``spec_version`` 1 (its ``controller`` named the
    blends alone) as version 2, in place: every other ``ControllerSettings`` field with the
    value version 1 ran with (the code's default), and the packaged robot model's hash; its
    comment lines kept. A version 2 file is left as it is. Returns the spec."""
    import yaml

    path = Path(path)
    text = path.read_text()
    data = yaml.safe_load(text)
    if not isinstance(data, dict) or data.get("spec_version") != 1:
        return load_spec(path)
    blends = data.get("controller") or {}
    data["spec_version"] = SPEC_VERSION
    data["controller"] = {k: list(v) if isinstance(v, tuple) else v
                          for k, v in asdict(_settings(blends)).items()}
    data["provenance"] = {**(data.get("provenance") or {}),
                          "upgraded": f"spec_version 1 -> {SPEC_VERSION} by convert.upgrade_spec at {code_commit()}"}
    spec = parse_spec(data)
    header = "\n".join(line[2:] if line.startswith("# ") else line.lstrip("#")
                       for line in text.splitlines() if line.startswith("#"))
    dump_spec(spec, path, header)
    return spec
