"""Making a controller by name: every one is its spec (:mod:`rabbit_policy.spec`), built by
:func:`~rabbit_policy.spec.build.build`: the packaged spec of a kind, a spec file, or a training
checkpoint (``.pt``, read with torch) converted to its spec in memory. ``policy_node``, the
scripts, training and evaluation get their controllers here."""

from __future__ import annotations

from pathlib import Path

from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming
from rabbit_policy.runtime.classic import LIBRARY_MODES, RateLimitedPolicy
from rabbit_policy.runtime.gait_command import Policy, PolicyUnavailable
from rabbit_policy.runtime.policies import NetworkPolicy, controller_name
from rabbit_policy.runtime.speed_integral import DEFAULT_OFFSET_LIMIT, check_gain
from rabbit_policy.spec.build import build
from rabbit_policy.spec.files import PACKAGED, file_sha256, packaged_spec, weights_spec_of
from rabbit_policy.spec.schema import SpecError, WeightsSpec, load_spec
from rabbit_policy.spec.variants import controller_spec


def checkpoint_policy(path: str | Path, decision: DecisionTiming = OWN) -> NetworkPolicy:
    """The HZD-RL network of a training checkpoint (``.pt``, read with torch) as its spec
    builds it (:func:`rabbit_policy.spec.convert.checkpoint_spec` from the checkpoint's
    ``info``, then :func:`rabbit_policy.spec.build`; nothing written). ``decision``: as
    trained (own), once per step (an overlay then drops: the rule acts within the step; the
    name says so) or every N ticks. The policy's ``checkpoint`` is the file read."""
    from rabbit_policy.runtime.network import PolicyCheckpoint  # torch is imported only when needed

    checkpoint = PolicyCheckpoint.load(path)
    if checkpoint.info.get("action") == "spec":
        raise ValueError(f"a run of train.py --spec: its policy is {Path(path).with_suffix('.yaml').name}, the "
                         "spec with these weights (this file records the run)")
    return policy_of_checkpoint(checkpoint, Path(path).name, decision)


def policy_of_checkpoint(checkpoint, name: str, decision: DecisionTiming = OWN) -> NetworkPolicy:
    """:func:`checkpoint_policy` of a ``PolicyCheckpoint`` in memory (a run being trained):
    ``name`` names it."""
    from rabbit_policy.spec.convert import checkpoint_spec, network_arrays  # checkpoints only: not the node's

    info = checkpoint.info
    weights, biases, buffers = network_arrays(checkpoint)
    spec = checkpoint_spec(info, (weights, biases), buffers, WeightsSpec(*weights_spec_of(weights, biases)),
                           Path(name).stem, PACKAGED, Path("."), decision, {"checkpoint": name})
    dropped = info.get("recovery_overlay") is not None and spec.overlay is None
    policy = build(spec, weights=(weights, biases),
                   source=name + (" (no recovery rule: once per step)" if dropped else ""))
    policy.checkpoint = checkpoint
    return policy


