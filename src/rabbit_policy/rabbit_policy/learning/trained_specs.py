"""Controller specs that training writes: a start whose network is restarted (the spec's rules on
the library alone) and a spec carrying a trained network's weights. Both need torch; the node
never imports this module."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rabbit_policy.learning.warm_start import restart_network
from rabbit_policy.runtime.forward import NetworkForward
from rabbit_policy.runtime.network import spec_network
from rabbit_policy.spec.build import load_controller
from rabbit_policy.spec.files import PACKAGED, library_dir, save_weights
from rabbit_policy.spec.provenance import code_commit
from rabbit_policy.spec.schema import ControllerSpec, WeightsSpec, dump_spec, load_spec


def restarted_spec(spec_file: str | Path, seed: int, path: Path) -> ControllerSpec:
    """Write the learned spec ``spec_file`` with its network restarted as ``path``: the same
    stages and constants, fresh hidden layers drawn from ``seed`` and a zero last layer
    (:func:`rabbit_policy.learning.warm_start.restart_network`). A residual spec's network
    then adds exactly 0: the spec's rules acting on the library alone, a documented start
    for training (``reproduce.py``'s ``start: zero``)."""
    source = Path(spec_file).resolve()
    net = restart_network(spec_network(load_controller(source).forward), seed)
    return trained_spec(source, net, path, {"written_by": "rabbit_policy.learning.trained_specs.restarted_spec",
                                            "from": f"{source.name} with its network restarted (seed {seed}: fresh "
                                                    "hidden layers, a zero last layer)"})


def trained_spec(spec_file: str | Path, net, path: Path, provenance: dict) -> ControllerSpec:
    """Write the spec ``spec_file`` with ``net``'s weights (a torch ``HZDPolicyNet`` trained
    from it) as ``path``, its weights file beside it; the gait library by an absolute path
    unless packaged. Returns the spec written."""
    source = Path(spec_file).resolve()
    spec = load_spec(source)
    forward = NetworkForward.of(net)
    file, sha = save_weights(list(forward.weights), list(forward.biases), path.parent, path.stem)
    library = spec.gait_library
    if library.source != PACKAGED:
        library = replace(library, source=str(library_dir(library.source, source.parent)))
    trained = replace(spec, gait_library=library,
                      network=replace(spec.network, weights=WeightsSpec(file, sha)),
                      provenance={**provenance, "from_spec": str(source), "code_commit": code_commit()})
    dump_spec(trained, path, f"{spec.name}, trained from {source.name} (rabbit_policy.learning.trained_specs.trained_spec)")
    return trained
