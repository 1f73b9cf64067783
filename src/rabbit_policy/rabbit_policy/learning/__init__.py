"""HZD-RL learning: the ``RabbitHZD-v0`` environment (:mod:`.env`, registered on import of
that module), Evolution Strategies (:mod:`.es`), PPO (:mod:`.ppo`), the warm start on the
classic library (:mod:`.warm_start`) and the training loop (:mod:`.training`)."""