def make_policy(kind: str = "classic", gait_dir: str | Path | None = None, mode: str = "interpolate",
                policy_file: str | Path | None = None, max_command_step: float = 0.0,
                decision: DecisionTiming = OWN, speed_integral: float = 0.0,
                integral_offset_limit: float = DEFAULT_OFFSET_LIMIT) -> Policy:
    """Build a policy by name; raises :class:`PolicyUnavailable` / ``ValueError`` with a
    message a user can act on. Every controller is its spec (:mod:`rabbit_policy.spec`): the
    packaged one of ``kind``, or the spec ``policy_file`` (``.yaml``, of that kind:
    :func:`spec_kind` says which), with the options below written into it, then built by
    :func:`rabbit_policy.spec.build`. A training checkpoint (``policy_file`` ``.pt``, learned
    only) is read with torch and built as its spec (:func:`checkpoint_policy`).
    ``max_command_step`` > 0 wraps it in a :class:`RateLimitedPolicy` (m/s per step; 0: no
    limit). ``decision``: the spec's own timing (classic every 20 ticks; learned as
    trained), once per step, or every N ticks. ``speed_integral`` > 0 (1/s, classic only):
    Westervelt's event-based speed integral with that gain, its offset within
    +-``integral_offset_limit`` m/s (see :class:`LibraryPolicy`)."""
    if not isinstance(decision, DecisionTiming):
        raise ValueError(f"decision must be a DecisionTiming (own, step or N ticks), got {decision!r}")
    check_gain(speed_integral, "the speed integral gain")
    kind = controller_name(kind)
    if kind != "classic" and speed_integral:
        raise ValueError("the speed integral is the classic controller's (Westervelt's event-based PI); a learned "
                         "policy with memory features carries its own")
    if policy_file and is_spec_file(policy_file):
        file_kind = spec_kind(policy_file)
        if file_kind != kind:
            raise PolicyUnavailable(f"controller spec {policy_file} is a {file_kind} controller, not {kind} (the kind "
                                    "is the file's: --spec FILE, spec_file:=FILE)")
    elif kind != "learned" and policy_file:
        raise ValueError("a training checkpoint is a learned policy's: it is for the learned controller "
                         "(policy:=learned, --controller learned); the classic one uses gait_dir")
    if kind == "learned" and gait_dir:
        raise ValueError("a gait directory is the classic controller's library: the learned one takes a policy "
                         "file (policy_file, --policy-file)")
    if mode not in LIBRARY_MODES:
        raise ValueError(f"library mode must be one of {LIBRARY_MODES}, got {mode!r}")
    if kind == "learned" and mode != "interpolate":
        raise ValueError("the library mode is classic's (and recovery's): a learned controller's gaits are the "
                         "calibrated blend with its residual")
    if kind == "learned" and policy_file and not is_spec_file(policy_file):
        policy = _checkpoint(policy_file, decision)  # a training checkpoint: it carries its decision period
    else:
        try:
            spec, base, source = controller_spec(kind, gait_dir, mode, policy_file, decision, speed_integral,
                                                 integral_offset_limit)
            policy = build(spec, base, source=source)
        except SpecError as exc:
            raise PolicyUnavailable(str(exc)) from None
    if max_command_step:
        policy = RateLimitedPolicy(policy, max_command_step)
    return policy


def is_spec_file(path: str | Path) -> bool:
    """A controller spec (YAML or JSON), not a training checkpoint."""
    return Path(path).suffix.lower() in (".yaml", ".yml", ".json")


def spec_record(kind: str, policy_file: str | Path | None = None) -> dict[str, str]:
    """The file a controller was built from, ``{"file", "sha256"}``: ``policy_file`` (a spec or
    a checkpoint), else the packaged spec of ``kind`` (a run's JSON names what ran)."""
    path = Path(policy_file) if policy_file else packaged_spec(controller_name(kind))
    return {"file": str(path.resolve()), "sha256": file_sha256(path)}


def spec_kind(path: str | Path) -> str:
    """The kind of controller the spec file ``path`` is (``classic``, ``recovery``,
    ``learned``); :class:`PolicyUnavailable` with one line for a file that is not a spec."""
    try:
        return load_spec(Path(path)).kind
    except SpecError as exc:
        raise PolicyUnavailable(str(exc)) from None


def _checkpoint(policy_file: str | Path, decision: DecisionTiming) -> NetworkPolicy:
    """The learned policy from the training checkpoint ``policy_file``."""
    path = Path(policy_file)
    if not path.is_file():
        raise PolicyUnavailable(f"policy file {path} does not exist")
    try:
        return checkpoint_policy(path, decision)
    except Exception as exc:  # noqa: BLE001 - any file that is not a checkpoint: torch raises many kinds
        raise PolicyUnavailable(f"cannot load policy file {path}: not a policy checkpoint "
                                f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
