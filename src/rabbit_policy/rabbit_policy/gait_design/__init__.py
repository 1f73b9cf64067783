"""Classic HZD gait design: the CMA-ES shooting optimizer (:mod:`.optimization`) and its
seed postures (:mod:`.seed`) that made the packaged gait library."""
