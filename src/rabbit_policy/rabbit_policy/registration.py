"""``RabbitHZD-v0`` (the paper's problem), the ids of the runs we ship and train
(:data:`PRESET_IDS`: ``RabbitHZD-Shipped-v0``, the shipped policy's episodes;
``RabbitHZD-Recovery-v0``, the push-recovery residual's) and of the shipped learned spec's
loop (:data:`SPEC_IDS`: ``RabbitHZD-Learned-v1``) in Gymnasium's registry once
``rabbit_policy`` is imported, at no cost to
what does not use Gymnasium (``policy_node``): the id is registered by entry-point string
(the env module is imported only by ``gymnasium.make``), at once if Gymnasium is imported
already, else as soon as it is (a one-shot import hook on ``sys.meta_path``). Gymnasium 1.x reads
no package entry points (its 0.x ``gymnasium.envs`` plugin group is gone; 1.4 has no
``importlib.metadata`` lookup), so a package cannot register there; importing Gymnasium here
instead would load it into every node."""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys

ENV_ID = "RabbitHZD-v0"
ENTRY_POINT = "rabbit_policy.learning.env:RabbitHZDEnv"
MAX_EPISODE_STEPS = 60
"""The spec's episode length (env steps), the env's own default (``learning.env.DEFAULT_MAX_STEPS``)."""
PRESET_IDS = {"RabbitHZD-Shipped-v0": "shipped", "RabbitHZD-Recovery-v0": "recovery"}
"""id -> ``learning.env.PRESETS`` name; their episodes are 500 env steps (10 s of sim time)."""
PRESET_EPISODE_STEPS = 500
SPEC_IDS = {"RabbitHZD-Learned-v1": "rabbit_policy.learning.spec_env:SpecEnv"}
"""id -> entry point of the envs built from a controller spec: the shipped learned controller's
closed loop with the network as the agent (``spec=`` another learned spec); 500 decisions."""


def register(gymnasium_module) -> None:
    """Register :data:`ENV_ID` and :data:`PRESET_IDS` with this Gymnasium (once), each with the
    :class:`~rabbit_policy.learning.env.EpisodeLength` wrapper after its TimeLimit."""
    from gymnasium.envs.registration import WrapperSpec

    length = (WrapperSpec("EpisodeLength", "rabbit_policy.learning.env:EpisodeLength", {}),)
    if ENV_ID not in gymnasium_module.registry:
        gymnasium_module.register(id=ENV_ID, entry_point=ENTRY_POINT, max_episode_steps=MAX_EPISODE_STEPS,
                                  additional_wrappers=length)
    for env_id, entry_point in SPEC_IDS.items():
        if env_id not in gymnasium_module.registry:
            gymnasium_module.register(id=env_id, entry_point=entry_point, max_episode_steps=PRESET_EPISODE_STEPS,
                                      additional_wrappers=length)
    for env_id, preset in PRESET_IDS.items():
        if env_id not in gymnasium_module.registry:
            gymnasium_module.register(id=env_id, entry_point="rabbit_policy.learning.env:make_preset",
                                      kwargs={"preset": preset}, max_episode_steps=PRESET_EPISODE_STEPS,
                                      additional_wrappers=length)


class _RegisterWhenImported(importlib.abc.MetaPathFinder):
    """Finds ``gymnasium`` the usual way and registers the env right after it is executed."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)  # one shot, and not in the way of the normal search below
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        execute = spec.loader.exec_module

        def exec_module(module) -> None:
            execute(module)
            register(module)

        spec.loader.exec_module = exec_module
        return spec


def register_when_gymnasium_is_imported() -> None:
    """See the module docstring (called by ``rabbit_policy/__init__``)."""
    if "gymnasium" in sys.modules:
        register(sys.modules["gymnasium"])
    elif not any(isinstance(finder, _RegisterWhenImported) for finder in sys.meta_path):
        sys.meta_path.insert(0, _RegisterWhenImported())
