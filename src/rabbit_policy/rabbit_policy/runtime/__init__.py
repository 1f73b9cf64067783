"""What ``policy_node`` runs: observation (:mod:`.speed_window`) -> gait policy
(:mod:`.policies`: the classic :mod:`.gait_library` or the learned :mod:`.network`) ->
alpha, Kd."""
